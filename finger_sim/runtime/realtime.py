"""Real-time scheduling of a stepping node, when it is started under a real-time policy.

A real-time simulation is deployed under SCHED_FIFO or SCHED_RR (`chrt -f 20 finger_node ...`).
Every thread and child process then inherits the same policy and priority, so on a machine with
few cores the stepping thread queues behind its own node's other work at equal priority (the
log's writer process compressing a chunk, the executor and DDS threads), and the kernel may page
out the node's code and data that a rare path needs (a major page fault is a disk read). With a
real-time policy, `prepare_process()` and `prepare_stepping_thread()` set the node up as a
real-time program should be:

- memory locked as it is touched (mlockall with MCL_ONFAULT: a page the node has used stays
  resident and is never paged out, and the libraries' untouched pages are not read in);
- the interpreter's switch interval at SWITCH_INTERVAL_S: a thread that wants the GIL (the
  stepping thread, woken for its step) asks the holder (the executor thread in a callback, a
  garbage collection) to hand it over after this long, instead of Python's 5 ms;
- the stepping thread one priority above the process (STEPPING_BOOST), the only thread there;
- child processes started so far (the log's writer process) one priority below it
  (CHILD_DROP), still above every normal process, so that the log keeps up under load.

One thing is the machine's, not the node's: real-time throttling (kernel.sched_rt_runtime_us
below kernel.sched_rt_period_us, 950 ms of 1 s by default). Once the real-time threads of a CPU
have run that long in a period, the kernel stops them all until it ends, up to 50 ms: a step
that late, whatever the priorities. The node says so in a warning with the two values (RT_SYSCTL),
and leaves the setting alone (it is the whole machine's).

Under a normal policy nothing changes, and nothing does with FINGER_SIM_REALTIME_SETUP=0 in the
environment (a deployment that sets priorities itself, or a side-by-side comparison; one info
line says so). Each step that the kernel refuses (no privilege: neither root nor CAP_SYS_NICE /
CAP_IPC_LOCK, or RLIMIT_RTPRIO / RLIMIT_MEMLOCK too small) is skipped and named in one warning;
the node runs on without it. Linux only (os.sched_*, mlockall, /proc): elsewhere nothing is done.
docs/soak_realtime.md has the measurements behind each step.
"""

from __future__ import annotations

import contextlib
import ctypes
import ctypes.util
import os
import sys
import threading
from collections.abc import Callable
from pathlib import Path

#: Priorities the stepping thread is raised above the process's real-time priority.
STEPPING_BOOST = 1
#: Priorities a child process (the log's writer) is lowered below the process's own.
CHILD_DROP = 1
#: mlockall flags (linux/mman.h): lock what is mapped now and whatever is mapped later, each page
#: once it is first touched (Linux >= 4.4).
MCL_CURRENT, MCL_FUTURE, MCL_ONFAULT = 1, 2, 4
#: Wall s a thread waits for the GIL before the holder is asked to hand it over (Python's default
#: is 5 ms: a step due at 1 kHz waited up to that long behind the executor thread).
SWITCH_INTERVAL_S = 0.0005
#: The real-time policies (os.SCHED_FIFO, os.SCHED_RR; absent off Linux).
REALTIME_POLICIES = {getattr(os, "SCHED_FIFO", -1), getattr(os, "SCHED_RR", -2)}

#: The kernel's real-time throttling: runtime and period, µs (runtime -1: off).
RT_SYSCTL = Path("/proc/sys/kernel/sched_rt_runtime_us"), Path("/proc/sys/kernel/sched_rt_period_us")
#: What lifts the kernel's refusals, for the log line.
PRIVILEGE_HINT = "run as root, or grant CAP_SYS_NICE and CAP_IPC_LOCK, or raise RLIMIT_RTPRIO and RLIMIT_MEMLOCK"
#: Environment variable that turns the set-up off when "0".
SETUP_ENV = "FINGER_SIM_REALTIME_SETUP"

Log = Callable[[str], None]


