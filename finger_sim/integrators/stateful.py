"""An explicit Runge-Kutta method on the declared flat state (q, q', the actuator's own slots).

The tableau is the scene's method's (`ExplicitRungeKutta`: rk4, rk6, dop8); the stages carry the whole
flat state (`state_layout`), q' and q'' from the actuator (`actuators.base.Actuator.accelerations`)
and its slots' rates (`Actuator.rates`); after the step (q, q') are projected onto the constraints as
`ExplicitRungeKutta.step` does: both run the one stage loop, `explicit.rk_stage_loop`.

The Simulator's events (trial steps, location, substeps) pass (q, q') alone; the integrator keeps the
own slots of the states it produced (`own_of`, by the identity of the q and q' objects), so each trial
continues a state with its own slots, and `begin` tells it the slots of a state it did not produce.
An actuator that declares its law (`actuators.base.ActuatorLaw`) has a compiled twin of this class,
`kernel.stateful.CompiledStatefulRungeKutta`: the same step, the same numbers.
"""

from __future__ import annotations

from collections import deque
from typing import ClassVar

from finger_sim.actuators.base import Actuator
from finger_sim.dynamics import FingerSystem
from finger_sim.errors import ConfigError
from finger_sim.integrators.base import Integrator, TorqueFn
from finger_sim.integrators.explicit import ExplicitRungeKutta, rk_stage_loop, tableau_rows
from finger_sim.kinematics import ZERO, Vec3
from finger_sim.projection import project

#: States whose own slots the integrator remembers (event location tries ≤ 2 × 60 per step).
MEMORY = 256


class StatefulRungeKutta(Integrator):
    """The explicit Runge-Kutta method `reference` on the flat state, `substeps` per step, projected
    after each. `actuator` supplies q'' and the rates of its slots at each stage."""

    reference: ClassVar[type[ExplicitRungeKutta]]
    substeps: ClassVar[int] = 1
    #: the actuator a class made by `of` steps when none is given
    bound: ClassVar[Actuator | None] = None

    def __init__(self, system: FingerSystem, actuator: Actuator | None = None) -> None:
        super().__init__(system)
        actuator = self.bound if actuator is None else actuator
        if actuator is None:
            raise TypeError(f"{type(self).__name__} needs an actuator")
        ref = self.reference
        self._rows = tableau_rows(ref.A, ref.B, ref.C)
        self.actuator = actuator
        #: the own slots of a state this integrator neither produced nor was told of
        self.own: tuple[float, ...] = actuator.initial()
        self._memory: deque[tuple[Vec3, Vec3, tuple[float, ...]]] = deque(maxlen=MEMORY)

    @classmethod
    def of(cls, reference: type[Integrator], substeps: int = 1,
           actuator: Actuator | None = None) -> type[StatefulRungeKutta]:
        """The class stepping the flat state with the tableau of `reference` (an ExplicitRungeKutta, or a
        class naming one as its `reference`), `actuator` bound; ConfigError for a method that has no
        explicit tableau."""
        ref = getattr(reference, "reference", reference)
        if not (isinstance(ref, type) and issubclass(ref, ExplicitRungeKutta)):
            raise ConfigError("integrator.method", "an explicit Runge-Kutta method (rk4, rk6, dop8) for an actuator "
                              "with its own state", reference.name)
        return type(f"{cls.__name__}{ref.__name__}", (cls,), {
            "reference": ref, "substeps": substeps, "bound": actuator, "name": reference.name, "order": reference.order,
            "keeps_constraints": reference.keeps_constraints, "implicit": False,
            "__doc__": f"{reference.name} on the flat state: {(reference.__doc__ or '').splitlines()[0]}",
        })

    def begin(self, q: Vec3, v: Vec3, own: tuple[float, ...]) -> None:
        """The state (q, q') the next steps start from has the own slots `own`, whatever they were when
        this integrator produced it (an event may set a slot, as the current limit sets i = ±i_max)."""
        self.own = own
        self._memory.append((q, v, own))

    def own_of(self, q: Vec3, v: Vec3) -> tuple[float, ...]:
        """The own slots of the state (q, q') (the same objects) this integrator produced or was told of
        last (`begin`), else `own`."""
        for qs, vs, own in reversed(self._memory):
            if qs is q and vs is v:
                return own
        return self.own

    def step(self, t: float, q: Vec3, v: Vec3, dt: float, torque: TorqueFn) -> tuple[Vec3, Vec3]:
        q, v, own = self.advance_state(t, q, v, self.own_of(q, v), dt, torque, self.substeps)
        self._memory.append((q, v, own))
        return q, v

    def advance_state(self, t: float, q: Vec3, v: Vec3, own: tuple[float, ...], dt: float, torque: TorqueFn,
                      n: int) -> tuple[Vec3, Vec3, tuple[float, ...]]:
        """(q, q', own) at t + dt from (q, q', own) at t in n substeps, remembering nothing."""
        h = dt / n
        for k in range(n):
            q, v, own = self._substep(t + k * h, q, v, own, h, torque)
        return q, v, own

    def advance_held(self, t: float, q: Vec3, own: tuple[float, ...], dt: float,
                     torque: TorqueFn) -> tuple[float, ...]:
        """The own slots at t + dt from `own` at t while the linkage is held at q with q' = 0 (at rest on a
        stop, locked by friction): the same tableau and substeps on the slots, their rates at (q, 0)."""
        held = _Held(self.actuator, q)
        h = dt / self.substeps
        for k in range(self.substeps):
            own = rk_stage_loop(self._rows, self.system, t + k * h, q, ZERO, own, h, torque, held)[2]
        return own

    def _substep(self, t: float, q: Vec3, v: Vec3, own: tuple[float, ...], dt: float,
                 torque: TorqueFn) -> tuple[Vec3, Vec3, tuple[float, ...]]:
        """`ExplicitRungeKutta.step` on the flat state: the same stage loop, then the same projection."""
        q, v, own = rk_stage_loop(self._rows, self.system, t, q, v, own, dt, torque, self.actuator)
        qn, vn = project(self.system.params, q, v)
        return qn, vn, own

    @classmethod
    def is_stable(cls, z: complex) -> bool:
        return cls.reference.is_stable(z / cls.substeps)


class _Held(Actuator):
    """The actuator's slots with the linkage held at q, q' = 0: no acceleration, the slots' rates at (q, 0)."""

    name = "held"

    def __init__(self, actuator: Actuator, q: Vec3) -> None:
        self.actuator, self.q = actuator, q

    def initial(self) -> tuple[float, ...]:
        return self.actuator.initial()

    def torque(self, system: FingerSystem, t: float, q: Vec3, v: Vec3, u: float, own: tuple[float, ...]) -> float:
        return self.actuator.torque(system, t, self.q, ZERO, u, own)

    def rates(self, t: float, q: Vec3, v: Vec3, u: float, own: tuple[float, ...]) -> tuple[float, ...]:
        return self.actuator.rates(t, self.q, ZERO, u, own)

    def accelerations(self, system: FingerSystem, t: float, q: Vec3, v: Vec3, u: float,
                      own: tuple[float, ...]) -> Vec3:
        return ZERO
