"""`finger_sim.rollout` against `simulate` and `Simulator.step`, row by row, to 1e-12 rad.

The references are the Simulator's own runs of each row's scene, built independently here from
the scene file with the row's keys set; the paper's row is also held to the spec's check values.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from finger_sim import rollout
from finger_sim.errors import ConfigError
from finger_sim.scene import Scene, load_scene, scene_from_dict
from finger_sim.simulate import Simulator, simulate
from finger_sim.sweep import set_key

CONFIG = Path(__file__).resolve().parents[2] / "config"
TOLERANCE = 1e-12  # rad, and rad/s for the rates
#: The spec's check values at t = 0.3 s of the paper's run, degrees (§5), to their printed digits.
PAPER_CHECK_DEG = (34.34, 54.39, -53.02)


def _scene(name: str, **values: object) -> Scene:
    data = load_scene(CONFIG / f"{name}.yaml").to_dict()
    for key, value in values.items():
        set_key(data, key, value)
    return scene_from_dict(data)


def _assert_rows_equal_simulate(res, scenes: list[Scene]) -> None:
    for i, scene in enumerate(scenes):
        ref = simulate(scene)
        assert res.q.shape[1] == len(ref.t)
        np.testing.assert_allclose(res.q[i], ref.q, rtol=0, atol=TOLERANCE, err_msg=f"row {i}")
        np.testing.assert_allclose(res.v[i], ref.v, rtol=0, atol=TOLERANCE, err_msg=f"row {i}")
        assert res.methods[i] == ref.method
        for name, values in ref.outputs.items():
            np.testing.assert_allclose(res.outputs[name][i], values, rtol=0, atol=1e-9, err_msg=f"{name} row {i}")


def test_params_rows_equal_simulate_and_the_spec():
    springs, slopes = [0.001, 0.0005, 0.002, 0.001], [0.01, 0.02, 0.01, 0.03]
    res = rollout(CONFIG / "paper_flexion.yaml",
                  params={"model.spring_stiffness": springs, "input.torque.slope": slopes})
    assert res.q.shape == (4, 301, 3) and res.v.shape == (4, 301, 3) and res.t.shape == (301,)
    np.testing.assert_array_equal(res.t, np.arange(301) * 0.001)
    assert res.compiled.all()
    scenes = [_scene("paper_flexion", **{"model.spring_stiffness": k, "input.torque.slope": s})
              for k, s in zip(springs, slopes)]
    _assert_rows_equal_simulate(res, scenes)
    np.testing.assert_allclose(np.degrees(res.q[0, -1]), PAPER_CHECK_DEG, atol=0.005)


def test_a_switch_inside_a_step_and_rows_with_events_equal_simulate():
    # a step switch at 100.5 ms lies inside a step: the compiled loop hands that step to the Simulator
    step = {"type": "step", "before": 0.001, "after": 0.02, "at": 0.1005}
    res = rollout(_scene("paper_flexion", **{"input.torque": step}), params={"model.damping": [0.0, 0.001]})
    assert res.compiled.all()
    _assert_rows_equal_simulate(res, [_scene("paper_flexion", **{"input.torque": step, "model.damping": c})
                                      for c in (0.0, 0.001)])
    # stops (impacts, rest) and contact (grip_force) run in their Simulators
    stops = rollout(CONFIG / "paper_to_stop.yaml", params={"model.restitution": [0.0, 0.5]})
    assert not stops.compiled.any()
    _assert_rows_equal_simulate(stops, [_scene("paper_to_stop", **{"model.restitution": e}) for e in (0.0, 0.5)])
    grasp = rollout(CONFIG / "grasp_cylinder.yaml")
    ref = simulate(load_scene(CONFIG / "grasp_cylinder.yaml"))
    np.testing.assert_allclose(grasp.q[0], ref.q, rtol=0, atol=TOLERANCE)
    np.testing.assert_allclose(grasp.outputs["grip_force"][0], ref.outputs["grip_force"], rtol=0, atol=1e-9)
    assert grasp.outputs["grip_force"][0, -1] > 0.0


def test_control_and_initial_state_equal_simulator_steps():
    rng = np.random.default_rng(7)
    nbatch, nstep = 3, 120
    control = rng.uniform(-0.01, 0.03, (nbatch, nstep))
    start = np.array([[0.0, 0.0], [0.3, 1.0], [0.6, -2.0]])
    res = rollout(CONFIG / "paper_flexion.yaml", control=control, initial_state=start)
    assert res.compiled.all() and res.q.shape == (nbatch, nstep + 1, 3)
    for i in range(nbatch):
        sim = Simulator(_scene("paper_flexion", **{"initial.theta1": start[i, 0], "initial.theta1_dot": start[i, 1]}))
        np.testing.assert_allclose(res.q[i, 0], sim.q, rtol=0, atol=0)
        for n in range(nstep):
            state = sim.step(float(control[i, n]))
            np.testing.assert_allclose(res.q[i, n + 1], state.q, rtol=0, atol=TOLERANCE)
            np.testing.assert_allclose(res.v[i, n + 1], state.v, rtol=0, atol=TOLERANCE)
    # a constant control is the scene with that constant torque
    held = rollout(CONFIG / "paper_flexion.yaml", control=np.full((1, 300), 0.015))
    ref = simulate(_scene("paper_flexion", **{"input.torque": {"type": "constant", "value": 0.015}}))
    np.testing.assert_allclose(held.q[0], ref.q, rtol=0, atol=TOLERANCE)
    # with stops the held input goes through the Simulator's events
    stop = rollout(CONFIG / "paper_to_stop.yaml", control=np.full((1, 600), 0.02))
    ref = simulate(_scene("paper_to_stop", **{"input.torque": {"type": "constant", "value": 0.02}}))
    assert not stop.compiled.any()
    np.testing.assert_allclose(stop.q[0], ref.q, rtol=0, atol=TOLERANCE)
    assert stop.q[0, -1, 0] == pytest.approx(np.pi / 2, abs=1e-9)  # resting on the 90° stop


def test_preallocated_outputs_are_filled_in_place():
    q, v = np.full((2, 51, 3), np.nan), np.full((2, 51, 3), np.nan)
    res = rollout(CONFIG / "paper_flexion.yaml", params={"input.torque.slope": [0.01, 0.02]}, nstep=50, q=q, v=v,
                  nthread=1)
    assert res.q is q and res.v is v
    ref = simulate(_scene("paper_flexion", **{"input.torque.slope": 0.02, "duration": 0.05}))
    np.testing.assert_allclose(q[1], ref.q, rtol=0, atol=TOLERANCE)


@pytest.mark.parametrize(("kwargs", "message"), [
    ({"control": np.zeros((2, 10)), "initial_state": np.zeros((3, 2))},
     "initial_state: expected leading dimension nbatch = 2 (from control), got '3'"),
    ({"initial_state": np.zeros((2, 3))}, "initial_state: expected trailing dimension 2"),
    ({"control": np.zeros(10)}, "control: expected a 2-D array, got '1-D, shape (10,)'"),
    ({"control": np.zeros((1, 10)), "nstep": 20}, "nstep: expected control's second dimension (10), got 20"),
    ({"control": [[0.0, np.nan]]}, "control: expected finite values"),
    ({"params": {"model.no_such_key": [1.0]}}, "params row 0 (model.no_such_key=1.0): model: expected only the keys"),
    ({"params": {"model.spring_stiffness": [-1.0]}}, "model.spring_stiffness"),
    ({"params": {"integrator.dt": [0.001, 0.0005]}}, "params: expected one integrator.dt for every row"),
    ({"initial_state": [[0.0, 0.0], [2.5, 0.0]]}, "initial_state[1]: initial.theta1: expected an MCP angle in the assemblable range"),
    ({"q": np.zeros((1, 300, 3))}, "q: expected a writeable C-contiguous float64 array of shape (1, 301, 3)"),
])
def test_bad_arguments_name_the_argument_expected_and_got(kwargs, message):
    with pytest.raises(ConfigError) as err:
        rollout(CONFIG / "paper_flexion.yaml", **kwargs)
    assert message in str(err.value)


def test_lockstep_tiles_equal_simulate_within_tolerance():
    # more rows than two lock-step tiles, every compiled law (spring, damping, gravity, tip force),
    # a sine input, and two element layouts (damping 0 drops the damper): each row is its
    # scene's `simulate` within 1e-12 rad. Not bit for bit: the tiles take their sines and
    # cosines from glibc's vector library (within 4 ulp, `kernel.vector_trig`), `simulate` from libm
    from finger_sim.kernel.rollout_loop import TILE

    base = {"model.gravity": [0.0, -9.81], "model.tip_force": [0.2, -0.1],
            "input.torque": {"type": "sine", "amplitude": 0.004, "frequency": 3.0, "offset": 0.001}}
    nbatch = 2 * TILE + 7
    damping = np.where(np.arange(nbatch) % 3 == 0, 0.0, 0.0005 + 1e-5 * np.arange(nbatch))
    start = np.column_stack([np.linspace(0.0, 0.8, nbatch), np.linspace(-1.0, 2.0, nbatch)])
    res = rollout(_scene("paper_flexion", **base), params={"model.damping": damping}, initial_state=start, nstep=200)
    assert res.compiled.all() and res.methods[0] == "rk6"
    for i in (0, 1, TILE - 1, TILE, 2 * TILE, nbatch - 1):
        ref = simulate(_scene("paper_flexion", **base, **{"model.damping": float(damping[i]),
                                                          "initial.theta1": start[i, 0],
                                                          "initial.theta1_dot": start[i, 1], "duration": 0.2}))
        np.testing.assert_allclose(res.q[i], ref.q, rtol=0, atol=TOLERANCE, err_msg=f"row {i}")
        # rates to 1e-12 of the run's largest (row 0, undamped, swings at 17 rad/s: a last-bit
        # difference that moves the projection's stop by one Newton iteration, ~1e-14 rad, is
        # carried at that speed)
        rate_scale = max(1.0, float(np.abs(ref.v).max()))
        np.testing.assert_allclose(res.v[i], ref.v, rtol=0, atol=TOLERANCE * rate_scale, err_msg=f"row {i}")


def test_a_row_diverging_in_a_lockstep_tile_raises_what_the_simulator_raises():
    # row 65 (the second tile) is driven to divergence from step 20: the rollout names the row
    # and reports the Simulator's own failure (the same kind and time)
    from finger_sim.errors import SimulationDiverged

    control = np.full((70, 50), 0.002)
    control[65, 20:] = 1e6
    sim = Simulator(load_scene(CONFIG / "paper_flexion.yaml"))
    with pytest.raises(SimulationDiverged) as ref:
        for value in control[65]:
            sim.step(float(value))
    with pytest.raises(SimulationDiverged, match="row 65: ") as got:
        rollout(CONFIG / "paper_flexion.yaml", control=control)
    # the same failure at the same step; the diverged state itself (|q| ~ 1e89, sines of such
    # angles) is not compared: the tile's vector sines differ from libm's there
    assert got.value.reason.split(": q = ")[0] == f"row 65: {ref.value.reason}".split(": q = ")[0]
    assert "non-finite" in ref.value.reason and got.value.t == ref.value.t
