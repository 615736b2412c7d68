"""Error-controlled adaptive integration with scipy: the reference method."""

from __future__ import annotations

import math


from finger_sim.dynamics import FingerSystem
from finger_sim.errors import SimulationDiverged
from finger_sim.integrators.base import Integrator, TorqueFn
from finger_sim.kinematics import Vec3
from finger_sim.projection import project

#: Tolerances of the reference: tight enough that its own error (~1e-12 rad on the
#: paper's run) is far below every fixed-step method's at the rates we compare.
REFERENCE_RTOL = 1e-12
REFERENCE_ATOL = 1e-14


class AdaptiveReference(Integrator):
    """scipy DOP853 (order 8, error-controlled) on the index-1 equations, projected at each step's end.

    Within a step it takes as many internal steps as rtol/atol demand, restarting at
    each step boundary (so torque breakpoints on the grid are honoured); the last
    accepted internal step size seeds the next call. Cost: ~12 acceleration solves per
    internal step plus scipy's per-call overhead (~0.1-1 ms); for references, not real time.
    """

    name = "adaptive"
    order = 8
    keeps_constraints = True

    def __init__(self, system: FingerSystem, *, rtol: float = REFERENCE_RTOL, atol: float = REFERENCE_ATOL,
                 method: str = "DOP853") -> None:
        super().__init__(system)
        self.rtol, self.atol, self.method = rtol, atol, method
        self._h: float | None = None

    def step(self, t: float, q: Vec3, v: Vec3, dt: float, torque: TorqueFn) -> tuple[Vec3, Vec3]:
        from scipy.integrate import solve_ivp  # here: importing scipy.integrate costs ≈ 0.3 s, only this method needs it

        rhs = self.system.rhs
        first = min(self._h, dt) if self._h and dt > 0.0 else None  # dt = 0: an event on the step end
        sol = solve_ivp(lambda s, y: rhs(s, y, torque), (t, t + dt), [*q, *v], method=self.method, rtol=self.rtol, atol=self.atol, first_step=first)
        if not sol.success:
            raise SimulationDiverged(sol.message, method=self.name, t=t)
        if sol.t.size >= 2:
            self._h = float(sol.t[-1] - sol.t[-2])
        t1, t2, t3, w1, w2, w3 = sol.y[:, -1].tolist()
        if not all(math.isfinite(c) for c in (t1, t2, t3, w1, w2, w3)):
            raise SimulationDiverged("non-finite state", method=self.name, t=t + dt)
        return project(self.system.params, (t1, t2, t3), (w1, w2, w3))

    @classmethod
    def is_stable(cls, z: complex) -> bool:
        return True  # error control shrinks the internal step as needed
