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

from finger_sim.errors import SimulationDiverged
from finger_sim.integrators.base import Integrator, TorqueFn
from finger_sim.kinematics import Vec3

#: Newton stops when every scaled update is below this: the error left after an update δ
#: is about δ times the finite-difference Jacobian's relative error (~1e-7), i.e. ~1e-17.
NEWTON_TOLERANCE = 1e-10
MAX_NEWTON_ITERATIONS = 12
#: Relative finite-difference step for the Jacobian: ~ sqrt(machine epsilon).
FD_STEP = 1.5e-8
#: With a Jacobian kept from an earlier step, give up and refresh it after this many iterations.
REUSE_ITERATIONS = 4


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
        self._jac: np.ndarray | None = None
        self._jac_dt = 0.0

    def step(self, t: float, q: Vec3, v: Vec3, dt: float, torque: TorqueFn) -> tuple[Vec3, Vec3]:
        s = self.system
        h2 = 0.5 * dt
        m0 = np.array(s.mass_matrix(q))
        m0_inv = np.linalg.inv(m0)
        g0 = np.array(s.constraint_jacobian(q))
        p0 = m0 @ np.array(v)
        kick0 = np.array(s.generalized_force(t, q, v, torque(t)))
        # predictor: the index-1 solution over half a step
        a0, lam0 = s.accelerations(t, q, v, torque(t))
        p_half = m0 @ (np.array(v) + h2 * np.array(a0))
        x = np.concatenate([p_half, np.array(q) + dt * np.array(v) + h2 * dt * np.array(a0), lam0])
        p_scale = max(float(np.max(np.abs(p0))), s.params.m3 * s.params.r1 * s.params.r1 * 1e-3)
        # λ is resolved only to (round-off in p) / (h/2 · |Φ_q|): scale it by what one step's impulse can carry
        lam_scale = max(abs(lam0[0]), abs(lam0[1]), p_scale / (h2 * s.params.r1))
        scale = np.array([p_scale] * 3 + [1.0] * 3 + [lam_scale] * 2)

        def residual(x: np.ndarray) -> np.ndarray:
            ph, q1, lam = x[:3], x[3:6], x[6:]
            v_a = m0_inv @ ph
            q1t = (float(q1[0]), float(q1[1]), float(q1[2]))
            v_b = np.linalg.solve(np.array(s.mass_matrix(q1t)), ph)
            return np.concatenate(
                [
                    ph - p0 - h2 * (kick0 - self._h_q(q, v_a) + g0.T @ lam),
                    q1 - np.array(q) - h2 * (v_a + v_b),
                    s.constraint(q1t),
                ]
            )

        x = self._newton(residual, x, scale, dt)
        if x is None:
            raise SimulationDiverged(f"rattle: Newton did not converge at t = {t:.6f} s (dt = {dt} s)")
        p_half, q1 = x[:3], (float(x[3]), float(x[4]), float(x[5]))
        # second half: linear in (v₁, μ) since Q is affine in q'
        t1 = t + dt
        tau1 = torque(t1)
        zero = (0.0, 0.0, 0.0)
        f0 = np.array(s.generalized_force(t1, q1, zero, tau1))
        damping = np.column_stack(
            [np.array(s.generalized_force(t1, q1, e, tau1)) - f0 for e in ((1.0, 0.0, 0.0), (0.0, 1.0, 0.0), (0.0, 0.0, 1.0))]
        )
        m1 = np.array(s.mass_matrix(q1))
        g1 = np.array(s.constraint_jacobian(q1))
        rhs = p_half + h2 * (f0 - self._h_q(q1, np.linalg.solve(m1, p_half)))
        kkt = np.zeros((5, 5))
        kkt[:3, :3] = m1 - h2 * damping
        kkt[:3, 3:] = -h2 * g1.T
        kkt[3:, :3] = g1
        sol = np.linalg.solve(kkt, np.concatenate([rhs, [0.0, 0.0]]))
        v1 = (float(sol[0]), float(sol[1]), float(sol[2]))
        if not all(math.isfinite(c) for c in q1 + v1):
            raise SimulationDiverged(f"rattle: non-finite state at t = {t1:.6f} s")
        return q1, v1

    def _newton(self, residual, x: np.ndarray, scale: np.ndarray, dt: float) -> np.ndarray | None:  # type: ignore[no-untyped-def]
        """Simplified Newton: the Jacobian of an earlier step is reused while it still converges fast."""
        fresh = self._jac is None or self._jac_dt != dt
        for attempt in range(2):
            if fresh:
                self._jac, self._jac_dt = self._jacobian(residual, x, scale), dt
            xk = x
            for k in range(MAX_NEWTON_ITERATIONS if fresh else REUSE_ITERATIONS):
                dx = np.linalg.solve(self._jac, -residual(xk))
                xk = xk + dx
                if np.max(np.abs(dx) / scale) < NEWTON_TOLERANCE:
                    return xk
            fresh = True
        return None

    def _h_q(self, q: Vec3 | np.ndarray, v: np.ndarray) -> np.ndarray:
        """∂H/∂q at fixed p, = −½ vᵀ (∂M/∂q) v; only M13 = c cos(θ1 − θ3 − α) depends on q."""
        s = self.system
        u = float(q[0]) - float(q[2]) - s.alpha
        w = s._c * math.sin(u) * float(v[0]) * float(v[2])  # −½·2·v1 v3 ∂M13/∂θ1, ∂M13/∂θ1 = −c sin u
        return np.array([w, 0.0, -w])

    @staticmethod
    def _jacobian(residual, x: np.ndarray, scale: np.ndarray) -> np.ndarray:  # type: ignore[no-untyped-def]
        r0 = residual(x)
        jac = np.empty((x.size, x.size))
        for j in range(x.size):
            dxj = FD_STEP * max(abs(x[j]), scale[j])
            xp = x.copy()
            xp[j] += dxj
            jac[:, j] = (residual(xp) - r0) / dxj
        return jac

    @classmethod
    def is_stable(cls, z: complex) -> bool:
        # Störmer-Verlet on an undamped oscillator: stable for ω·dt < 2.
        return abs(z) < 2.0
