"""An object's own contact law (stiffness, damping) has the compiled form when it is the scene's only law.

Reference: the same scene with that law written scene-wide (`model.contact`) and the object
without its own, the compiled path every contact scene takes: an object's own k_c and d_c must
give the same run bit for bit, on the compiled DOP853, not on stages in Python. Two objects with
two laws still have no compiled form (the kernel's law has one k_c, d_c).
"""

from __future__ import annotations

import copy
from pathlib import Path

import numpy as np
import pytest
import yaml

from finger_sim.scene import scene_from_dict
from finger_sim.simulate import Simulator, simulate

CUP = Path(__file__).resolve().parents[2] / "config" / "grasp_cylinder.yaml"


def cup_scene(**law: float) -> dict:
    data = yaml.safe_load(CUP.read_text(encoding="utf-8"))
    data["duration"] = 0.3
    data["input"]["torque"]["value"] = 0.03
    data["objects"][0].update(law)
    return data


@pytest.mark.parametrize("law", [{"stiffness": 1.0e3}, {"stiffness": 1.0e7, "damping": 0.5}])
def test_one_objects_own_law_runs_compiled_and_equals_the_scene_wide_law(law):
    own = scene_from_dict(cup_scene(**law))
    wide_data = cup_scene()
    wide_data["model"]["contact"].update(law)
    wide = scene_from_dict(wide_data)
    sim = Simulator(own)
    assert sim.method == "dop853" and sim.integrator.compiled and sim.kernel.startswith("numba-")
    a, b = simulate(own), simulate(wide)
    assert np.array_equal(a.q, b.q) and np.array_equal(a.v, b.v)
    assert np.array_equal(a.outputs["grip_force"], b.outputs["grip_force"])
    assert a.outputs["grip_force"].max() > 0.05  # the finger closed on the cup and pressed it
    # and the law is the object's: the default law gives another run
    default = simulate(scene_from_dict(cup_scene()))
    assert not np.array_equal(default.q, a.q)


def test_two_objects_with_two_laws_step_in_python():
    data = cup_scene(stiffness=1.0e3)
    data["objects"].append({"name": "far", "type": "circle", "center": [-0.2, -0.2], "radius": 0.01})
    sim = Simulator(scene_from_dict(copy.deepcopy(data)))
    assert not sim.integrator.compiled and "its stages run in Python" in sim.method_reason
