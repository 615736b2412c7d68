"""finger_sim.runtime.stall_trace: its rows against what the test itself timed and caused.

References: a collection forced by gc.collect(2) and timed here with perf_counter; a stall made
here by sleeping past the due time, timed here; the thread's own run time from
time.thread_time() (an independent clock of the same kernel counter's owner)."""

from __future__ import annotations

import csv
import gc
import sys
import threading
import time

import pytest

from finger_sim.bench.soak_report import cause
from finger_sim.runtime import stall_trace

#: Slack for the gaps between the trace's clock readings and the test's, ms.
SLACK_MS = 2.0
#: Lateness and run-queue waits against a thread's GIL hold: in make test's half at normal priority.
pytestmark = pytest.mark.timing


def rows(directory, prefix):
    [path] = directory.glob(f"{prefix}_*.csv")
    return list(csv.DictReader(path.open()))


@pytest.fixture
def trace(tmp_path):
    t = stall_trace.StallTrace(tmp_path)
    yield t
    gc.callbacks.remove(t._on_gc)


def test_a_late_wakeup_covered_by_a_collection_is_named_gc(trace, tmp_path):
    garbage = [[i] for i in range(20_000)]  # a collection with something to walk
    due = time.perf_counter()
    trace.sleeping(due)
    wall0 = time.time()
    t0 = time.perf_counter()
    gc.collect(2)
    t1 = time.perf_counter()
    time.sleep(0.012)
    trace.woke()
    t2 = time.perf_counter()
    trace.flush()
    del garbage
    [stall] = rows(tmp_path, "stalls")
    assert (t1 - due) * 1e3 + 10 <= float(stall["late_ms"]) <= (t2 - due) * 1e3
    gen2 = [r for r in rows(tmp_path, "gc") if r["generation"] == "2" and float(r["wall_s"]) >= wall0]
    assert len(gen2) == 1 and 0 < float(gen2[0]["duration_ms"]) <= (t1 - t0) * 1e3
    assert float(stall["gc_ms"]) == pytest.approx(float(gen2[0]["duration_ms"]), abs=0.01)
    assert float(stall["blocked_ms"]) == pytest.approx(float(stall["late_ms"]) - float(stall["runqueue_ms"]), abs=0.002)


def test_a_thread_holding_the_gil_shows_as_blocked_and_by_name(trace, tmp_path):
    """A thread spinning in Python for 40 ms wakes the traced one as it starts: the traced one, due 1 ms after it
    went to sleep, gets the GIL only after the spin, late, blocked (the GIL), not in a collection, and the spinner
    is listed where it was. The traced thread waits for the spinner's wake-up rather than sleeping a fixed 1 ms,
    so the spinner holds the GIL however late the machine schedules it (at nice 19 under load it can miss 1 ms)."""
    go, spinning, done = threading.Event(), threading.Event(), threading.Event()

    def spin() -> None:
        go.wait()
        end = time.perf_counter() + 0.04
        spinning.set()  # wakes the traced thread, which then waits for the GIL this thread keeps
        while time.perf_counter() < end:
            pass
        done.wait()  # still there, waiting, when the traced thread wakes

    spinner = threading.Thread(target=spin, name="spinner")
    spinner.start()
    old = sys.getswitchinterval()
    sys.setswitchinterval(0.1)  # the spinner keeps the GIL for its whole 40 ms
    try:
        cpu0 = time.thread_time()
        due = time.perf_counter() + 0.001
        trace.sleeping(due)
        go.set()
        spinning.wait()
        woke_before = time.perf_counter()
        trace.woke()
        woke = time.perf_counter()
        cpu1 = time.thread_time()
    finally:
        sys.setswitchinterval(old)
        done.set()
        spinner.join()
    trace.flush()
    [stall] = rows(tmp_path, "stalls")
    assert (woke_before - due) * 1e3 <= float(stall["late_ms"]) <= (woke - due) * 1e3  # read between the two
    assert float(stall["late_ms"]) >= 20
    assert float(stall["gc_ms"]) == 0
    assert float(stall["run_ms"]) <= (cpu1 - cpu0) * 1e3 + SLACK_MS
    assert cause(stall) == "blocked"
    assert "spinner@threading.py:" in stall["others"]  # in done.wait()


def test_an_early_wakeup_writes_nothing(trace, tmp_path):
    """Woken before the step is due (a service request does that): no stall."""
    trace.sleeping(time.perf_counter() + 1.0)
    trace.woke()
    trace.flush()
    assert rows(tmp_path, "stalls") == []


def test_off_without_the_environment_variable(monkeypatch):
    monkeypatch.delenv(stall_trace.TRACE_ENV, raising=False)
    assert stall_trace.from_environment() is None
