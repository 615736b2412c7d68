"""Generalized RATTLE: symplectic, constraint-preserving, for long runs.

Hairer, Lubich & Wanner, *Geometric Numerical Integration*, §VII.1.4 (the 2-stage
Lobatto IIIA-IIIB pair) for H(q, p) = ½ pᵀ M(q)⁻¹ p with a q-dependent mass matrix,
the applied forces Q entering as kicks at both ends of the step:

    p½  = p₀ + h/2 (Q(t₀, q₀, v₀) − H_q(q₀, p½) + Φ_q(q₀)ᵀ λ)
    q₁  = q₀ + h/2 (M(q₀)⁻¹ + M(q₁)⁻¹) p½,            Φ(q₁) = 0
    p₁  = p½ + h/2 (Q(t₁, q₁, v₁) − H_q(q₁, p½) + Φ_q(q₁)ᵀ μ),  Φ_q(q₁) v₁ = 0

with H_q = −½ vᵀ M_q v. The first half is an 8×8 nonlinear system (Newton, finite-
difference Jacobian); the second is linear in (v₁, μ) because every force element is
affine in q'. Order 2; Φ = 0 to the Newton tolerance; with τ = 0 and no damping the
energy error stays bounded and does not drift. Cost: about 15-25 acceleration-solve
equivalents per step.
"""

from __future__ import annotations

import math

import numpy as np
from scipy.linalg import lu_factor, lu_solve

from finger_sim.errors import SimulationDiverged
from finger_sim.integrators.base import Integrator, TorqueFn
from finger_sim.kinematics import Vec3

#: Newton stops when every scaled update is below this: the error left after an update δ
#: is about δ times the finite-difference Jacobian's relative error (~1e-7), i.e. ~1e-17.
NEWTON_TOLERANCE = 1e-10
MAX_NEWTON_ITERATIONS = 12
#: Relative finite-difference step for the Jacobian: ~ sqrt(machine epsilon).
FD_STEP = 1.5e-8
#: With a Jacobian kept from an earlier step, give up and refresh it after this many
#: iterations: one costs ~1/6 of a fresh Jacobian, and at 5 ms steps on a fast swing an
#: old Jacobian contracts by only ~0.03 per iteration.
REUSE_ITERATIONS = 8
#: A Jacobian is reused for steps whose length differs by less than this, relatively.
JAC_REUSE_RTOL = 1e-6


