"""Constrained Lagrange dynamics of the finger: M(q) q'' + h = Q + Φ_qᵀ λ, Φ(q) = 0.

Spec §2-4 (the paper's equations 4-5). `FingerSystem.accelerations` solves the
index-1 form for (q'', λ) by a Schur complement: M is block-sparse (θ2 decouples),
so M⁻¹ is closed form and λ needs one 2×2 SPD solve. All scalar `math`: this is the
hot path of every integrator.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Hashable, Sequence
from typing import TYPE_CHECKING

from finger_sim.effects.base import ForceElement
from finger_sim.kinematics import Vec3, constraint, distal_offset
from finger_sim.model import FingerParams
from finger_sim.state_layout import OwnModes

if TYPE_CHECKING:
    from finger_sim.actuators.base import Actuator


class FingerSystem:
    """The finger's equations of motion with a fixed set of force elements.

    Immutable after construction. The motor torque τ (N·m, on link 1) is an input
    to each call, not an element, so a held command and a scripted profile share
    one path. `actuator`: one whose force a subclass applies inside the acceleration solve
    (the drive's mesh, `actuators.drive.DrivenSystem`); None: the ideal torque source.
    """

    def __init__(self, params: FingerParams, elements: Sequence[ForceElement] = (),
                 actuator: Actuator | None = None) -> None:
        self.params = params
        self.elements = tuple(elements)
        self.actuator = actuator
        #: the elements and the actuator whose laws read their own modes (`state_layout.OwnModes`), in order
        self.mode_owners: tuple[OwnModes, ...] = tuple(o for o in (*self.elements, actuator) if isinstance(o, OwnModes))
        self.alpha = distal_offset(params)
        p = params
        self._m11 = p.inertia_A + p.m3 * p.r1**2
        self._m22 = p.inertia_D
        self._m33 = p.inertia_G3 + p.m3 * p.L3**2 / 4.0
        self._c = p.m3 * p.r1 * p.L3 / 2.0
        self._r = (p.r1, p.r2, p.r3)
        self._forces = tuple(e.force for e in self.elements)

    def mode_key(self) -> list[Hashable]:
        """The mode keys of `mode_owners` (`OwnModes.mode_key`), in order: the equations this system
        integrates change exactly when this does."""
        return [o.mode_key() for o in self.mode_owners]

    # -- constraint geometry ----------------------------------------------------------
    def constraint(self, q: Vec3) -> tuple[float, float]:
        """Φ(q), m (equations 2-3)."""
        return constraint(self.params, q)

    def constraint_jacobian(self, q: Vec3) -> tuple[Vec3, Vec3]:
        """Φ_q(q) as two rows, m/rad."""
        r1, r2, r3 = self._r
        s1, s2, s3 = math.sin(q[0]), math.sin(q[1]), math.sin(q[2])
        c1, c2, c3 = math.cos(q[0]), math.cos(q[1]), math.cos(q[2])
        return ((-r1 * s1, r2 * s2, r3 * s3), (r1 * c1, -r2 * c2, -r3 * c3))

    def mass_matrix(self, q: Vec3) -> tuple[Vec3, Vec3, Vec3]:
        """M(q), kg·m² (spec §2)."""
        b = self._c * math.cos(q[0] - q[2] - self.alpha)
        return ((self._m11, 0.0, b), (0.0, self._m22, 0.0), (b, 0.0, self._m33))

    def generalized_force(self, t: float, q: Vec3, v: Vec3, tau: float) -> Vec3:
        """Q = (τ, 0, 0) + Σ elements, N·m."""
        f1, f2, f3 = tau, 0.0, 0.0
        for force in self._forces:
            e1, e2, e3 = force(t, q, v)
            f1 += e1
            f2 += e2
            f3 += e3
        return (f1, f2, f3)

    # -- the hot path ------------------------------------------------------------------
    def accelerations(self, t: float, q: Vec3, v: Vec3, tau: float) -> tuple[Vec3, tuple[float, float]]:
        """(q'', λ) of the index-1 system [M −Φ_qᵀ; Φ_q 0][q''; λ] = [Q − h; γ] (spec §4).

        q in rad, v in rad/s, τ in N·m; q'' in rad/s², λ in N (per unit constraint, m).
        """
        f1, f2, f3 = tau, 0.0, 0.0
        for force in self._forces:
            e1, e2, e3 = force(t, q, v)
            f1 += e1
            f2 += e2
            f3 += e3
        a1, a2, a3, lam1, lam2 = schur_solve(self._m11, self._m22, self._m33, self._c, *self._r,
                                             *trig(q[0], q[1], q[2], self.alpha), *v, f1, f2, f3)
        return (a1, a2, a3), (lam1, lam2)

    def mass_solve(self, q: Vec3, p: Vec3) -> Vec3:
        """M(q)⁻¹ p in closed form (θ2 decouples, the (1,3) block is 2×2): velocities from momenta."""
        b = self._c * math.cos(q[0] - q[2] - self.alpha)
        det = self._m11 * self._m33 - b * b
        return ((self._m33 * p[0] - b * p[2]) / det, p[1] / self._m22, (self._m11 * p[2] - b * p[0]) / det)

    def kinetic_gradient(self, q: Vec3, v: Vec3) -> Vec3:
        """∂T/∂q at fixed q', J/rad: only M13 = c cos(θ1 − θ3 − α) depends on q."""
        w = self._c * math.sin(q[0] - q[2] - self.alpha) * v[0] * v[2]
        return (-w, 0.0, w)

    def rhs(self, t: float, y: Sequence[float], torque: Callable[[float], float]) -> list[float]:
        """The first-order form y' = f(t, y), y = (θ1, θ2, θ3, θ1', θ2', θ3') (rad, rad/s), under a
        motor torque τ(t) (N·m): [q', q''] as six floats. The one right-hand side every
        first-order solver (adaptive, radau, the bench's peers and reference) calls."""
        q, v = (y[0], y[1], y[2]), (y[3], y[4], y[5])
        return [*v, *self.accelerations(t, q, v, torque(t))[0]]

    # -- energy ------------------------------------------------------------------------
    def kinetic_energy(self, q: Vec3, v: Vec3) -> float:
        """T = ½ q'ᵀ M q', J."""
        b = self._c * math.cos(q[0] - q[2] - self.alpha)
        return 0.5 * (self._m11 * v[0] ** 2 + self._m22 * v[1] ** 2 + self._m33 * v[2] ** 2) + b * v[0] * v[2]

    def potential_energy(self, q: Vec3) -> float:
        """Σ V of the conservative elements, J."""
        return sum(e.potential(q) for e in self.elements)

    def energy(self, q: Vec3, v: Vec3) -> float:
        """T + V, J: conserved when τ = 0 and no damping acts."""
        return self.kinetic_energy(q, v) + self.potential_energy(q)


def trig(t1: float, t2: float, t3: float, alpha: float) -> tuple[float, float, float, float, float, float, float, float]:
    """(sin θ1, cos θ1, sin θ2, cos θ2, sin θ3, cos θ3, sin u, cos u), u = θ1 − θ3 − α: what `schur_solve` reads."""
    u = t1 - t3 - alpha
    return math.sin(t1), math.cos(t1), math.sin(t2), math.cos(t2), math.sin(t3), math.cos(t3), math.sin(u), math.cos(u)


def schur_solve(m11: float, m22: float, m33: float, cc: float, r1: float, r2: float, r3: float,
                s1: float, c1: float, s2: float, c2: float, s3: float, c3: float, su: float, cu: float,
                w1: float, w2: float, w3: float, f1: float, f2: float, f3: float) -> tuple[float, float, float, float, float]:
    """(θ1'', θ2'', θ3'', λ1, λ2) of [M −Φ_qᵀ; Φ_q 0][q''; λ] = [Q − h; γ] (spec §4), by a Schur complement.

    The one definition of the solve: `FingerSystem.accelerations` calls it plainly, and the compiled
    kernel compiles it (`finger_sim.kernel.numerics.accelerations`). M's constant entries m11, m22,
    m33 (kg·m²) and M13's amplitude cc (kg·m², M13 = cc cos(θ1 − θ3 − α)); link lengths r (m);
    the sines and cosines of θ1, θ2, θ3 and u = θ1 − θ3 − α (`trig`: a caller that needs them too,
    as the drive's reflected inertia does, computes them once); q' (rad/s); Q = (f1, f2, f3), N·m.
    q'' in rad/s², λ in N.
    """
    # f = Q − h
    f1 -= cc * su * w3 * w3
    f3 += cc * su * w1 * w1
    # M⁻¹: the (1,3) block is 2×2, θ2 is decoupled.
    b = cc * cu
    det = m11 * m33 - b * b
    i11, i13, i33 = m33 / det, -b / det, m11 / det
    i22 = 1.0 / m22
    x1, x2, x3 = i11 * f1 + i13 * f3, i22 * f2, i13 * f1 + i33 * f3
    # rows of Φ_q and y_i = M⁻¹ g_i
    g11, g12, g13 = -r1 * s1, r2 * s2, r3 * s3
    g21, g22, g23 = r1 * c1, -r2 * c2, -r3 * c3
    y11, y12, y13 = i11 * g11 + i13 * g13, i22 * g12, i13 * g11 + i33 * g13
    y21, y22, y23 = i11 * g21 + i13 * g23, i22 * g22, i13 * g21 + i33 * g23
    # W = Φ_q M⁻¹ Φ_qᵀ, rhs = γ − Φ_q x
    a11 = g11 * y11 + g12 * y12 + g13 * y13
    a12 = g11 * y21 + g12 * y22 + g13 * y23
    a22 = g21 * y21 + g22 * y22 + g23 * y23
    gam1 = r1 * c1 * w1 * w1 - r2 * c2 * w2 * w2 - r3 * c3 * w3 * w3
    gam2 = r1 * s1 * w1 * w1 - r2 * s2 * w2 * w2 - r3 * s3 * w3 * w3
    b1 = gam1 - (g11 * x1 + g12 * x2 + g13 * x3)
    b2 = gam2 - (g21 * x1 + g22 * x2 + g23 * x3)
    dw = a11 * a22 - a12 * a12
    lam1 = (a22 * b1 - a12 * b2) / dw
    lam2 = (a11 * b2 - a12 * b1) / dw
    return x1 + lam1 * y11 + lam2 * y21, x2 + lam1 * y12 + lam2 * y22, x3 + lam1 * y13 + lam2 * y23, lam1, lam2
