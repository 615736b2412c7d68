"""Generalized RATTLE: symplectic, constraint-preserving, for long runs.

Hairer, Lubich & Wanner, *Geometric Numerical Integration*, §VII.1.4 (the 2-stage
Lobatto IIIA-IIIB pair) for H(q, p) = ½ pᵀ M(q)⁻¹ p with a q-dependent mass matrix,
the applied forces Q entering as kicks at both ends of the step:

    p½  = p₀ + h/2 (Q(t₀, q₀, v₀) − H_q(q₀, p½) + Φ_q(q₀)ᵀ λ)
    q₁  = q₀ + h/2 (M(q₀)⁻¹ + M(q₁)⁻¹) p½,            Φ(q₁) = 0
    p₁  = p½ + h/2 (Q(t₁, q₁, v₁) − H_q(q₁, p½) + Φ_q(q₁)ᵀ μ),  Φ_q(q₁) v₁ = 0

with H_q = −½ vᵀ M_q v. The first half is an 8×8 nonlinear system (Newton, finite-
difference Jacobian); the second is linear in (v₁, μ) when every force element is
affine in q' (`affine_in_velocity`), and solved by Newton otherwise. Order 2; Φ = 0 to
the Newton tolerance; with τ = 0 and no damping the energy error stays bounded and does
not drift. A step whose Newton iteration fails is retried as two half steps, as radau does. Cost: about 15-25 acceleration-solve
equivalents per step.
"""

from __future__ import annotations

import math

import numpy as np

from finger_sim.dynamics import FingerSystem
from finger_sim.errors import SimulationDiverged
from finger_sim.integrators.base import Integrator, TorqueFn
from finger_sim.integrators.newton import LU, VectorFn, factor, forward_jacobian, simplified_newton
from finger_sim.kinematics import Vec3

#: Newton stops when every scaled update is below this: the error left after an update δ
#: is about δ times the finite-difference Jacobian's relative error (~1e-7), i.e. ~1e-17.
NEWTON_TOLERANCE = 1e-10
MAX_NEWTON_ITERATIONS = 12
#: With a Jacobian kept from an earlier step, give up and refresh it after this many
#: iterations: one costs ~1/6 of a fresh Jacobian, and at 5 ms steps on a fast swing an
#: old Jacobian contracts by only ~0.03 per iteration.
REUSE_ITERATIONS = 8
#: A Jacobian is reused for steps whose length differs by less than this, relatively.
JAC_REUSE_RTOL = 1e-6
#: The momentum scale never drops below that of the distal mass m3 at r1 turning at this
#: rate (rad/s): a finger at rest would otherwise make Newton's scaled test demand round-off.
MOMENTUM_FLOOR_RATE = 1e-3
#: A step whose Newton iteration fails is retried as two half steps, at most this deep.
MAX_HALVINGS = 6
#: What to use instead when rattle cannot step a scene.
ALTERNATIVES = "radau, or a projected explicit method (rk6, dop8) at this dt, steps this scene"


