"""The step of a drive with L > 0: `stepping.advance` with the winding current carried along.

The same events as with L = 0 (spec §8), on the state (q, q', i):
- rolling: turn (direction·θ1' < 0: stick or roll on), flank (direction·τ_g against the flank) and
  the current limit (`Drive.limit_guard`: where |i| reaches i_max pushing outward, i is set to ±i_max
  exactly and held there by `current_rate`, until the winding pulls it back);
- stuck: q fixed and q' = 0 while the current follows L i' = u − R i; the holding margin (τ_a = k_t i)
  is a guard of the step like the others, and where it turns negative the mesh breaks free.
A rest on a stop holds q and q' = 0 while the current goes on (its release by brentq on the free
acceleration at the current then). Every trial step starts from a state with its own current
(`StatefulRungeKutta.own_of`).

With stick–slip friction at the contacts (spec §7) the linkage locks as one, as with L = 0
(`finger_sim.stick_slip`): the stuck mesh and the friction cones share τ_h, so the holding margin is the
mesh's plus the cones' capacity Σ μ_s F_n,k |j_k| (τ_h taken with the friction left out); stuck means
friction `locked`, rolling means friction `sliding` the same way; an ideal gear gets the stuck mode too,
held by the friction alone.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import TYPE_CHECKING

import numpy as np
from scipy.optimize import brentq

from finger_sim.actuators.drive import BACK, DRIVE, STUCK, DrivenSystem, holding_margin
from finger_sim.actuators.stepping import (FLANK, GAUSS_NODES, GAUSS_WEIGHTS, GUARDS_TWO_SIDED, MAX_EVENTS_PER_STEP,
                                           TURN, EnergyLedger)
from finger_sim.effects.friction_modes import LOCKED, SLIDING, StickSlipContact
from finger_sim.errors import SimulationDiverged
from finger_sim.integrators.base import TorqueFn
from finger_sim.integrators.stateful import StatefulRungeKutta
from finger_sim.kinematics import ZERO, Vec3
from finger_sim.simulation.locate import LOCATE_TOLERANCE, GuardCrossing, first_guard_crossing

if TYPE_CHECKING:
    from finger_sim.simulation.driver import Simulator

#: (q, q', i) at a time: rad, rad/s, A.
Trial = Callable[[float, Vec3, Vec3, float, float], tuple[Vec3, Vec3, float]]


def start(sim: Simulator) -> None:
    """The current 0 at t = 0 and the mesh mode of the initial state (`stepping.start`)."""
    system: DrivenSystem = sim.system  # type: ignore[assignment]
    system.drive.i = 0.0
    sim.integrator.own = system.drive.initial()  # type: ignore[attr-defined]
    u = sim.scene.torque(0.0)
    if sim.v[0] == 0.0:
        sim.v = _turn(system, 0.0, sim.q, u, 0.0)
    else:
        _roll(system, 0.0, sim.q, sim.v, u, math.copysign(1.0, sim.v[0]), 0.0)


def start_friction(sim: Simulator) -> None:
    """Stick–slip friction at the start, carried (its mode was set with the mesh's, `start`): its holding
    memory cleared, the initial state remembered at rest."""
    friction = _friction(sim.system)  # type: ignore[arg-type]
    if friction is not None:
        friction.holds.clear()
        if sim.v[0] == 0.0:
            friction.remember(0.0, sim.q)


def advance(sim: Simulator, t0: float, t1: float, u_fn: TorqueFn) -> None:
    """Integrate [t0, t1] under a smooth voltage u(s) with the current as a state, split at every
    mode change, current-limit event and gap event (stops, contact) on the way."""
    system: DrivenSystem = sim.system  # type: ignore[assignment]
    drive = system.drive
    integ = sim.integrator
    ledger: EnergyLedger | None = drive.ledger
    p = drive.params

    def trial(s0: float, q0: Vec3, v0: Vec3, i0: float, s: float) -> tuple[Vec3, Vec3, float]:
        integ.begin(q0, v0, (i0,))  # type: ignore[attr-defined]
        qs, vs = sim._step(s0, q0, v0, s - s0, u_fn)
        return qs, vs, integ.own_of(qs, vs)[0]  # type: ignore[attr-defined]

    friction = _friction(system)
    t, q, v, i = t0, sim.q, sim.v, drive.i
    for _ in range(MAX_EVENTS_PER_STEP):
        if drive.mode == STUCK and _margin(system, t, q, i) < 0.0:
            v = ZERO
            _roll(system, t, q, v, u_fn(t), _break_direction(system, t, q, i), i)
        if sim._resting is not None and drive.mode != STUCK:  # at rest on a stop: the current goes on
            t, i, released = _rest(sim, t, t1, q, i, u_fn)
            if not released:
                _commit(sim, t1, q, ZERO, i)
                return
            v = _turn(system, t, q, u_fn(t), i)
            if t >= t1:
                _commit(sim, t1, q, v, i)
                return
            if drive.mode == STUCK:
                continue
        q1, v1, i1 = trial(t, q, v, i, t1)
        event = _first_event(system, t, (q, v, i), t1, (q1, v1, i1), u_fn, trial)
        end, qe, ve, ie = (t1, q1, v1, i1) if event is None else (event.t, *event.state)
        crossing = None
        if sim._gaps and drive.mode != STUCK:
            integ.begin(q, v, (i,))  # type: ignore[attr-defined]
            crossing = sim._first_crossing(t, q, v, end, qe, ve, u_fn)
            if crossing is not None:  # a stop or a contact change first: the mode guards are checked again after it
                end, qe, ve = crossing.t, crossing.q, crossing.v
                ie = integ.own_of(qe, ve)[0]  # type: ignore[attr-defined]
        if ledger is not None:
            _integrate_resolved(ledger, sim, t, end, (q, v, i), u_fn)
        if crossing is not None and end <= t and crossing.gap.restitution is not None and not any(v):
            # back on the stop at once after an impact that left it at rest: the current (not the
            # voltage) sets the push, and it turns into the stop within the step: the finger rests
            sim._resting = crossing.gap
            if friction is not None:  # idle while the stop holds the load
                friction.mode, friction.hold = LOCKED, 0.0
            continue
        t, q, v, i = end, qe, ve, ie
        if crossing is not None:
            if crossing.gap.restitution is not None:
                before = system.kinetic_energy(q, v) + system.rotor_energy(v)
                drive.i = i
                v = sim._impact(crossing, u_fn)
                if ledger is not None:
                    ledger.impact_loss += before - system.kinetic_energy(q, v) - system.rotor_energy(v)
                if sim._resting is not None:  # at rest on the stop: the mesh may hold it
                    v = _turn(system, t, q, u_fn(t), i)
                    if drive.mode == STUCK:
                        sim._resting = None
                    elif friction is not None:  # idle while the stop holds the load
                        friction.mode, friction.hold = LOCKED, 0.0
                elif friction is not None and v[0] != 0.0:  # the impact reversed the motion: slide on that way
                    _roll(system, t, q, v, u_fn(t), math.copysign(1.0, v[0]), i)
        elif event is not None:
            u = u_fn(t)
            if event.guard == TURN and drive.mode == STUCK:  # the holding margin crossed: break free
                v = ZERO
                _roll(system, t, q, v, u, _break_direction(system, t, q, i), i)
            elif event.guard == TURN:
                v = _turn(system, t, q, u, i)
            elif event.guard == FLANK:
                drive.mode = BACK if drive.mode == DRIVE else DRIVE
            elif abs(i) >= p.current_limit:  # the limit starts to act: i = ±i_max exactly from here
                i = math.copysign(p.current_limit, i)
        else:
            _commit(sim, t1, q1, v1, i1)
            return
        if t >= t1:
            _commit(sim, t1, q, v, i)
            return
    raise SimulationDiverged(f"more than {MAX_EVENTS_PER_STEP} events (mesh modes, current limit, stops, contact) in "
                             "one step", method=sim.method, t=t0, dt=sim.dt)


def _commit(sim: Simulator, t: float, q: Vec3, v: Vec3, i: float) -> None:
    """The Simulator's state at t (s) is (q, q', i); at rest, a stick–slip element remembers its mode there."""
    sim.q, sim.v = q, v
    sim.system.drive.i = i
    sim.integrator.begin(q, v, (i,))  # type: ignore[attr-defined]
    friction = _friction(sim.system)  # type: ignore[arg-type]
    if friction is not None and v[0] == 0.0:  # at rest the mode is not a function of the state
        if friction.mode == LOCKED and sim._resting is None:
            friction.hold = _holding(sim.system, t, q)  # type: ignore[arg-type]
        friction.remember(t, q)


# -- modes --------------------------------------------------------------------------------
def _friction(system: DrivenSystem) -> StickSlipContact | None:
    """The system's stick–slip contact element (spec §7), or None."""
    return next((e for e in system.elements if isinstance(e, StickSlipContact)), None)


