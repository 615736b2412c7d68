"""The bench's timing repeats: a long first run is timed once, a short one at least SHORT_RUN_REPEATS times (its
median of three moved by a third between benches), the rest `repeats` times, for every runner alike."""

from __future__ import annotations

from finger_sim.bench.runners import LONG_RUN_SECONDS, SHORT_RUN_REPEATS, SHORT_RUN_SECONDS, _timed, repeats_after


def test_repeats_follow_the_first_runs_cpu() -> None:
    assert repeats_after(LONG_RUN_SECONDS * 1.5, 3) == 1
    assert repeats_after(SHORT_RUN_SECONDS / 2, 3) == SHORT_RUN_REPEATS
    assert repeats_after(SHORT_RUN_SECONDS / 2, 40) == 40
    assert repeats_after(0.1, 3) == 3


def test_a_short_run_is_timed_short_run_repeats_times() -> None:
    calls: list[int] = []
    result, cpu, done = _timed(lambda: calls.append(1) or len(calls), 3)  # a call of ~1 µs: far under 5 ms
    assert (result, done, len(calls)) == (1, SHORT_RUN_REPEATS, SHORT_RUN_REPEATS)
    assert 0 <= cpu < SHORT_RUN_SECONDS
