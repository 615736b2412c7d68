"""Stall trace for soaks (opt-in): what held the stepping thread when it woke late.

Set FINGER_SIM_STALL_TRACE=<directory> and the node's stepping loop writes two CSV files there
(one pair per process, `<pid>` in the name), flushed every FLUSH_PERIOD_S by a daemon thread:

- `gc_<pid>.csv`: every garbage collection of generation >= 1, and any of generation 0 that
  took >= GC_ROW_MIN_S: wall time at its start (time.time(), s), generation, duration (ms),
  objects collected, the thread that ran it.
- `stalls_<pid>.csv`: every wake-up of the paced loop at least STALL_MIN_S after the step it
  slept for was due: wall time of the wake-up (s), lateness (ms); from
  /proc/thread-self/schedstat over the sleep: the stepping thread's run time and run-queue wait
  (ms); the lateness neither explains (`blocked_ms` = lateness - run-queue wait, the time the
  thread was woken late or blocked on a lock, e.g. the GIL, after its timer fired);
  the milliseconds of the stall a garbage collection of this process overlapped (`gc_ms`);
  and where every other Python thread was on the wake-up (`others`: name@file:line, `|`-separated).

A late wake-up with `gc_ms` near its lateness was a collection (it holds the GIL); one with a
large `blocked_ms` and no gc is another thread's GIL hold (its thread in `others`, its CPU in
soak_probe's samples) or the kernel; one with a large run-queue wait is scheduling.
"""

from __future__ import annotations

import gc
import os
import sys
import threading
import time
from pathlib import Path
from typing import Any

#: Environment variable naming the directory to write to; unset or empty: no trace.
TRACE_ENV = "FINGER_SIM_STALL_TRACE"
#: A wake-up this late (wall s) is written (half the 10 ms that pulls a window below 0.99).
STALL_MIN_S = 0.005
#: A generation-0 collection this long (wall s) is written (all of generations 1 and 2 are).
GC_ROW_MIN_S = 0.0005
#: How often the rows are written out, wall s.
FLUSH_PERIOD_S = 1.0
#: Collections kept for matching against stalls (the last ones; a stall is matched at once).
GC_KEEP = 64
SCHEDSTAT = "/proc/thread-self/schedstat"
GC_HEADER = "wall_s,generation,duration_ms,collected,thread\n"
STALL_HEADER = "wall_s,late_ms,run_ms,runqueue_ms,blocked_ms,gc_ms,others\n"


#: Bytes read from schedstat (three decimal counters of at most 20 digits).
SCHEDSTAT_BYTES = 80


def schedstat(fd: int) -> tuple[int, int]:
    """(run ns, run-queue wait ns) since it started of the thread that opened `fd` on SCHEDSTAT."""
    run, wait, _ = os.pread(fd, SCHEDSTAT_BYTES, 0).split()
    return int(run), int(wait)


class StallTrace:
    """gc callback and wake-up probe for one process; see the module doc."""

    def __init__(self, directory: Path) -> None:
        directory.mkdir(parents=True, exist_ok=True)
        pid = os.getpid()
        self._gc_file = (directory / f"gc_{pid}.csv").open("w")
        self._stall_file = (directory / f"stalls_{pid}.csv").open("w")
        self._gc_file.write(GC_HEADER)
        self._stall_file.write(STALL_HEADER)
        self._gc_rows: list[str] = []
        self._stall_rows: list[str] = []
        self._recent_gc: list[tuple[float, float]] = []  # (perf_counter start, end) s, newest last
        self._gc_start = (0.0, 0.0)  # (perf_counter, time.time()) of the running collection
        self._due = 0.0
        self._sched = (0, 0)
        self._schedstat_fd: int | None = None  # opened by the stepping thread (thread-self is the opener)
        gc.callbacks.append(self._on_gc)
        threading.Thread(target=self._flush_forever, name="stall-trace", daemon=True).start()

    def _on_gc(self, phase: str, info: dict[str, Any]) -> None:
        now = time.perf_counter()
        if phase == "start":
            self._gc_start = (now, time.time())
            return
        start, wall = self._gc_start
        self._recent_gc = self._recent_gc[-GC_KEEP + 1:] + [(start, now)]
        if info["generation"] >= 1 or now - start >= GC_ROW_MIN_S:
            self._gc_rows.append(f"{wall:.6f},{info['generation']},{(now - start) * 1e3:.3f},{info['collected']},"
                                 f"{threading.current_thread().name}\n")

    def sleeping(self, due: float) -> None:
        """The stepping thread is about to sleep until `due` (perf_counter s)."""
        self._due = due
        if self._schedstat_fd is None:
            self._schedstat_fd = os.open(SCHEDSTAT, os.O_RDONLY)
        self._sched = schedstat(self._schedstat_fd)

    def woke(self) -> None:
        """The stepping thread is back from the sleep begun at the last `sleeping()`."""
        now = time.perf_counter()
        late = now - self._due
        if late < STALL_MIN_S:
            return
        run, wait = schedstat(self._schedstat_fd)
        run_ms, queue_ms = (run - self._sched[0]) * 1e-6, (wait - self._sched[1]) * 1e-6
        gc_ms = sum(max(0.0, min(end, now) - max(start, self._due)) for start, end in self._recent_gc) * 1e3
        names = {t.ident: t.name for t in threading.enumerate()}
        me = threading.get_ident()
        others = "|".join(f"{names.get(ident, ident)}@{Path(f.f_code.co_filename).name}:{f.f_lineno}"
                          for ident, f in sys._current_frames().items() if ident != me)
        self._stall_rows.append(f"{time.time():.6f},{late * 1e3:.3f},{run_ms:.3f},{queue_ms:.3f},"
                                f"{late * 1e3 - queue_ms:.3f},{gc_ms:.3f},{others.replace(',', ';')}\n")

    def _flush_forever(self) -> None:
        while True:
            time.sleep(FLUSH_PERIOD_S)
            self.flush()

    def flush(self) -> None:
        """Write out the rows gathered so far."""
        for rows, out in ((self._gc_rows, self._gc_file), (self._stall_rows, self._stall_file)):
            taken = rows[:]
            del rows[:len(taken)]  # rows appended meanwhile stay for the next flush
            out.write("".join(taken))
            out.flush()


def from_environment() -> StallTrace | None:
    """A StallTrace writing to $FINGER_SIM_STALL_TRACE, or None when it is unset or empty."""
    directory = os.environ.get(TRACE_ENV, "")
    return StallTrace(Path(directory)) if directory else None
