"""Radau IIA (3 stages, order 5): the implicit method for stiff scenes.

Hairer & Wanner, *Solving ODEs II*, §IV.5 and §IV.8. Applied at a fixed step to the
index-1 equations y' = f(t, y), y = (q, q'), then projected onto Φ = 0, Φ_q q' = 0.
L-stable: a near-rigid spring whose period is shorter than dt is damped out instead
of blowing up, so the slow motion stays accurate.
"""

from __future__ import annotations

import math

import numpy as np
from scipy.linalg import lu_solve

from finger_sim.errors import SimulationDiverged
from finger_sim.integrators.base import Integrator, TorqueFn
from finger_sim.integrators.newton import LU, factor, forward_jacobian, simplified_newton
from finger_sim.kinematics import Vec3
from finger_sim.projection import project

_S6 = math.sqrt(6.0)
#: Butcher tableau of Radau IIA, order 5 (Hairer & Wanner, Table IV.5.6).
A = np.array(
    [
        [(88 - 7 * _S6) / 360, (296 - 169 * _S6) / 1800, (-2 + 3 * _S6) / 225],
        [(296 + 169 * _S6) / 1800, (88 + 7 * _S6) / 360, (-2 - 3 * _S6) / 225],
        [(16 - _S6) / 36, (16 + _S6) / 36, 1 / 9],
    ]
)
C = np.array([(4 - _S6) / 10, (4 + _S6) / 10, 1.0])
#: Simplified-Newton stop: scaled stage update below this (the error left is ~ its square).
NEWTON_TOLERANCE = 1e-12
MAX_NEWTON_ITERATIONS = 10
#: Newton iterations with a refreshed Jacobian when the simplified iteration fails.
MAX_REFRESHES = 20
#: A step whose Newton iteration fails is retried as two half steps, at most this deep.
MAX_HALVINGS = 6
#: Size of (θ, θ') below which the Jacobian's difference steps and Newton's scale stop shrinking (rad, rad/s).
UNIT_SCALE = (1.0,) * 6


class RadauIIA(Integrator):
    """Radau IIA, 3 stages: order 5, L-stable, projected to Φ = 0; for stiff scenes.

    Cost per step: a finite-difference Jacobian (7 acceleration solves), one 18×18 LU,
    and 3 acceleration solves per simplified-Newton iteration (typically 2-5).
    """

    name = "radau"
    order = 5
    keeps_constraints = True
    implicit = True

    def step(self, t: float, q: Vec3, v: Vec3, dt: float, torque: TorqueFn) -> tuple[Vec3, Vec3]:
        return self._step(t, q, v, dt, torque, 0)

    def _step(self, t: float, q: Vec3, v: Vec3, dt: float, torque: TorqueFn, depth: int) -> tuple[Vec3, Vec3]:
        y = [*q, *v]
        result = self._solve_stages(t, y, dt, torque)
        if result is None:
            if depth >= MAX_HALVINGS:
                raise SimulationDiverged(f"Newton did not converge even at dt = {dt:.3g} s", method=self.name, t=t)
            half = 0.5 * dt
            qm, vm = self._step(t, q, v, half, torque, depth + 1)
            return self._step(t + half, qm, vm, half, torque, depth + 1)
        t1, t2, t3, w1, w2, w3 = (a + b for a, b in zip(y, result))
        return project(self.system.params, (t1, t2, t3), (w1, w2, w3))

    def _solve_stages(self, t: float, y: list[float], dt: float, torque: TorqueFn) -> list[float] | None:
        """Last stage increment Z₃ = y₁ − y₀ (stiffly accurate), or None when Newton fails.

        Simplified Newton on the Jacobian at y₀; if that fails, Newton with the Jacobian refreshed
        at the last stage's iterate every iteration (up to MAX_REFRESHES): a force steep in q' (the
        regularized friction's tanh(v_t/v_s) in the stick phase) has its slope where the stages
        end, not where the step starts.
        """
        rhs = self.system.rhs
        f0 = np.array(rhs(t, y, torque))
        y0 = np.array(y)
        times = t + C * dt

        def residual(z: np.ndarray) -> np.ndarray:
            stages = z.reshape(3, 6)
            f = np.array([rhs(ts, (y0 + zi).tolist(), torque) for ts, zi in zip(times, stages)])
            return (stages - dt * (A @ f)).ravel()

        def newton_matrix(at: list[float], f_at: np.ndarray | None) -> LU:
            jac = forward_jacobian(lambda yp: rhs(t, yp, torque), at, UNIT_SCALE, f_at)
            return factor(np.eye(18) - dt * np.kron(A, jac))

        guess = np.outer(C * dt, f0).ravel()  # explicit guess: Z_i ≈ c_i h f(y₀)
        scale = np.tile(np.maximum(np.abs(y0), 1.0), 3)
        z = simplified_newton(residual, guess, newton_matrix(y, f0), scale, NEWTON_TOLERANCE, MAX_NEWTON_ITERATIONS,
                              stop_when_growing=True)
        if z is None:  # full Newton: the Jacobian refreshed at the last stage's iterate each iteration
            z = guess
            for _ in range(MAX_REFRESHES):
                dz = lu_solve(newton_matrix((y0 + z[12:]).tolist(), None), -residual(z), check_finite=False)
                z = z + dz
                size = float(np.max(np.abs(dz) / scale))
                if not math.isfinite(size):
                    return None
                if size < NEWTON_TOLERANCE:
                    break
            else:
                return None
        return z[12:].tolist()

    @classmethod
    def is_stable(cls, z: complex) -> bool:
        return True  # A-stable (and L-stable)
