"""The stick–slip friction modes stepped inside the Simulator's fixed step (spec §7), beside its gap events.

The pattern of the drive's stuck mesh (`finger_sim.actuators.stepping`) and of the rest on a stop:
- sliding, the guard is direction·θ1' ≥ 0; where a step ends below −`locate.GUARD_TOLERANCE` the turn
  is located by Illinois regula falsi on the step's length (`locate.first_guard_crossing`). There θ1' = 0 and the holding test decides:
  `locked` (q fixed, q' = 0 exactly from then on) or sliding on towards the excess;
- locked, q is fixed and q' = 0, so the holding margin Σ μ_s F_n,k |j_k| − |τ_h| is a function of
  time alone (the input): its root (brentq) is the breakaway, and the finger slides towards
  −sgn τ_h (the way the unheld linkage accelerates).
τ_h is the torque on θ1 that keeps θ1'' = 0 with the friction left out (§4 at q' = 0); the
accelerations are affine in the torque on θ1, so two solves give it exactly. The steps themselves
(`Simulator._step`) run on the compiled friction law where the scene has one (the element mirrors its
mode into the flat model); the loops here are Python and cost a few evaluations per step.

With a drive (§8, L = 0) the linkage locks as one: the friction cones and the stuck mesh share τ_h
(τ_h = τ_mesh + Σ j_k F_t,k, τ_mesh in the stuck set), which holds while τ_h lies within Σ μ_s F_n,k |j_k|
of that set: the margin is the mesh's `holding_margin` plus the cones' capacity. Locked, the mesh is
`stuck` and the friction `locked`; moving, the mesh rolls (its flank and current-limit guards located
as `finger_sim.actuators.stepping` does) and the friction slides, both towards the same direction. It
breaks free towards sgn(N τ_a − τ_h) (−sgn τ_h without a drive). With L > 0 the current is a state and
`actuators.inductive_stepping` steps the same shared lock (its stuck margin a guard of the step).

A stop impact reverses θ1' (the sliding direction follows); at rest on a stop the stop holds the
load and the friction is idle; leaving the stop is a turning point. With an object that moves, the slip is relative to its surface
(`finger_sim.stick_slip_moving`: locked rides with it).
"""

from __future__ import annotations

import logging
import math
from contextlib import nullcontext
from typing import TYPE_CHECKING

import numpy as np

from finger_sim.actuators import stepping as drive_stepping
from finger_sim.actuators.drive import STUCK, DrivenSystem, holding_margin
from finger_sim.effects import build_elements
from finger_sim.effects.friction_modes import FRICTION, LOCKED, SLIDING, STICK_SLIP, StickSlipContact
from finger_sim.errors import SimulationDiverged
from finger_sim.integrators.base import TorqueFn
from finger_sim.kinematics import ZERO, Vec3
from finger_sim.simulation.locate import LOCATE_TOLERANCE, first_guard_crossing
from finger_sim.simulation.mode_stepping import AutoPick, ModeStepping

if TYPE_CHECKING:
    from finger_sim.actuators.drive import Drive
    from finger_sim.dynamics import FingerSystem
    from finger_sim.scene import Scene
    from finger_sim.simulate import Simulator

LOG = logging.getLogger(__name__)
#: The sliding linkage's one guard, direction·θ1' (rad/s), one-sided: `locate.first_guard_crossing`.
TURN_GUARD = (False,)
#: Events (turns, breakaways, impacts, contact changes) allowed within one step before it is
#: declared chattering.
MAX_EVENTS_PER_STEP = 64  # room for a stop's Zeno series down to its rest (effects.stops.REST_HEIGHT)
#: auto's method on a stick–slip scene (`auto_method`): our error-controlled DOP853, restarted at every
#: friction mode change (`StickSlipContact.mode_key`).
AUTO_METHOD = "dop853"
#: The torque step (N·m) by which `holding_torque` probes the affine map τ ↦ θ1''.
PROBE_TORQUE = 1.0


def in_scene(scene: Scene) -> bool:
    """Whether an element the scene builds owns the friction mode (`FRICTION`: the contacts' stick–slip
    friction); then its Simulators each build their own system: the friction mode is state of the element."""
    return any(FRICTION in getattr(e, "modes", ()) for e in build_elements(scene))


