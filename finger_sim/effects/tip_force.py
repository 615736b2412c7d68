"""A constant force at the fingertip (scene key `tip_force`, (FX, FY) N; zero removes it)."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING, ClassVar

from finger_sim.effects.base import TIP_FORCE, Smooth, Vec3, effect, kernel_law
from finger_sim.effects.parameters import vector
from finger_sim.kinematics import distal_offset
from finger_sim.model import FingerParams

if TYPE_CHECKING:
    from finger_sim.scene import Scene


@dataclass(frozen=True)
class TipForce(Smooth):
    """A constant force F = (FX, FY), N, at the fingertip: Q = J_tipᵀ F, V = −F·tip."""

    fx: float
    fy: float
    params: FingerParams
    alpha: float

    affine_in_velocity: ClassVar[bool] = True
    kernel_code: ClassVar[int] = TIP_FORCE

    def kernel_params(self) -> tuple[float, ...]:
        return (self.fx, self.fy, self.params.r1, self.params.L3, self.alpha)

    def force(self, t: float, q: Vec3, v: Vec3) -> Vec3:
        return tip_force(self.fx, self.fy, self.params.r1, self.params.L3, self.alpha, q[0], q[2])

    def potential(self, q: Vec3) -> float:
        p = self.params
        psi = q[2] + self.alpha
        x = p.r1 * math.cos(q[0]) + p.L3 * math.cos(psi)
        y = p.r1 * math.sin(q[0]) + p.L3 * math.sin(psi)
        return -(self.fx * x + self.fy * y)

    def modal(self, q: Vec3, n: Vec3) -> tuple[float, float]:
        """(0, 0): a constant tip force's geometric stiffness (|F| r1 ≲ 1e-2 N·m for a few N) is
        left out of the stability check, as gravity's is."""
        return (0.0, 0.0)


def tip_force(fx: float, fy: float, r1: float, l3: float, alpha: float, t1: float, t3: float) -> Vec3:
    """Q = J_tipᵀ F, N·m, of a force F = (FX, FY) (N) at the tip r1 e(θ1) + L3 e(θ3 + α) (m, rad):
    the tip force's one law, which the compiled kernel compiles."""
    psi = t3 + alpha
    return (r1 * (-math.sin(t1) * fx + math.cos(t1) * fy), 0.0, l3 * (-math.sin(psi) * fx + math.cos(psi) * fy))


kernel_law(tip_force, ("q0", "q2"), code=TIP_FORCE)


#: Largest component, N.
MAX_TIP_FORCE = 1e4
PARAMETERS = {"tip_force": vector((0.0, 0.0), "N", "constant force (FX, FY) at the fingertip; zero removes it",
                                  bound=MAX_TIP_FORCE)}


@effect("tip_force", "constant force at the fingertip, (FX, FY) N", PARAMETERS)
def build(scene: Scene) -> TipForce | None:
    if not any(scene.tip_force):
        return None
    return TipForce(*scene.tip_force, scene.params, distal_offset(scene.params))
