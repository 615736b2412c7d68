"""The gap events (stop impacts and rest, contact onsets and releases) of a run whose actuator has its own state.

`Simulator._advance`'s loop with the actuator's own slots (`integrators.stateful.StatefulRungeKutta`)
carried through every piece of it:
- a trial step, the location of a crossing and a contact substep continue each state with its own
  slots (`StatefulRungeKutta.begin` / `own_of`, by the identity of the q and q' objects);
- an impact keeps the slots of the located state, and decides the rest under the actuator's torque there;
- at rest on a stop q is held and q' = 0 while the slots go on by their own equation at (q, 0)
  (`StatefulRungeKutta.advance_held`); the release is located on the free acceleration under the
  actuator's torque at those slots (`JointStops.release_time`).
Stick–slip friction (fixed objects) is `stick_slip.FrictionStepping.advance`'s loop the same way: locked,
q is held and the slots go on; the holding test, the breakaway and the turn read the actuator's torque at
its slots there.
An actuator acts here through its torque on θ1 (`Actuator.torque`); one that writes its own
`accelerations` (a constrained one, the drive's mesh) is refused with gaps (`simulation.actuated`).
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

from finger_sim import stick_slip
from finger_sim.effects.friction_modes import LOCKED, SLIDING
from finger_sim.errors import SimulationDiverged
from finger_sim.integrators import TorqueFn
from finger_sim.integrators.stateful import StatefulRungeKutta
from finger_sim.kinematics import ZERO, Vec3
from finger_sim.simulation.mode_stepping import ModeStepping

if TYPE_CHECKING:
    from finger_sim.actuators.base import Actuator
    from finger_sim.effects.friction_modes import StickSlipContact
    from finger_sim.simulation.driver import Simulator

#: Events allowed within one step (as `simulation.driver.MAX_EVENTS_PER_STEP`: a stop's Zeno series to rest).
MAX_EVENTS_PER_STEP = 64


class ActuatorStepping(ModeStepping):
    """An actuator in the slot with its own slots (`Simulator(scene, actuator=...)`), as the Simulator steps
    it (`simulation.mode_stepping`): the gap events with its slots carried (`advance`), stick–slip friction on
    fixed objects carried too (`advance_friction`); its slots are the integrator's (`own_of`)."""

    name = "actuator"
    carries = ("stick_slip",)

    def __init__(self, actuator: Actuator) -> None:
        self.actuator = actuator
        #: the stick–slip contact whose modes it carries, or None (found at `start`)
        self.friction: StickSlipContact | None = None

    def start(self, sim: Simulator) -> None:
        self.friction = stick_slip.element(sim.system)
        if self.friction is not None:
            start_friction(sim, self.friction)

    def advance(self, sim: Simulator, t0: float, t1: float, u: TorqueFn) -> None:
        if not sim._gaps:  # a smooth scene: one step of the stateful integrator
            sim.q, sim.v = sim.integrator.step(t0, sim.q, sim.v, t1 - t0, u)
        elif self.friction is not None:
            advance_friction(sim, self.friction, t0, t1, u)
        else:
            advance(sim, t0, t1, u)

    def after_step(self, sim: Simulator) -> None:  # type: ignore[override]
        commit(sim)

    def own_slots(self, sim: Simulator) -> tuple[float, ...]:
        return sim.integrator.own_of(sim.q, sim.v)  # type: ignore[attr-defined]


def held_torque(integ: StatefulRungeKutta, t: float, q: Vec3, own: tuple[float, ...], u: TorqueFn) -> TorqueFn:
    """s ↦ the actuator's torque on θ1 (N·m) at s ≥ t with the linkage held at q, q' = 0, from the slots
    `own` at t (stepped to s by `advance_held`); u: the scene's input."""
    actuator, system = integ.actuator, integ.system

    def torque(s: float) -> float:
        slots = own if s == t else integ.advance_held(t, q, own, s - t, u)
        return actuator.torque(system, s, q, ZERO, u(s), slots)

    return torque


def advance(sim: Simulator, t0: float, t1: float, u: TorqueFn) -> None:
    """Integrate [t0, t1] under a smooth input u(s), splitting it at every gap event, with the actuator's
    own slots carried along; the state reached is committed with its slots (`commit`)."""
    integ: StatefulRungeKutta = sim.integrator  # type: ignore[assignment]
    t, q, v = t0, sim.q, sim.v
    own = integ.own_of(q, v)
    for _ in range(MAX_EVENTS_PER_STEP):
        if sim._resting is not None:
            release = sim._release_time(sim._resting, t, t1, q, held_torque(integ, t, q, own, u))
            if release is None:  # held on the stop for the whole segment, the slots going on
                _commit(sim, q, ZERO, integ.advance_held(t, q, own, t1 - t, u))
                return
            own = integ.advance_held(t, q, own, release - t, u)
            t, v, sim._resting = release, ZERO, None
        integ.begin(q, v, own)
        q1, v1 = sim._step(t, q, v, t1 - t, u)
        crossing = sim._first_crossing(t, q, v, t1, q1, v1, u)
        if crossing is None:
            sim.q, sim.v = q1, v1  # the integrator holds their slots
            return
        t, q, v = crossing.t, crossing.q, crossing.v
        own = integ.own_of(q, v)
        if crossing.gap.restitution is not None:
            v = sim._impact(crossing, held_torque(integ, t, q, own, u))
        if t >= t1:
            _commit(sim, q, v, own)
            return
    raise SimulationDiverged(f"more than {MAX_EVENTS_PER_STEP} events (stop impacts, contact changes) in one step",
                             method=sim.method, t=t0, dt=sim.dt)


