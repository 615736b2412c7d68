"""`grasp_objects.carry_over` (a task's scene change: a crush, a tip-force disturbance) carries every
declared mode of the run over to the new Simulator, with the data that goes with it: the stops' rest
(the gap rested on) and stick–slip friction's mode (its sliding direction and holding torque), not only
the drive's mesh.

Reference: the run carried over to the same scene every CARRY_EVERY steps equals the run left alone,
state for state and mode for mode, through the modes in question (resting on the stop; locked and
sliding on the table). A fixed-step method: auto's dop853 restarts its step-size control at a carry-over,
as at any change of the scene. The drive's case is test/effects/test_drive.py's. Before the friction mode
was carried the new run started in the mode of the scene's initial state and left the straight run (the
friction cases fail there); the rest case held before too, the finger landing on the stop again within
the step, and holds now with the rest carried.
"""

from __future__ import annotations

from pathlib import Path

import pytest

from finger_sim.grasp_objects import carry_over
from finger_sim.scene import load_scene
from finger_sim.simulate import Simulator

CONFIG = Path(__file__).resolve().parents[2] / "config"
CARRY_EVERY = 50  # steps between two carry-overs, at an offset so that some fall inside a mode
CARRY_AT = 25


@pytest.mark.parametrize("kernel", ["python", "compiled"])
@pytest.mark.parametrize(("name", "method", "mode", "value"), [
    ("paper_to_stop.yaml", "rk4", "rest", "resting"),
    ("friction/sawtooth.yaml", "rk4", "friction", "locked"),
    ("friction/sawtooth.yaml", "rk4", "friction", "sliding"),
])
def test_carrying_a_run_over_to_the_same_scene_changes_nothing(name: str, method: str, mode: str,
                                                               value: str, kernel: str) -> None:
    scene = load_scene(CONFIG / name).with_overrides(method=method)
    straight, carried = Simulator(scene, kernel=kernel), Simulator(scene, kernel=kernel)
    at = [m.name for _, m in straight.layout.modes].index(mode)
    seen, carried_in_mode = set(), 0
    for k in range(scene.step_count):
        if k % CARRY_EVERY == CARRY_AT:
            carried_in_mode += straight.modes[at] == value
            carried = carry_over(carried, carried.scene)
        a, b = straight.step(), carried.step()
        assert (a.q, a.v, straight.modes) == (b.q, b.v, carried.modes), (k, a.t)
        seen.add(straight.modes[at])
    assert carried_in_mode > 0  # a carry-over fell inside the mode in question


@pytest.mark.parametrize("name", ["paper_flexion.yaml", "paper_to_stop.yaml"])
def test_an_actuator_and_its_own_state_are_carried_over(name: str) -> None:
    """A run with an actuator in the slot (the torque lag declared in test_state_layout.py) keeps the
    actuator and its own slot (the lagged torque) across a carry-over: the same states and slots as the
    run left alone. (Before, the new Simulator was built without the actuator: the command acted as the
    torque itself.)"""
    from test_state_layout import LAG, TorqueLag

    scene = load_scene(CONFIG / name).with_overrides(method="rk4")
    straight = Simulator(scene, kernel="python", actuator=TorqueLag(LAG))
    carried = Simulator(scene, kernel="python", actuator=TorqueLag(LAG))
    for k in range(scene.step_count):
        if k % CARRY_EVERY == CARRY_AT:
            carried = carry_over(carried, carried.scene)
        straight.step()
        carried.step()
        assert straight.state_vector == carried.state_vector, (k, straight.state_vector, carried.state_vector)
        assert straight.modes == carried.modes
    assert straight.state_vector[6] != 0.0
