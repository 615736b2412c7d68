"""The declared state (spec §8's drive needs it; issue of the house, item 2): the flat layout (q, q', then
each owner's slots), the modes the elements own, and an actuator slot that a new stateful actuator fills
without a line of the integrators.

The proof: a first-order lag on the torque, τ_a' = (u − τ_a)/T, declared in this file alone, runs in the
Simulator on the paper's scene and matches an independent tight solve of the same ODE written here
(test/reference.py's §4 equations in numpy, scipy solve_ivp at rtol 1e-12)."""

from __future__ import annotations

import numpy as np
import pytest
import reference as ref
from scipy.integrate import solve_ivp

from finger_sim.actuators.base import Actuator
from finger_sim.actuators.drive import MESH_MODES
from finger_sim.dynamics import FingerSystem
from finger_sim.errors import ConfigError
from finger_sim.kinematics import Vec3
from finger_sim.effects.stops import JointStops
from finger_sim.scene import load_scene, scene_from_dict
from finger_sim.simulate import Simulator, simulate
from finger_sim.state_layout import Slot, StateLayout

#: The lag's time constant, s: the torque reaches the command after a few T (0.3 s run: 15 T).
LAG = 0.02
#: The paper's scene (config/paper_flexion.yaml: τ = 1 + 10 t N·mm, PIP spring), stepped by rk6.
PAPER = {"model": {"spring_stiffness": 0.001}, "input": {"torque": {"type": "ramp", "offset": 0.001, "slope": 0.01}},
         "duration": 0.3, "integrator": {"method": "rk6", "dt": 1e-3}}
STEPS = 300
CONFIG = ref.CONFIG
#: rk6 at 1 ms against the tight solve: measured 6.7e-13 rad, 2.6e-14 N·m (the lag moves θ1 by 0.09 rad).
THETA_TOLERANCE = 1e-10  # rad
TORQUE_TOLERANCE = 1e-12  # N·m


class TorqueLag(Actuator):
    """A first-order lag between the command u (N·m) and the torque on θ1: τ_a' = (u − τ_a)/T, τ_a(0) = 0."""

    name = "lag"
    slots = (Slot("torque", "N·m", "the lagged torque on θ1"),)

    def __init__(self, time_constant: float) -> None:
        self.time_constant = time_constant

    def initial(self) -> tuple[float, ...]:
        return (0.0,)

    def torque(self, system: FingerSystem, t: float, q: Vec3, v: Vec3, u: float, own: tuple[float, ...]) -> float:
        return own[0]

    def rates(self, t: float, q: Vec3, v: Vec3, u: float, own: tuple[float, ...]) -> tuple[float, ...]:
        return ((u - own[0]) / self.time_constant,)


def lag_reference(t_end: float) -> object:
    """Tight solve of (q, q', τ_a)' = (q', §4's q'' under τ_a, (u(t) − τ_a)/T), from the scene's rest state."""
    command = ref.ramp(0.001, 0.01)
    effects = ref.Effects(k=0.001)

    def rhs(t: float, y: np.ndarray) -> np.ndarray:
        acc, _ = ref.kkt(y[:3], y[3:6], y[6], effects)
        return np.concatenate([y[3:6], acc, [(command(t) - y[6]) / LAG]])

    q0 = ref.assemble(0.0)
    sol = solve_ivp(rhs, (0.0, t_end), [*q0, *ref.rates(q0, 0.0), 0.0], method="DOP853", rtol=ref.RTOL, atol=ref.ATOL,
                    dense_output=True)
    assert sol.success, sol.message
    return sol.sol


def test_a_stateful_actuator_declared_in_a_test_matches_the_tight_solve_of_its_ode():
    sim = Simulator(scene_from_dict(PAPER), actuator=TorqueLag(LAG))
    assert sim.layout.names == ("theta1", "theta2", "theta3", "theta1_dot", "theta2_dot", "theta3_dot", "lag.torque")
    assert sim.layout.units[-1] == "N·m" and sim.kernel == "python" and sim.method == "rk6"
    assert sim.state_vector[-1] == 0.0
    xs = np.array([(sim.step(), sim.state_vector)[1] for _ in range(STEPS)])
    t = sim.dt * np.arange(1, STEPS + 1)
    expected = lag_reference(t[-1])(t).T
    assert np.max(np.abs(xs[:, :3] - expected[:, :3])) < THETA_TOLERANCE
    assert np.max(np.abs(xs[:, 6] - expected[:, 6])) < TORQUE_TOLERANCE
    # the lag matters: the ideal source's run ends 0.09 rad away
    plain = ref.solve_scene(PAPER).y(t[-1])
    assert abs(plain[0] - xs[-1, 0]) > 1e3 * THETA_TOLERANCE
    # reset starts the actuator's own state again from its initial value: the same run, bit for bit
    sim.reset()
    again = np.array([(sim.step(), sim.state_vector)[1] for _ in range(STEPS)])
    assert np.array_equal(again, xs)


