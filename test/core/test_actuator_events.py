"""A stateful actuator through the Simulator's events: stop impacts, the rest mode and its release, contact.

The actuator is test_state_layout's first-order torque lag, τ_a' = (u − τ_a)/T. Its ODE does not read q,
so its solution is a closed form of the input (written here); the linkage's reference is then
test/hybrid_reference.py's tight solve (solve_ivp DOP853 at rtol 1e-11 with a terminal event per stop
and contact gap, spec §3's impacts and the rest convention) driven by that closed form."""

from __future__ import annotations

import math

import numpy as np
import pytest
import yaml

import hybrid_reference as hybrid
import reference as ref
import stick_slip_reference
from test_state_layout import LAG, PAPER, TorqueLag

from finger_sim.errors import ConfigError
from finger_sim.scene import scene_from_dict
from finger_sim.simulate import Simulator

#: Flexion into an MCP stop at 0.8 rad and back onto the stop at 0 under a 2 Hz sine through the lag.
AMPLITUDE, FREQUENCY = 0.01, 2.0  # N·m, Hz
STOPS = {"model": {"spring_stiffness": 0.001, "joint_limits": {"mcp": [0.0, 0.8]}},
         "input": {"torque": {"type": "sine", "amplitude": AMPLITUDE, "frequency": FREQUENCY}}, "duration": 0.6,
         "integrator": {"method": "rk6", "dt": 1e-3}}
#: The reference restarts every RESTART s: its rest checks the release at each restart (its own rule,
#: `hybrid_reference.solve`, looks for a release only within one piece between restarts).
RESTART = 5e-3
#: rk6 at 1 ms against the tight solve, measured: 5.5e-13 rad (rest, e = 0), 3.7e-13 rad (rebounds, e = 0.5).
THETA_TOLERANCE = 1e-10  # rad
#: The lag's slot against its closed form, measured 1.0e-14 N·m.
TORQUE_TOLERANCE = 1e-13  # N·m


def lag_of_sine(t: float) -> float:
    """τ_a(t), N·m, under u = A sin ωt from τ_a(0) = 0: the closed form of τ_a' = (u − τ_a)/T."""
    w = 2.0 * math.pi * FREQUENCY
    k = 1.0 + (w * LAG) ** 2
    return AMPLITUDE / k * (math.sin(w * t) - w * LAG * math.cos(w * t) + w * LAG * math.exp(-t / LAG))


def run(data: dict, actuator: TorqueLag | None = None) -> tuple[Simulator, np.ndarray, list[str]]:
    sim = Simulator(scene_from_dict(data), actuator=actuator, kernel="python")
    xs, modes = [], []
    for _ in range(round(data["duration"] / data["integrator"]["dt"])):
        sim.step()
        xs.append(sim.state_vector)
        modes.append(sim.modes[0] if sim.modes else "")
    return sim, np.array(xs), modes


@pytest.mark.parametrize("restitution, impacts", [(0.0, 2), (0.5, 3)])
def test_the_lag_on_stops_rests_releases_and_rebounds_as_the_tight_solve(restitution, impacts):
    """e = 0: rests on the upper stop, released when the lagged torque lets the spring pull it off, rests on the
    lower stop and leaves it again; e = 0.5: three rebounds. The lag's slot goes on through the rest."""
    data = {**STOPS, "model": {**STOPS["model"], "restitution": restitution}}
    sim, xs, modes = run(data, TorqueLag(LAG))
    t = sim.dt * np.arange(1, len(xs) + 1)
    expected = hybrid.solve(data, torque=(lambda a, b: lag_of_sine, lambda end: list(np.arange(RESTART, end, RESTART))))
    assert sim.impacts == expected.impacts == impacts
    assert np.max(np.abs(xs[:, :6] - expected.states(t).T)[:, :3]) < THETA_TOLERANCE
    assert np.max(np.abs(xs[:, 6] - [lag_of_sine(s) for s in t])) < TORQUE_TOLERANCE
    if restitution == 0.0:  # two rests, each left again: the release under the lagged torque, not the command
        rests = [k for k, m in enumerate(modes) if m == "resting"]
        assert modes[-1] == "free" and 100 < len(rests) < 150
        _, ideal, ideal_modes = run(data)
        assert ideal_modes.count("resting") != len(rests)
        assert np.max(np.abs(ideal[:, 0] - xs[:, 0])) > 1e3 * THETA_TOLERANCE