def auto_method(scene: Scene) -> tuple[str, str, dict[str, float], int]:
    """(method, reason, options, substeps) of `method: auto` on a stick–slip scene: our error-controlled
    DOP853 (`AUTO_METHOD`) at auto's tolerances for scene.tolerance, its internal solution restarted at
    every mode change and every event; compiled where the contact has a compiled form."""
    from finger_sim.auto import error_control

    rtol, atol = error_control(scene.tolerance)
    reason = (f"contact scene with {STICK_SLIP} friction: error-controlled DOP853 at rtol = atol = {rtol:.0e} for "
              f"{scene.tolerance:g} rad on θ, restarted at every friction mode change; turns, breakaways and contact "
              "changes located inside the step")
    LOG.info("method auto → %s: %s", AUTO_METHOD, reason)
    return AUTO_METHOD, reason, {"rtol": rtol, "atol": atol}, 1


class FrictionStepping(ModeStepping):
    """Stick–slip friction's modes as the Simulator steps them (`simulation.mode_stepping`): `start` and
    `advance` here, auto's method (`auto_method`); it carries a drive's mesh (L = 0): the two lock as one."""

    name = "stick_slip"
    carries = ("drive",)

    def __init__(self, friction: StickSlipContact) -> None:
        self.friction = friction
        #: the drive (L = 0) it carries, or None: found at `start`
        self.drive: Drive | None = None

    def auto_method(self, scene: Scene) -> AutoPick:
        return AutoPick(*auto_method(scene))

    def start(self, sim: Simulator) -> None:
        for carried in sim.mode_steppings:  # a drive's flank or turning-point rule first
            if carried is not self:
                carried.start(sim)
        self.drive = carried_drive(sim)
        start(sim, self.friction)

    def advance(self, sim: Simulator, t0: float, t1: float, torque: TorqueFn) -> None:
        """Integrate [t0, t1] of a stick–slip scene under a smooth input (torque τ(s), or a drive's voltage
        u(s)), splitting it at every turn, breakaway, mesh flank, current-limit kink and gap event (stops,
        contact onsets) on the way. (With L > 0 the drive's stepper carries the friction instead.)"""
        friction, drive = self.friction, self.drive
        if friction.time_varying:  # a moving object: ride with it while locked (`stick_slip_moving`)
            from finger_sim import stick_slip_moving

            stick_slip_moving.advance(sim, friction, t0, t1, torque)
            return
        ledger = None if drive is None else drive.ledger
        t, q, v = t0, sim.q, sim.v
        for _ in range(MAX_EVENTS_PER_STEP):
            if sim._resting is not None:  # on a stop: it holds the load; leaving it is a turning point
                release = sim._release_time(sim._resting, t, t1, q, torque)
                if release is None:
                    friction.mode, friction.hold = LOCKED, 0.0  # the stop holds the load
                    friction.remember(t1, q)
                    _account(ledger, sim, t, t1, q, torque)
                    sim.q, sim.v = q, ZERO
                    return
                _account(ledger, sim, t, release, q, torque)
                sim._resting = None
                t, v = release, _turn(sim, friction, release, q, torque)
            if friction.mode == LOCKED:
                release = _release_time(sim, friction, t, t1, q, torque)
                _account(ledger, sim, t, t1 if release is None else release, q, torque)
                if release is None:
                    friction.hold = _holding(sim, friction, t1, q, torque)
                    friction.remember(t1, q)
                    sim.q, sim.v = q, ZERO
                    return
                t, v = release, ZERO
                _slide(sim, friction, t, q, torque, _break_direction(sim, t, _holding(sim, friction, t, q, torque), torque))
            if t >= t1:  # freed on the step's end (breakaway, release from the stop): a zero-length step divides by zero
                friction.remember(t1, q)
                sim.q, sim.v = q, v
                return
            q1, v1 = sim._step(t, q, v, t1 - t, torque)
            guard = drive_stepping.TURN
            if drive is None:
                turn = _turn_event(sim, friction, t, q, v, t1, q1, v1, torque)
            else:  # the mesh's guards: turn (the friction's too), flank and current limit
                event = drive_stepping._first_event(sim, sim.system, t, q, v, t1, q1, v1, torque)
                turn = None if event is None else (event.t, *event.state)
                guard = drive_stepping.TURN if event is None else event.guard
            end, qe, ve = (t1, q1, v1) if turn is None else turn
            crossing = sim._first_crossing(t, q, v, end, qe, ve, torque) if sim._gaps else None
            if crossing is not None:  # a stop or a contact change first: the turn is looked for again after it
                end, qe, ve = crossing.t, crossing.q, crossing.v
            if ledger is not None:
                t_, q_, v_ = t, q, v
                with getattr(sim.integrator, "aside", nullcontext)():
                    drive_stepping._integrate(ledger, sim.system, t, end, lambda s: sim._step(t_, q_, v_, s - t_, torque),
                                              torque)
            t, q, v = end, qe, ve
            if crossing is not None:
                if crossing.gap.restitution is not None:
                    before = sim.system.kinetic_energy(q, v) + _rotor_energy(sim, v)
                    v = sim._impact(crossing, torque)
                    if ledger is not None:
                        ledger.impact_loss += before - sim.system.kinetic_energy(q, v) - _rotor_energy(sim, v)
                    if sim._resting is not None:
                        friction.mode, friction.hold, v = LOCKED, 0.0, ZERO  # idle while the stop holds the load
                    elif v[0] == 0.0:
                        v = _turn(sim, friction, t, q, torque)
                    else:  # the impact reversed the motion
                        _slide(sim, friction, t, q, torque, math.copysign(1.0, v[0]), v)
            elif turn is not None:
                if guard == drive_stepping.TURN:
                    v = _turn(sim, friction, t, q, torque)
                elif guard == drive_stepping.FLANK:
                    drive.mode = drive_stepping.BACK if drive.mode == drive_stepping.DRIVE else drive_stepping.DRIVE
                # the current limit: a kink of the force, no mode change
            else:
                sim.q, sim.v = q1, v1
                return
            if t >= t1:
                if v[0] == 0.0:  # at rest: the mode is not a function of the state
                    if friction.mode == LOCKED and sim._resting is None:
                        friction.hold = _holding(sim, friction, t1, q, torque)
                    friction.remember(t1, q)
                sim.q, sim.v = q, v
                return
        raise SimulationDiverged(f"more than {MAX_EVENTS_PER_STEP} events (friction lock and breakaway, mesh modes, stops, "
                                 "contact) in one step", method=sim.method, t=t0, dt=sim.dt)

    def before_run(self, sim: Simulator, n: int) -> None:
        self.friction.memory = n + 1  # its holding torques are read back after the run: keep every row's


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


