"""DOP853's deferred output estimates (`DormandPrince853.defer_estimates`): a stretch of compiled steps records
its outputs' estimates as one array block, made into the dict only when the dict is read.

The reference is the rule as the dict applies it one output at a time (`store_estimate`: at MAX_OUTPUTS the oldest
are dropped down to KEEP_OUTPUTS), written again here: every read (`error_estimate` of any q, before and after the
blocks are settled, `_estimates` itself) gives the same values and the same order, across drops, with single
outputs stored in between and outputs repeated.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("numba")
from finger_sim.integrators.dop853 import KEEP_OUTPUTS, MAX_OUTPUTS, DormandPrince853  # noqa: E402
from finger_sim.scene import load_scene  # noqa: E402
from finger_sim.simulate import Simulator  # noqa: E402
from finger_sim import stepper_slot  # noqa: E402

CONFIG = Path(__file__).resolve().parents[2] / "config"


def one_at_a_time(expected: dict, q: tuple, estimate: float) -> dict:
    """`store_estimate`'s rule on a plain dict."""
    if len(expected) >= MAX_OUTPUTS:
        expected = dict(list(expected.items())[-KEEP_OUTPUTS:])
    expected[q] = estimate
    return expected


def fresh() -> DormandPrince853:
    return Simulator(load_scene(CONFIG / "paper_to_stop.yaml")).integrator


def test_blocks_and_single_outputs_read_as_one_store_per_output():
    rng = np.random.default_rng(7)
    integ, expected = fresh(), {}
    asked: list[tuple] = []
    deferred = 0
    for n in [10, 1, 300, 2, 1500, 1, 2000, 700, 5, 3000, 1]:  # past MAX_OUTPUTS twice: blocks that must settle
        rows = rng.random((n, 4))
        rows[n // 2, :3] = rows[0, :3]  # an output repeated within a block: the later estimate wins
        q = tuple(rows[-1, :3].tolist())
        if n > 1 and integ.defer_estimates(rows[:-1].copy(), q, float(rows[-1, 3])):
            deferred += 1
        else:
            for r in rows.tolist():
                integ.store_estimate((r[0], r[1], r[2]), r[3])
        for r in rows.tolist():
            expected = one_at_a_time(expected, (r[0], r[1], r[2]), r[3])
        asked += [tuple(rows[0, :3].tolist()), tuple(rows[n // 3, :3].tolist()), q]
        # reads before settling: the newest entry of each q, 0 for one dropped or never stored
        for a in asked[-12:] + [(9.0, 9.0, 9.0)]:
            assert integ.error_estimate(a) == expected.get(a, 0.0)
        single = tuple(rng.random(3).tolist())
        integ.store_estimate(single, 0.5)  # after a deferred block: kept in order behind it
        expected = one_at_a_time(expected, single, 0.5)
    assert deferred >= 3 and len(integ._deferred) >= 1  # the test exercises unsettled blocks
    assert list(integ._estimates.items()) == list(expected.items())
    assert not integ._deferred


def test_a_stretched_run_reads_its_estimates_without_building_the_dict():
    """paper_to_stop's whole run (`kernel.advance`): the estimates equal those of the step-by-step run, and the
    final estimate is answered from the blocks (the dict built from them only on the `_estimates` read)."""
    scene = load_scene(CONFIG / "paper_to_stop.yaml")
    sim, ref = Simulator(scene), Simulator(scene)
    stepper_slot.kernel().advance(sim, scene.step_count)
    for _ in range(scene.step_count):
        ref.step()
    assert sim._event_step is not None and sim._event_step.taken > 0.5 * scene.step_count
    assert sim.integrator._deferred  # the run's stretches were deferred
    assert sim.error_estimate == ref.error_estimate > 0.0
    assert sim.integrator._deferred  # and reading the last estimate left them so
    assert list(sim.integrator._estimates.items()) == list(ref.integrator._estimates.items())



def test_the_kernels_estimate_rows_read_late_equal_the_estimates_read_at_every_step():
    """The common step records each output's estimate in the kernel (`kernel.event_step.common_step`'s rows, 512
    of them) and the integrator takes them in when it reads or stores one (`DormandPrince853.estimates_elsewhere`).
    grasp_rigid's 1.6 s (> 3 × 512 kernel steps, past the rows' fill) stepped three times side by side: read never,
    read every 300th step, and the Python step (`_event_step` switched off) read at every step. Every read equals
    the Python step's; the estimate of every output read after the run equals the Python step's at that step;
    the runs' whole tables (order and values) are equal, and stay so across a reset whose new integrator the
    kernel follows next (the old one's rows reach it then)."""
    scene = load_scene(CONFIG / "grasp_rigid.yaml").with_overrides(duration=1.6)
    never, sometimes, ref = Simulator(scene), Simulator(scene), Simulator(scene)
    ref._event_step = None
    outputs = []
    for k in range(scene.step_count):
        state = ref.step()
        assert never.step() == sometimes.step() == state
        outputs.append((state.q, ref.error_estimate))
        if k % 300 == 299:
            assert sometimes.error_estimate == outputs[-1][1] > 0.0
    assert never._event_step.taken > 0.9 * scene.step_count
    assert never.integrator._deferred  # the late rows were taken in as blocks
    assert [never.integrator.error_estimate(q) for q, _ in outputs] == [e for _, e in outputs]
    assert list(never.integrator._estimates.items()) == list(sometimes.integrator._estimates.items())
    old = never.integrator, sometimes.integrator
    for sim in (never, sometimes, ref):
        sim.reset()
    for _ in range(50):
        assert never.step() == sometimes.step() == ref.step()
    assert never.error_estimate == ref.error_estimate
    assert list(never.integrator._estimates.items()) == list(sometimes.integrator._estimates.items())
    assert list(old[0]._estimates.items()) == list(old[1]._estimates.items())


def test_a_reset_leaves_the_old_run_its_estimate_rows_until_it_reads_them():
    """A reset gives the kernel a new integrator to follow; the rows it recorded for the old one (none read yet) are
    kept for it and taken in when it first reads or stores an estimate (`event_step.KeptEstimates`), however many
    resets later. grasp_impact (contact onset and release located in the kernel) stepped three ways side by side:
    estimates never read, read at every step (nothing left to keep at a reset), and the Python step (`_event_step`
    switched off), with two resets. Every state and every output's estimate equal the Python step's; the tables
    (order and values) of the first two ways are equal."""
    scene = load_scene(CONFIG / "grasp_impact.yaml")
    never, eager, ref = Simulator(scene), Simulator(scene), Simulator(scene)
    ref._event_step = None
    sims = (never, eager, ref)
    runs = []
    for steps in (100, 60, 30):
        outputs = []
        for _ in range(steps):
            state = ref.step()
            assert never.step() == eager.step() == state
            outputs.append((state.q, ref.error_estimate))
            assert eager.error_estimate == outputs[-1][1]
        assert never._event_step.taken > 0.9 * steps
        runs.append(([s.integrator for s in sims], outputs))
        for s in sims:
            s.reset()
    (first, outputs), (second, second_outputs) = runs[:2]
    assert callable(first[0].estimates_elsewhere) and not first[0]._settled and not first[0]._deferred  # kept aside
    assert [second[0].error_estimate(q) for q, _ in second_outputs] == [e for _, e in second_outputs]
    assert list(second[0]._estimates.items()) == list(second[1]._estimates.items())
    assert [first[0].error_estimate(q) for q, _ in outputs] == [e for _, e in outputs]
    assert list(first[0]._estimates.items()) == list(first[1]._estimates.items())
    assert len(first[0]._estimates) >= 100