class Rattle(Integrator):
    """Generalized RATTLE (Lobatto IIIA-IIIB): order 2, symplectic, Φ = 0 to round-off; for long runs.

    Cost per step: one 8×8 Newton solve (finite-difference Jacobian) and one 5×5 linear solve.
    """

    name = "rattle"
    order = 2
    keeps_constraints = True
    implicit = True

    def __init__(self, system: FingerSystem) -> None:
        super().__init__(system)
        self._lu: LU | None = None
        self._jac_dt = 0.0
        self._affine = all(e.affine_in_velocity for e in system.elements)

    def step(self, t: float, q: Vec3, v: Vec3, dt: float, torque: TorqueFn) -> tuple[Vec3, Vec3]:
        return self._step(t, q, v, dt, torque, 0)

    def _step(self, t: float, q: Vec3, v: Vec3, dt: float, torque: TorqueFn, depth: int) -> tuple[Vec3, Vec3]:
        result = self._try_step(t, q, v, dt, torque)
        if result is None:  # near a turning point: resolve p½ only to the round-off of the step's impulses
            result = self._try_step(t, q, v, dt, torque, impulse_scale=True)
        if result is not None:
            return result
        if depth >= MAX_HALVINGS:
            raise SimulationDiverged(f"Newton did not converge even at dt/{2 ** depth}", method=self.name, t=t, dt=dt,
                                     hint=ALTERNATIVES)
        half = 0.5 * dt
        qm, vm = self._step(t, q, v, half, torque, depth + 1)
        return self._step(t + half, qm, vm, half, torque, depth + 1)

    def _try_step(self, t: float, q: Vec3, v: Vec3, dt: float, torque: TorqueFn,
                  impulse_scale: bool = False) -> tuple[Vec3, Vec3] | None:
        """One RATTLE step, or None when a Newton iteration does not converge.

        Newton's test scales p½ by |p₀| (with a floor). Where the finger turns (p₀ ≈ 0) while
        the constraint and applied forces stay large, p½ cannot be resolved below the round-off
        of the impulses h/2·(Q + Φ_qᵀλ) that make it up; `impulse_scale` widens the scale to them.
        """
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
        p_scale = max(max(abs(c) for c in p0), s.params.m3 * s.params.r1 * s.params.r1 * MOMENTUM_FLOOR_RATE)
        if impulse_scale:
            impulse = h2 * max(abs(k0[i]) + abs(g01[i] * lam0[0]) + abs(g02[i] * lam0[1]) for i in range(3))
            p_scale = max(p_scale, impulse)
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

        solved = self._newton(residual, x, scale, dt)
        if solved is None:
            return None
        p_half, q1 = (solved[0], solved[1], solved[2]), (solved[3], solved[4], solved[5])
        t1 = t + dt
        v1 = self._second_half(t1, q1, p_half, h2, torque(t1), p_scale)
        if v1 is None:
            return None
        if not all(math.isfinite(c) for c in q1 + v1):
            raise SimulationDiverged("non-finite state", method=self.name, t=t1, dt=dt, hint=ALTERNATIVES)
        return q1, v1

    def _second_half(self, t1: float, q1: Vec3, p_half: Vec3, h2: float, tau1: float, p_scale: float) -> Vec3 | None:
        """v₁ from p₁ = p½ + h/2 (Q(t₁, q₁, v₁) − H_q(q₁, p½) + Φ_q(q₁)ᵀ μ), Φ_q(q₁) v₁ = 0.

        Linear in (v₁, μ) when Q is affine in q' (a 5×5 solve); Newton otherwise (None if it fails).
        """
        s = self.system
        zero = (0.0, 0.0, 0.0)
        g1 = np.array(s.constraint_jacobian(q1))
        kinetic = np.array(s.kinetic_gradient(q1, s.mass_solve(q1, p_half)))
        if self._affine:
            f0 = np.array(s.generalized_force(t1, q1, zero, tau1))
            damping = np.column_stack(
                [np.array(s.generalized_force(t1, q1, e, tau1)) - f0 for e in ((1.0, 0.0, 0.0), (0.0, 1.0, 0.0), (0.0, 0.0, 1.0))]
            )
            rhs = np.array(p_half) + h2 * (f0 + kinetic)
            kkt = np.zeros((5, 5))
            kkt[:3, :3] = np.array(s.mass_matrix(q1)) - h2 * damping
            kkt[:3, 3:] = -h2 * g1.T
            kkt[3:, :3] = g1
            w1, w2, w3, _, _ = np.linalg.solve(kkt, np.concatenate([rhs, [0.0, 0.0]])).tolist()
            return (w1, w2, w3)
        m1 = s.mass_matrix(q1)

        def residual(x: list[float]) -> list[float]:
            v1 = (x[0], x[1], x[2])
            f = s.generalized_force(t1, q1, v1, tau1)
            return [
                *(sum(m1[i][j] * v1[j] for j in range(3)) - p_half[i] - h2 * (f[i] + kinetic[i] + g1[0][i] * x[3] + g1[1][i] * x[4])
                  for i in range(3)),
                *(float(g1[k] @ np.array(v1)) for k in range(2)),
            ]

        guess = [*s.mass_solve(q1, p_half), 0.0, 0.0]
        v_scale = max(max(abs(c) for c in guess), MOMENTUM_FLOOR_RATE)
        mu_scale = p_scale / (h2 * s.params.r1)
        scale = [v_scale] * 3 + [mu_scale] * 2
        lu = factor(forward_jacobian(residual, guess, scale))
        x = simplified_newton(residual, guess, lu, np.array(scale), NEWTON_TOLERANCE, MAX_NEWTON_ITERATIONS)
        return None if x is None else (x[0], x[1], x[2])

    def _newton(self, residual: VectorFn, x: list[float], scale: np.ndarray, dt: float) -> list[float] | None:
        """Simplified Newton: the LU of an earlier step's Jacobian is reused while it still converges fast."""
        # sub-steps (breakpoints, stops) differ from dt in the last bits: compare relatively
        fresh = self._lu is None or abs(self._jac_dt - dt) > JAC_REUSE_RTOL * dt
        for _ in range(2):
            if fresh or self._lu is None:
                self._lu, self._jac_dt = factor(forward_jacobian(residual, x, scale.tolist())), dt
            solved = simplified_newton(residual, x, self._lu, scale, NEWTON_TOLERANCE,
                                       MAX_NEWTON_ITERATIONS if fresh else REUSE_ITERATIONS)
            if solved is not None:
                return solved
            fresh = True
        return None

    @classmethod
    def is_stable(cls, z: complex) -> bool:
        # Störmer-Verlet on an undamped oscillator: stable for ω·dt < 2.
        return abs(z) < 2.0