def start_friction(sim: Simulator, friction: StickSlipContact) -> None:
    """The stick–slip mode of the initial state (`stick_slip.start`) under the actuator's torque at t = 0."""
    friction.holds.clear()
    if sim.v[0] == 0.0:
        integ: StatefulRungeKutta = sim.integrator  # type: ignore[assignment]
        sim.v = stick_slip._turn(sim, friction, 0.0, sim.q, held_torque(integ, 0.0, sim.q, integ.own, sim.scene.torque))
        friction.remember(0.0, sim.q)
    else:
        friction.mode, friction.direction = SLIDING, math.copysign(1.0, sim.v[0])


def advance_friction(sim: Simulator, friction: StickSlipContact, t0: float, t1: float, u: TorqueFn) -> None:
    """`stick_slip.FrictionStepping.advance` (no drive, fixed objects) with the actuator's own slots carried
    along: locked or at rest on a stop, q is held and the slots go on (`advance_held`); the holding test, the
    breakaway and the turn read the actuator's torque at the slots there (`held_torque`)."""
    integ: StatefulRungeKutta = sim.integrator  # type: ignore[assignment]
    t, q, v = t0, sim.q, sim.v
    own = integ.own_of(q, v)
    for _ in range(MAX_EVENTS_PER_STEP):
        if sim._resting is not None:  # on a stop: it holds the load; leaving it is a turning point
            release = sim._release_time(sim._resting, t, t1, q, held_torque(integ, t, q, own, u))
            if release is None:
                friction.mode, friction.hold = LOCKED, 0.0
                friction.remember(t1, q)
                _commit(sim, q, ZERO, integ.advance_held(t, q, own, t1 - t, u))
                return
            own = integ.advance_held(t, q, own, release - t, u)
            sim._resting = None
            t, v = release, stick_slip._turn(sim, friction, release, q, held_torque(integ, release, q, own, u))
        if friction.mode == LOCKED:
            held = held_torque(integ, t, q, own, u)
            release = stick_slip._release_time(sim, friction, t, t1, q, held)
            if release is None:
                own = integ.advance_held(t, q, own, t1 - t, u)
                friction.hold = stick_slip._holding(sim, friction, t1, q, held_torque(integ, t1, q, own, u))
                friction.remember(t1, q)
                _commit(sim, q, ZERO, own)
                return
            own = integ.advance_held(t, q, own, release - t, u)
            held = held_torque(integ, release, q, own, u)
            t, v = release, ZERO
            stick_slip._slide(sim, friction, t, q, held,
                              stick_slip._break_direction(sim, t, stick_slip._holding(sim, friction, t, q, held), held))
        if t >= t1:  # freed on the step's end: no zero-length step (as stick–slip friction's advance)
            friction.remember(t1, q)
            _commit(sim, q, v, own)
            return
        integ.begin(q, v, own)
        q1, v1 = sim._step(t, q, v, t1 - t, u)
        turn = stick_slip._turn_event(sim, friction, t, q, v, t1, q1, v1, u)
        end, qe, ve = (t1, q1, v1) if turn is None else turn
        crossing = sim._first_crossing(t, q, v, end, qe, ve, u) if sim._gaps else None
        if crossing is not None:  # a stop or a contact change first: the turn is looked for again after it
            end, qe, ve = crossing.t, crossing.q, crossing.v
        if crossing is None and turn is None:
            sim.q, sim.v = q1, v1  # the integrator holds their slots
            return
        t, q, v = end, qe, ve
        own = integ.own_of(q, v)
        held = held_torque(integ, t, q, own, u)
        if crossing is not None:
            if crossing.gap.restitution is not None:
                v = sim._impact(crossing, held)
                if sim._resting is not None:
                    friction.mode, friction.hold, v = LOCKED, 0.0, ZERO  # idle while the stop holds the load
                elif v[0] == 0.0:
                    v = stick_slip._turn(sim, friction, t, q, held)
                else:  # the impact reversed the motion
                    stick_slip._slide(sim, friction, t, q, held, math.copysign(1.0, v[0]), v)
        else:
            v = stick_slip._turn(sim, friction, t, q, held)
        if t >= t1:
            if v[0] == 0.0:  # at rest: the mode is not a function of the state
                if friction.mode == LOCKED and sim._resting is None:
                    friction.hold = stick_slip._holding(sim, friction, t1, q, held)
                friction.remember(t1, q)
            _commit(sim, q, v, own)
            return
    raise SimulationDiverged(f"more than {MAX_EVENTS_PER_STEP} events (friction lock and breakaway, stops, contact) "
                             "in one step", method=sim.method, t=t0, dt=sim.dt)


def commit(sim: Simulator) -> None:
    """Make the slots of the Simulator's current (q, q') the integrator's own: a q or q' set from outside
    (`sim.q = ...`) then continues with the slots the run had, not the initial ones."""
    integ: StatefulRungeKutta = sim.integrator  # type: ignore[assignment]
    integ.begin(sim.q, sim.v, integ.own_of(sim.q, sim.v))


def _commit(sim: Simulator, q: Vec3, v: Vec3, own: tuple[float, ...]) -> None:
    sim.q, sim.v = q, v
    sim.integrator.begin(q, v, own)  # type: ignore[attr-defined]