def _holding(system: DrivenSystem, t: float, q: Vec3) -> float:
    """τ_h, N·m, at rest at q: the torque on θ1 that keeps θ1'' = 0, a stick–slip friction left out (its
    locked law: normal forces only)."""
    friction = _friction(system)
    if friction is None:
        return system.holding_torque(t, q, ZERO)
    mode = friction.mode
    friction.mode = LOCKED
    try:
        return system.holding_torque(t, q, ZERO)
    finally:
        friction.mode = mode


def _margin(system: DrivenSystem, t: float, q: Vec3, i: float) -> float:
    """The stuck mesh's holding margin (`holding_margin`) at rest at q with τ_a = k_t i, plus a stick–slip
    friction's capacity Σ μ_s F_n,k |j_k| (the two share the load, §7)."""
    p = system.drive.params
    friction = _friction(system)
    capacity = 0.0 if friction is None else friction.capacity(q)
    return capacity + holding_margin(_holding(system, t, q), p.torque_constant * i, p.gear_ratio, p.efficiency,
                                     p.backward_efficiency)


def _turn(system: DrivenSystem, t: float, q: Vec3, u: float, i: float) -> Vec3:
    """At θ1' = 0: stick if the mesh (and a stick–slip friction) hold τ_h under τ_a = k_t i, else roll
    towards sgn(N τ_a − τ_h)."""
    friction = _friction(system)
    if system.drive.params.ideal and friction is None:
        return ZERO
    if _margin(system, t, q, i) >= 0.0:
        system.drive.mode = STUCK
        if friction is not None:
            friction.mode, friction.direction, friction.hold = LOCKED, 0.0, _holding(system, t, q)
        return ZERO
    _roll(system, t, q, ZERO, u, _break_direction(system, t, q, i), i)
    return ZERO


