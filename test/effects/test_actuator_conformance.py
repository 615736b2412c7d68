"""The shipped actuator (the drive, spec §8) against the slot's promise that its compiled form is its
Python law: at random states, voltages and every mesh mode, the compiled q'' (`kernel.drive.driven_accelerations`)
and, rolling, the compiled guards (`kernel.drive.drive_guards`) equal the Python path's (`DrivenSystem.accelerations`,
`actuators.stepping._guards` without a compiled model) to AGREEMENT of their size; NaN where the flank is not
unique on both. The effects' counterpart is test_effect_conformance.py; whole runs of both kernels are
compared in test_drive.py.

Drives: the shipped drive scenes' and an ideal gear, with the paper's spring and the cup (contact in the
force sum).
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from finger_sim import kinematics
from finger_sim.actuators import stepping
from finger_sim.actuators.drive import BACK, DRIVE, STUCK
from finger_sim.kernel.drive import drive_guards, driven_accelerations
from finger_sim.kernel.layout import model_array
from finger_sim.scene import load_scene, scene_from_dict
from finger_sim.simulate import Simulator

CONFIG = Path(__file__).resolve().parents[2] / "config"
SAMPLES = 300  # random states per drive and mode
AGREEMENT = 1e-13  # compiled vs Python, relative to the largest component
SPEED = 5.0  # rad/s: the range of random velocities
VOLTAGE = 8.0  # V: the range of random voltages, past the 6 V supply (the clamp's both sides)
CUP = {"name": "cup", "type": "circle", "center": [0.065, 0.040], "radius": 0.012}


def _scenes() -> list[tuple[str, object]]:
    shipped = [(p.stem, load_scene(p)) for p in sorted(CONFIG.glob("*.yaml")) if p.name != "finger_node.yaml"]
    ideal = scene_from_dict({"model": {"drive": {"efficiency": 1.0, "backward_efficiency": 1.0}},
                             "objects": [CUP], "input": {"voltage": {"type": "constant", "value": 6.0}}})
    return [(name, s) for name, s in shipped if s.drive is not None] + [("ideal_gear_cup", ideal)]


SCENES = _scenes()


def _states(scene, seed: int):
    """Assembled poses over the assembly range, random rates and voltages."""
    rng = np.random.default_rng(seed)
    low, high = kinematics.assembly_range(scene.params)
    for theta1 in rng.uniform(low, high, SAMPLES).tolist():
        q = tuple(kinematics.assemble(scene.params, theta1))
        v = tuple(rng.uniform(-SPEED, SPEED, 3).tolist())
        yield q, v, float(rng.uniform(-VOLTAGE, VOLTAGE)), float(rng.choice([-1.0, 1.0]))


def _close(want, got) -> bool:
    if any(math.isnan(x) for x in want):
        return all(math.isnan(x) for x in got)
    size = max([abs(x) for x in want if math.isfinite(x)] + [0.0])
    return all(x == y if math.isinf(x) else abs(x - y) <= AGREEMENT * size for x, y in zip(want, got))


def test_the_shipped_drive_scenes_are_checked() -> None:
    assert {name for name, _ in SCENES} >= {"drive_grasp", "drive_grasp_backdrivable", "ideal_gear_cup"}


@pytest.mark.parametrize("mode", [DRIVE, BACK, STUCK])
@pytest.mark.parametrize(("name", "scene"), SCENES, ids=[n for n, _ in SCENES])
def test_compiled_drive_equals_python(name: str, scene, mode: int) -> None:
    system = Simulator(scene, kernel="python").system
    drive = system.drive
    model = model_array(system)
    assert model is not None and drive.kernel_model is None  # the guards below take the Python branch
    drive.mode = mode  # mirrored into the model's mode slot
    moving = 0
    for q, v, u, direction in _states(scene, seed=mode + 1):
        drive.direction, drive.guard_cache = direction, None
        want = system.accelerations(0.0, q, v, u)[0]
        got = driven_accelerations(model, 0.0, *q, *v, u)
        assert _close(want, got), (q, v, u, want, got)
        if mode != STUCK:  # the guards are the rolling mesh's (a stuck mesh waits for its release time)
            want_guards = stepping._guards(system, 0.0, q, v, u)
            got_guards = drive_guards(model, 0.0, *q, *v, u, direction)
            assert _close(want_guards, got_guards), (q, v, u, want_guards, got_guards)
        moving += any(x != 0.0 for x in want if math.isfinite(x))
    assert (moving == 0) == (mode == STUCK)  # stuck: q'' = 0; rolling: the law really acted
