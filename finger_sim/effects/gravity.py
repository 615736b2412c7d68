"""Gravity in the model plane (scene key `gravity`, (gX, gY) m/s²; zero removes it). Spec §2-3."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING, ClassVar

from finger_sim.effects.base import GRAVITY, Smooth, Vec3, effect, kernel_law
from finger_sim.effects.parameters import vector
from finger_sim.kinematics import distal_offset
from finger_sim.model import FingerParams

if TYPE_CHECKING:
    from finger_sim.scene import Scene


@dataclass(frozen=True)
class Gravity(Smooth):
    """Uniform gravity g = (gX, gY) in the model plane, m/s², on the centres of mass of spec §2."""

    gx: float
    gy: float
    params: FingerParams
    alpha: float

    affine_in_velocity: ClassVar[bool] = True
    kernel_code: ClassVar[int] = GRAVITY

    def kernel_params(self) -> tuple[float, ...]:
        """(gX, gY, w1, w2, w3, α): `gravity_force`'s parameters."""
        p = self.params
        return (self.gx, self.gy, p.m1 * p.r1 / 2.0 + p.m3 * p.r1, p.m2 * p.r2 / 2.0, p.m3 * p.L3 / 2.0, self.alpha)

    def force(self, t: float, q: Vec3, v: Vec3) -> Vec3:
        return gravity_force(*self.kernel_params(), q[0], q[1], q[2])

    def potential(self, q: Vec3) -> float:
        p = self.params
        psi = q[2] + self.alpha
        dx, dy = -p.r4 * math.cos(p.theta4), -p.r4 * math.sin(p.theta4)
        g1 = (p.r1 / 2.0 * math.cos(q[0]), p.r1 / 2.0 * math.sin(q[0]))
        g2 = (dx + p.r2 / 2.0 * math.cos(q[1]), dy + p.r2 / 2.0 * math.sin(q[1]))
        g3 = (
            p.r1 * math.cos(q[0]) + p.L3 / 2.0 * math.cos(psi),
            p.r1 * math.sin(q[0]) + p.L3 / 2.0 * math.sin(psi),
        )
        return -sum(m * (r[0] * self.gx + r[1] * self.gy) for m, r in ((p.m1, g1), (p.m2, g2), (p.m3, g3)))

    def modal(self, q: Vec3, n: Vec3) -> tuple[float, float]:
        """(0, 0): gravity's stiffness, m g r ≈ 1e-4 N·m at 9.81 m/s², is a pendulum mode far
        slower than any step; the stability check leaves it out."""
        return (0.0, 0.0)


def gravity_force(gx: float, gy: float, w1: float, w2: float, w3: float, alpha: float,
                  t1: float, t2: float, t3: float) -> Vec3:
    """Q_i = Σ m_j (∂r_Gj/∂q_i)·g, N·m, with ∂e(a)/∂a = (−sin a, cos a): gravity's one law, which the
    compiled kernel compiles. g in m/s²; weights w (kg·m): m1 r1/2 + m3 r1, m2 r2/2, m3 L3/2; rad."""
    psi = t3 + alpha
    return (
        w1 * (-math.sin(t1) * gx + math.cos(t1) * gy),
        w2 * (-math.sin(t2) * gx + math.cos(t2) * gy),
        w3 * (-math.sin(psi) * gx + math.cos(psi) * gy),
    )


kernel_law(gravity_force, ("q0", "q1", "q2"), code=GRAVITY)


#: Largest component, m/s² (~1000 g).
MAX_GRAVITY = 1e4
PARAMETERS = {"gravity": vector((0.0, 0.0), "m/s²", "uniform gravity (gX, gY) in the model plane; zero removes it",
                                bound=MAX_GRAVITY)}


@effect("gravity", "uniform gravity in the model plane, (gX, gY) m/s²", PARAMETERS)
def build(scene: Scene) -> Gravity | None:
    if not any(scene.gravity):
        return None
    return Gravity(*scene.gravity, scene.params, distal_offset(scene.params))
