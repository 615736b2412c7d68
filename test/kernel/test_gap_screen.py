"""The Simulator's compiled step-end gap check (`simulation.gap_screen`, `kernel.gap_screen`).

A step it clears skips the Python gap check (`crossings.first_crossing`), so it may clear only a
step the Python check finds nothing in. Held here two ways on every shipped scene with contact or
stops: every step's decision against the Python check's own, and whole runs with the screen
against the same runs with it switched off (the Python check alone), bit for bit.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("numba")
from finger_sim.errors import SimulationDiverged  # noqa: E402
from finger_sim.scene import load_scene, scene_from_dict  # noqa: E402
from finger_sim.simulate import Simulator  # noqa: E402
from finger_sim.simulation import crossings  # noqa: E402

CONFIG = Path(__file__).resolve().parents[2] / "config"
#: The shipped scenes with contact or stops that step through the Simulator's gap check (drive and
#: stick–slip scenes step their own modes, which call the same check).
SCENES = ("grasp_cylinder", "press_table", "grasp_impact", "grasp_rigid", "paper_to_stop", "drive_grasp",
          "hard/chatter_wall", "hard/elastic_impact", "hard/grasp_release", "hard/rigid_fast",
          "hard/soft_pass_through", "hard/stops_elastic")
#: Least share of a contact run's steps the screen must clear by itself (the rest go to Python).
MIN_CLEARED = 0.9


def run(scene, screened: bool) -> tuple[np.ndarray, np.ndarray, str]:
    """Every step's (q, q') and the integrator's error estimate, with or without the screen, and
    the error that ended the run early ("" if none: soft_pass_through ends at its depth crossing)."""
    sim = Simulator(scene)
    sim._event_step = None  # the screen inside Python's step (the compiled step: test_event_step)
    if not screened:
        sim._gap_screen = None
    states, estimates, error = [], [], ""
    try:
        for _ in range(scene.step_count):
            state = sim.step()
            states.append((*state.q, *state.v))
            estimates.append(sim.error_estimate)
    except SimulationDiverged as exc:
        error = str(exc)
    return np.array(states), np.array(estimates), error


@pytest.mark.parametrize("name", SCENES)
def test_runs_with_the_screen_equal_runs_without_bit_for_bit(name):
    scene = load_scene(CONFIG / f"{name}.yaml")
    with_screen, estimates, error = run(scene, True)
    without, reference_estimates, reference_error = run(scene, False)
    np.testing.assert_array_equal(with_screen, without)
    np.testing.assert_array_equal(estimates, reference_estimates)
    assert error == reference_error


@pytest.mark.parametrize("name", ["grasp_cylinder", "press_table", "grasp_impact", "hard/grasp_release",
                                  "hard/chatter_wall", "paper_to_stop"])
def test_every_cleared_step_is_one_the_python_check_finds_nothing_in(name, monkeypatch):
    scene = load_scene(CONFIG / f"{name}.yaml")
    sim = Simulator(scene)
    sim._event_step = None  # every step through Python's check (the compiled step: test_event_step)
    screen = sim._gap_screen
    assert screen is not None  # these scenes' gaps all have a compiled form
    python_check = crossings.first_crossing
    decisions = []

    def checked(sim_, t, q, v, t1, q1, v1, torque):
        screen_, sim_._gap_screen = sim_._gap_screen, None
        try:
            found = python_check(sim_, t, q, v, t1, q1, v1, torque)  # the Python check alone
        finally:
            sim_._gap_screen = screen_
        cleared = screen_.clear(t, q, v, t1, q1, v1)
        decisions.append(cleared)
        assert not (cleared and found is not None), f"the screen cleared a step with a crossing at t = {found.t}"
        return found

    monkeypatch.setattr(crossings, "first_crossing", checked)
    for _ in range(scene.step_count):
        sim.step()
    assert decisions  # (a step resting on a stop does not check its gaps)
    assert np.mean(decisions) >= MIN_CLEARED  # the common step no longer enters the Python check


def test_a_moving_object_has_no_screen():
    data = load_scene(CONFIG / "grasp_cylinder.yaml").to_dict()
    data["objects"][0]["motion"] = {"type": "push", "direction": [-1.0, 0.0], "distance": 0.001,
                                    "start": 0.0, "duration": 0.1}
    assert Simulator(scene_from_dict(data))._gap_screen is None  # its gaps move with t: the Python check alone
    assert Simulator(load_scene(CONFIG / "grasp_cylinder.yaml"))._gap_screen is not None
