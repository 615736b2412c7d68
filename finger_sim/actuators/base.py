"""The actuator slot: what takes the scene's input u and applies a generalized force on link 1.

An actuator declares its input (`input`: a torque in N·m today, a voltage in V for the drive), its
own continuous state (`slots`, which follow q and q' in the flat state, `state_layout`) and its
discrete modes (`modes`). During a step the integrator asks it, at each stage, for q'' under its
force (`accelerations`) and for the rates of its own slots (`rates`), both at the stage's (t, q, q',
own) and input u. `integrators.stateful.StatefulRungeKutta` steps any actuator this way: a new one
is a module (or a class in a test), not a change to the integrators.

An actuator that declares its law (`ActuatorLaw`: its torque and its slots' rates as plain functions of
floats, `LawActuator`) has a compiled form too: the kernel compiles the same functions into its stateful
step (`kernel.stateful`), so `kernel="auto"` runs it compiled, with the same numbers.

Without an actuator (`Simulator(scene)`) the input is applied as the torque on θ1 (spec §3's ideal
source) and the state is (q, q') alone.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from collections.abc import Callable, Sequence
from typing import TYPE_CHECKING, ClassVar, NamedTuple

from finger_sim.kinematics import Vec3
from finger_sim.state_layout import ModeSet, Slot

if TYPE_CHECKING:
    from finger_sim.dynamics import FingerSystem

#: The ideal source's input: the motor torque on θ1.
TORQUE_INPUT = Slot("torque", "N·m", "motor torque on θ1")


class Actuator(ABC):
    """An actuator with its own state: subclasses declare `name`, `input`, `slots` (and `modes`) and
    write `initial`, `torque` and `rates`; a constrained actuator (the drive's mesh) writes
    `accelerations` itself."""

    name: ClassVar[str]
    input: ClassVar[Slot] = TORQUE_INPUT
    slots: tuple[Slot, ...] = ()
    modes: tuple[ModeSet, ...] = ()
    #: the time constant of the fastest own slot, s (its mode s = −1/T enters the stability check); None: none
    time_constant: float | None = None

    @abstractmethod
    def initial(self) -> tuple[float, ...]:
        """The own slots at t = 0, in `slots` order."""

    @abstractmethod
    def torque(self, system: FingerSystem, t: float, q: Vec3, v: Vec3, u: float, own: tuple[float, ...]) -> float:
        """The generalized force it applies on θ1 (N·m) at (t, q, q', own) under input u."""

    @abstractmethod
    def rates(self, t: float, q: Vec3, v: Vec3, u: float, own: tuple[float, ...]) -> tuple[float, ...]:
        """d/dt of the own slots (each slot's unit per second)."""

    def accelerations(self, system: FingerSystem, t: float, q: Vec3, v: Vec3, u: float,
                      own: tuple[float, ...]) -> Vec3:
        """q'' (rad/s²) of `system` with this actuator's torque on θ1 (spec §4)."""
        return system.accelerations(t, q, v, self.torque(system, t, q, v, u, own))[0]


class ActuatorLaw(NamedTuple):
    """An actuator's law as plain functions, its one definition: the Python path calls them (`LawActuator`)
    and the compiled kernel compiles them (`kernel.stateful`).

    Both take (p, t, q0, q1, q2, v0, v1, v2, u, own): p the actuator's parameters (`kernel_params`, floats),
    t (s), q (rad), q' (rad/s), u the input (its `input` unit), own its slots in `slots` order (a sequence of
    floats: a tuple in Python, an array in the kernel). `torque` returns the generalized force on θ1 (N·m),
    `rates` the tuple of d/dt of the own slots (one float per slot). `callees`: plain functions the two call
    by name, compiled with them."""

    torque: Callable[..., float]
    rates: Callable[..., tuple[float, ...]]
    callees: tuple[Callable[..., object], ...] = ()


class LawActuator(Actuator):
    """An actuator whose torque and rates are its declared `law` (`ActuatorLaw`) at its `kernel_params`:
    it has a compiled form. Subclasses declare `name`, `slots`, `law` and write `initial` and `kernel_params`."""

    law: ClassVar[ActuatorLaw]

    @abstractmethod
    def kernel_params(self) -> tuple[float, ...]:
        """The law's parameters p, floats (SI)."""

    def torque(self, system: FingerSystem, t: float, q: Vec3, v: Vec3, u: float, own: Sequence[float]) -> float:
        return self.law.torque(self.kernel_params(), t, q[0], q[1], q[2], v[0], v[1], v[2], u, own)

    def rates(self, t: float, q: Vec3, v: Vec3, u: float, own: Sequence[float]) -> tuple[float, ...]:
        return self.law.rates(self.kernel_params(), t, q[0], q[1], q[2], v[0], v[1], v[2], u, own)
