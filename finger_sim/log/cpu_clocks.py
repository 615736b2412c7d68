"""CPU time of single threads and processes, in ns, from the kernel's own counters (Linux /proc).

A task's figure is its `sum_exec_runtime`, the first field of /proc/<pid>/task/<tid>/schedstat: the
nanoseconds it ran on a CPU, user and system, the counter its CPU-time clock
(`time.pthread_getcpuclockid`) reads. Unlike utime and stime in /proc/.../stat it is not rounded to
clock ticks (10 ms), so a thread using 5 ms of a 1 s window is resolved. Any thread may read any
thread of a process it may read (a benchmark reads the node's from outside); a read opens a file
(~10 µs): meant for once per report, never per step. Here because the recorder counts its own CPU
with it (log/ imports nothing else of finger_sim); the node and the benchmarks use it too.
"""

from __future__ import annotations

import ctypes
from pathlib import Path

__all__ = ["name_os_thread", "process_cpu_ns", "task_cpu_ns", "threads_cpu_ns"]

_PR_SET_NAME = 15  # prctl(2): the calling thread's name, as `top -H`, /proc/<pid>/task/<tid>/comm show it
_OS_NAME_BYTES = 15  # the kernel's TASK_COMM_LEN less the terminating NUL


def task_cpu_ns(pid: int, tid: int) -> int | None:
    """CPU ns thread `tid` of process `pid` has run so far; None once it has ended (or not on Linux)."""
    try:
        return int(Path(f"/proc/{pid}/task/{tid}/schedstat").read_text().split()[0])
    except (OSError, ValueError, IndexError):
        return None


def threads_cpu_ns(pid: int) -> dict[int, tuple[str, int]]:
    """Every living thread of process `pid`: tid → (its OS name, CPU ns so far). Empty once it has ended."""
    out: dict[int, tuple[str, int]] = {}
    try:
        tasks = list(Path(f"/proc/{pid}/task").iterdir())
    except OSError:
        return out
    for task in tasks:
        try:
            name = (task / "comm").read_text().rstrip("\n")
            out[int(task.name)] = (name, int((task / "schedstat").read_text().split()[0]))
        except (OSError, ValueError, IndexError):  # the thread ended meanwhile
            continue
    return out


def process_cpu_ns(pid: int) -> int | None:
    """CPU ns the living threads of process `pid` have run so far (a single-purpose child such as the
    log writer, whose threads live as long as it does); None once it has ended."""
    threads = threads_cpu_ns(pid)
    return sum(ns for _, ns in threads.values()) if threads else None


def name_os_thread(name: str) -> None:
    """Give the calling thread `name` (its first 15 bytes) as the operating system shows it (`top -H`,
    `perf`, /proc/<pid>/task/<tid>/comm), so that a thread's CPU can be told from the others'.
    Python's own thread names stay inside Python (before 3.14). Does nothing where prctl is missing."""
    try:
        prctl = ctypes.CDLL(None).prctl  # the C library the interpreter is linked with
    except (AttributeError, OSError):  # not Linux
        return
    prctl(_PR_SET_NAME, name.encode()[:_OS_NAME_BYTES], 0, 0, 0)
