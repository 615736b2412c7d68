"""DOP853's internal steps in one compiled call (`kernel.internal_steps`, `DormandPrince853._advance_compiled`).

Under a held torque `DormandPrince853.step` runs its loop of internal steps in the kernel, keeping each
step in its history as `_advance` does (event location's trial steps are answered from it). The
reference is the Python loop itself (`_steps` switched off: main's path), run side by side: every state,
torque and error estimate bit for bit, every located crossing and internal step the same, on the shipped
scenes with stops and contact (onsets, releases and impacts located inside steps), with the kernel's
event step and without it, and under commands held step by step; and a run that fails fails alike.
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("numba")
from finger_sim.errors import SimulationDiverged  # noqa: E402
from finger_sim.integrators.dop853 import COMPILED_CHUNK, DormandPrince853  # noqa: E402
from finger_sim.scene import load_scene  # noqa: E402
from finger_sim.simulate import Simulator  # noqa: E402

CONFIG = Path(__file__).resolve().parents[2] / "config"
#: Shipped scenes stepped by DOP853 with located events: contact onsets and releases, stop impacts and
#: rests, stick–slip friction (its mode changes restart the solution).
SCENES = ("grasp_impact", "grasp_rigid", "grasp_cylinder", "press_table", "paper_to_stop", "hard/chatter_wall",
          "hard/elastic_impact", "hard/grasp_release", "hard/rigid_fast", "hard/soft_pass_through",
          "hard/stops_elastic", "hard/friction_table", "friction/hold_table")

Command = Callable[[int, Simulator], "float | None"]


def run(scene, compiled: bool, event_step: bool, command: Command = lambda k, sim: None,
        tolerances: tuple[float, float] | None = None) -> tuple[np.ndarray, str, dict]:
    """Every step's (q, q', torque, error estimate), the error that ended the run ("" if none), and the
    integrator's counts: accepted internal steps, internal steps taken by the compiled loop, its watched passes
    that the watch stopped before their output time, and the most internal steps of one watched pass.
    tolerances: DOP853's (rtol, atol) instead of the scene's."""
    sim = Simulator(scene)
    if tolerances is not None:
        sim.integrator.rtol, sim.integrator.atol = tolerances
    if not event_step:
        sim._event_step = None
    assert isinstance(sim.integrator, DormandPrince853)
    counts = {"compiled": 0, "stopped": 0, "most watched": 0}
    original = DormandPrince853._advance_compiled

    def counted(integ, target, held, bounded=False, gaps=None):
        before = integ.accepted
        state = original(integ, target, held, bounded, gaps)
        counts["compiled"] += integ.accepted - before
        if gaps is not None:
            counts["stopped"] += state == integ._steps.STOPPED
            counts["most watched"] = max(counts["most watched"], integ.accepted - before)
        return state

    if compiled:
        sim.integrator._advance_compiled = lambda *args, **kwargs: counted(sim.integrator, *args, **kwargs)
    else:
        sim.integrator._steps = None  # the Python loop of `_advance` (main's path)
    rows, error = [], ""
    try:
        for k in range(scene.step_count):
            state = sim.step(command(k, sim))
            rows.append((*state.q, *state.v, sim.torque, sim.error_estimate))
    except SimulationDiverged as exc:
        error = str(exc)
    counts["accepted"] = sim.integrator.accepted
    return np.array(rows), error, counts


def assert_same(scene, event_step: bool, command: Command = lambda k, sim: None) -> dict:
    rows, error, counts = run(scene, True, event_step, command)
    reference, reference_error, reference_counts = run(scene, False, event_step, command)
    np.testing.assert_array_equal(rows, reference)
    assert error == reference_error
    assert counts["accepted"] == reference_counts["accepted"]  # the same internal steps, in number too
    return counts


@pytest.mark.parametrize("event_step", [True, False], ids=["kernel event step", "python step"])
@pytest.mark.parametrize("name", SCENES)
def test_runs_equal_the_python_loop_bit_for_bit(name, event_step):
    scene = load_scene(CONFIG / f"{name}.yaml")
    counts = assert_same(scene, event_step)
    if not event_step and hasattr(scene.torque, "value"):
        # a constant torque: every internal step is compiled, the watched ones of the plain event loop
        # (`DormandPrince853._watched`) too; those stopped by the watch are among them on the impact scenes
        assert counts["compiled"] == counts["accepted"] > 0
        assert counts["stopped"] > 0 or name not in ("grasp_impact", "grasp_rigid")


@pytest.mark.parametrize("name", ["grasp_impact", "friction/hold_table", "hard/grasp_release"])
def test_held_commands_step_by_step_equal_the_python_loop(name):
    scene = load_scene(CONFIG / f"{name}.yaml")
    rng = np.random.default_rng(11)
    values = np.repeat(rng.uniform(-0.03, 0.05, 30), rng.integers(1, 20, 30))  # runs of a value, and new ones
    assert assert_same(scene, False, lambda k, sim: float(values[k % len(values)]))["compiled"] > 0


def test_a_watched_pass_longer_than_one_call_stops_where_the_python_loop_stops():
    """grasp_rigid through the plain event loop (`crossings.step_to_crossing`, the kernel's event step off) at
    tolerances 1000× tighter: a watched pass takes more internal steps than one compiled chunk holds (the watch's
    state carried from one call to the next), and every state, error estimate and internal step equals Python's
    loop's, the passes the watch stopped before their output time included."""
    scene = load_scene(CONFIG / "grasp_rigid.yaml")
    integ = Simulator(scene).integrator
    tight = (integ.rtol / 1000.0, integ.atol / 1000.0)
    rows, error, counts = run(scene, True, False, tolerances=tight)
    reference, reference_error, reference_counts = run(scene, False, False, tolerances=tight)
    np.testing.assert_array_equal(rows, reference)
    assert error == reference_error == ""
    assert counts["compiled"] == counts["accepted"] == reference_counts["accepted"]
    assert counts["most watched"] > COMPILED_CHUNK and counts["stopped"] > 0


def test_a_stiff_contact_takes_more_internal_steps_than_one_call_holds():
    """grasp_rigid's onset step, integrated across the onset unwatched (no event location: the integrator's
    own `step`) at tolerances 1000× tighter, needs more internal steps than one compiled chunk: the loop goes on,
    and the history holds every one of them, each covering the next (the trial steps' dense outputs), as
    Python's loop does."""
    scene = load_scene(CONFIG / "grasp_rigid.yaml")
    states = []
    for compiled in (True, False):
        integ = Simulator(scene).integrator
        integ.rtol, integ.atol = integ.rtol / 1000.0, integ.atol / 1000.0
        if not compiled:
            integ._steps = None
        (q, v), torque, dt = scene.initial_state(), scene.torque, scene.dt
        most, rows = 0, []
        for k in range(scene.step_count):
            before = integ.accepted
            q, v = integ.step(k * dt, q, v, dt, torque)
            rows.append((*q, *v))
            most = max(most, integ.accepted - before)
            starts = [entry[0] for entry in integ._history]
            ends = [entry[0] + entry[1] for entry in integ._history]
            assert starts == integ._history_starts and starts[1:] == ends[:-1]
        assert most > COMPILED_CHUNK
        states.append(np.array(rows))
    np.testing.assert_array_equal(states[0], states[1])


def test_a_failing_internal_step_fails_with_the_python_loops_error():
    """A tolerance no internal step can meet: the compiled loop stops before the failing step, and the
    Python loop retries it and raises its own error at the same time."""
    scene = load_scene(CONFIG / "grasp_impact.yaml")
    rows, error, _ = run(scene, True, False, tolerances=(0.0, 1e-300))
    reference, reference_error, _ = run(scene, False, False, tolerances=(0.0, 1e-300))
    assert error and error == reference_error
    np.testing.assert_array_equal(rows, reference)
