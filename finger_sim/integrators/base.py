"""The one step interface every integrator shares.

An integrator advances (q, q') of a `FingerSystem` from t to t + dt under a motor
torque τ(s) (N·m) that it evaluates at each stage time s: a scripted profile is a
function of time, a held command a constant function. Bookkeeping that is not a
method's own (time grid, torque breakpoints, joint stops, checks) lives in
`finger_sim.simulate.Simulator`.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from collections.abc import Callable
from typing import TYPE_CHECKING, ClassVar

from finger_sim.dynamics import FingerSystem
from finger_sim.kinematics import Vec3

if TYPE_CHECKING:
    from finger_sim.stepper_slot import CompiledCall

TorqueFn = Callable[[float], float]

#: Growth per step above 1 that `is_stable` still accepts. A weak instability such as
#: Euler's on a slow undamped mode (growth ≈ 1 + (ω dt)²/2) is an accuracy error the
#: error figures show; growth beyond 1e-3 per step is a blow-up within a few thousand steps.
STABILITY_SLACK = 1e-3


class HeldTorque:
    """τ(s) = value (N·m) at every s: a command held over a step. `value` tells a method that τ is the
    same at every stage (DOP853 then skips evaluating it per stage)."""

    __slots__ = ("value",)

    def __init__(self, value: float) -> None:
        self.value = value

    def __call__(self, s: float) -> float:
        return self.value


class Integrator(ABC):
    """A fixed-step method for the constrained finger. Subclasses write only `step`."""

    name: ClassVar[str]
    #: global order of accuracy on smooth problems
    order: ClassVar[int]
    #: True when the method returns states on Φ = 0 and Φ_q q' = 0 (to round-off)
    keeps_constraints: ClassVar[bool]
    #: True when each step solves a nonlinear system (stable for stiff scenes)
    implicit: ClassVar[bool] = False

    def __init__(self, system: FingerSystem) -> None:
        self.system = system

    @abstractmethod
    def step(self, t: float, q: Vec3, v: Vec3, dt: float, torque: TorqueFn) -> tuple[Vec3, Vec3]:
        """(q, q') at t + dt from (q, q') at t; rad, rad/s, s."""

    def compiled_calls(self) -> tuple[CompiledCall, ...]:
        """The compiled functions `step` may call from Python, with arguments of their types
        (`stepper_slot.CompiledCall`), for the Simulator to load before its first step; none by default."""
        return ()

    @classmethod
    @abstractmethod
    def is_stable(cls, z: complex) -> bool:
        """Whether the method is stable on y' = λy for z = λ·dt (linear stability region)."""
