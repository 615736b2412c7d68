"""The inductive drive's Runge–Kutta step in the compiled kernel (`kernel.drive.inductive_step_tuple`):
`actuators.inductive.InductiveRungeKutta` with its substeps in one call, same numbers."""

from __future__ import annotations

import numpy as np

from finger_sim.actuators.drive import DrivenSystem
from finger_sim.actuators.inductive import InductiveRungeKutta
from finger_sim.integrators.base import TorqueFn
from finger_sim.kernel import drive as kernel_drive
from finger_sim.kernel.integrators import check_status
from finger_sim.kernel.layout import model_array, tableau_array
from finger_sim.kinematics import Vec3


class CompiledInductiveRungeKutta(InductiveRungeKutta):
    """`InductiveRungeKutta` in the compiled kernel (`kernel.drive.inductive_step_tuple`), same numbers."""

    def __init__(self, system: DrivenSystem) -> None:  # type: ignore[override]
        super().__init__(system)
        ref = self.reference
        self.model = model_array(system)
        self.tableau = tableau_array(ref.A, ref.B, ref.C)
        self.nodes = tuple(dict.fromkeys(float(x) for x in ref.C))
        self._kernel = kernel_drive.inductive_step_tuple
        self._numerics = kernel_drive.numerics

    def advance_state(self, t: float, q: Vec3, v: Vec3, own: tuple[float, ...], dt: float, torque: TorqueFn,
                      n: int) -> tuple[Vec3, Vec3, tuple[float, ...]]:
        h = dt / n
        nodes = self.nodes
        taus = np.array([torque(tk + c * h) for tk in [t + k * h for k in range(n)] for c in nodes]).reshape(n, len(nodes))
        status, q1, v1, i1 = self._kernel(self.model, self.tableau, t, q, v, own[0], dt, n, taus)
        if status != self._numerics.OK:
            check_status(status, self.name, t, q)
        return q1, v1, (i1,)
