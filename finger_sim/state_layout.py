"""The declared state of a run: the continuous slots in one flat layout, and the discrete modes by owner.

The continuous state is x = (θ1, θ2, θ3, θ1', θ2', θ3', then each owner's own slots in order): an
actuator's (`actuators.base.Actuator.slots`, e.g. the winding current of a drive with L > 0) and any
force element's that declares `slots`. Like MuJoCo's `mjtState` (qpos, qvel, then act) and Drake's
Context: an element declares what it owns, the integrators step the flat vector
(`integrators.stateful.StatefulRungeKutta`) and need no change for a new one.

The discrete state is the modes the elements own, each with the guards whose crossings are located as
events and switch it (`ModeSet`): the stops' rest mode, the drive's mesh mode, stick–slip friction's
lock. A mode is not part of x: it selects which equations x follows. A run keeps their values in one
home beside x (`ModeValues`, like Drake's discrete state): each owner reads and writes its own entries,
an element whose laws read its mode through `OwnModes.mode`, bound to the run's entry. Such an owner
also says when its laws changed (`OwnModes.mode_key`); the system collects the keys of its owners
(`FingerSystem.mode_key`), and an integrator that keeps its own solution restarts it when they change,
whatever owns them.
"""

from __future__ import annotations

from collections.abc import Hashable, Iterable, Sequence
from typing import NamedTuple

from finger_sim.kinematics import Vec3


class Slot(NamedTuple):
    """One continuous state variable: its name, unit (SI) and meaning."""

    name: str
    unit: str
    doc: str = ""


class ModeSet(NamedTuple):
    """A discrete mode an element owns: its name, its values, the guards whose crossings, located as
    events inside a step, switch it, and the value a run starts in (an index into `values`) unless the
    element decides otherwise at t = 0."""

    name: str
    values: tuple[str, ...]
    guards: tuple[str, ...]
    initial: int = 0


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


class ModeValues:
    """A run's discrete state, its one home: the value of each declared mode (an index into its
    `ModeSet.values`), in `StateLayout.modes` order. Built from the same owners as the layout; each owner
    that reads its modes in its laws (`OwnModes`) is bound to its entries here, any other (the frozen
    stops, shared by one scene's runs) is read and written through `position`."""

    def __init__(self, layout: StateLayout, owners: Iterable[object]) -> None:
        self.sets: tuple[ModeSet, ...] = tuple(m for _, m in layout.modes)
        #: the values, one int per mode: owners index into this list
        self.values: list[int] = [m.initial for m in self.sets]
        self._at: dict[int, int] = {}  # id(owner) → position of its first mode
        at = 0
        for owner in owners:
            owned = tuple(getattr(owner, "modes", ()))
            if owned:
                self._at[id(owner)] = at
                if isinstance(owner, OwnModes):
                    owner.bind_modes(self.values, at)
                at += len(owned)

    def reset(self) -> None:
        """Every mode back to its declared initial value."""
        self.values[:] = [m.initial for m in self.sets]

    def position(self, owner: object, name: str) -> int | None:
        """Where `owner`'s mode `name` is in `values`; None if it declares none of that name."""
        first = self._at.get(id(owner))
        if first is None:
            return None
        names = [m.name for m in getattr(owner, "modes", ())]
        return first + names.index(name) if name in names else None

    @property
    def names(self) -> tuple[str, ...]:
        """The value of each mode by name, in `values` order."""
        return tuple(m.values[v] for m, v in zip(self.sets, self.values))


class OwnModes:
    """Mixin of an element whose laws read its own mode (`mode`: the value of its first declared
    `ModeSet`): bound to a run's `ModeValues` by the Simulator, before that in a home of its own (an
    element on its own, a batch row). An element bound to a run belongs to that run alone."""

    modes: tuple[ModeSet, ...] = ()
    _mode_values: list[int]
    _mode_at: int = 0

    def bind_modes(self, values: list[int], at: int) -> None:
        """Keep this element's modes at values[at:at + len(modes)] (a run's `ModeValues.values`)."""
        self._mode_values, self._mode_at = values, at

    def own_modes(self) -> None:
        """A home of its own for its modes, at their initial values (call in __init__)."""
        self.bind_modes([m.initial for m in self.modes], 0)

    @property
    def mode(self) -> int:
        return self._mode_values[self._mode_at]

    @mode.setter
    def mode(self, value: int) -> None:
        self._mode_values[self._mode_at] = value
        self.mode_changed(value)

    def mode_changed(self, value: int) -> None:
        """Called after every write of `mode` (an element mirrors it into compiled models here); nothing by default."""

    def mode_key(self) -> Hashable:
        """What its laws read of its discrete state, as one comparable value: an integrator that keeps its own
        solution across steps restarts it when the system's key (`FingerSystem.mode_key`) changes. By default
        the values of its modes; an owner whose laws read more (a direction) or that counts its switches says so."""
        return tuple(self._mode_values[self._mode_at:self._mode_at + len(self.modes)])