def _break_direction(system: DrivenSystem, t: float, q: Vec3, i: float) -> float:
    """sgn(N k_t i − τ_h) at rest (§8)."""
    p = system.drive.params
    excess = p.gear_ratio * p.torque_constant * i - _holding(system, t, q)
    return 1.0 if excess >= 0.0 else -1.0


def _roll(system: DrivenSystem, t: float, q: Vec3, v: Vec3, u: float, direction: float, i: float) -> None:
    """Enter the rolling flank whose solution meets its sign condition along `direction` (`stepping._roll`);
    a stick–slip friction slides that way (its kinetic friction applied before the flank is chosen)."""
    drive = system.drive
    drive.direction = direction
    friction = _friction(system)
    if friction is not None:
        friction.mode, friction.direction = SLIDING, direction
    if drive.params.ideal:
        drive.mode = DRIVE
        return
    tau_d = system.mesh(t, q, v, u, DRIVE, i)[0]
    drive.mode = DRIVE if direction * tau_d >= 0.0 else BACK


def _guards(system: DrivenSystem, t: float, q: Vec3, v: Vec3, i: float, u: float) -> tuple[float, float, float]:
    """(turn, flank, limit), ≥ 0 while the mode's conditions hold; stuck: (holding margin, ∞, limit)."""
    drive = system.drive
    limit = drive.limit_guard(u, i, v[0])
    if drive.mode == STUCK:
        return _margin(system, t, q, i), math.inf, limit
    if drive.params.ideal:  # no flanks; a stick–slip friction's turn is still a guard
        return (math.inf if _friction(system) is None else drive.direction * v[0]), math.inf, limit
    tau_g = system.mesh(t, q, v, u, drive.mode, i)[0]
    s = drive.direction
    return s * v[0], (s if drive.mode == DRIVE else -s) * tau_g, limit


def _first_event(system: DrivenSystem, t: float, x0: tuple[Vec3, Vec3, float], t1: float,
                 x1: tuple[Vec3, Vec3, float], u_fn: TorqueFn, trial: Trial) -> GuardCrossing | None:
    """The earliest guard crossing of the step (t, x0) → (t1, x1), located (state (q, q', i) there);
    None if none."""
    def at(k: int, s: float) -> tuple[float, tuple[Vec3, Vec3, float]]:
        x = trial(t, *x0, s)
        return _guards(system, s, *x, u_fn(s))[k], x

    g0 = _guards(system, t, *x0, u_fn(t))
    g1 = _guards(system, t1, *x1, u_fn(t1))
    return first_guard_crossing(GUARDS_TWO_SIDED, g0, g1, at, t, t1, x1)


