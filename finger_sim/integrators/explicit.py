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

#: A tableau's stages as the stage loop takes them: (c, the non-zero (j, a_j) of its row) each.
Stages = tuple[tuple[float, tuple[tuple[int, float], ...]], ...]
#: A tableau's non-zero weights (j, b_j).
Weights = tuple[tuple[int, float], ...]


def rk_stage_loop(stages: Stages, weights: Weights, system: FingerSystem, t: float, q: Vec3, v: Vec3,
                  own: tuple[float, ...], dt: float, torque: TorqueFn,
                  actuator: Actuator | None = None) -> tuple[Vec3, Vec3, tuple[float, ...]]:
    """One explicit Runge-Kutta step of (q, q', own) from t to t + dt (s), before any projection: the one
    stage loop of `ExplicitRungeKutta` and `integrators.stateful.StatefulRungeKutta` (as scipy's `rk_step`).

    stages: (c, the non-zero (j, a_j) of its row) per stage; weights: the non-zero (j, b_j). Without an
    actuator q'' is the system's under the torque τ(s) on θ1 and `own` is empty; with one, q'' and the
    rates of its own slots `own` come from it (`actuators.base.Actuator`) under the input u(s) = torque(s).
    q and q' take the same operations in the same order either way."""
    acc = system.accelerations
    kq: list[Vec3] = []  # stage velocities: dq/dt
    kv: list[Vec3] = []  # stage accelerations: dv/dt
    ko: list[tuple[float, ...]] = []  # stage rates of the own slots
    q0, q1, q2 = q
    v0, v1, v2 = v
    for c, row in stages:
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
        ts = t + c * dt
        kq.append((w0, w1, w2))
        if actuator is None:
            kv.append(acc(ts, (x0, x1, x2), (w0, w1, w2), torque(ts))[0])
        else:
            u = torque(ts)
            kv.append(actuator.accelerations(system, ts, (x0, x1, x2), (w0, w1, w2), u, xo))
            ko.append(actuator.rates(ts, (x0, x1, x2), (w0, w1, w2), u, xo))
    for j, b in weights:
        hb = dt * b
        dq, dv = kq[j], kv[j]
        q0 += hb * dq[0]
        q1 += hb * dq[1]
        q2 += hb * dq[2]
        v0 += hb * dv[0]
        v1 += hb * dv[1]
        v2 += hb * dv[2]
        if own:
            own = tuple([x + hb * k for x, k in zip(own, ko[j])])
    return (q0, q1, q2), (v0, v1, v2), own


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
        # keep only the non-zero tableau entries: the step loop then skips nothing
        self._stages = tuple(
            (c, tuple((j, a) for j, a in enumerate(row) if a != 0.0)) for c, row in zip(self.C, self.A)
        )
        self._weights = tuple((j, b) for j, b in enumerate(self.B) if b != 0.0)

    def step(self, t: float, q: Vec3, v: Vec3, dt: float, torque: TorqueFn) -> tuple[Vec3, Vec3]:
        q, v, _ = rk_stage_loop(self._stages, self._weights, self.system, t, q, v, (), dt, torque)
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
