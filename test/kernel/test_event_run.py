"""Stretches of Simulator steps on scenes with events in one compiled call (`kernel.run_stretch`,
`kernel.event_run`), and piecewise-constant profiles that restart DOP853 only at a switch.

The reference for a stretch is the Simulator stepped one `step()` at a time (the node's path, itself
tested bit for bit against the Python step in test_event_step.py), side by side: every state, the
torque, the step index, the error estimate and the integrator's estimates, bit for bit.
"""

from __future__ import annotations


import numpy as np
import pytest

pytest.importorskip("numba")
from finger_sim import stepper_slot  # noqa: E402
from finger_sim.errors import SimulationDiverged  # noqa: E402
from finger_sim.inputs import Square, Step  # noqa: E402
from finger_sim.integrators.dop853 import KEEP_OUTPUTS, MAX_OUTPUTS  # noqa: E402
from helpers import EVENT_PROFILES as PROFILES, EVENT_SCENES, event_scene, with_profile  # noqa: E402
from finger_sim.scene import scene_from_dict  # noqa: E402
from finger_sim.simulate import Simulator, simulate  # noqa: E402
from finger_sim.kernel import run_stretch  # noqa: E402

def stretched_steps(monkeypatch) -> list[int]:
    """The number of steps each kernel stretch took, recorded as `advance` runs."""
    counts: list[int] = []
    inner = run_stretch._stretch

    def counted(*args):  # type: ignore[no-untyped-def]
        counts.append(inner(*args))
        return counts[-1]

    monkeypatch.setattr(run_stretch, "_stretch", counted)
    return counts


def outcome(run):  # type: ignore[no-untyped-def]
    """(run's result, ""), or (None, the message of the SimulationDiverged that ended it)."""
    try:
        return run(), ""
    except SimulationDiverged as exc:
        return None, str(exc)


def assert_same_as_stepping(scene, monkeypatch) -> float:
    """`advance` (stretches) and n `step()` calls agree bit for bit; the share of steps taken in stretches."""
    counts = stretched_steps(monkeypatch)
    n = scene.step_count
    sim, ref = Simulator(scene), Simulator(scene)
    assert sim._event_step is not None
    xs, error = outcome(lambda: stepper_slot.kernel().advance(sim, n))
    reference, reference_error = outcome(lambda: np.array([(*s.q, *s.v) for s in (ref.step() for _ in range(n))]))
    assert error == reference_error  # a scene that diverges (soft_pass_through) stops at the same step, same words
    if not error:
        np.testing.assert_array_equal(xs, reference)
    assert (sim.q, sim.v, sim.torque, sim.step_index) == (ref.q, ref.v, ref.torque, ref.step_index)
    assert sim.error_estimate == ref.error_estimate
    assert sim.integrator._estimates == ref.integrator._estimates
    assert sim._event_step.taken == ref._event_step.taken
    return sum(counts) / n


@pytest.mark.parametrize("name", EVENT_SCENES)
def test_stretches_equal_stepping_on_every_shipped_event_scene(name, monkeypatch):
    share = assert_same_as_stepping(event_scene(name), monkeypatch)
    if name in ("paper_to_stop", "grasp_cylinder", "press_table"):
        assert share >= 0.9  # the ramp onto the stop and the rest on it, the hold in contact: in stretches


@pytest.mark.parametrize("profile", sorted(PROFILES))
@pytest.mark.parametrize("name", ["paper_to_stop", "grasp_cylinder", "press_table", "hard/stops_elastic"])
def test_stretches_equal_stepping_under_profiles(name, profile, monkeypatch):
    share = assert_same_as_stepping(with_profile(name, PROFILES[profile]), monkeypatch)
    assert share >= 0.3  # all but the steps near a crossing, a switch or a release


def test_simulate_outputs_equal_stepping():
    scene = event_scene("grasp_cylinder")
    traj = simulate(scene, kernel="compiled")
    sim = Simulator(scene)
    states = [sim.state, *(sim.step() for _ in range(scene.step_count))]
    np.testing.assert_array_equal(traj.q, [s.q for s in states])
    np.testing.assert_array_equal(traj.v, [s.v for s in states])
    assert traj.error_estimate == sim.error_estimate


def test_estimates_dropped_as_one_remember_per_step():
    """`_remember_all` leaves the estimates as MAX_OUTPUTS-bounded `_remember` calls would, across drops."""
    class Integ:
        _estimates: dict

    rng = np.random.default_rng(3)
    for size, count in [(0, 10), (MAX_OUTPUTS - 5, 5), (MAX_OUTPUTS - 5, 6), (MAX_OUTPUTS, 1), (100, 3 * MAX_OUTPUTS + 17),
                        (KEEP_OUTPUTS + 1, MAX_OUTPUTS - KEEP_OUTPUTS), (10, MAX_OUTPUTS - 10)]:
        old = {(float(i), 0.0, 0.0): float(i) for i in range(size)}
        rows = np.column_stack([rng.random((count, 6)), rng.random(count)])
        expected = dict(old)
        for r in rows.tolist():  # `DormandPrince853._remember`'s rule, one output at a time
            if len(expected) >= MAX_OUTPUTS:
                expected = dict(list(expected.items())[-KEEP_OUTPUTS:])
            expected[(r[0], r[1], r[2])] = r[6]
        integ = Integ()
        integ._estimates = dict(old)
        last = rows[-1].tolist()
        run_stretch._remember_all(integ, rows, (last[0], last[1], last[2]), last[6])
        assert list(integ._estimates.items()) == list(expected.items()), (size, count)


@pytest.mark.parametrize("profile", [Square(0.02, 4.0, 0.01), Step(0.03, -0.01, 0.2005)])
def test_piecewise_constant_profiles_restart_dop853_only_at_a_switch(profile):
    """On a segment the level is one function object, so DOP853 continues its solution across output steps:
    its internal steps are then fewer than the output steps (a restart at each output step costs at least
    one internal step per output step: main's 300 and more here)."""
    data = event_scene("paper_flexion").to_dict()
    data["input"] = {"torque": profile.to_dict()}
    scene = scene_from_dict(data).with_overrides(method="dop853")
    sim = Simulator(scene)
    for _ in range(scene.step_count):
        sim.step()
    assert sim.integrator.accepted < scene.step_count
    assert profile.on_segment(0.0, 0.001) is profile.on_segment(0.001, 0.002)