def _rest(sim: Simulator, t: float, t1: float, q: Vec3, i: float, u_fn: TorqueFn) -> tuple[float, float, bool]:
    """At rest on a stop from t: (time, current, released). The current follows L i' = u − R i (the
    mesh frozen as if stuck); the release is where the free acceleration at that current leaves the
    stop (brentq), else the rest lasts to t1."""
    system: DrivenSystem = sim.system  # type: ignore[assignment]
    drive = system.drive
    gap = sim._resting
    assert gap is not None
    n = gap.element.gap_gradient(gap.index, q)
    mode = drive.mode

    def held(s: float) -> float:  # the current at s, q held
        if s <= t:
            return i
        drive.mode = STUCK
        try:
            sim.integrator.begin(q, ZERO, (i,))  # type: ignore[attr-defined]
            qs, vs = sim.integrator.step(t, q, ZERO, s - t, u_fn)
            limit = drive.params.current_limit  # the driver's limit: a step's overshoot of it is cut off
            return max(-limit, min(limit, sim.integrator.own_of(qs, vs)[0]))  # type: ignore[attr-defined]
        finally:
            drive.mode = mode

    def push(s: float) -> float:
        a = system.mesh(s, q, ZERO, u_fn(s), mode, held(s))[2]
        return -(n[0] * a[0] + n[1] * a[1] + n[2] * a[2])

    ledger = drive.ledger
    pushed_at_end = push(t1) > 0.0
    if push(t) <= 0.0 and not pushed_at_end:
        sim._resting = None
        return t, i, True
    if pushed_at_end:  # (a pull at t that the rising current turns into a push within the step: a rest)
        end, released = t1, False
    else:
        end = brentq(push, t, t1, xtol=LOCATE_TOLERANCE * (t1 - t), rtol=4 * np.finfo(float).eps)
        released = True
        sim._resting = None
    if ledger is not None:
        _integrate(ledger, system, t, end, lambda s: (q, ZERO, held(s)), u_fn)
    return end, held(end), released


def _integrate(ledger: EnergyLedger, system: DrivenSystem, a: float, b: float,
               state_at: Callable[[float], tuple[Vec3, Vec3, float]], u_fn: TorqueFn) -> None:
    """Add ∫_a^b of the drive's powers (3-point Gauss–Legendre) to the ledger (`stepping._integrate`)."""
    h = b - a
    if h <= 0.0:
        return
    for x, w in zip(GAUSS_NODES, GAUSS_WEIGHTS):
        s = a + x * h
        qs, vs, i_s = state_at(s)
        elec, copper, mesh, work = system.powers(s, qs, vs, u_fn(s), i_s)
        ledger.electrical_work += w * h * elec
        ledger.copper_loss += w * h * copper
        ledger.mesh_loss += w * h * mesh
        ledger.element_work += w * h * work


def _integrate_resolved(ledger: EnergyLedger, sim: Simulator, a: float, b: float, x: tuple[Vec3, Vec3, float],
                        u_fn: TorqueFn) -> None:
    """`_integrate` over [a, b] from the state x = (q, q', i) at a, in the integrator's substeps (the
    electrical transient resolved): each substep's Gauss nodes by one integrator substep from its start."""
    integ: StatefulRungeKutta = sim.integrator  # type: ignore[assignment]
    n = integ.substeps
    h = (b - a) / n
    for k in range(n):
        s0 = a + k * h
        _integrate(ledger, sim.system, s0, s0 + h,  # type: ignore[arg-type]
                   lambda s, s0=s0, x=x: _advance(integ, s0, x, s - s0, u_fn), u_fn)
        if k < n - 1:
            x = _advance(integ, s0, x, h, u_fn)


def _advance(integ: StatefulRungeKutta, t: float, x: tuple[Vec3, Vec3, float], h: float,
             u_fn: TorqueFn) -> tuple[Vec3, Vec3, float]:
    """(q, q', i) at t + h from x = (q, q', i) at t, in one integrator substep."""
    q, v, own = integ.advance_state(t, x[0], x[1], (x[2],), h, u_fn, 1)
    return q, v, own[0]
