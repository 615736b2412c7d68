"""The declared state of a run: the continuous slots in one flat layout, and the discrete modes by owner.

The continuous state is x = (θ1, θ2, θ3, θ1', θ2', θ3', then each owner's own slots in order): an
actuator's (`actuators.base.Actuator.slots`, e.g. the winding current of a drive with L > 0) and any
force element's that declares `slots`. Like MuJoCo's `mjtState` (qpos, qvel, then act) and Drake's
Context: an element declares what it owns, the integrators step the flat vector
(`integrators.stateful.StatefulRungeKutta`) and need no change for a new one.

The discrete state is the modes the elements own, each with the guards whose crossings are located as
events and switch it (`ModeSet`): the stops' rest mode, the drive's mesh mode, stick–slip friction's
lock. A mode is not part of x: it selects which equations x follows.
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from typing import NamedTuple

from finger_sim.kinematics import Vec3


class Slot(NamedTuple):
    """One continuous state variable: its name, unit (SI) and meaning."""

    name: str
    unit: str
    doc: str = ""


class ModeSet(NamedTuple):
    """A discrete mode an element owns: its name, its values (the first is the one a run starts in
    unless the element decides otherwise at t = 0) and the guards whose crossings, located as events
    inside a step, switch it."""

    name: str
    values: tuple[str, ...]
    guards: tuple[str, ...]


#: The linkage's slots: q then q', always first.
POSITIONS = (Slot("theta1", "rad", "MCP angle"), Slot("theta2", "rad", "coupler angle"),
             Slot("theta3", "rad", "distal link angle"))
VELOCITIES = (Slot("theta1_dot", "rad/s"), Slot("theta2_dot", "rad/s"), Slot("theta3_dot", "rad/s"))
#: Length of the linkage's block (q, q').
LINKAGE_SIZE = len(POSITIONS) + len(VELOCITIES)


class StateLayout:
    """The flat continuous state's layout and the modes of a run's owners.

    owners: (owner name, its slots, its modes) in order; owners with neither are left out."""

    def __init__(self, owners: Iterable[tuple[str, Sequence[Slot], Sequence[ModeSet]]] = ()) -> None:
        slots: list[tuple[str, Slot]] = [("linkage", s) for s in POSITIONS + VELOCITIES]
        modes: list[tuple[str, ModeSet]] = []
        self.offsets: dict[str, slice] = {"linkage": slice(0, LINKAGE_SIZE)}
        for owner, own, owned_modes in owners:
            if own:
                if owner in self.offsets:
                    raise ValueError(f"two owners of state slots named {owner!r}")
                self.offsets[owner] = slice(len(slots), len(slots) + len(own))
                slots += [(owner, s) for s in own]
            modes += [(owner, m) for m in owned_modes]
        self.slots: tuple[tuple[str, Slot], ...] = tuple(slots)
        self.modes: tuple[tuple[str, ModeSet], ...] = tuple(modes)

    @property
    def size(self) -> int:
        """Length of the flat continuous state."""
        return len(self.slots)

    @property
    def names(self) -> tuple[str, ...]:
        """Slot names in order; an owner's own slots as `owner.name`."""
        return tuple(s.name if owner == "linkage" else f"{owner}.{s.name}" for owner, s in self.slots)

    @property
    def units(self) -> tuple[str, ...]:
        return tuple(s.unit for _, s in self.slots)

    def index(self, name: str) -> int:
        """Position of slot `name` (as in `names`) in the flat state; KeyError naming the known ones."""
        names = self.names
        if name not in names:
            raise KeyError(f"no state slot {name!r}; the layout has {', '.join(names)}")
        return names.index(name)

    def pack(self, q: Vec3, v: Vec3, own: Sequence[float] = ()) -> tuple[float, ...]:
        """The flat state from q (rad), q' (rad/s) and the owners' slots in layout order."""
        if len(own) != self.size - LINKAGE_SIZE:
            raise ValueError(f"the layout's own slots take {self.size - LINKAGE_SIZE} values, got {len(own)}")
        return (*q, *v, *own)

    @staticmethod
    def unpack(x: Sequence[float]) -> tuple[Vec3, Vec3, tuple[float, ...]]:
        """(q, q', the owners' slots) of a flat state."""
        return (x[0], x[1], x[2]), (x[3], x[4], x[5]), tuple(x[LINKAGE_SIZE:])


def layout_of(elements: Iterable[object], actuator: object | None = None) -> StateLayout:
    """The layout of a system's force elements (each may declare `slots` and `modes`, class or instance
    attributes) and its actuator (`actuators.base.Actuator`, or None: the ideal torque source)."""
    owners = [(type(e).__name__, tuple(getattr(e, "slots", ())), tuple(getattr(e, "modes", ()))) for e in elements]
    if actuator is not None:
        owners.append((getattr(actuator, "name", type(actuator).__name__), tuple(actuator.slots),  # type: ignore[attr-defined]
                       tuple(actuator.modes)))  # type: ignore[attr-defined]
    return StateLayout(owners)
