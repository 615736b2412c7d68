"""Force elements describe themselves: the registry, the protocol, generic events, non-affine RATTLE.

References: the closed-form modal stiffness and damping, a tight scipy solve restarted at a
kink (its own event location, not the Simulator's), and RATTLE's linear second half against
its Newton form on the same (affine) forces.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import ClassVar

import numpy as np
import pytest
from scipy.integrate import solve_ivp

import reference as ref
from finger_sim import scene as scene_module
from finger_sim.dynamics import FingerSystem
from finger_sim.effects import EFFECTS, Effect, Smooth, build_elements
from finger_sim.effects.damping import JointDamping
from finger_sim.effects.spring import PipSpring
from finger_sim.effects.stops import JointStops
from finger_sim.integrators.rattle import Rattle
from finger_sim.kinematics import Vec3, distal_offset
from finger_sim.scene import load_scene, scene_from_dict
from finger_sim.simulate import Simulator

ALL_ON = {
    "spring_stiffness": 0.003, "damping": 0.002, "gravity": [3.0, -9.81], "tip_force": [0.5, -1.2],
    "joint_limits": {"mcp": [-0.1, 1.5]}, "restitution": 0.5,
}


def test_every_effect_is_a_scene_key_and_builds_only_when_on():
    # the original five first, in their summation order (old runs stay bit for bit); new ones after
    assert list(EFFECTS)[:5] == ["spring_stiffness", "damping", "gravity", "tip_force", "joint_limits"]
    assert set(EFFECTS) <= scene_module._MODEL_KEYS  # every effect has its schema entry
    on = build_elements(scene_from_dict({"model": ALL_ON}))
    assert [type(e).__name__ for e in on][:5] == ["PipSpring", "JointDamping", "Gravity", "TipForce", "JointStops"]
    assert build_elements(scene_from_dict({"model": {"spring_stiffness": 0}})) == []
    stops = on[4]
    assert (stops.smooth, stops.impact(0), stops.impact(1)) == (False, 0.5, 0.5)
    assert stops.gaps((0.2, 0.0, 0.0)) == pytest.approx((0.3, 1.3))
    assert all(e.smooth for e in on[:4]) and all(e.affine_in_velocity for e in on[:5])


def test_modal_is_the_closed_form_stiffness_and_damping():
    n = (0.3, -0.7, 1.1)
    assert PipSpring(0.003, 0.2).modal((0.1, 0.2, 0.3), n) == pytest.approx((0.003 * (1.1 - 0.3) ** 2, 0.0))
    assert JointDamping(0.002).modal((0.1, 0.2, 0.3), n) == pytest.approx((0.0, 0.002 * (0.09 + 0.49 + 0.64)))
    assert JointStops(0.0, 1.0, 0.0).modal((0.1, 0.2, 0.3), n) == (0.0, 0.0)


# -- a kink: a one-sided spring on θ1 (like a contact), registered as a new effect ------------
LIMIT = 0.5  # rad, where the soft stop begins
K_SOFT = 0.05  # N·m/rad


@dataclass(frozen=True)
class SoftStop(Smooth):
    """Q1 = −K (θ1 − LIMIT) beyond LIMIT: continuous force, a kink in its derivative."""

    located: bool
    affine_in_velocity: ClassVar[bool] = True

    @property
    def smooth(self) -> bool:  # type: ignore[override]
        return not self.located

    def force(self, t: float, q: Vec3, v: Vec3) -> Vec3:
        return (-K_SOFT * max(0.0, q[0] - LIMIT), 0.0, 0.0)

    def potential(self, q: Vec3) -> float:
        return 0.5 * K_SOFT * max(0.0, q[0] - LIMIT) ** 2

    def modal(self, q: Vec3, n: Vec3) -> tuple[float, float]:
        return (K_SOFT * n[0] ** 2, 0.0)

    def gaps(self, q: Vec3) -> tuple[float, ...]:
        return (LIMIT - q[0],) if self.located else ()

    def impact(self, index: int) -> float | None:
        return None

    def gap_gradient(self, index: int, q: Vec3) -> Vec3:
        return (-1.0, 0.0, 0.0)

    def outputs(self, t: float, q: Vec3, v: Vec3) -> Mapping[str, float]:
        return {"soft_stop_torque": self.force(t, q, v)[0]}


def soft_stop_run(monkeypatch: pytest.MonkeyPatch, located: bool) -> Simulator:
    monkeypatch.setitem(EFFECTS, "soft_stop", Effect("soft_stop", lambda scene: SoftStop(located), "test kink"))
    scene = scene_from_dict({"model": {}, "input": {"torque": {"type": "constant", "value": 0.0}},
                             "initial": {"theta1": 0.0, "theta1_dot": 5.0}, "duration": 0.3,
                             "integrator": {"method": "rk4", "dt": 0.001}})
    sim = Simulator(scene)
    for _ in range(300):
        sim.step()
    return sim


@pytest.fixture(scope="module")
def soft_stop_reference() -> np.ndarray:
    """A tight DOP853 solve that restarts at each crossing of θ1 = LIMIT (scipy's own event location)."""
    scene = scene_from_dict({"model": {}, "initial": {"theta1": 0.0, "theta1_dot": 5.0}})
    system = FingerSystem(scene.params, [*build_elements(scene), SoftStop(located=False)])
    q, v = scene.initial_state()
    y, t = np.array([*q, *v]), 0.0

    def crossing(s: float, y: np.ndarray) -> float:
        return y[0] - LIMIT

    crossing.terminal = True  # type: ignore[attr-defined]
    while True:
        sol = solve_ivp(lambda s, y: system.rhs(s, y, lambda _: 0.0), (t, 0.3), y, method="DOP853",
                        rtol=ref.RTOL, atol=ref.ATOL, events=crossing)
        if sol.status != 1:
            return sol.y[:3, -1]
        # stopped at a crossing: restart a hair past it, so the event does not fire again at once
        t, y = float(sol.t_events[0][0]), sol.y_events[0][0]
        sol = solve_ivp(lambda s, y: system.rhs(s, y, lambda _: 0.0), (t, t + 1e-9), y, method="DOP853",
                        rtol=ref.RTOL, atol=ref.ATOL)
        t, y = float(sol.t[-1]), sol.y[:, -1]


def test_a_kink_event_is_located_and_splits_the_step(soft_stop_reference, monkeypatch):
    located = soft_stop_run(monkeypatch, located=True)
    assert located.impacts == 0  # a kink changes no velocity
    smeared = soft_stop_run(monkeypatch, located=False)
    reference = soft_stop_reference
    err_located = float(np.max(np.abs(np.array(located.q) - reference)))
    err_smeared = float(np.max(np.abs(np.array(smeared.q) - reference)))
    assert err_located < 1e-8  # measured 2.6e-9
    assert err_located < err_smeared / 100  # not located: 2.7e-6


# -- RATTLE: the Newton second half for forces that are not affine in q' --------------------
@dataclass(frozen=True)
class NotAffine(JointDamping):
    """Joint damping declared non-affine: RATTLE must take its Newton branch."""

    affine_in_velocity: ClassVar[bool] = False


def test_rattle_newton_second_half_matches_the_linear_solve():
    scene = load_scene(ref.CONFIG / "paper_flexion.yaml")
    alpha = distal_offset(scene.params)
    affine = Rattle(FingerSystem(scene.params, [PipSpring(0.001, alpha), JointDamping(0.01)]))
    newton = Rattle(FingerSystem(scene.params, [PipSpring(0.001, alpha), NotAffine(0.01)]))
    assert affine._affine and not newton._affine
    q, v = scene.initial_state()
    for k in range(50):
        q1, v1 = affine.step(k * 1e-3, q, v, 1e-3, scene.torque)
        q2, v2 = newton.step(k * 1e-3, q, v, 1e-3, scene.torque)
        assert q2 == pytest.approx(q1, abs=1e-13)
        assert v2 == pytest.approx(v1, abs=1e-9 * max(1.0, max(map(abs, v1))))
        q, v = q1, v1


# -- issue 8 item 8: rattle's long free swing ------------------------------------------------
#: The state of free_swing.yaml under rattle at dt = 1 ms at t = 18.988 s, where the first-half
#: Newton iteration used to stall at round-off (p₀ ≈ 0 at the turning point, large constraint impulses).
STALL_T = 18.988
STALL_Q = (1.6484643103638248, 1.8698574055993376, 1.3063886168643681)
STALL_V = (-0.0016790556770805035, -0.0010924928010394167, -0.00412384394622181)


def test_rattle_passes_the_turning_point_where_newton_stalled():
    scene = load_scene(ref.CONFIG / "free_swing.yaml")
    system = scene.build_system()
    rattle = Rattle(system)
    assert rattle._try_step(STALL_T, STALL_Q, STALL_V, 1e-3, scene.torque) is None  # the stall is reproduced
    q, v, t = STALL_Q, STALL_V, STALL_T
    e0 = system.energy(q, v)
    y = np.array([*q, *v])
    for _ in range(20):
        q, v = rattle.step(t, q, v, 1e-3, scene.torque)
        t += 1e-3
    # against a tight solve over the same 20 steps: rattle's order-2 error, no more
    sol = solve_ivp(lambda s, y: system.rhs(s, y, scene.torque), (STALL_T, t), y, method="DOP853",
                    rtol=ref.RTOL, atol=ref.ATOL)
    assert np.max(np.abs(np.array(q) - sol.y[:3, -1])) < 1e-5
    assert max(map(abs, system.constraint(q))) < 1e-14
    assert abs(system.energy(q, v) - e0) < 1e-6 * abs(e0) + 1e-12
