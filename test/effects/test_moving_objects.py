"""Objects with a prescribed motion (`objects[i].motion`): onset located inside the step, and the
energy balance with the motion's work.

References: a finger that no force moves (no spring, torque, gravity) and a cup pushed onto its
distal phalanx along the phalanx's normal, whose contact onset is then the closed-form root
s(t*) = gap0 of the push profile; the energy balance E(t) − E(0) = ∫ P_motion dt (no damping,
no friction, no torque), P_motion = F·ċ integrated by the trapezoid rule, whose error falls
as dt² (checked at two step sizes).
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from finger_sim import kinematics as kin
from finger_sim.effects.contact_geometry import ObjectMotion, objects_from_list
from finger_sim.errors import ConfigError
from finger_sim.model import FingerParams
from finger_sim.scene import scene_from_dict
from finger_sim.simulate import Simulator, simulate

P = FingerParams()
THETA1 = 0.2  # rad
R = 0.012  # m, the cup
RHO3 = 0.007  # m, the distal capsule (spec §7)
PUSH_DISTANCE, PUSH_TIME = 0.004, 0.2  # m, s


def _cup_beside_the_distal_phalanx(gap0: float) -> tuple[tuple[float, float], tuple[float, float]]:
    """(centre, unit normal): a cup gap0 m off the middle of the distal phalanx at θ1 = THETA1."""
    q = kin.assemble(P, THETA1)
    psi = q[2] + kin.distal_offset(P)
    bx, by = P.r1 * math.cos(q[0]), P.r1 * math.sin(q[0])
    mid = (bx + 0.5 * P.L3 * math.cos(psi), by + 0.5 * P.L3 * math.sin(psi))
    n = (-math.sin(psi), math.cos(psi))
    return (mid[0] + n[0] * (RHO3 + R + gap0), mid[1] + n[1] * (RHO3 + R + gap0)), n


def _pushed_scene(gap0: float, *, dt: float = 1e-3, duration: float = 0.3, damping: float = 1.5):
    centre, n = _cup_beside_the_distal_phalanx(gap0)
    return scene_from_dict({
        "model": {"spring_stiffness": 0.0, "contact": {"damping": damping}},
        "objects": [{"name": "cup", "type": "circle", "center": list(centre), "radius": R,
                     "motion": {"type": "push", "direction": [-n[0], -n[1]], "distance": PUSH_DISTANCE,
                                "start": 0.0, "duration": PUSH_TIME}}],
        "input": {"torque": {"type": "constant", "value": 0.0}},
        "initial": {"theta1": THETA1},
        "duration": duration,
        "integrator": {"method": "auto", "dt": dt},
    })


class _Recording(Simulator):
    """The Simulator, keeping the time of every crossing it locates."""

    def __init__(self, *args, **kwargs):
        self.located: list[float] = []
        super().__init__(*args, **kwargs)

    def _locate(self, *args, **kwargs):
        crossing = super()._locate(*args, **kwargs)
        self.located.append(crossing.t)
        return crossing


def test_onset_caused_by_the_motion_is_located_inside_the_step():
    gap0 = 0.00119  # m
    # the push s(t) = L (1 − cos(π t / T)) / 2 along the normal closes gap0 at t*:
    t_star = PUSH_TIME / math.pi * math.acos(1.0 - 2.0 * gap0 / PUSH_DISTANCE)
    dt = 1e-3
    assert 0.2 < (t_star / dt) % 1.0 < 0.8  # well inside a step
    sim = _Recording(_pushed_scene(gap0, dt=dt))
    before = None
    while sim.time < t_star + dt:
        before = sim.q if sim.time < t_star else before
        sim.step()
    assert before == kin.assemble(P, THETA1)  # nothing moved the finger before the onset
    assert sim.located and sim.located[0] == pytest.approx(t_star, abs=1e-9)
    assert sim.kernel == "python"  # a moving object has no compiled form


def _work_balance(dt: float) -> tuple[float, float]:
    """(max |E − E(0) − W|, W at the end), J, no damping: the motion's work is all that enters."""
    run = simulate(_pushed_scene(0.001, dt=dt, damping=0.0))
    power, t = run.outputs["motion_power"], run.t
    work = np.concatenate([[0.0], np.cumsum(0.5 * (power[1:] + power[:-1]) * np.diff(t))])
    return float(np.max(np.abs(run.energy - run.energy[0] - work))), float(work[-1])


def test_energy_gained_equals_the_work_of_the_prescribed_motion():
    err_coarse, work = _work_balance(1e-3)
    err_fine, work_fine = _work_balance(2.5e-4)
    assert work > 1e-5  # the push did work on the finger (J)
    assert err_fine < 1e-3 * work_fine
    assert err_coarse / err_fine > 10.0  # the trapezoid rule's dt²: 16 for a 4× finer step


def test_motion_profiles_and_their_validation():
    push = ObjectMotion("push", (0.0, -1.0), 0.002, 0.5, 1.0 / 0.2)
    assert push.offset(0.4) == (0.0, -0.0) and push.offset(0.8) == (0.0, -0.002)
    assert push.offset(0.6)[1] == pytest.approx(-0.001, abs=1e-15)  # halfway in time, halfway in distance
    h = 1e-7  # the velocity is the derivative of the offset
    assert push.velocity(0.55)[1] == pytest.approx((push.offset(0.55 + h)[1] - push.offset(0.55 - h)[1]) / (2 * h), rel=1e-6)
    vib = ObjectMotion("vibration", (1.0, 0.0), 0.001, 0.0, 5.0)
    assert vib.offset(0.1)[0] == pytest.approx(0.001, abs=1e-15) and vib.offset(0.2)[0] == pytest.approx(0.0, abs=1e-15)
    obj = {"name": "c", "type": "circle", "center": [0.0, 1.0], "radius": 0.1}
    with pytest.raises(ConfigError, match=r"objects\[0\]\.motion\.duration"):
        objects_from_list([{**obj, "motion": {"type": "push", "direction": [0, 1], "distance": 0.01, "start": 0}}])
    with pytest.raises(ConfigError, match=r"objects\[0\]\.motion\.direction"):
        objects_from_list([{**obj, "motion": {"type": "vibration", "direction": [0, 0], "amplitude": 0.01,
                                              "frequency": 2, "start": 0}}])
    scene = _pushed_scene(0.001)
    assert scene_from_dict(scene.to_dict()) == scene  # round-trips through the schema
