"""The stick–slip friction modes stepped inside the Simulator's fixed step (spec §7), beside its gap events.

The pattern of the drive's stuck mesh (`finger_sim.actuators.stepping`) and of the rest on a stop:
- sliding, the guard is direction·θ1' ≥ 0; where a step ends below −GUARD_TOLERANCE the turn is
  located by Illinois regula falsi on the step's length. There θ1' = 0 and the holding test decides:
  `locked` (q fixed, q' = 0 exactly from then on) or sliding on towards the excess;
- locked, q is fixed and q' = 0, so the holding margin Σ μ_s F_n,k |j_k| − |τ_h| is a function of
  time alone (the input): its root (brentq) is the breakaway, and the finger slides towards
  −sgn τ_h (the way the unheld linkage accelerates).
τ_h is the torque on θ1 that keeps θ1'' = 0 with the friction left out (§4 at q' = 0); the
accelerations are affine in the torque on θ1, so two solves give it exactly.

A stop impact reverses θ1' (the sliding direction follows); at rest on a stop the stop holds the
load and the friction is idle; leaving the stop is a turning point. Objects that move and a drive
are refused by the scene (`finger_sim.scene`): neither is in this law yet.
"""

from __future__ import annotations

import logging
import math
from typing import TYPE_CHECKING

import numpy as np

from finger_sim.effects.friction_modes import LOCKED, SLIDING, STICK_SLIP, StickSlipContact
from finger_sim.errors import ConfigError, SimulationDiverged
from finger_sim.integrators.base import TorqueFn
from finger_sim.kinematics import Vec3

if TYPE_CHECKING:
    from finger_sim.dynamics import FingerSystem
    from finger_sim.scene import Scene
    from finger_sim.simulate import Simulator

LOG = logging.getLogger(__name__)
ZERO: Vec3 = (0.0, 0.0, 0.0)
#: The turn guard direction·θ1' counts as crossed below −GUARD_TOLERANCE, rad/s.
GUARD_TOLERANCE = 1e-12
#: A located turn (and a breakaway) is bracketed to this fraction of the step.
LOCATE_TOLERANCE = 1e-13
MAX_LOCATE_ITERATIONS = 100
#: Events (turns, breakaways, impacts, contact changes) allowed within one step before it is
#: declared chattering.
MAX_EVENTS_PER_STEP = 16
#: auto's method on a stick–slip scene (`auto_method`): scipy's error-controlled DOP853.
AUTO_METHOD = "adaptive"
#: The torque step (N·m) by which `holding_torque` probes the affine map τ ↦ θ1''.
PROBE_TORQUE = 1.0


def in_scene(scene: Scene) -> bool:
    """Whether the scene's contacts use stick–slip friction (then its Simulators each build their own
    system: the friction mode is state of the element)."""
    law = getattr(scene, "friction_law", None)
    return bool(scene.objects) and law is not None and law.model == STICK_SLIP


def auto_method(scene: Scene) -> tuple[str, str, dict[str, float], int]:
    """(method, reason, options, substeps) of `method: auto` on a stick–slip scene. The friction has no
    compiled form, so the compiled error-controlled dop853 cannot run it; scipy's DOP853 (`adaptive`)
    can, at auto's tolerances for scene.tolerance, restarted at every step and every event. Its global
    error is not estimated, and it is far from real time: the reason says both."""
    from finger_sim.auto import ERROR_CONTROLLED, error_control

    rtol, atol = error_control(scene.tolerance)
    reason = (f"contact scene with {STICK_SLIP} friction, which has no compiled form (so not {ERROR_CONTROLLED}); "
              f"scipy's error-controlled DOP853 in Python at rtol = atol = {rtol:.0e} for {scene.tolerance:g} rad on θ, "
              "turns, breakaways and contact changes located inside the step; the global error is not estimated, "
              "and the steps cost milliseconds: not for real time")
    LOG.info("method auto → %s: %s", AUTO_METHOD, reason)
    return AUTO_METHOD, reason, {"rtol": rtol, "atol": atol}, 1


