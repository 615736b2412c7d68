"""CPU time of single threads and processes, in ns, from the kernel's own counters (Linux /proc).

A task's figure is its `sum_exec_runtime`, the first field of /proc/<pid>/task/<tid>/schedstat: the
nanoseconds it ran on a CPU, user and system, the counter its CPU-time clock
(`time.pthread_getcpuclockid`) reads. Unlike utime and stime in /proc/.../stat it is not rounded to
clock ticks (10 ms), so a thread using 5 ms of a 1 s window is resolved. Any thread may read any
thread of a process it may read (a benchmark reads the node's from outside); a read opens a file
(~5 µs): meant for once per report, never per step. Here because the recorder counts its own CPU
with it (log/ imports nothing else of finger_sim); the node and the benchmarks use it too.
"""

from __future__ import annotations

import ctypes
import os

__all__ = ["name_os_thread", "process_cpu_ns", "task_cpu_ns", "threads_cpu_ns"]

_PR_SET_NAME = 15  # prctl(2): the calling thread's name, as `top -H`, /proc/<pid>/task/<tid>/comm show it
_OS_NAME_BYTES = 15  # the kernel's TASK_COMM_LEN less the terminating NUL
_READ_BYTES = 256  # more than a schedstat or comm file holds


def _read(path: str) -> bytes:
    """A small /proc file's bytes (os.read: a fifth of the cost of Path.read_text)."""
    fd = os.open(path, os.O_RDONLY)
    try:
        return os.read(fd, _READ_BYTES)
    finally:
        os.close(fd)


def task_cpu_ns(pid: int, tid: int) -> int | None:
    """CPU ns thread `tid` of process `pid` has run so far; None once it has ended (or not on Linux)."""
    try:
        return int(_read(f"/proc/{pid}/task/{tid}/schedstat").split()[0])
    except (OSError, ValueError, IndexError):
        return None


def threads_cpu_ns(pid: int, *, names: bool = True) -> dict[int, tuple[str, int]]:
    """Every living thread of process `pid`: tid → (its OS name, or '' without `names`; CPU ns so far).
    Empty once the process has ended."""
    out: dict[int, tuple[str, int]] = {}
    try:
        tids = os.listdir(f"/proc/{pid}/task")
    except OSError:
        return out
    for tid in tids:
        try:
            name = _read(f"/proc/{pid}/task/{tid}/comm").decode(errors="replace").rstrip("\n") if names else ""
            out[int(tid)] = (name, int(_read(f"/proc/{pid}/task/{tid}/schedstat").split()[0]))
        except (OSError, ValueError, IndexError):  # the thread ended meanwhile
            continue
    return out


def process_cpu_ns(pid: int) -> int | None:
    """CPU ns the living threads of process `pid` have run so far (a single-purpose child such as the
    log writer, whose threads live as long as it does); None once it has ended."""
    threads = threads_cpu_ns(pid, names=False)
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