def carried_drive(sim: Simulator) -> Drive | None:
    """The drive (§8, L = 0) whose mesh locks with the friction, or None."""
    return getattr(sim.system, "drive", None)


def start(sim: Simulator, friction: StickSlipContact) -> None:
    """The friction mode of the scene's initial state: at rest, the holding test; moving, sliding."""
    if friction.time_varying:  # a moving object: the slip is relative to it
        from finger_sim import stick_slip_moving

        stick_slip_moving.start(sim, friction, sim.scene.torque)
        return
    friction.holds.clear()
    if sim.v[0] == 0.0:
        drive = carried_drive(sim)
        kept = sim.kept_start.get(__name__)  # the holding test's outcome depends on the scene alone
        if kept is None:
            sim.v = _turn(sim, friction, 0.0, sim.q, sim.scene.torque)
            sim.kept_start[__name__] = (friction.mode, friction.direction, friction.hold,
                                        None if drive is None else (drive.mode, drive.direction))
        else:
            friction.mode, friction.direction, friction.hold, mesh = kept
            if drive is not None:
                drive.mode, drive.direction = mesh
            sim.v = ZERO
        friction.remember(0.0, sim.q)
    else:  # a drive's flank was chosen by `actuators.stepping.start`
        friction.mode, friction.direction = SLIDING, math.copysign(1.0, sim.v[0])


def _rotor_energy(sim: Simulator, v: Vec3) -> float:
    """½ J_m ω_m² with a drive (J), else 0."""
    return 0.0 if carried_drive(sim) is None else sim.system.rotor_energy(v)  # type: ignore[attr-defined]


def _account(ledger, sim: Simulator, a: float, b: float, q: Vec3, torque: TorqueFn) -> None:  # type: ignore[no-untyped-def]
    """Add a drive's energy integrals over [a, b] at rest at q to `ledger` (None: nothing to add)."""
    if ledger is not None and b > a:
        drive_stepping._integrate(ledger, sim.system, a, b, lambda s: (q, ZERO), torque)


def _holding(sim: Simulator, friction: StickSlipContact, t: float, q: Vec3, torque: TorqueFn) -> float:
    """τ_h, N·m, at rest at q at time t: the torque on θ1 that keeps θ1'' = 0, friction left out (with a
    drive: the torque the mesh and the friction must share, `DrivenSystem.holding_torque`)."""
    if carried_drive(sim) is None:
        return holding_torque(sim.system, friction, t, q, torque(t))
    system: DrivenSystem = sim.system  # type: ignore[assignment]
    mode = friction.mode
    friction.mode = LOCKED  # the locked law: normal forces only
    try:
        return system.holding_torque(t, q, ZERO)
    finally:
        friction.mode = mode