def check_method(method: str) -> None:
    """Refuse a method named for a stick–slip scene that its mode stepping does not drive: our dop853
    keeps its own solution across steps, which the locked and sliding modes do not restart."""
    from finger_sim.auto import ERROR_CONTROLLED

    if method == ERROR_CONTROLLED:
        raise ConfigError("integrator.method", f"a method other than {ERROR_CONTROLLED} for {STICK_SLIP} friction "
                          f"(auto takes {AUTO_METHOD})", method)


def element(system: FingerSystem) -> StickSlipContact | None:
    """The system's stick–slip contact element, or None."""
    return next((e for e in system.elements if isinstance(e, StickSlipContact)), None)


def holding_torque(system: FingerSystem, friction: StickSlipContact, t: float, q: Vec3, tau: float) -> float:
    """τ_h, N·m: the torque on θ1 that keeps θ1'' = 0 at rest at q under the input τ (N·m), friction
    left out. θ1'' is affine in the torque on θ1, so τ_h = −a(τ) / (a(τ + PROBE_TORQUE) − a(τ)) · PROBE_TORQUE."""
    mode = friction.mode
    friction.mode = LOCKED  # the locked law: normal forces only
    try:
        a0 = system.accelerations(t, q, ZERO, tau)[0][0]
        a1 = system.accelerations(t, q, ZERO, tau + PROBE_TORQUE)[0][0]
    finally:
        friction.mode = mode
    return -a0 * PROBE_TORQUE / (a1 - a0)


def start(sim: Simulator) -> None:
    """The friction mode of the scene's initial state: at rest, the holding test; moving, sliding."""
    friction = sim._friction
    friction.holds.clear()
    if sim.v[0] == 0.0:
        sim.v = _turn(sim, friction, 0.0, sim.q, sim.scene.torque)
        friction.remember(0.0, sim.q)
    else:
        friction.mode, friction.direction = SLIDING, math.copysign(1.0, sim.v[0])


def advance(sim: Simulator, t0: float, t1: float, torque: TorqueFn) -> None:
    """Integrate [t0, t1] of a stick–slip scene under a smooth torque τ(s), splitting it at every
    turn, breakaway and gap event (stops, contact onsets) on the way."""
    friction: StickSlipContact = sim._friction
    t, q, v = t0, sim.q, sim.v
    for _ in range(MAX_EVENTS_PER_STEP):
        if sim._resting is not None:  # on a stop: it holds the load; leaving it is a turning point
            release = sim._release_time(sim._resting, t, t1, q, torque)
            if release is None:
                friction.mode, friction.hold = LOCKED, 0.0  # the stop holds the load
                friction.remember(t1, q)
                sim.q, sim.v = q, ZERO
                return
            sim._resting = None
            t, v = release, _turn(sim, friction, release, q, torque)
        if friction.mode == LOCKED:
            release = _release_time(sim, friction, t, t1, q, torque)
            if release is None:
                friction.hold = holding_torque(sim.system, friction, t1, q, torque(t1))
                friction.remember(t1, q)
                sim.q, sim.v = q, ZERO
                return
            t, v = release, ZERO
            friction.mode = SLIDING
            friction.direction = -math.copysign(1.0, holding_torque(sim.system, friction, t, q, torque(t)))
        q1, v1 = sim._step(t, q, v, t1 - t, torque)
        turn = _turn_event(sim, friction, t, q, v, t1, q1, v1, torque)
        end, qe, ve = (t1, q1, v1) if turn is None else turn
        crossing = sim._first_crossing(t, q, v, end, qe, ve, torque) if sim._gaps else None
        if crossing is not None:  # a stop or a contact change first: the turn is looked for again after it
            end, qe, ve = crossing.t, crossing.q, crossing.v
        t, q, v = end, qe, ve
        if crossing is not None:
            if crossing.gap.restitution is not None:
                v = sim._impact(crossing, torque)
                if sim._resting is not None:
                    friction.mode, friction.hold, v = LOCKED, 0.0, ZERO  # idle while the stop holds the load
                elif v[0] == 0.0:
                    v = _turn(sim, friction, t, q, torque)
                else:
                    friction.direction = math.copysign(1.0, v[0])  # the impact reversed the motion
        elif turn is not None:
            v = _turn(sim, friction, t, q, torque)
        else:
            sim.q, sim.v = q1, v1
            return
        if t >= t1:
            if v[0] == 0.0:  # at rest: the mode is not a function of the state
                if friction.mode == LOCKED and sim._resting is None:
                    friction.hold = holding_torque(sim.system, friction, t1, q, torque(t1))
                friction.remember(t1, q)
            sim.q, sim.v = q, v
            return
    raise SimulationDiverged(f"more than {MAX_EVENTS_PER_STEP} events (friction lock and breakaway, stops, contact) "
                             "in one step", method=sim.method, t=t0, dt=sim.dt)


