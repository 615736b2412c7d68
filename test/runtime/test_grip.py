"""The grip-force law of finger_sim.runtime.grip, without ROS.

References: a static first-order plant F' = (G τ − F)/T, whose steady state under any
integrating controller is τ = F*/G exactly; the same PI law without anti-windup (whose
integral grows while saturated); the closed loop on the Simulator's grasp_cylinder (its
equilibrium torque found independently by a 1-D root find of the grip force at rest).
"""

from __future__ import annotations

import math
from pathlib import Path

import pytest
from scipy.optimize import brentq

from finger_sim import kinematics
from finger_sim.runtime.grip import (
    CLOSING_TORQUE,
    MAX_SAMPLE_GAP,
    GripController,
    GripSettings,
    Phase,
    PiLaw,
)
from finger_sim.runtime.parameters import ParameterError
from finger_sim.scene import load_scene
from finger_sim.simulate import Simulator, output_names

CUP = Path(__file__).resolve().parents[2] / "config" / "grasp_cylinder.yaml"
DT = 1e-3


def first_order(pi: PiLaw, setpoint: float, gain: float, tau: float, steps: int, f0: float = 0.0) -> list[tuple[float, float]]:
    """(F, u) per step of F' = (gain·u − F)/tau under `pi` (exact discretization, u held)."""
    decay = math.exp(-DT / tau)
    f, out = f0, []
    for _ in range(steps):
        u = pi.update(setpoint - f, DT)
        f = gain * u + (f - gain * u) * decay
        out.append((f, u))
    return out


def test_pi_reaches_the_setpoint_on_a_static_first_order_plant():
    gain, tau = 8.8, 0.01  # N per N·m, s: the cup's static gain, a fast lag
    pi = PiLaw(0.005, 4.0, 0.1)
    run = first_order(pi, 0.5, gain, tau, 3000)
    f_end, u_end = run[-1]
    assert f_end == pytest.approx(0.5, abs=1e-12)
    assert u_end == pytest.approx(0.5 / gain, rel=1e-12)  # the plant's own steady state
    assert pi.integral == pytest.approx(0.5 / gain, rel=1e-12)  # no error left for kp
    assert max(f for f, _ in run) < 0.5 * 1.01  # an integral-dominated loop barely overshoots


def test_anti_windup_freezes_the_integral_while_saturated():
    limit = 0.1
    pi, plain = PiLaw(0.005, 4.0, limit), PiLaw(0.005, 4.0, math.inf)  # plain: no clamping
    integrals, outputs = [], []
    for _ in range(500):  # an unreachable setpoint: the plant gives nothing back
        outputs.append(pi.update(1.0, DT))
        plain.update(1.0, DT)
        integrals.append(pi.integral)
    first = next(i for i, u in enumerate(outputs) if u >= limit * (1 - 1e-15))  # saturated from here on ...
    assert 10 < first < 100 and all(u == pytest.approx(limit, rel=1e-15) for u in outputs[first:])
    assert integrals[first:] == [integrals[first]] * (500 - first)  # ... and the integral frozen
    assert integrals[first] <= limit
    assert plain.integral == pytest.approx(4.0 * 1.0 * 500 * DT)  # 2 N·m without anti-windup
    # the error reverses: the clamped law leaves saturation at once, the plain one would wait
    # until its 2 N·m integral unwinds (0.5 s at this error)
    assert pi.update(-0.2, DT) < limit
    assert plain.update(-0.2, DT) > limit


def test_anti_windup_integrates_back_out_of_saturation():
    pi = PiLaw(0.0, 1.0, 0.1)
    pi.reset(0.1)
    assert pi.update(1.0, DT) == 0.1 and pi.integral == 0.1  # pushed further out: frozen
    assert pi.update(-1.0, DT) == pytest.approx(0.1 - DT)  # pulled back: integrates at once


