"""Stick–slip friction against a moving object (spec §7, `friction_model: stick_slip` with an object's
`motion`): the modes of `finger_sim.stick_slip` with the slip taken relative to the object's surface.

Stick is still a state of the one-DOF linkage, but `locked` now means riding with the object: the
contacts in touch have no tangential velocity relative to it, θ1' = ω(t, q) = w_k / j_k
(`StickSlipContact.stick_speed`: w_k = t_k·ċ_k, j_k = t_k·∂p_k/∂θ1), which is 0 where the object
is at rest, so a fixed object's lock is the case ω = 0.

- locked: θ1 follows the first-order ODE θ1' = ω(t, θ1) on Φ = 0 (q = `kinematics.assemble(θ1)`),
  integrated by scipy's DOP853 at RIDE_RTOL. The holding torque τ_h is the torque on θ1 that gives the
  ride's θ1'' = dω/dt (a central difference along the path, RIDE_PROBE s), friction left out; θ1'' is
  affine in it (`stick_slip.PROBE_TORQUE`). The linkage holds while Σ μ_s F_n,k |j_k| ≥ |τ_h|; the root
  of that margin is solve_ivp's terminal event (the breakaway), after which it slides towards −sgn τ_h
  relative to the object;
- sliding towards `direction` = sgn(θ1' − ω): the guard direction·(θ1' − ω) is located by Illinois
  regula falsi as the fixed case's turn; there the holding test decides again. A contact onset or
  release changes ω: the slip's sign is taken afresh after it.

Covered: moving objects without a drive or joint stops (the scene refuses those, `finger_sim.scene`);
two contacts that would need different stick speeds at once stop the run with a one-line error.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

from finger_sim.effects.friction_modes import LOCKED, SLIDING, StickSlipContact
from finger_sim.errors import SimulationDiverged
from finger_sim.integrators.base import TorqueFn
from finger_sim.kinematics import Vec3, assemble, dependent_rates
from finger_sim.simulation.locate import first_guard_crossing

if TYPE_CHECKING:
    from finger_sim.simulate import Simulator

#: Tolerances of the ride's ODE θ1' = ω(t, θ1) (rad): far below auto's 1e-6 rad promise; a ride adds
#: RIDE_RTOL·|Δθ1| + RIDE_ATOL to the run's error estimate.
RIDE_RTOL, RIDE_ATOL = 1e-12, 1e-14
#: Half-width of the central difference that gives the ride's θ1'' = dω/dt, s (error ∝ RIDE_PROBE²).
RIDE_PROBE = 1e-5


def start(sim: Simulator, friction: StickSlipContact, torque: TorqueFn) -> None:
    """The friction mode of the scene's initial state: at rest relative to the objects, the holding
    test; else sliding towards sgn(θ1' − ω)."""
    friction.holds.clear()
    start_q = sim.q
    kept = sim.kept_start.get(__name__)  # the test's outcome depends on the scene alone (torque: its input)
    if kept is None:
        slip = sim.v[0] - friction.stick_speed(0.0, start_q)
        if slip == 0.0:
            sim.q, sim.v = _turn(sim, friction, 0.0, start_q, torque)
        else:
            friction.mode, friction.direction = SLIDING, math.copysign(1.0, slip)
        kept = sim.kept_start[__name__] = (slip == 0.0, sim.q, sim.v, friction.mode, friction.direction,
                                           friction.hold)
    else:
        turned, sim.q, sim.v, friction.mode, friction.direction, friction.hold = kept
        if turned:
            _carry(sim, start_q, sim.q, 0.0)  # as `_turn` does
    if kept[0]:  # at rest relative to the objects
        friction.remember(0.0, sim.q, sim.v)


def advance(sim: Simulator, friction: StickSlipContact, t0: float, t1: float, torque: TorqueFn) -> None:
    """Integrate [t0, t1] under a smooth input τ(s), splitting it at every turn, breakaway and contact
    change (`stick_slip.MAX_EVENTS_PER_STEP` at most)."""
    from finger_sim.stick_slip import MAX_EVENTS_PER_STEP

    t, q, v = t0, sim.q, sim.v
    for _ in range(MAX_EVENTS_PER_STEP):
        if friction.mode == LOCKED:
            start = q
            t, q, v, tau_h, released = _ride(sim, friction, t, t1, q, torque)
            _carry(sim, start, q, RIDE_RTOL * abs(q[0] - start[0]) + RIDE_ATOL)
            if not released:
                friction.hold = tau_h
                friction.remember(t1, q, v)
                sim.q, sim.v = q, v
                return
            friction.mode, friction.direction = SLIDING, -math.copysign(1.0, tau_h)
            if t >= t1:
                sim.q, sim.v = q, v
                return
        q1, v1 = sim._step(t, q, v, t1 - t, torque)
        turn = _turn_event(sim, friction, t, q, v, t1, q1, v1, torque)
        end, qe, ve = (t1, q1, v1) if turn is None else turn
        crossing = sim._first_crossing(t, q, v, end, qe, ve, torque) if sim._gaps else None
        if crossing is not None:  # a contact change first: ω changes with it
            end, qe, ve = crossing.t, crossing.q, crossing.v
        t, q, v = end, qe, ve
        if crossing is not None:
            slip = v[0] - friction.stick_speed(t, q)
            if slip == 0.0:
                q, v = _turn(sim, friction, t, q, torque)
            else:
                friction.direction = math.copysign(1.0, slip)
        elif turn is not None:
            q, v = _turn(sim, friction, t, q, torque)
        else:
            sim.q, sim.v = q1, v1
            return
        if t >= t1:
            if friction.mode == LOCKED:
                friction.remember(t1, q, v)
            sim.q, sim.v = q, v
            return
    raise SimulationDiverged(f"more than {MAX_EVENTS_PER_STEP} events (friction lock and breakaway, contact) in one step",
                             method=sim.method, t=t0, dt=sim.dt)


def riding_state(sim: Simulator, friction: StickSlipContact, t: float, theta1: float) -> tuple[Vec3, Vec3]:
    """(q, q') riding with the objects at θ1 (rad) and time t (s): q on Φ = 0, θ1' = ω(t, q)."""
    p = sim.system.params
    q = assemble(p, theta1)
    return q, dependent_rates(p, q, friction.stick_speed(t, q))


def holding_test(sim: Simulator, friction: StickSlipContact, t: float, theta1: float,
                 torque: TorqueFn) -> tuple[float, float]:
    """(margin N·m, τ_h N·m) riding with the objects at θ1 and time t: τ_h is the torque on θ1 that gives
    θ1'' = dω/dt along the ride (friction left out), the margin Σ μ_s F_n,k |j_k| − |τ_h|."""
    from finger_sim.stick_slip import PROBE_TORQUE

    q, v = riding_state(sim, friction, t, theta1)
    h = RIDE_PROBE
    ahead = friction.stick_speed(t + h, assemble(sim.system.params, theta1 + h * v[0]))
    behind = friction.stick_speed(t - h, assemble(sim.system.params, theta1 - h * v[0]))
    need = (ahead - behind) / (2.0 * h)
    mode = friction.mode
    friction.mode = LOCKED  # the locked law: normal forces only
    try:
        tau = torque(t)
        a0 = sim.system.accelerations(t, q, v, tau)[0][0]
        a1 = sim.system.accelerations(t, q, v, tau + PROBE_TORQUE)[0][0]
        capacity = friction.capacity(q, t, v)
    finally:
        friction.mode = mode
    tau_h = (need - a0) * PROBE_TORQUE / (a1 - a0)
    return capacity - abs(tau_h), tau_h


def _ride(sim: Simulator, friction: StickSlipContact, t: float, t1: float, q: Vec3,
          torque: TorqueFn) -> tuple[float, Vec3, Vec3, float, bool]:
    """Ride with the objects from (t, q) towards t1: (end s, q, q', τ_h there, broke free)."""
    from scipy.integrate import solve_ivp  # here: scipy costs ≈ 0.15 s to import, only these scenes need it

    def margin(s: float, y) -> float:  # type: ignore[no-untyped-def]
        return holding_test(sim, friction, s, float(y[0]), torque)[0]

    margin.terminal, margin.direction = True, -1  # type: ignore[attr-defined]
    first, tau_h = holding_test(sim, friction, t, q[0], torque)
    if first < 0.0:
        q, v = riding_state(sim, friction, t, q[0])
        return t, q, v, tau_h, True
    sol = solve_ivp(lambda s, y: [friction.stick_speed(s, assemble(sim.system.params, float(y[0])))], (t, t1), [q[0]],
                    method="DOP853", rtol=RIDE_RTOL, atol=RIDE_ATOL, events=margin)
    if not sol.success:
        raise SimulationDiverged(f"riding with a moving object: {sol.message}", method=sim.method, t=t, dt=sim.dt)
    released = sol.status == 1
    end, theta1 = (float(sol.t_events[0][0]), float(sol.y_events[0][0][0])) if released else (t1, float(sol.y[0, -1]))
    q, v = riding_state(sim, friction, end, theta1)
    return end, q, v, holding_test(sim, friction, end, theta1, torque)[1], released


def _turn(sim: Simulator, friction: StickSlipContact, t: float, q: Vec3, torque: TorqueFn) -> tuple[Vec3, Vec3]:
    """At zero slip: lock (ride with the objects) if the cones hold τ_h, else slide towards −sgn τ_h
    relative to them. Returns (q, q') riding at q's θ1."""
    margin, tau_h = holding_test(sim, friction, t, q[0], torque)
    if margin >= 0.0:
        friction.mode, friction.direction, friction.hold = LOCKED, 0.0, tau_h
    else:
        friction.mode, friction.direction = SLIDING, -math.copysign(1.0, tau_h)
    riding = riding_state(sim, friction, t, q[0])
    _carry(sim, q, riding[0], 0.0)
    return riding


def _carry(sim: Simulator, q_from: Vec3, q_to: Vec3, error: float) -> None:
    """Let the run's error estimate (`Simulator.error_estimate`) follow a state the ride moved or re-closed:
    q_from's plus `error` (rad); nothing for an integrator without an estimate."""
    carry = getattr(sim.integrator, "carry", None)
    if carry is not None:
        carry(q_from, q_to, error)


def _turn_event(sim: Simulator, friction: StickSlipContact, t: float, q: Vec3, v: Vec3, t1: float, q1: Vec3,
                v1: Vec3, torque: TorqueFn) -> tuple[float, Vec3, Vec3] | None:
    """(s, q, q') where the slip direction·(θ1' − ω) crosses 0 in (t, t1], the far side; None if the step
    ends on the near side (`locate.first_guard_crossing`, the guard `stick_slip.TURN_GUARD`; its start
    value is lazy: ω(t, q) is asked only of a step that crosses)."""
    from finger_sim.stick_slip import TURN_GUARD

    s_dir = friction.direction

    def slip(s: float, qs: Vec3, vs: Vec3) -> float:
        return s_dir * (vs[0] - friction.stick_speed(s, qs))

    def at(_: int, s: float) -> tuple[float, tuple[Vec3, Vec3]]:
        qs, vs = sim._step(t, q, v, s - t, torque)
        return slip(s, qs, vs), (qs, vs)

    event = first_guard_crossing(TURN_GUARD, (lambda: slip(t, q, v),), (slip(t1, q1, v1),), at, t, t1, (q1, v1))
    return None if event is None else (event.t, *event.state)
