"""Force elements: each effect a scene may turn on, present only when the scene has it.

Every element gives its generalized force Q(t, q, q') on q = (θ1, θ2, θ3) in N·m and
the potential energy it stores (J; 0 for non-conservative elements). Spec §3.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from finger_sim.kinematics import Vec3
from finger_sim.model import FingerParams


@dataclass(frozen=True)
class PipSpring:
    """Torsional PIP spring, V = ½ k β², β = θ3 + α − θ1; Q = (kβ, 0, −kβ) (spec §3, energy-consistent sign)."""

    stiffness: float  # N·m/rad
    alpha: float  # rad, distal offset

    def force(self, t: float, q: Vec3, v: Vec3) -> Vec3:
        kb = self.stiffness * (q[2] + self.alpha - q[0])
        return (kb, 0.0, -kb)

    def potential(self, q: Vec3) -> float:
        beta = q[2] + self.alpha - q[0]
        return 0.5 * self.stiffness * beta * beta

    def stiffness_along(self, n: Vec3) -> float:
        """nᵀ K n, N·m: the spring's stiffness along a direction n of q."""
        return self.stiffness * (n[2] - n[0]) ** 2


@dataclass(frozen=True)
class JointDamping:
    """Viscous damping at the MCP, coupler and PIP joints: R = ½ c (θ1'² + θ2'² + β'²)."""

    coefficient: float  # N·m·s/rad

    def force(self, t: float, q: Vec3, v: Vec3) -> Vec3:
        c = self.coefficient
        beta_dot = v[2] - v[0]
        return (-c * v[0] + c * beta_dot, -c * v[1], -c * beta_dot)

    def potential(self, q: Vec3) -> float:
        return 0.0

    def damping_along(self, n: Vec3) -> float:
        """nᵀ C n, N·m·s: the damping along a direction n of q."""
        return self.coefficient * (n[0] ** 2 + n[1] ** 2 + (n[2] - n[0]) ** 2)


@dataclass(frozen=True)
class Gravity:
    """Uniform gravity g = (gX, gY) in the model plane, m/s², on the centres of mass of spec §2."""

    gx: float
    gy: float
    params: FingerParams
    alpha: float

    def force(self, t: float, q: Vec3, v: Vec3) -> Vec3:
        p = self.params
        psi = q[2] + self.alpha
        # Q_i = Σ m_j (∂r_Gj/∂q_i)·g with ∂e(a)/∂a = (−sin a, cos a).
        w1 = p.m1 * p.r1 / 2.0 + p.m3 * p.r1
        w2 = p.m2 * p.r2 / 2.0
        w3 = p.m3 * p.L3 / 2.0
        return (
            w1 * (-math.sin(q[0]) * self.gx + math.cos(q[0]) * self.gy),
            w2 * (-math.sin(q[1]) * self.gx + math.cos(q[1]) * self.gy),
            w3 * (-math.sin(psi) * self.gx + math.cos(psi) * self.gy),
        )

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


@dataclass(frozen=True)
class TipForce:
    """A constant force F = (FX, FY), N, at the fingertip: Q = J_tipᵀ F, V = −F·tip."""

    fx: float
    fy: float
    params: FingerParams
    alpha: float

    def force(self, t: float, q: Vec3, v: Vec3) -> Vec3:
        p = self.params
        psi = q[2] + self.alpha
        return (
            p.r1 * (-math.sin(q[0]) * self.fx + math.cos(q[0]) * self.fy),
            0.0,
            p.L3 * (-math.sin(psi) * self.fx + math.cos(psi) * self.fy),
        )

    def potential(self, q: Vec3) -> float:
        p = self.params
        psi = q[2] + self.alpha
        x = p.r1 * math.cos(q[0]) + p.L3 * math.cos(psi)
        y = p.r1 * math.sin(q[0]) + p.L3 * math.sin(psi)
        return -(self.fx * x + self.fy * y)


ForceElement = PipSpring | JointDamping | Gravity | TipForce
