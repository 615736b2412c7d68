"""finger_sim.batch against Simulator, finger by finger: the same method, the same numbers.

Every run of a small grid (the paper's run with varied spring and torque, the MCP stop with
rest and with a bounce, bang-bang switches, contact onset with explicit methods, and a contact
scene under auto that goes to a per-finger Simulator) is compared at every step with `simulate`
on both kernels, to 1e-12 rad.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from finger_sim.batch import run_batch
from finger_sim.errors import ConfigError, StabilityError
from finger_sim.scene import Scene, load_scene, scene_from_dict
from finger_sim.simulate import simulate
from finger_sim.sweep import set_key

CONFIG = Path(__file__).resolve().parents[2] / "config"
TOLERANCE = 1e-12  # rad, and rad/s for the rates


def _varied(name: str, **values: object) -> Scene:
    data = load_scene(CONFIG / f"{name}.yaml").to_dict()
    for key, value in values.items():
        set_key(data, key.replace("__", "."), value)
    return scene_from_dict(data)


GRID = [
    *(_varied("paper_flexion", model__spring_stiffness=k, input__torque__slope=s)
      for k in (0.0005, 0.002) for s in (0.01, 0.02)),
    _varied("paper_flexion", integrator__method="euler", initial__theta1=0.2, model__geometry__r1=0.047),
    _varied("paper_flexion", integrator__method="dop8", model__damping=0.001, model__gravity=[0.0, -9.81]),
    # rk4 named: auto steps a scene with stops on the error-controlled dop853, a per-finger Simulator
    _varied("paper_to_stop", model__restitution=0.0, integrator__method="rk4"),  # rests on the 90° stop from t ≈ 0.425 s
    _varied("paper_to_stop", model__restitution=0.5, duration=0.45, integrator__method="rk4"),  # bounces
    _varied("bang_bang", input__torque__amplitude=0.006),  # a switch every 10 ms
    _varied("bang_bang", input__torque={"type": "step", "before": 0.0, "after": 0.01, "at": 0.0105}),
    _varied("free_swing", input__torque={"type": "sine", "amplitude": 0.002, "frequency": 7.0}, duration=0.3),
    _varied("grasp_cylinder", integrator__method="rk4"),  # contact onset located by the Simulator
    _varied("grasp_impact", integrator__method="rk6"),  # onset and release
    _varied("press_table", integrator__method="rk4"),  # the fingertip on a plane
    _varied("grasp_cylinder"),  # auto: dop853 with events, a per-finger Simulator
    _varied("stiff_spring"),  # auto: dop853, a per-finger Simulator
]


@pytest.fixture(scope="module")
def batch():
    return run_batch(GRID, record=True)


@pytest.mark.parametrize("kernel", ["python", "compiled"])
def test_every_step_equals_the_simulator(batch, kernel: str) -> None:
    for i, scene in enumerate(GRID):
        ref = simulate(scene, kernel=kernel if batch.compiled[i] else "auto")
        assert batch.methods[i] == ref.method, scene.name
        assert batch.trajectories[i].shape == ref.q.shape
        assert np.abs(batch.trajectories[i] - ref.q).max() <= TOLERANCE, (i, scene.name)
        assert np.abs(batch.v[i] - ref.v[-1]).max() <= TOLERANCE, (i, scene.name)
        assert batch.max_residual[i] == pytest.approx(ref.residual.max(), rel=1e-6, abs=1e-15)
        assert batch.energy_change[i] == pytest.approx(ref.energy[-1] - ref.energy[0], rel=1e-9, abs=1e-15)


def test_what_ran_compiled_and_what_was_handed_over(batch) -> None:
    by_name = list(zip((s.name for s in GRID), batch.compiled.tolist(), batch.handed_over.tolist()))
    assert all(compiled and handed == 0 for _, compiled, handed in by_name[:6]), by_name[:6]
    assert by_name[6][1] and by_name[6][2] > 100  # resting on the stop: its Simulator holds it there
    assert by_name[7][1] and 1 <= by_name[7][2] <= 5  # a bounce: a few event steps only
    # switches on the step grid stay in the loop; the step holding the switch at 10.5 ms goes to
    # the Simulator, which splits it there (as `simulate` does)
    assert [(c, h) for _, c, h in by_name[8:11]] == [(True, 0), (True, 1), (True, 0)]
    assert all(c and 1 <= h <= 4 for _, c, h in by_name[11:14])  # contact onset / release steps
    assert not by_name[14][1] and not by_name[15][1]  # per-finger Simulator


def test_grip_force_of_the_contact_runs(batch) -> None:
    """The grip force at rest against the cup: the contact law k δ^e at the final pose (spec §7)."""
    i = 11
    system = GRID[i].build_system()
    outputs = [e.outputs(GRID[i].duration, tuple(batch.q[i]), tuple(batch.v[i])) for e in system.elements]
    assert batch.grip_force[i] == pytest.approx(sum(o.get("grip_force", 0.0) for o in outputs), rel=1e-12)
    assert batch.grip_force[i] == pytest.approx(0.17, abs=0.01)  # grasp_cylinder.yaml's comment
    assert batch.grip_force[0] == 0.0


def test_python_kernel_runs_every_finger_through_simulate() -> None:
    result = run_batch(GRID[:2], kernel="python")
    assert not result.compiled.any()
    for i, scene in enumerate(GRID[:2]):
        assert np.abs(result.q[i] - simulate(scene, kernel="python").q[-1]).max() <= TOLERANCE


def test_refusals_name_the_run() -> None:
    with pytest.raises(ConfigError, match=r"scenes\[1\] \(stiff_spring\)"):
        run_batch([GRID[0], GRID[-1]], kernel="compiled")
    unstable = _varied("stiff_spring", integrator__method="rk4")
    with pytest.raises(StabilityError, match="batch run 1"):
        run_batch([GRID[0], unstable])
    with pytest.raises(ConfigError, match="kernel"):
        run_batch(GRID[:1], kernel="fast")