def test_a_held_command_steps_the_actuator_towards_it():
    """Held at u from rest: τ_a follows u (1 − e^(−t/T)), the closed form of its ODE, whatever the linkage
    does (the lag does not read q). Measured 8e-15 N·m."""
    sim = Simulator(scene_from_dict(PAPER), actuator=TorqueLag(LAG))
    u = 2e-3
    taus = [(sim.step(u), sim.state_vector[-1])[1] for _ in range(50)]
    t = sim.dt * np.arange(1, 51)
    # rk6's local error on a linear ODE at dt/T = 0.05: ≈ (dt/T)⁷/7! ≈ 2e-13 of u per step
    assert np.max(np.abs(np.array(taus) - u * (1.0 - np.exp(-t / LAG)))) < 1e-13


def test_the_layout_of_a_drive_with_inductance_declares_its_current_and_the_modes_their_owners():
    sc = scene_from_dict({"model": {"drive": {"inductance": 1e-3}, "joint_limits": {"mcp": [0.0, 0.5]}},
                          "input": {"voltage": {"type": "constant", "value": 3.0}}, "duration": 0.02})
    sim = Simulator(sc, kernel="python")
    assert sim.layout.names[6:] == ("drive.i",) and sim.layout.units[6:] == ("A",)
    assert {(owner, m.name): m.values for owner, m in sim.layout.modes} == {
        ("JointStops", "rest"): ("free", "resting"), ("drive", "mesh"): ("drive", "back", "stuck")}
    for _ in range(10):
        sim.step()
    assert sim.state_vector == (*sim.q, *sim.v, sim.system.drive.i) and sim.system.drive.i > 0.0
    # without inductance the current follows the voltage: no slot, the mode still declared
    l0 = Simulator(scene_from_dict({"model": {"drive": {}}, "input": {"voltage": {"type": "constant", "value": 3.0}},
                                    "duration": 0.02}), kernel="python")
    assert l0.layout.size == 6 and [m.name for _, m in l0.layout.modes] == ["mesh"]
    assert Simulator(scene_from_dict(PAPER)).layout.size == 6


def test_layout_packs_unpacks_and_names_what_it_lacks():
    layout = StateLayout([("lag", (Slot("torque", "N·m"),), ())])
    x = layout.pack((1.0, 2.0, 3.0), (4.0, 5.0, 6.0), (7.0,))
    assert layout.unpack(x) == ((1.0, 2.0, 3.0), (4.0, 5.0, 6.0), (7.0,)) and layout.index("lag.torque") == 6
    with pytest.raises(KeyError, match="no state slot 'lag.current'; the layout has theta1, .*lag.torque"):
        layout.index("lag.current")
    with pytest.raises(ValueError, match="take 1 values, got 0"):
        layout.pack((0.0,) * 3, (0.0,) * 3)


@pytest.mark.parametrize("change, kernel, words", [
    ({"model": {"contact": {"friction_model": "stick_slip", "friction": 0.5}},
      "objects": [{"name": "table", "type": "plane", "point": [0.0, 0.045], "normal": [0.0, -1.0],
                   "motion": {"type": "push", "direction": [1.0, 0.0], "distance": 0.01, "start": 0.1, "duration": 1.0}}]}, "auto",
     "objects: expected fixed objects with stick–slip friction for the actuator 'lag'"),
    ({}, "compiled", "kernel: expected python or auto for the actuator 'lag'"),
    ({"integrator": {"method": "radau", "dt": 1e-3}}, "auto", "integrator.method: expected an explicit Runge-Kutta"),
])
def test_what_the_actuator_slot_does_not_carry_yet_is_refused_in_one_line(change, kernel, words):
    data = {**PAPER, **change, "model": {**PAPER["model"], **change.get("model", {})}}
    with pytest.raises(ConfigError) as err:
        Simulator(scene_from_dict(data), kernel=kernel, actuator=TorqueLag(LAG))
    assert str(err.value).startswith(words) and "\n" not in str(err.value)


def test_the_declared_modes_read_as_the_run_switches_them():
    """paper_to_stop rests on its stop (restitution 0): `resting` exactly on the steps where θ1 is at the
    stop (to the location's round-off) with q' = 0; drive_grasp's mesh mode equals the `mesh_mode` output its run records."""
    sc = load_scene(CONFIG / "paper_to_stop.yaml")
    sim = Simulator(sc)
    upper = next(e for e in sim.system.elements if isinstance(e, JointStops)).upper
    for _ in range(sc.step_count):
        sim.step()
        at_rest = abs(sim.q[0] - upper) < 1e-12 and sim.v == (0.0, 0.0, 0.0)
        assert sim.modes == (("resting",) if at_rest else ("free",))
    assert sim.modes == ("resting",)
    sc = load_scene(CONFIG / "drive_grasp.yaml")
    sim = Simulator(sc)
    modes = [(sim.step(), sim.modes)[1] for _ in range(sc.step_count)]
    recorded = simulate(sc).outputs["mesh_mode"][1:]
    assert modes == [(MESH_MODES[int(m)],) for m in recorded] and modes[-1] == ("stuck",)