def test_sequence_close_hold_open():
    s = GripSettings.from_values({})
    ctl = GripController(s)
    assert ctl.phase is Phase.IDLE and ctl.update(0.0, DT) == 0.0
    ctl.set_setpoint(0.5)
    assert ctl.phase is Phase.CLOSING and ctl.update(0.0, DT) == CLOSING_TORQUE
    u = ctl.update(2 * s.contact_threshold, DT)  # contact: bumpless hand-over to the PI law
    assert ctl.phase is Phase.HOLDING
    assert u == pytest.approx(CLOSING_TORQUE + s.ki * (0.5 - 2 * s.contact_threshold) * DT, rel=1e-12)
    ctl.set_setpoint(0.0)
    opening = [ctl.update(0.3, DT) for _ in range(round(s.opening_time / DT) + 5)]
    assert opening[: round(s.opening_time / DT)] == [-s.opening_torque] * round(s.opening_time / DT)
    assert opening[-5:] == [0.0] * 5 and ctl.phase is Phase.IDLE


@pytest.mark.parametrize("value", [-0.1, math.nan, math.inf])
def test_a_bad_setpoint_is_refused(value):
    ctl = GripController(GripSettings.from_values({}))
    with pytest.raises(ValueError, match="grip setpoint"):
        ctl.set_setpoint(value)
    assert ctl.setpoint == 0.0


def test_bad_parameters_name_themselves():
    with pytest.raises(ParameterError, match="'ki'"):
        GripSettings.from_values({"ki": -1.0})
    with pytest.raises(ParameterError, match="'closing_torque'.*max_torque"):
        GripSettings.from_values({"closing_torque": 0.2, "max_torque": 0.1})
    with pytest.raises(ParameterError, match="'kp'.*type float"):
        GripSettings.from_values({"kp": "1"})
    assert GripSettings.from_values({"kp": 1}).kp == 1.0  # an int is taken for a float, as ROS 2 users type it


def test_closed_loop_on_the_cup_holds_the_setpoint():
    """The defaults on grasp_cylinder (Simulator, 1 kHz, a loop delay of 2 steps): 98 % of 0.5 N
    within 0.15 s of contact, no overshoot beyond 1 %, and at rest the torque that holds 0.5 N in
    the static equilibrium (a root find of the grip force at rest over the held torque)."""
    scene = load_scene(CUP).with_overrides(duration=1.0)
    sim = Simulator(scene)
    index = output_names(sim.system.elements, sim.q).index("grip_force")

    def grip(s: Simulator) -> float:
        return [v for e in s.system.elements for v in e.outputs(s.time, s.q, s.v).values()][index]

    ctl = GripController(GripSettings.from_values({}))
    ctl.set_setpoint(0.5)
    delayed, forces, contact = [0.0, 0.0], [], None
    for n in range(1000):
        delayed.append(ctl.update(grip(sim), DT))
        sim.step(delayed.pop(0))
        forces.append(grip(sim))
        if contact is None and forces[-1] > 0.0:
            contact = n
    reached = next(n for n, f in enumerate(forces) if f >= 0.49)
    assert (reached - contact) * DT < 0.15
    assert max(forces) < 0.5 * 1.01
    assert max(abs(f - 0.5) for f in forces[-300:]) < 1e-6

    # reference: the static equilibrium (spec §7) at 0.5 N, from closed-form kinematics: the θ1
    # where the grip force at rest is 0.5 N, and there τ = dV/dθ1 along the linkage
    p = scene.params

    def at_rest(theta1: float) -> dict[str, float]:
        q = kinematics.assemble(p, theta1)
        return {k: v for e in sim.system.elements for k, v in e.outputs(0.0, q, (0.0, 0.0, 0.0)).items()}

    def potential(theta1: float) -> float:
        q = kinematics.assemble(p, theta1)
        return sum(e.potential(q) for e in sim.system.elements)

    theta = brentq(lambda t1: at_rest(t1)["grip_force"] - 0.5, 0.19, 0.23, xtol=1e-15)
    h = 1e-6
    held = (potential(theta + h) - potential(theta - h)) / (2 * h)
    assert sim.q[0] == pytest.approx(theta, abs=1e-7)
    assert ctl.pi.integral == pytest.approx(held, rel=1e-6)


def test_a_stalled_sample_does_not_kick_the_integral():
    s = GripSettings.from_values({})
    ctl = GripController(s)
    ctl.set_setpoint(0.5)
    ctl.update(0.0, DT)
    ctl.update(0.1, DT)  # contact: holding, integral at the closing torque
    before = ctl.pi.integral
    ctl.update(0.1, 0.5)  # half a second without a sample counts as MAX_SAMPLE_GAP
    assert ctl.pi.integral == pytest.approx(before + s.ki * 0.4 * MAX_SAMPLE_GAP, rel=1e-12)