def holding_test(sim: Simulator, friction: StickSlipContact, t: float, q: Vec3, torque: TorqueFn,
                 capacity: float | None = None) -> tuple[float, float]:
    """(margin N·m, τ_h N·m) of the locked linkage at rest at q at time t: the margin is ≥ 0 while the
    friction cones (capacity Σ μ_s F_n,k |j_k|) and a stuck mesh can share τ_h (§7): capacity − |τ_h|
    without a drive, capacity + the mesh's `holding_margin` under τ_a = k_t i(u(t), 0) with one."""
    tau_h = _holding(sim, friction, t, q, torque)
    if capacity is None:
        capacity = friction.capacity(q)
    drive = carried_drive(sim)
    if drive is None:
        return capacity - abs(tau_h), tau_h
    p = drive.params
    tau_a = p.torque_constant * drive.current(torque(t), 0.0)
    return capacity + holding_margin(tau_h, tau_a, p.gear_ratio, p.efficiency, p.backward_efficiency), tau_h


def _break_direction(sim: Simulator, t: float, tau_h: float, torque: TorqueFn) -> float:
    """The way a linkage that does not hold starts to move: −sgn τ_h, with a drive sgn(N τ_a − τ_h) (§8)."""
    drive = carried_drive(sim)
    if drive is None:
        return -math.copysign(1.0, tau_h)
    p = drive.params
    excess = p.gear_ratio * p.torque_constant * drive.current(torque(t), 0.0) - tau_h
    return 1.0 if excess >= 0.0 else -1.0


def _slide(sim: Simulator, friction: StickSlipContact, t: float, q: Vec3, torque: TorqueFn, direction: float,
           v: Vec3 = ZERO) -> None:
    """Enter sliding towards `direction` at (t, q, q'); a drive rolls on the flank that motion takes
    (`actuators.stepping._roll`, with the kinetic friction opposing the motion already applied)."""
    friction.mode, friction.direction = SLIDING, direction
    if carried_drive(sim) is not None:
        drive_stepping._roll(sim.system, t, q, v, torque(t), direction)  # type: ignore[arg-type]


def _turn(sim: Simulator, friction: StickSlipContact, t: float, q: Vec3, torque: TorqueFn) -> Vec3:
    """At θ1' = 0: lock if the friction cones (and a stuck mesh) hold τ_h, else slide towards the excess
    (`_break_direction`). Returns q' (zero)."""
    margin, tau_h = holding_test(sim, friction, t, q, torque)
    if margin >= 0.0:
        friction.mode, friction.direction, friction.hold = LOCKED, 0.0, tau_h
        drive = carried_drive(sim)
        if drive is not None:
            drive.mode = STUCK
    else:
        _slide(sim, friction, t, q, torque, _break_direction(sim, t, tau_h, torque))
    return ZERO


def _release_time(sim: Simulator, friction: StickSlipContact, t: float, t1: float, q: Vec3,
                  torque: TorqueFn) -> float | None:
    """When in [t, t1] the locked linkage breaks free; None if it holds throughout. q is fixed and
    q' = 0 (the objects are fixed), so the margin (`holding_test`) is a function of time alone: its
    root, by brentq."""
    capacity = friction.capacity(q)

    def margin(s: float) -> float:
        return holding_test(sim, friction, s, q, torque, capacity)[0]

    if margin(t) < 0.0:
        return t
    if margin(t1) >= 0.0:
        return None
    from scipy.optimize import brentq  # here: scipy.optimize costs ≈ 0.15 s to import, a breakaway is rare

    return brentq(margin, t, t1, xtol=LOCATE_TOLERANCE * (t1 - t), rtol=4 * np.finfo(float).eps)


def _turn_event(sim: Simulator, friction: StickSlipContact, t: float, q: Vec3, v: Vec3, t1: float, q1: Vec3,
                v1: Vec3, torque: TorqueFn) -> tuple[float, Vec3, Vec3] | None:
    """(s, q, q') where the sliding linkage turns (direction·θ1' crosses 0) in (t, t1], the bracket's far
    side (the guard crossed); None if the step ends on the near side (`locate.first_guard_crossing`)."""
    s_dir = friction.direction

    def at(_: int, s: float) -> tuple[float, tuple[Vec3, Vec3]]:
        qs, vs = sim._step(t, q, v, s - t, torque)
        return s_dir * vs[0], (qs, vs)

    event = first_guard_crossing(TURN_GUARD, (s_dir * v[0],), (s_dir * v1[0],), at, t, t1, (q1, v1))
    return None if event is None else (event.t, *event.state)