def _turn(sim: Simulator, friction: StickSlipContact, t: float, q: Vec3, torque: TorqueFn) -> Vec3:
    """At θ1' = 0: lock if the friction cones hold τ_h, else slide towards −sgn τ_h. Returns q' (zero)."""
    tau_h = holding_torque(sim.system, friction, t, q, torque(t))
    if friction.capacity(q) - abs(tau_h) >= 0.0:
        friction.mode, friction.direction, friction.hold = LOCKED, 0.0, tau_h
    else:
        friction.mode, friction.direction = SLIDING, -math.copysign(1.0, tau_h)
    return ZERO


def _release_time(sim: Simulator, friction: StickSlipContact, t: float, t1: float, q: Vec3,
                  torque: TorqueFn) -> float | None:
    """When in [t, t1] the locked linkage breaks free; None if it holds throughout. q is fixed and
    q' = 0 (the objects are fixed), so the margin is a function of time alone: its root, by brentq."""
    capacity = friction.capacity(q)

    def margin(s: float) -> float:
        return capacity - abs(holding_torque(sim.system, friction, s, q, torque(s)))

    if margin(t) < 0.0:
        return t
    if margin(t1) >= 0.0:
        return None
    from scipy.optimize import brentq  # here: scipy.optimize costs ≈ 0.15 s to import, a breakaway is rare

    return brentq(margin, t, t1, xtol=LOCATE_TOLERANCE * (t1 - t), rtol=4 * np.finfo(float).eps)


def _turn_event(sim: Simulator, friction: StickSlipContact, t: float, q: Vec3, v: Vec3, t1: float, q1: Vec3,
                v1: Vec3, torque: TorqueFn) -> tuple[float, Vec3, Vec3] | None:
    """(s, q, q') where the sliding linkage turns (direction·θ1' crosses 0) in (t, t1], the bracket's far
    side (the guard crossed); None if the step ends on the near side. Illinois regula falsi."""
    s_dir = friction.direction
    gb = s_dir * v1[0]
    if gb >= -GUARD_TOLERANCE:
        return None
    a, ga = t, max(s_dir * v[0], 0.0)
    b, qb, vb = t1, q1, v1
    keep = 0
    for _ in range(MAX_LOCATE_ITERATIONS):
        if b - a <= LOCATE_TOLERANCE * (t1 - t):
            break
        s = b - gb * (b - a) / (gb - ga) if gb != ga else 0.5 * (a + b)
        if not a < s < b:
            s = 0.5 * (a + b)
        qs, vs = sim._step(t, q, v, s - t, torque)
        gs = s_dir * vs[0]
        if gs < 0.0:
            b, gb, qb, vb = s, gs, qs, vs
            ga = ga / 2 if keep == 1 else ga
            keep = 1
        else:
            a, ga = s, gs
            gb = gb / 2 if keep == -1 else gb
            keep = -1
    return b, qb, vb
