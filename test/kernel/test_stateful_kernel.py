"""A stateful actuator on the compiled kernel (`kernel.stateful`): an actuator that declares its law
(`actuators.base.ActuatorLaw`) is stepped compiled, and `kernel="auto"` takes that path by itself.

The actuator is declared in this file alone (0 package files): a first-order lag with velocity feedback
between the command u (N·m) and the torque on θ1, τ_a' = (u − b θ1' − τ_a)/T (b = 0: test/core/
test_state_layout's lag). Its compiled run is held to the Python path of the same actuator (1e-13 rad, in
practice bit for bit) on a smooth scene, through stop impacts, the rest mode and its release, contact and
stick–slip friction, and with substeps; and to a tight solve of its ODE written here (scipy solve_ivp,
DOP853 at test/reference.py's rtol, on its §4 equations)."""

from __future__ import annotations

import numpy as np
import pytest
import reference as ref
import yaml
from scipy.integrate import solve_ivp

from finger_sim.actuators.base import ActuatorLaw, LawActuator
from finger_sim.errors import ConfigError
from finger_sim.scene import scene_from_dict
from finger_sim.simulate import Simulator
from finger_sim.state_layout import Slot

pytest.importorskip("numba")
from finger_sim.kernel import compiled_name  # noqa: E402

#: The lag's time constant, s, and its velocity feedback, N·m·s/rad (θ1' ≈ 1 rad/s: comparable to u).
LAG, FEEDBACK = 0.02, 1e-3
#: The paper's scene (config/paper_flexion.yaml: τ = 1 + 10 t N·mm, PIP spring), stepped by rk6.
PAPER = {"model": {"spring_stiffness": 0.001}, "input": {"torque": {"type": "ramp", "offset": 0.001, "slope": 0.01}},
         "duration": 0.3, "integrator": {"method": "rk6", "dt": 1e-3}}
#: Compiled against the Python path: the same arithmetic in the same order (measured: 0, bit for bit).
KERNEL_TOLERANCE = 1e-13  # rad, rad/s, N·m
#: rk6 at 1 ms against the tight solve (measured 3.4e-12 rad, 3.9e-13 N·m; the feedback moves θ1 by 0.17 rad).
THETA_TOLERANCE = 1e-10  # rad
TORQUE_TOLERANCE = 1e-12  # N·m


def lag_torque(p, t, q0, q1, q2, v0, v1, v2, u, own):
    """The torque on θ1 (N·m): the lag's slot."""
    return own[0]


def lag_rates(p, t, q0, q1, q2, v0, v1, v2, u, own):
    """τ_a' = (u − b θ1' − τ_a)/T, N·m/s; p = (T s, b N·m·s/rad)."""
    return ((u - p[1] * v0 - own[0]) / p[0],)


class FeedbackLag(LawActuator):
    """A first-order lag with velocity feedback between the command u (N·m) and the torque on θ1, τ_a(0) = 0."""

    name = "lag"
    slots = (Slot("torque", "N·m", "the lagged torque on θ1"),)
    law = ActuatorLaw(lag_torque, lag_rates)

    def __init__(self, time_constant: float, feedback: float = FEEDBACK) -> None:
        self.time_constant, self.feedback = time_constant, feedback

    def initial(self) -> tuple[float, ...]:
        return (0.0,)

    def kernel_params(self) -> tuple[float, ...]:
        return (self.time_constant, self.feedback)


def run(data: dict, kernel: str, steps: int, actuator: FeedbackLag | None = None) -> tuple[Simulator, np.ndarray, list]:
    """`steps` steps of the scene `data` with the lag on `kernel`: (Simulator, flat states, modes) after each."""
    sim = Simulator(scene_from_dict(data), kernel=kernel, actuator=actuator or FeedbackLag(LAG))
    xs, modes = [], []
    for _ in range(steps):
        sim.step()
        xs.append(sim.state_vector)
        modes.append(sim.modes)
    return sim, np.array(xs), modes


def test_auto_steps_a_declared_law_compiled_as_the_python_path_and_the_tight_solve_of_its_ode():
    sim, xs, _ = run(PAPER, "auto", 300)
    assert sim.kernel == compiled_name() and "Python path" not in sim.method_reason and sim.method == "rk6"
    assert sim.layout.names[-1] == "lag.torque"
    python, reference_xs, _ = run(PAPER, "python", 300)
    assert python.kernel == "python"
    assert np.max(np.abs(xs - reference_xs)) <= KERNEL_TOLERANCE
    command = ref.ramp(0.001, 0.01)
    effects = ref.Effects(k=0.001)

    def rhs(t: float, y: np.ndarray) -> np.ndarray:
        acc, _ = ref.kkt(y[:3], y[3:6], y[6], effects)
        return np.concatenate([y[3:6], acc, [(command(t) - FEEDBACK * y[3] - y[6]) / LAG]])

    q0 = ref.assemble(0.0)
    t = sim.dt * np.arange(1, 301)
    solution = solve_ivp(rhs, (0.0, t[-1]), [*q0, *ref.rates(q0, 0.0), 0.0], method="DOP853", rtol=ref.RTOL,
                         atol=ref.ATOL, dense_output=True)
    assert solution.success, solution.message
    expected = solution.sol(t).T
    assert np.max(np.abs(xs[:, :3] - expected[:, :3])) < THETA_TOLERANCE
    assert np.max(np.abs(xs[:, 6] - expected[:, 6])) < TORQUE_TOLERANCE
    # the feedback matters: the lag without it ends far away
    _, plain, _ = run(PAPER, "auto", 300, FeedbackLag(LAG, 0.0))
    assert abs(plain[-1, 0] - xs[-1, 0]) > 1e3 * THETA_TOLERANCE
    # reset starts the slot again from its initial value: the same run, bit for bit
    sim.reset()
    assert np.array_equal(np.array([(sim.step(), sim.state_vector)[1] for _ in range(300)]), xs)