def test_the_lag_closing_onto_a_cup_matches_the_tight_solve_with_contact():
    """config/grasp_cylinder.yaml (0.02 N·m through the lag): the distal phalanx meets the cup and presses it;
    rk6 at 0.25 ms against the tight solve with the contact's onset as an event."""
    with open(ref.CONFIG / "grasp_cylinder.yaml") as f:
        data = yaml.safe_load(f)
    data.update(duration=0.35, integrator={"method": "rk6", "dt": 2.5e-4})
    value = data["input"]["torque"]["value"]
    sim, xs, _ = run(data, TorqueLag(LAG))
    t = sim.dt * np.arange(1, len(xs) + 1)
    expected = hybrid.solve(data, torque=(lambda a, b: lambda s: value * (1.0 - math.exp(-s / LAG)), lambda end: []))
    theta = expected.states(t)[:3].T
    # measured 1.75e-8 rad: rk6's error across the contact's onset (a kink), as the ideal source's own on
    # this scene and step (2.3e-8 rad against its tight solve)
    assert np.max(np.abs(xs[:, :3] - theta)) < 5e-8
    assert np.max(np.abs(xs[:, 6] - value * (1.0 - np.exp(-t / LAG)))) < TORQUE_TOLERANCE
    assert sim.system.elements and any(g < 0 for e in sim.system.elements if not e.smooth for g in e.gaps(sim.q))


def lag_of_step(before: float, after: float, at: float) -> tuple:
    """(segment → τ_a(t), t_end → switches) under the command u = before, after from `at` s: the closed form of
    the lag (exponentials joined at `at`), in `stick_slip_reference.solve`'s torque pair."""
    at_value = before * (1.0 - math.exp(-at / LAG))

    def on(a: float, b: float):
        if b <= at:
            return lambda t: before * (1.0 - math.exp(-t / LAG))
        return lambda t: after + (at_value - after) * math.exp(-(t - at) / LAG)

    return on, lambda end: [at] if at < end else []


def test_the_lag_holding_a_table_by_stick_slip_locks_and_breaks_away_as_the_tight_solve():
    """config/friction/hold_table.yaml with μ_s = 1 through the lag: the tip slides on the table, locks at its
    turning point, and breaks away after the command drops at 0.5 s, once the lagged torque has fallen below
    what the friction cone holds; rk6 at 0.5 ms against test/stick_slip_reference.py's tight solve."""
    with open(ref.CONFIG / "friction" / "hold_table.yaml") as f:
        data = yaml.safe_load(f)
    data["model"]["contact"]["static_friction"] = 1.0
    data.update(duration=0.6, integrator={"method": "rk6", "dt": 5e-4})
    command = data["input"]["torque"]
    torque = lag_of_step(command["before"], command["after"], command["at"])
    sim = Simulator(scene_from_dict(data), actuator=TorqueLag(LAG), kernel="python")
    xs, modes = [], []
    for _ in range(1200):
        sim.step()
        xs.append(sim.state_vector)
        modes.append(sim.modes[-1])
    t = sim.dt * np.arange(1, 1201)
    expected = stick_slip_reference.solve(data, torque=torque)
    # measured 5.0e-8 rad (rk6's error across the contact and the mode changes)
    assert np.max(np.abs(np.array(xs)[:, :3] - expected.states(t)[:3].T)) < 2e-7
    assert np.max(np.abs(np.array(xs)[:, 6] - [torque[0](s - 1e-9, s)(s) for s in t])) < TORQUE_TOLERANCE
    changes = [(t[k], modes[k]) for k in range(1, len(t)) if modes[k] != modes[k - 1]]
    assert [m for _, m in changes] == ["locked", "sliding"]
    assert [c for _, c in expected.changes[1:]] == ["lock", "break"]
    for (s, _), (s_ref, _) in zip(changes, expected.changes[1:]):
        assert s_ref <= s < s_ref + sim.dt  # the first step that ends in the new mode
    assert changes[1][0] > command["at"] + 2 * sim.dt  # the lag delays the breakaway (0.5028 s)


