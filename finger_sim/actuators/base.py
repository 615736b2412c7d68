"""The actuator slot: what takes the scene's input u and applies a generalized force on link 1.

An actuator declares its input (`input`: a torque in N·m today, a voltage in V for the drive), its
own continuous state (`slots`, which follow q and q' in the flat state, `state_layout`) and its
discrete modes (`modes`). During a step the integrator asks it, at each stage, for q'' under its
force (`accelerations`) and for the rates of its own slots (`rates`), both at the stage's (t, q, q',
own) and input u. `integrators.stateful.StatefulRungeKutta` steps any actuator this way: a new one
is a module (or a class in a test), not a change to the integrators.

Without an actuator (`Simulator(scene)`) the input is applied as the torque on θ1 (spec §3's ideal
source) and the state is (q, q') alone.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from typing import TYPE_CHECKING, ClassVar

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
