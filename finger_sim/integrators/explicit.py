"""Explicit fixed-step methods: the paper's Euler baseline and projected Runge-Kutta."""

from __future__ import annotations

import cmath
from typing import TYPE_CHECKING, ClassVar

from finger_sim.dynamics import FingerSystem
from finger_sim.integrators.base import STABILITY_SLACK, Integrator, TorqueFn
from finger_sim.kinematics import Vec3
from finger_sim.projection import project

if TYPE_CHECKING:
    from finger_sim.actuators.base import Actuator

#: A tableau as the stage loop takes it: per stage (c, the non-zero (j, a_j) of its row), then the
#: weights as a last row (None, the non-zero (j, b_j)): the step's result, combined as a stage is.
Rows = tuple[tuple[float | None, tuple[tuple[int, float], ...]], ...]


def tableau_rows(a: tuple[tuple[float, ...], ...], b: tuple[float, ...], c: tuple[float, ...]) -> Rows:
    """The rows of a Butcher tableau (A, B, C) for `rk_stage_loop`, zero entries left out (the loop then
    skips nothing)."""
    stages = tuple((ci, tuple((j, x) for j, x in enumerate(row) if x != 0.0)) for ci, row in zip(c, a))
    return (*stages, (None, tuple((j, x) for j, x in enumerate(b) if x != 0.0)))


def rk_stage_loop(rows: Rows, system: FingerSystem, t: float, q: Vec3, v: Vec3, own: tuple[float, ...], dt: float,
                  torque: TorqueFn, actuator: Actuator | None = None) -> tuple[Vec3, Vec3, tuple[float, ...]]:
    """One explicit Runge-Kutta step of (q, q', own) from t to t + dt (s), before any projection: the one
    stage loop of `ExplicitRungeKutta` and `integrators.stateful.StatefulRungeKutta` (as scipy's `rk_step`).

    rows: `tableau_rows`. Each row combines the stages before it, x + dt Σ a_j k_j; a stage row then
    evaluates its stage there, the last row (the weights) is the result. Without an actuator q'' is the
    system's under the torque τ(s) on θ1 and `own` is empty; with one, q'' and the rates of its own slots
    `own` come from it (`actuators.base.Actuator`) under the input u(s) = torque(s). q and q' take the
    same operations in the same order either way."""
    acc = system.accelerations
    kq: list[Vec3] = []  # stage velocities: dq/dt
    kv: list[Vec3] = []  # stage accelerations: dv/dt
    ko: list[tuple[float, ...]] = []  # stage rates of the own slots
    q0, q1, q2 = q
    v0, v1, v2 = v
    for c, row in rows:
        x0, x1, x2, w0, w1, w2, xo = q0, q1, q2, v0, v1, v2, own
        for j, a in row:
            ha = dt * a
            dq, dv = kq[j], kv[j]
            x0 += ha * dq[0]
            x1 += ha * dq[1]
            x2 += ha * dq[2]
            w0 += ha * dv[0]
            w1 += ha * dv[1]
            w2 += ha * dv[2]
            if own:
                xo = tuple([x + ha * k for x, k in zip(xo, ko[j])])
        if c is None:  # the weights' row: the step's end
            return (x0, x1, x2), (w0, w1, w2), xo
        ts = t + c * dt
        kq.append((w0, w1, w2))
        if actuator is None:
            kv.append(acc(ts, (x0, x1, x2), (w0, w1, w2), torque(ts))[0])
        else:
            u = torque(ts)
            kv.append(actuator.accelerations(system, ts, (x0, x1, x2), (w0, w1, w2), u, xo))
            ko.append(actuator.rates(ts, (x0, x1, x2), (w0, w1, w2), u, xo))
    raise ValueError("a tableau's rows end with its weights (tableau_rows)")


class PaperEuler(Integrator):
    """The paper's Euler step, equations (6)-(7): order 1, no constraint control (Φ drifts).

    θ += θ'Δt + ½θ''Δt², θ' += θ''Δt with θ'' from the index-1 solve at the step's start.
    Cost: one acceleration solve per step. Kept as the baseline others are compared to.
    """

    name = "euler"
    order = 1
    keeps_constraints = False

    def step(self, t: float, q: Vec3, v: Vec3, dt: float, torque: TorqueFn) -> tuple[Vec3, Vec3]:
        a, _ = self.system.accelerations(t, q, v, torque(t))
        h2 = 0.5 * dt * dt
        return (
            (q[0] + v[0] * dt + a[0] * h2, q[1] + v[1] * dt + a[1] * h2, q[2] + v[2] * dt + a[2] * h2),
            (v[0] + a[0] * dt, v[1] + a[1] * dt, v[2] + a[2] * dt),
        )

    @classmethod
    def is_stable(cls, z: complex) -> bool:
        # On q'' = a q + b q' with roots z, z̄ (scaled by dt): A = a dt² = −|z|², B = b dt = 2 Re z.
        # The step's amplification matrix on (q, dt·q') is [[1 + A/2, 1 + B/2], [A, 1 + B]].
        big_a, big_b = -abs(z) ** 2, 2.0 * z.real
        tr = 2.0 + big_a / 2.0 + big_b
        det = (1.0 + big_a / 2.0) * (1.0 + big_b) - big_a * (1.0 + big_b / 2.0)
        disc = cmath.sqrt(tr * tr - 4.0 * det)
        return max(abs((tr + disc) / 2.0), abs((tr - disc) / 2.0)) <= 1.0 + STABILITY_SLACK


class ExplicitRungeKutta(Integrator):
    """Explicit Runge-Kutta on the index-1 equations, projected onto Φ = 0, Φ_q q' = 0 after each step.

    Subclasses are data: the Butcher tableau (A, B, C) and the order. The projection
    (spec §4 has no drift control of its own) costs about one acceleration solve.
    """

    keeps_constraints = True
    A: ClassVar[tuple[tuple[float, ...], ...]]
    B: ClassVar[tuple[float, ...]]
    C: ClassVar[tuple[float, ...]]

    def __init__(self, system: FingerSystem) -> None:
        super().__init__(system)
        self._rows = tableau_rows(self.A, self.B, self.C)

    def step(self, t: float, q: Vec3, v: Vec3, dt: float, torque: TorqueFn) -> tuple[Vec3, Vec3]:
        q, v, _ = rk_stage_loop(self._rows, self.system, t, q, v, (), dt, torque)
        return project(self.system.params, q, v)

    @classmethod
    def is_stable(cls, z: complex) -> bool:
        # R(z) = 1 + z bᵀ(I − zA)⁻¹1, the Taylor polynomial of degree `order` for ≤4 stages;
        # evaluated generically by the stage recursion on y' = λy.
        ks: list[complex] = []
        for row in cls.A:
            ks.append(z * (1.0 + sum(a * k for a, k in zip(row, ks))))
        return abs(1.0 + sum(b * k for b, k in zip(cls.B, ks))) <= 1.0 + STABILITY_SLACK


class RK4(ExplicitRungeKutta):
    """Classic fourth-order Runge-Kutta with projection: order 4, Φ = 0 to round-off; the real-time default.

    Cost: 4 acceleration solves + 1 projection per step. Stable for |λ|dt ≲ 2.8 on the
    oscillatory axis: a stiff element (period ≲ 2.2 dt) needs the implicit method.
    """

    name = "rk4"
    order = 4
    A = ((), (0.5,), (0.0, 0.5), (0.0, 0.0, 1.0))
    B = (1 / 6, 1 / 3, 1 / 3, 1 / 6)
    C = (0.0, 0.5, 0.5, 1.0)