def test_auto_runs_the_actuator_on_the_python_path_and_says_so_while_compiled_is_refused():
    sim = Simulator(scene_from_dict(PAPER), actuator=TorqueLag(LAG))
    assert sim.kernel == "python"
    assert sim.method_reason.endswith("; the actuator 'lag' has no compiled form: the Python path")
    assert sim.integrator.substeps == 1  # T = 20 dt: one step resolves it
    assert "\n" not in sim.method_reason
    with pytest.raises(ConfigError) as err:
        Simulator(scene_from_dict(PAPER), kernel="compiled", actuator=TorqueLag(LAG))
    assert str(err.value) == ("kernel: expected python or auto for the actuator 'lag' with its own state "
                              "(it has no compiled form), got 'compiled'")


#: A lag ten times faster than a 1 ms step: rk4 is unstable on its mode s = −1/T (|s|·dt = 10 > 2.79).
FAST_LAG = 1e-4  # s


def test_auto_substeps_resolve_the_declared_time_constant_and_a_named_method_unstable_on_it_is_refused():
    """`Actuator.time_constant` (the lag declares T) enters the stability check: auto takes
    ceil(dt/(T·0.25)) = 40 substeps and the slot follows its closed form u (1 − e^(−t/T)) under a held
    command; rk4 named at that dt is refused in one line, naming the largest stable dt."""
    sim = Simulator(scene_from_dict({**PAPER, "integrator": {"method": "auto", "dt": 1e-3}}), actuator=TorqueLag(FAST_LAG))
    assert sim.integrator.substeps == 40 and sim.method_reason.endswith(
        "; 40 substeps per step resolve the time constant 0.0001 s of the actuator 'lag'")
    u = 2e-3
    taus = [(sim.step(u), sim.state_vector[-1])[1] for _ in range(5)]
    t = sim.dt * np.arange(1, 6)
    # measured 1.9e-13 N·m (auto's rk6, h/T = 0.025: ≈ 1e-10 of u); unresolved, rk4's |R(−10)| = 291 per step
    assert np.max(np.abs(np.array(taus) - u * (1.0 - np.exp(-t / FAST_LAG)))) < 1e-12
    with pytest.raises(ConfigError) as err:
        Simulator(scene_from_dict({**PAPER, "integrator": {"method": "rk4", "dt": 1e-3}}), actuator=TorqueLag(FAST_LAG))
    assert str(err.value) == ("integrator.method: rk4 is unstable on the time constant 0.0001 s of the actuator 'lag' "
                              "at dt = 0.001 s; expected auto, or dt ≤ 0.000279 s, got 'rk4'")


def test_a_state_set_from_outside_keeps_the_actuators_slots():
    """sim.q and sim.v replaced by equal values (new objects) mid-run: the lag goes on from its own value, so the
    run is bit-identical to one left alone; a new pose keeps the slot's value too."""
    left, touched = (Simulator(scene_from_dict(PAPER), actuator=TorqueLag(LAG)) for _ in range(2))
    for k in range(200):
        left.step()
        touched.step()
        if k == 99:
            touched.q, touched.v = tuple(list(touched.q)), tuple(list(touched.v))
    assert left.state_vector == touched.state_vector
    tau = touched.state_vector[-1]
    touched.q, touched.v = touched.scene.initial_state()
    assert touched.state_vector[-1] == tau != 0.0
