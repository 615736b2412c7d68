"""Objects that break, and scene changes at step boundaries, for a Simulator stepped step by step.

An object with a `break_force` (N) is *crushed* at the end of the first step at which the sum of
the normal forces on it (`Contact.object_forces`) exceeds that force. What happens after
(**assumption**, the simplest physical reading of a crushed cup): the object gives way at once
and is taken out of the scene; from the next step on it pushes no more, so the finger, still
driven, closes through where it was. The event is therefore resolved to one step (dt), not
located inside it: the force law up to the break is the scene's own, and the break changes no
state (q, q' carry over), only the set of objects.

A scene change at a step boundary (the object removed, a new `tip_force` of a piecewise-constant
tip-force profile) builds a Simulator of the changed scene and hands it the state: q, q', the
step count, the last torque, an actuator in the slot with its own slots, and every mode the new
scene declares too (a rest on a joint stop, stick–slip friction's, the drive's mesh). The new
integrator starts fresh (a warm start would have been dropped by `Simulator.reset` anyway).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Iterable
from dataclasses import dataclass

from finger_sim import stick_slip
from finger_sim.effects.contact import Contact
from finger_sim.scene import Scene
from finger_sim.simulate import Simulator
from finger_sim.simulation.crossings import Gap


@dataclass(frozen=True)
class Crush:
    """An object crushed at the end of step `step` (time t, s) under `force` N > `break_force` N."""

    object: str
    t: float
    step: int
    force: float
    break_force: float

    def log_line(self) -> str:
        """The one-line record a run's log keeps."""
        return (f"object '{self.object}' crushed at t = {self.t:.6g} s: normal force {self.force:.6g} N "
                f"> break_force {self.break_force:.6g} N; removed from the scene")


def contact_element(sim: Simulator) -> Contact | None:
    """The contact element of a simulator's system, or None (a scene without objects)."""
    return next((e for e in sim.system.elements if isinstance(e, Contact)), None)


def crushed(sim: Simulator) -> list[Crush]:
    """The objects of `sim`'s scene whose normal force now exceeds their break_force."""
    contact = contact_element(sim)
    if contact is None:
        return []
    forces = contact.object_forces(sim.time, sim.q, sim.v)
    return [Crush(obj.name, sim.time, sim.step_index, f, obj.properties.break_force)
            for obj, f in zip(contact.objects, forces)
            if obj.properties.break_force is not None and f > obj.properties.break_force]


def crush_step(sim: Simulator) -> tuple[Simulator, list[Crush]]:
    """After a step of `sim`: the Simulator to go on with and the objects that step crushed
    (taken out of its scene, the state carried over); `sim` itself and [] when none broke.
    The one rule of crushing, shared by the task runner, finger_node and resim."""
    broken = crushed(sim)
    if not broken:
        return sim, []
    return carry_over(sim, without_objects(sim.scene, (c.object for c in broken))), broken


def breakable(scene: Scene) -> bool:
    """Whether any object of `scene` has a break_force."""
    return any(o.properties.break_force is not None for o in scene.objects)


def without_objects(scene: Scene, names: Iterable[str]) -> Scene:
    """`scene` with the named objects taken out."""
    gone = set(names)
    return dataclasses.replace(scene, objects=tuple(o for o in scene.objects if o.name not in gone))


def with_tip_force(scene: Scene, force: tuple[float, float]) -> Scene:
    """`scene` with a new constant tip force (N, model plane)."""
    return dataclasses.replace(scene, tip_force=(float(force[0]), float(force[1])))


def carry_over(sim: Simulator, scene: Scene) -> Simulator:
    """A Simulator of `scene` (the same kernel) in the state `sim` has reached: q, q', step, torque, and
    the discrete state (`_carry_modes`), and an actuator in the slot with its own slots. An error-controlled
    method (dop853) starts its step size afresh there, as at any change of the scene."""
    actuator = sim._actuator
    new = Simulator(scene, kernel=sim.kernel, actuator=actuator)
    new.q, new.v, new.step_index, new.torque = sim.q, sim.v, sim.step_index, sim.torque
    new.impacts = sim.impacts
    if actuator is not None:  # its own slots go with (q, q'): `StatefulRungeKutta.begin`
        new.integrator.begin(new.q, new.v, sim.integrator.own_of(sim.q, sim.v))  # type: ignore[attr-defined]
    _carry_modes(sim, new)
    return new


def _carry_modes(sim: Simulator, new: Simulator) -> None:
    """Every declared mode of `sim` that `new` declares too (same owner, same name) takes its value in
    `new`, with the data that goes with it: the gap the stops' rest rests on, stick–slip friction's
    sliding direction and holding torque, the drive's direction and current (spec §7, §8)."""
    values = {(owner, mode.name): value for (owner, mode), value in zip(sim.layout.modes, sim.mode_values.values)}
    for k, (owner, mode) in enumerate(new.layout.modes):
        new.mode_values.values[k] = values.get((owner, mode.name), new.mode_values.values[k])
    gap = sim._resting
    if gap is not None and new._rest_at is not None:  # the same gap of the new run's element of that kind
        element = next(e for e in new.system.elements if type(e) is type(gap.element))
        new._resting = Gap(element, gap.index, gap.restitution)
    friction, old_friction = stick_slip.element(new.system), stick_slip.element(sim.system)
    if friction is not None and old_friction is not None:
        friction.direction, friction.hold = old_friction.direction, old_friction.hold  # mirrors the mode too
        friction.holds.update(old_friction.holds)
    if sim.scene.drive is not None:
        drive, old = new.system.drive, sim.system.drive  # type: ignore[attr-defined]
        drive.mode, drive.direction, drive.i = old.mode, old.direction, old.i  # the setter mirrors and counts
