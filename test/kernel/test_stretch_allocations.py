"""A compiled stretch's output steps allocate nothing (`kernel.event_run.run`): no temporary array per output.

The count is numba's own: its runtime's allocation statistics (`rtsys.get_allocation_stats`), switched on
around the run as numba's own tests do (`_nrt_python.memsys_enable_stats`). What a stretch still allocates
is per DOP853 attempt (`integrators.steps.dop853_attempt`'s stage state: an array and its meminfo), and
paper_to_stop's 425 free outputs take a few tens of attempts (it made 2.1 allocations per output before:
895 arrays over the stretch). The numbers the stretch gives are held bit for bit to stepping in
test_event_run.py; this test holds what they cost in allocations.
"""

from __future__ import annotations

import pytest

pytest.importorskip("numba")
from numba.core.runtime import _nrt_python, rtsys  # noqa: E402

from finger_sim import stepper_slot  # noqa: E402
from finger_sim.kernel import run_stretch  # noqa: E402
from finger_sim.simulate import Simulator  # noqa: E402
from helpers import event_scene  # noqa: E402


def allocations() -> int:
    """Allocations (data buffers and their meminfos) numba's runtime has made so far."""
    stats = rtsys.get_allocation_stats()
    return stats.alloc + stats.mi_alloc


def test_free_stretches_allocate_nothing_per_output_step(monkeypatch):
    scene = event_scene("paper_to_stop")
    stepper_slot.kernel().advance(Simulator(scene), scene.step_count)  # compiled (or loaded) before counting
    steps, made = [0], [0]
    inner = run_stretch._stretch

    def counted(sim, *args):  # type: ignore[no-untyped-def]
        if sim._resting is not None:  # resting on a stop: no output step is integrated
            return inner(sim, *args)
        before = allocations()
        count = inner(sim, *args)
        made[0] += allocations() - before
        steps[0] += count
        return count

    monkeypatch.setattr(run_stretch, "_stretch", counted)
    enabled = _nrt_python.memsys_stats_enabled()
    _nrt_python.memsys_enable_stats()
    try:
        stepper_slot.kernel().advance(Simulator(scene), scene.step_count)
    finally:
        if not enabled:
            _nrt_python.memsys_disable_stats()
    assert steps[0] == 425  # the ramp up to the stop at t ≈ 0.425 s, in free stretches
    assert made[0] <= 0.25 * steps[0]  # the attempts' arrays only: 74 here (37 arrays, each with its meminfo), 1790 before
