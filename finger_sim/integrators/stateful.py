"""An explicit Runge-Kutta method on the declared flat state (q, q', the actuator's own slots).

The tableau is the scene's method's (`ExplicitRungeKutta`: rk4, rk6, dop8); the stages carry the whole
flat state (`state_layout`), q' and q'' from the actuator (`actuators.base.Actuator.accelerations`)
and its slots' rates (`Actuator.rates`); after the step (q, q') are projected onto the constraints as
`ExplicitRungeKutta.step` does, with the same operations in the same order on q and q'.

The Simulator's events (trial steps, location, substeps) pass (q, q') alone; the integrator keeps the
own slots of the states it produced (`own_of`, by the identity of the q and q' objects), so each trial
continues a state with its own slots, and `begin` tells it the slots of a state it did not produce.
"""

from __future__ import annotations

from collections import deque
from typing import ClassVar

from finger_sim.actuators.base import Actuator
from finger_sim.dynamics import FingerSystem
from finger_sim.errors import ConfigError
from finger_sim.integrators.base import Integrator, TorqueFn
from finger_sim.integrators.explicit import ExplicitRungeKutta
from finger_sim.kinematics import Vec3
from finger_sim.projection import project

ZERO: Vec3 = (0.0, 0.0, 0.0)
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
        self._stages = tuple(
            (c, tuple((j, a) for j, a in enumerate(row) if a != 0.0)) for c, row in zip(ref.C, ref.A)
        )
        self._weights = tuple((j, b) for j, b in enumerate(ref.B) if b != 0.0)
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
        stop): the same tableau and substeps on the slots alone, their rates at (q, 0)."""
        h = dt / self.substeps
        rates = self.actuator.rates
        for k in range(self.substeps):
            s = t + k * h
            ko: list[tuple[float, ...]] = []
            for c, row in self._stages:
                xo = own
                for j, a in row:
                    xo = tuple([x + h * a * r for x, r in zip(xo, ko[j])])
                ts = s + c * h
                ko.append(rates(ts, q, ZERO, torque(ts), xo))
            for j, b in self._weights:
                own = tuple([x + h * b * r for x, r in zip(own, ko[j])])
        return own

    def _substep(self, t: float, q: Vec3, v: Vec3, own: tuple[float, ...], dt: float,
                 torque: TorqueFn) -> tuple[Vec3, Vec3, tuple[float, ...]]:
        """`ExplicitRungeKutta.step` on the flat state (q and q' with the same operations in the same order)."""
        system = self.system
        actuator = self.actuator
        kq: list[Vec3] = []  # stage velocities: dq/dt
        kv: list[Vec3] = []  # stage accelerations: dv/dt
        ko: list[tuple[float, ...]] = []  # stage rates of the own slots
        q0, q1, q2 = q
        v0, v1, v2 = v
        for c, row in self._stages:
            x0, x1, x2, w0, w1, w2, xo = q0, q1, q2, v0, v1, v2, own
            for j, a in row:
                ha = dt * a
                dq, dv = kq[j], kv[j]
                x0 += ha * dq[0]
                x1 += ha * dq[1]
                x2 += ha * dq[2]
                w0 += ha * dv[0]
                w1 += ha * dv[1]
                w2 += ha * dv[2]
                xo = tuple([x + ha * k for x, k in zip(xo, ko[j])])
            ts = t + c * dt
            u = torque(ts)
            kq.append((w0, w1, w2))
            kv.append(actuator.accelerations(system, ts, (x0, x1, x2), (w0, w1, w2), u, xo))
            ko.append(actuator.rates(ts, (x0, x1, x2), (w0, w1, w2), u, xo))
        for j, b in self._weights:
            hb = dt * b
            dq, dv = kq[j], kv[j]
            q0 += hb * dq[0]
            q1 += hb * dq[1]
            q2 += hb * dq[2]
            v0 += hb * dv[0]
            v1 += hb * dv[1]
            v2 += hb * dv[2]
            own = tuple([x + hb * k for x, k in zip(own, ko[j])])
        qn, vn = project(self.system.params, (q0, q1, q2), (v0, v1, v2))
        return qn, vn, own

    @classmethod
    def is_stable(cls, z: complex) -> bool:
        return cls.reference.is_stable(z / cls.substeps)