def _scene(path: str, **changes: object) -> dict:
    with open(ref.CONFIG / path) as f:
        data = yaml.safe_load(f)
    data.update(changes)
    return data


def _hold_table() -> dict:
    """config/friction/hold_table.yaml with μ_s = 1: the tip locks on the table and breaks away when the command drops."""
    data = _scene("friction/hold_table.yaml", integrator={"method": "rk6", "dt": 5e-4})
    data["model"]["contact"]["static_friction"] = 1.0
    return data


#: Flexion into an MCP stop at 0.8 rad and back onto the stop at 0 under a 2 Hz sine (test/core/test_actuator_events).
STOPS = {"model": {"spring_stiffness": 0.001, "joint_limits": {"mcp": [0.0, 0.8]}},
         "input": {"torque": {"type": "sine", "amplitude": 0.01, "frequency": 2.0}}, "duration": 0.6,
         "integrator": {"method": "rk6", "dt": 1e-3}}


@pytest.mark.parametrize("data, steps, events", [
    ({**STOPS, "model": {**STOPS["model"], "restitution": 0.0}}, 600, "rests"),
    ({**STOPS, "model": {**STOPS["model"], "restitution": 0.5}}, 600, "impacts"),
    (_scene("grasp_cylinder.yaml", integrator={"method": "rk6", "dt": 2.5e-4}), 1400, "contact"),
    (_hold_table(), 1200, "friction"),
], ids=["rest", "rebounds", "contact", "stick-slip"])
def test_the_compiled_lag_through_the_events_is_the_python_path(data, steps, events):
    """The events carry the slot (`simulation.actuated_events`) on either kernel: the same impacts, the same
    modes on every step, the states to 1e-13."""
    compiled, xs, modes = run(data, "compiled", steps)
    python, expected, expected_modes = run(data, "python", steps)
    assert compiled.kernel == compiled_name() and python.kernel == "python"
    assert np.max(np.abs(xs - expected)) <= KERNEL_TOLERANCE
    assert modes == expected_modes and compiled.impacts == python.impacts
    seen = {m for step in modes for m in step}
    if events == "rests":  # the held path (`advance_held`): the slot goes on while the stop holds q
        assert "resting" in seen and compiled.impacts >= 2
    elif events == "impacts":
        assert compiled.impacts >= 2 and "resting" not in seen
    elif events == "contact":  # the distal phalanx presses the cup at the end
        assert any(g < 0 for e in compiled.system.elements if not e.smooth for g in e.gaps(compiled.q))
    else:
        assert {"locked", "sliding"} <= seen


def test_substeps_resolving_a_fast_lag_run_compiled_and_follow_its_closed_form():
    """T = 0.1 ms under a 1 ms step: auto takes 40 substeps (`Actuator.time_constant`); held at u from rest,
    the slot follows u (1 − e^(−t/T)) (b = 0), on the compiled path as on the Python one."""
    data = {**PAPER, "integrator": {"method": "auto", "dt": 1e-3}}
    sims = [Simulator(scene_from_dict(data), kernel=kernel, actuator=FeedbackLag(1e-4, 0.0)) for kernel in ("auto", "python")]
    assert sims[0].kernel == compiled_name() and sims[0].integrator.substeps == 40
    u = 2e-3
    states = [[(sim.step(u), sim.state_vector)[1] for _ in range(5)] for sim in sims]
    assert np.max(np.abs(np.array(states[0]) - np.array(states[1]))) <= KERNEL_TOLERANCE
    t = 1e-3 * np.arange(1, 6)
    # measured 1.9e-13 N·m (auto's rk6, 40 substeps: h/T = 0.25)
    assert np.max(np.abs(np.array(states[0])[:, 6] - u * (1.0 - np.exp(-t / 1e-4)))) < 1e-12


#: A cup far from the finger, moving: a contact with a moving object has no compiled form.
MOVING = {**PAPER, "objects": [{"name": "cup", "type": "circle", "center": [0.2, 0.2], "radius": 0.01,
                                "motion": {"type": "push", "direction": [1.0, 0.0], "distance": 0.01,
                                           "start": 0.0, "duration": 1.0}}]}


def test_where_the_scene_has_no_compiled_form_auto_says_so_and_compiled_is_refused_in_one_line():
    sim = Simulator(scene_from_dict(MOVING), actuator=FeedbackLag(LAG))
    assert sim.kernel == "python"
    assert sim.method_reason.endswith("; a force element has no compiled form: the Python path")
    with pytest.raises(ConfigError) as err:
        Simulator(scene_from_dict(MOVING), kernel="compiled", actuator=FeedbackLag(LAG))
    assert str(err.value) == ("kernel: expected a kernel that can run here (a force element has no compiled form), "
                              "got 'compiled'")