def prepare(info: Log, warn: Log) -> None:
    """Called by the stepping thread before its first step: `prepare_process()`, then
    `prepare_stepping_thread()` (see the module doc); logs what it did and what it could not."""
    if os.environ.get(SETUP_ENV) == "0":
        if realtime_priority() is not None:
            info(f"real-time policy at priority {realtime_priority()}; {SETUP_ENV}=0: scheduling and memory left as inherited")
        return
    prepare_stepping_thread(prepare_process(info, warn), info, warn)


def realtime_priority() -> int | None:
    """The calling thread's real-time priority (1..99), or None under a normal policy or off Linux."""
    if not hasattr(os, "sched_getscheduler"):
        return None
    if os.sched_getscheduler(0) not in REALTIME_POLICIES:
        return None
    return os.sched_getparam(0).sched_priority


def lock_memory() -> str | None:
    """mlockall(MCL_CURRENT | MCL_FUTURE | MCL_ONFAULT); None when done, else why not (the errno's text)."""
    libc = ctypes.CDLL(ctypes.util.find_library("c"), use_errno=True)
    if libc.mlockall(MCL_CURRENT | MCL_FUTURE | MCL_ONFAULT) != 0:
        errno = ctypes.get_errno()
        return f"mlockall failed: {os.strerror(errno)} (errno {errno})"
    return None


def throttling() -> str | None:
    """Why real-time threads may be stopped for part of each period, or None (throttling off)."""
    try:
        runtime, period = (int(p.read_text()) for p in RT_SYSCTL)
    except (OSError, ValueError):
        return None
    if runtime < 0 or runtime >= period:
        return None
    return (f"kernel.sched_rt_runtime_us is {runtime} of kernel.sched_rt_period_us {period}: once the real-time threads "
            f"of a CPU have run {runtime / 1e3:g} ms in a period, the kernel stops them for up to {(period - runtime) / 1e3:g} ms "
            "(a step that late); a real-time run sets it to -1 (sysctl, root)")


def child_pids() -> list[int]:
    """Process ids of this process's children (any thread's), from /proc."""
    pids = []
    for children in Path("/proc/self/task").glob("*/children"):
        with contextlib.suppress(OSError):  # a thread that ended meanwhile
            pids += [int(pid) for pid in children.read_text().split()]
    return pids


def prepare_process(info: Log, warn: Log) -> int | None:
    """Under a real-time policy: lock the memory and lower the child processes (see the module
    doc). Returns the process's real-time priority, None under a normal policy (nothing done)."""
    if not sys.platform.startswith("linux"):
        return None
    priority = realtime_priority()
    if priority is None:
        return None
    done, skipped = [], []
    problem = lock_memory()
    (skipped if problem else done).append(problem or "memory locked as touched (mlockall)")
    sys.setswitchinterval(SWITCH_INTERVAL_S)
    done.append(f"GIL switch interval {SWITCH_INTERVAL_S * 1e3:g} ms")
    policy = os.sched_getscheduler(0)
    child = max(priority - CHILD_DROP, 1)
    for pid in child_pids():
        try:
            os.sched_setscheduler(pid, policy, os.sched_param(child))
            done.append(f"child process {pid} at priority {child}")
        except OSError as exc:
            skipped.append(f"child process {pid} stays at priority {priority}: {exc.strerror}")
    info(f"real-time policy at priority {priority}: " + "; ".join(done))
    if (why := throttling()) is not None:
        warn(why)
    if skipped:
        warn("real-time set-up incomplete, late steps under load are likelier: " + "; ".join(skipped) + f" ({PRIVILEGE_HINT})")
    return priority


def prepare_stepping_thread(priority: int | None, info: Log, warn: Log) -> None:
    """In the stepping thread: raise it STEPPING_BOOST above the process's real-time `priority`
    (None: a normal policy, nothing done)."""
    if priority is None:
        return
    boosted = min(priority + STEPPING_BOOST, os.sched_get_priority_max(os.sched_getscheduler(0)))
    try:
        os.sched_setscheduler(threading.get_native_id(), os.sched_getscheduler(0), os.sched_param(boosted))
    except OSError as exc:
        warn(f"the stepping thread stays at real-time priority {priority} (raising it to {boosted}: {exc.strerror}); "
             f"late steps under load are likelier ({PRIVILEGE_HINT})")
        return
    info(f"the stepping thread runs at real-time priority {boosted}")
