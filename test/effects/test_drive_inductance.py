"""A drive with inductance L > 0 (spec §8: L i' = u − R i − k_e N θ1' is a state), against references
written here:

- the ideal gear: the §4 KKT system (reference.py's M, h, Φ_q, γ) with N²J_m added to M on θ1 and
  N k_t i to Q, and the current's ODE beside it, by scipy's DOP853 at rtol 1e-11; the driver's limit
  as two scipy events (|i| reaches i_max: i held there; the winding pulls back: free again);
- L → 0: the runs approach the L = 0 run (the current follows the voltage at once) linearly in L;
- the energy balance with the magnetic energy ½ L i²: W = copper + mesh + Δ½J_m ω_m² + Δ½L i² + Δ(T + V)
  + dissipated, to 1e-9 of the work;
- the stuck mesh: θ1' = 0 exactly while the current decays as i0 e^{−R t/L} (u = 0, ω_m = 0);
- the two kernels agree; methods that cannot carry or resolve the current are refused in one line.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from scipy.integrate import solve_ivp

import reference as ref
from finger_sim.actuators.drive import STUCK, DrivenSystem
from finger_sim.actuators.inductive import CARRYING_METHODS
from finger_sim.errors import ConfigError
from finger_sim.scene import Scene, scene_from_dict
from finger_sim.simulate import Simulator, simulate

#: Spec §8's defaults, typed in again.
R, KT, JM, UMAX, IMAX, N = 8.0, 4.0e-3, 5.0e-9, 6.0, 0.5, 300.0
IDEAL = {"efficiency": 1.0, "backward_efficiency": 1.0}
CUP = {"name": "cup", "type": "circle", "center": [0.065, 0.040], "radius": 0.012}


def scene(drive: dict, voltage: dict, **top) -> Scene:
    data = {"model": {"drive": drive, **top.pop("model", {})}, "input": {"voltage": voltage}, **top}
    return scene_from_dict(data)


def states(sim: Simulator, n: int) -> tuple[np.ndarray, np.ndarray]:
    """(n + 1) × 6 states and the currents after each step, from the start."""
    xs, currents = [(*sim.q, *sim.v)], [sim.system.drive.i]
    for _ in range(n):
        s = sim.step()
        xs.append((*s.q, *s.v))
        currents.append(sim.system.drive.i)
    return np.array(xs), np.array(currents)


def ideal_reference(sc: Scene, inductance: float, ts: np.ndarray) -> np.ndarray:
    """(q, q', i) at ts: the §4 system with the ideal gear's inertia and torque and L i' = u − R i − k_e N θ1',
    by DOP853 at rtol 1e-11; while |i| = i_max and the winding pushes further, i' = 0 (restarted at both events)."""
    system = sc.build_system()

    def accel(t: float, y: np.ndarray) -> np.ndarray:
        q, v = y[:3], y[3:6]
        a = np.zeros((5, 5))
        a[:3, :3] = ref.mass(q)
        a[0, 0] += N * N * JM
        g = ref.phi_q(q)
        a[:3, 3:], a[3:, :3] = -g.T, g
        force = np.array(super(DrivenSystem, system).generalized_force(t, tuple(q), tuple(v), 0.0))
        force[0] += N * KT * y[6]
        return np.linalg.solve(a, np.concatenate([force - ref.coriolis(q, v), ref.gamma(q, v)]))[:3]

    def push(t: float, y: np.ndarray) -> float:
        return min(UMAX, max(-UMAX, sc.torque(t))) - R * y[6] - KT * N * y[3]

    q0, v0 = sc.initial_state()
    y, t, limited, out = np.array([*q0, *v0, 0.0]), 0.0, False, {}
    while t < ts[-1]:
        def rhs(s, x, held=limited):
            return [*x[3:6], *accel(s, x), 0.0 if held else push(s, x) / inductance]

        def event(s, x, held=limited):  # free: |i| reaches i_max; held: the winding stops pushing outward
            return math.copysign(1.0, x[6]) * push(s, x) if held else IMAX - abs(x[6])

        event.terminal, event.direction = True, -1.0  # each ends where it turns negative (it starts at 0)
        sol = solve_ivp(rhs, (t, ts[-1]), y, method="DOP853", rtol=1e-11, atol=1e-13, events=event, dense_output=True)
        assert sol.success
        for k in np.flatnonzero((ts >= t) & (ts <= sol.t[-1])):
            out.setdefault(int(k), sol.sol(ts[k]))
        t, y = sol.t[-1], sol.y[:, -1].copy()
        if sol.status == 1:
            limited = not limited
            if limited:
                y[6] = math.copysign(IMAX, y[6])
    return np.array([out[k] for k in sorted(out)])


@pytest.mark.parametrize("voltage, limit_acts", [(2.0, False), (6.0, True)])
def test_ideal_gear_with_inductance_equals_the_section4_solve_with_the_current_ode(voltage, limit_acts):
    sc = scene({**IDEAL, "inductance": 2e-3}, {"type": "constant", "value": voltage}, duration=0.06,
               integrator={"method": "auto", "dt": 0.001})
    sim = Simulator(sc, kernel="python")
    assert sim.method in CARRYING_METHODS and sim.integrator.substeps > 1  # auto resolves L/R = 2.5e-4 s in substeps
    xs, currents = states(sim, sc.step_count)
    expected = ideal_reference(sc, 2e-3, np.arange(sc.step_count + 1) * sc.dt)
    assert (np.max(np.abs(currents)) >= IMAX) == limit_acts
    assert np.max(np.abs(currents)) <= IMAX
    assert np.max(np.abs(xs[:, :3] - expected[:, :3])) < 1e-6  # auto's promise on θ
    assert np.max(np.abs(currents - expected[:, 6])) < 1e-5 * IMAX


def test_as_the_inductance_goes_to_zero_the_run_approaches_the_inductance_free_run():
    def end_state(inductance: float) -> np.ndarray:
        sc = scene({"inductance": inductance}, {"type": "constant", "value": 3.0}, duration=0.05,
                   integrator={"method": "auto", "dt": 1e-4})
        return np.array(simulate(sc, kernel="compiled").q)

    base = end_state(0.0)
    errors = [np.max(np.abs(end_state(L) - base)) for L in (1e-3, 1e-4, 1e-5)]
    assert errors[0] > errors[1] > errors[2]
    assert errors[1] / errors[0] < 0.2 and errors[2] / errors[1] < 0.2  # first order in L
    assert errors[2] < 1e-4


@pytest.mark.parametrize("drive", [{}, {"efficiency": 0.9, "backward_efficiency": 0.8}, IDEAL])
def test_energy_balance_closes_with_the_magnetic_energy(drive):
    sc = scene({**drive, "inductance": 1e-3}, {"type": "sine", "amplitude": 6.0, "frequency": 8.0, "offset": 0.0},
               duration=0.15, integrator={"method": "dop8", "dt": 2.5e-5})
    run = simulate(sc, kernel="compiled")
    report = run.energy_report
    assert report["magnetic_energy_change"] != 0.0
    assert abs(report["residual"]) < 1e-9 * report["electrical_work"]
    assert np.min(run.outputs["mesh_loss"]) >= -1e-12
    modes = set(run.outputs["mesh_mode"].tolist())
    assert len(modes) >= (1 if drive == IDEAL else 2)


def test_stuck_mesh_holds_still_while_the_current_decays_with_the_time_constant():
    sc = scene({"inductance": 1e-3}, {"type": "step", "before": 6.0, "after": 0.0, "at": 0.3},
               objects=[CUP], duration=0.31, integrator={"method": "auto", "dt": 0.001})
    sim = Simulator(sc, kernel="compiled")
    xs, currents = states(sim, 300)
    assert sim.system.drive.mode == STUCK
    q_held, i_held = tuple(xs[-1, :3]), currents[-1]
    assert xs[-1, 3] == 0.0 and i_held > 0.1
    for k in range(1, 11):
        s = sim.step()
        assert s.q == q_held and s.v == (0.0, 0.0, 0.0)
        # auto's substeps resolve |s| h ≤ 1/4: rk's relative error on the decay ≈ 1e-6 per step
        assert sim.system.drive.i == pytest.approx(i_held * math.exp(-R / 1e-3 * k * 1e-3), rel=2e-6 * k, abs=1e-15)


def test_the_compiled_kernel_carries_the_current_as_the_python_one():
    sc = scene({"inductance": 1e-2}, {"type": "step", "before": 6.0, "after": -3.0, "at": 0.1},
               objects=[CUP], duration=0.12, integrator={"method": "auto", "dt": 0.001})
    a = simulate(sc, kernel="python")
    b = simulate(sc, kernel="compiled")
    assert {0.0, 2.0} <= set(a.outputs["mesh_mode"].tolist())  # it rolls, sticks on the cup and is opened again
    assert np.max(np.abs(a.q - b.q)) < 1e-13
    assert np.max(np.abs(a.outputs["motor_current"] - b.outputs["motor_current"])) < 1e-12


def test_a_scene_without_inductance_pays_nothing_for_it():
    sim = Simulator(scene({}, {"type": "constant", "value": 6.0}), kernel="python")
    assert not hasattr(sim.integrator, "current_of")


@pytest.mark.parametrize("method, inductance, dt, key, words", [
    ("euler", 1e-3, 1e-5, "integrator.method", "carries the winding current"),
    ("rk4", 1e-3, 1e-3, "integrator.method", "does not resolve the winding"),
    ("auto", 1e-6, 1e-3, "model.drive.inductance", "L/R = 1.25e-07 s"),
])
def test_a_method_that_cannot_carry_or_resolve_the_current_is_refused_in_one_line(method, inductance, dt, key, words):
    sc = scene({"inductance": inductance}, {"type": "constant", "value": 6.0}, integrator={"method": method, "dt": dt})
    with pytest.raises(ConfigError) as err:
        Simulator(sc)
    message = str(err.value)
    assert message.startswith(key) and words in message and "\n" not in message


def test_node_publishes_and_logs_the_current_state_and_resims_it_bit_for_bit(launcher, tmp_path):
    """finger_node over real DDS on an inductive drive_grasp: its log resims exactly, and its motor
    topics (read back with rosbags) are the offline run's, current included."""
    pytest.importorskip("rclpy")
    import yaml
    from rosbags.highlevel import AnyReader

    from finger_sim.log import read_log
    from finger_sim.run_log import load_run, resimulate
    from helpers import NODE

    data = yaml.safe_load((Path(__file__).resolve().parents[2] / "config" / "drive_grasp.yaml").read_text())
    data["model"]["drive"] = {"inductance": 5e-4}
    data["duration"] = 0.35
    path = tmp_path / "drive_grasp_inductive.yaml"
    path.write_text(yaml.safe_dump(data))
    bags = tmp_path / "bags"
    node = launcher.node(NODE, dict(scene=str(path), torque_source="scene", realtime_factor=0.0, record_dir=str(bags)))
    assert node.wait(60.0) == 0
    (log,) = sorted(bags.glob("*.mcap"))
    assert resimulate(load_run(read_log(log))).exact
    with AnyReader([log]) as reader:
        currents = [reader.deserialize(raw, c.msgtype).data for c, _, raw in reader.messages()
                    if c.topic == "/motor/current"]
    offline = simulate(scene_from_dict(data), kernel="compiled")
    assert currents == offline.outputs["motor_current"].tolist()
    assert 0.0 < currents[-1] < currents[300]  # decaying through L/R after the voltage drops


@pytest.mark.parametrize("drive, leaves", [({}, False), ({"efficiency": 0.9, "backward_efficiency": 0.8}, True)])
def test_a_finger_on_its_stop_keeps_its_current_going_and_is_held_or_let_go_after_the_voltage_drops(drive, leaves):
    """Driven into the MCP stop it rests there while the current settles; at 0 V the current decays
    through L/R: the self-locking mesh holds the finger on the stop (bit for bit), a back-drivable one
    lets the spring pull it off. The energy still balances (impacts included)."""
    sc = scene({**drive, "inductance": 1e-2}, {"type": "step", "before": 6.0, "after": 0.0, "at": 0.3},
               model={"joint_limits": {"mcp": [0.0, 0.5]}, "spring_stiffness": 0.05}, duration=0.5,
               integrator={"method": "auto", "dt": 0.001})
    run = simulate(sc, kernel="compiled")
    on_stop = (run.t > 0.25) & (run.t <= 0.3)
    assert np.all(np.abs(run.q[on_stop, 0] - 0.5) < 1e-9)
    # resting on the stop, ω_m = 0: the current settles to u/R limited, i.e. i_max, with L/R = 1.25 ms
    assert run.outputs["motor_current"][on_stop][-1] == pytest.approx(IMAX, rel=1e-9)
    after = run.t > 0.3
    if leaves:
        assert run.q[-1, 0] < 0.5 - 1e-3
    else:
        # the decaying current keeps it pressed on the stop for ≈ 2 L/R, then the mesh sticks where it rests
        assert np.all(run.q[after] == run.q[-1]) and np.all(run.v[after] == 0.0)
        assert np.all(run.outputs["mesh_mode"][run.t > 0.31] == STUCK)
    # (≤ 3.5e-4 measured: the rest on the stop cuts the current at the limit and drops micro-bounces)
    assert abs(run.energy_report["residual"]) < 1e-3 * run.energy_report["electrical_work"]