class Rattle(Integrator):
    """Generalized RATTLE (Lobatto IIIA-IIIB): order 2, symplectic, Φ = 0 to round-off; for long runs.

    Cost per step: one 8×8 Newton solve (finite-difference Jacobian) and one 5×5 linear solve.
    """

    name = "rattle"
    order = 2
    keeps_constraints = True
    implicit = True

    def __init__(self, system) -> None:  # type: ignore[no-untyped-def]
        super().__init__(system)
        self._lu: tuple[np.ndarray, np.ndarray] | None = None
        self._jac_dt = 0.0

    def step(self, t: float, q: Vec3, v: Vec3, dt: float, torque: TorqueFn) -> tuple[Vec3, Vec3]:
        s = self.system
        h2 = 0.5 * dt
        tau0 = torque(t)
        m0 = s.mass_matrix(q)
        p0 = tuple(m0[i][0] * v[0] + m0[i][1] * v[1] + m0[i][2] * v[2] for i in range(3))
        k0 = s.generalized_force(t, q, v, tau0)
        g01, g02 = s.constraint_jacobian(q)
        # predictor: the index-1 solution over half a step
        a0, lam0 = s.accelerations(t, q, v, tau0)
        vh = tuple(v[i] + h2 * a0[i] for i in range(3))
        x = [
            *(m0[i][0] * vh[0] + m0[i][1] * vh[1] + m0[i][2] * vh[2] for i in range(3)),
            *(q[i] + dt * v[i] + h2 * dt * a0[i] for i in range(3)),
            *lam0,
        ]
        p_scale = max(max(abs(c) for c in p0), s.params.m3 * s.params.r1 * s.params.r1 * 1e-3)
        # λ is resolved only to (round-off in p) / (h/2 · |Φ_q|): scale it by what one step's impulse can carry
        lam_scale = max(abs(lam0[0]), abs(lam0[1]), p_scale / (h2 * s.params.r1))
        scale = np.array([p_scale] * 3 + [1.0] * 3 + [lam_scale] * 2)

        def residual(x: list[float]) -> list[float]:
            ph = (x[0], x[1], x[2])
            q1 = (x[3], x[4], x[5])
            va, vb = s.mass_solve(q, ph), s.mass_solve(q1, ph)
            dt0 = s.kinetic_gradient(q, va)  # −H_q at (q₀, p½)
            return [
                *(ph[i] - p0[i] - h2 * (k0[i] + dt0[i] + g01[i] * x[6] + g02[i] * x[7]) for i in range(3)),
                *(q1[i] - q[i] - h2 * (va[i] + vb[i]) for i in range(3)),
                *s.constraint(q1),
            ]

        x = self._newton(residual, x, scale, dt)
        if x is None:
            raise SimulationDiverged(f"rattle: Newton did not converge at t = {t:.6f} s (dt = {dt} s)")
        p_half, q1 = (x[0], x[1], x[2]), (x[3], x[4], x[5])
        # second half: linear in (v₁, μ) since Q is affine in q'
        t1 = t + dt
        tau1 = torque(t1)
        zero = (0.0, 0.0, 0.0)
        f0 = np.array(s.generalized_force(t1, q1, zero, tau1))
        damping = np.column_stack(
            [np.array(s.generalized_force(t1, q1, e, tau1)) - f0 for e in ((1.0, 0.0, 0.0), (0.0, 1.0, 0.0), (0.0, 0.0, 1.0))]
        )
        g1 = np.array(s.constraint_jacobian(q1))
        rhs = np.array(p_half) + h2 * (f0 + np.array(s.kinetic_gradient(q1, s.mass_solve(q1, p_half))))
        kkt = np.zeros((5, 5))
        kkt[:3, :3] = np.array(s.mass_matrix(q1)) - h2 * damping
        kkt[:3, 3:] = -h2 * g1.T
        kkt[3:, :3] = g1
        w1, w2, w3, _, _ = np.linalg.solve(kkt, np.concatenate([rhs, [0.0, 0.0]])).tolist()
        v1 = (w1, w2, w3)
        if not all(math.isfinite(c) for c in q1 + v1):
            raise SimulationDiverged(f"rattle: non-finite state at t = {t1:.6f} s")
        return q1, v1

    def _newton(self, residual, x: list[float], scale: np.ndarray, dt: float) -> list[float] | None:  # type: ignore[no-untyped-def]
        """Simplified Newton: the LU of an earlier step's Jacobian is reused while it still converges fast."""
        # sub-steps (breakpoints, stops) differ from dt in the last bits: compare relatively
        fresh = self._lu is None or abs(self._jac_dt - dt) > JAC_REUSE_RTOL * dt
        for _ in range(2):
            if fresh:
                self._lu, self._jac_dt = lu_factor(self._jacobian(residual, x, scale), check_finite=False), dt
            xk = x
            for _ in range(MAX_NEWTON_ITERATIONS if fresh else REUSE_ITERATIONS):
                dx = lu_solve(self._lu, -np.array(residual(xk)), check_finite=False)
                xk = [a + b for a, b in zip(xk, dx.tolist())]
                if np.max(np.abs(dx) / scale) < NEWTON_TOLERANCE:
                    return xk
            fresh = True
        return None

    @staticmethod
    def _jacobian(residual, x: list[float], scale: np.ndarray) -> np.ndarray:  # type: ignore[no-untyped-def]
        """Forward-difference Jacobian of the 8×8 first-half system."""
        r0 = np.array(residual(x))
        jac = np.empty((len(x), len(x)))
        for j in range(len(x)):
            dxj = FD_STEP * max(abs(x[j]), scale[j])
            xp = list(x)
            xp[j] += dxj
            jac[:, j] = (np.array(residual(xp)) - r0) / dxj
        return jac

    @classmethod
    def is_stable(cls, z: complex) -> bool:
        # Störmer-Verlet on an undamped oscillator: stable for ω·dt < 2.
        return abs(z) < 2.0
