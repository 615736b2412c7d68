"""Under our DOP853 (auto's method on the drive scenes) the rolling mesh's guards are the compiled ones
(`kernel.drive.drive_guards` on the integrator's model, `DormandPrince853.guard_model`), and the run is the one the
Python guards (`DrivenSystem.mesh`, kernel="python") give: every mode change at the same step, θ within 1e-12 rad."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

import reference as ref
from finger_sim.actuators.drive import STUCK, DrivenSystem
from finger_sim.inputs import Square
from finger_sim.scene import load_scene
from finger_sim.simulate import Simulator, simulate

TOLERANCE = 1e-12  # rad, rad/s


def scenes():
    grasp = load_scene(ref.CONFIG / "drive_grasp.yaml")
    back = load_scene(ref.CONFIG / "drive_grasp_backdrivable.yaml")
    # a square voltage on the back-drivable train: closing, back-driven opening, closing again (turns and flank
    # changes in and out of contact, each located on the guards)
    square = dataclasses.replace(back, torque=Square(amplitude=6.0, frequency=2.0), duration=1.0, name="square")
    return [grasp, back, square]


@pytest.mark.parametrize("scene", scenes(), ids=lambda s: s.name)
def test_the_compiled_guards_give_the_python_guards_run(scene, monkeypatch):
    compiled, python = Simulator(scene, kernel="compiled"), Simulator(scene, kernel="python")
    assert compiled.method == python.method == "dop853"
    assert compiled.system.drive.kernel_model is compiled.integrator.guard_model is not None
    assert python.system.drive.kernel_model is None

    calls = {"compiled": 0, "python": 0}
    mesh = DrivenSystem.mesh
    runs = {}
    for kernel in calls:
        def counted(self, *args, _kernel=kernel, **kwargs):
            calls[_kernel] += 1
            return mesh(self, *args, **kwargs)

        monkeypatch.setattr(DrivenSystem, "mesh", counted)
        runs[kernel] = simulate(scene, kernel=kernel)
    fast, slow = runs["compiled"], runs["python"]
    np.testing.assert_array_equal(fast.outputs["mesh_mode"], slow.outputs["mesh_mode"])
    np.testing.assert_allclose(fast.q, slow.q, rtol=0, atol=TOLERANCE)
    np.testing.assert_allclose(fast.v, slow.v, rtol=0, atol=TOLERANCE)
    # the Python law is left to the mode entries (turn, roll) and the outputs: a rolling step asks it nothing
    rolling = int(np.count_nonzero(slow.outputs["mesh_mode"][1:] != STUCK))
    assert calls["python"] - calls["compiled"] >= rolling
