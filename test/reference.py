"""A slow, independent reference for the finger: the spec's equations written again in numpy.

Nothing here imports finger_sim. The constants are the spec's numbers (shared/spec/
finger_model.md §1-3) typed in again; the equations are built the textbook way rather
than copied from the fast path:

- M(q) = diag(I_A, I_D, I_G3) + m3 J_G3ᵀ J_G3 and h(q, q') = m3 J_G3ᵀ (J̇_G3 q'), the
  rigid-body form of T of spec §2 (the core uses the closed-form entries instead);
- the accelerations come from `np.linalg.solve` on the full 5×5 KKT matrix of spec §4
  (the core eliminates θ2 and λ by hand in a Schur complement);
- the assembly is a Newton solve of Φ = 0 continued from the extended pose (the core
  uses the closed-form circle intersection);
- reference trajectories are `scipy.integrate.solve_ivp` (DOP853 at rtol 1e-12 by
  default) on that right-hand side, restarted at every switch of a piecewise-constant
  torque, with dense output.

This is the "slow reference vs fast path" of STYLE.md: the two share only the spec.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from scipy.integrate import solve_ivp
from scipy.optimize import brentq

#: The shipped scenes (config/*.yaml of this repository).
CONFIG = Path(__file__).resolve().parent.parent / "config"

# -- spec §1-2 constants, SI -----------------------------------------------------------
R1 = 0.046  # m, proximal link A→B
R2 = 0.0444  # m, coupler D→C
R3 = 0.0077  # m, distal short edge C→B
R4 = 0.0085  # m, ground link D→A
THETA4 = math.pi - 0.49  # rad
L3 = 0.0425  # m, distal phalanx B→tip
M1 = 16.91e-3  # kg
M2 = 2 * 0.86e-3  # kg, two coupler plates
M3 = 14.16e-3  # kg
K_PAPER = 1e-3  # N·m/rad, PIP spring
#: Spec §1 values, deg, to the digits the spec shows.
THETA_EXT_DEG = (0.0, 13.1028, -128.0309)
TOGGLES_DEG = (104.2116, -160.3615)

#: Tight tolerances of the reference solve.
RTOL = 1e-12
ATOL = 1e-14


def e(a: float) -> np.ndarray:
    return np.array([math.cos(a), math.sin(a)])


def e_perp(a: float) -> np.ndarray:
    """d e(a) / da."""
    return np.array([-math.sin(a), math.cos(a)])


# -- geometry ---------------------------------------------------------------------------
D = -R4 * e(THETA4)


def phi(q: Sequence[float]) -> np.ndarray:
    """Loop closure of the paper's (2)-(3): B − (D + r2 e(θ2) + r3 e(θ3)), m."""
    return R1 * e(q[0]) - D - R2 * e(q[1]) - R3 * e(q[2])


def phi_q(q: Sequence[float]) -> np.ndarray:
    """∂Φ/∂q, 2×3, from the derivative of e()."""
    return np.column_stack([R1 * e_perp(q[0]), -R2 * e_perp(q[1]), -R3 * e_perp(q[2])])


def gamma(q: Sequence[float], v: Sequence[float]) -> np.ndarray:
    """γ = −(Φ_q q')_q q': the velocity-product part of Φ'' (d²e/da² = −e)."""
    return -(-R1 * e(q[0]) * v[0] ** 2 + R2 * e(q[1]) * v[1] ** 2 + R3 * e(q[2]) * v[2] ** 2)


def _close(theta1: float, guess: Sequence[float]) -> np.ndarray:
    """(θ2, θ3) with Φ(θ1, θ2, θ3) = 0 by Newton from `guess`."""
    x = np.array(guess, dtype=float)
    for _ in range(50):
        q = (theta1, x[0], x[1])
        f = phi(q)
        dx = np.linalg.solve(phi_q(q)[:, 1:], -f)
        x = x + dx
        if np.max(np.abs(dx)) < 1e-15:
            break
    return x


def assemble(theta1: float) -> np.ndarray:
    """q on the spec's branch, continued by Newton from the spec's extended pose (guess in degrees)."""
    x = np.radians(THETA_EXT_DEG[1:])
    n = max(1, int(math.ceil(abs(theta1) / 0.02)))
    for i in range(1, n + 1):
        x = _close(theta1 * i / n, x)
    return np.array([theta1, *x])


def theta_ext() -> np.ndarray:
    return assemble(0.0)


ALPHA = -float(theta_ext()[2])  # distal offset: straight finger at extension (spec §1)


def rates(q: Sequence[float], theta1_dot: float) -> np.ndarray:
    """q' with Φ_q q' = 0 for a given θ1'."""
    g = phi_q(q)
    w = np.linalg.solve(g[:, 1:], -g[:, 0] * theta1_dot)
    return np.array([theta1_dot, *w])


def toggles() -> tuple[float, float]:
    """(flexion, extension) toggle θ1, rad: where |D→B| = r2 + r3."""
    f = lambda t1: float(np.linalg.norm(R1 * e(t1) - D)) - (R2 + R3)  # noqa: E731
    return brentq(f, math.radians(90), math.radians(120), xtol=1e-15), brentq(f, math.radians(-175), math.radians(-140), xtol=1e-15)


def beta(q: Sequence[float]) -> float:
    """PIP flexion β = θ3 + α − θ1, rad."""
    return q[2] + ALPHA - q[0]


def tip(q: Sequence[float]) -> np.ndarray:
    return R1 * e(q[0]) + L3 * e(q[2] + ALPHA)


def tip_jacobian(q: Sequence[float]) -> np.ndarray:
    return np.column_stack([R1 * e_perp(q[0]), np.zeros(2), L3 * e_perp(q[2] + ALPHA)])


def g3(q: Sequence[float]) -> np.ndarray:
    """Centre of mass of the distal link, B + (L3/2) e(ψ)."""
    return R1 * e(q[0]) + 0.5 * L3 * e(q[2] + ALPHA)


def g3_jacobian(q: Sequence[float]) -> np.ndarray:
    return np.column_stack([R1 * e_perp(q[0]), np.zeros(2), 0.5 * L3 * e_perp(q[2] + ALPHA)])


# -- dynamics ---------------------------------------------------------------------------
I_A = M1 * R1**2 / 3
I_D = M2 * R2**2 / 3
I_G3 = M3 * L3**2 / 12


def mass(q: Sequence[float]) -> np.ndarray:
    """M(q) = diag(I_A, I_D, I_G3) + m3 J_G3ᵀ J_G3, kg·m²."""
    j = g3_jacobian(q)
    return np.diag([I_A, I_D, I_G3]) + M3 * j.T @ j


def coriolis(q: Sequence[float], v: Sequence[float]) -> np.ndarray:
    """h(q, q') = m3 J_G3ᵀ J̇_G3 q' with J̇_G3 q' = −r1 θ1'² e(θ1) − (L3/2) θ3'² e(ψ)."""
    jdot_v = -R1 * v[0] ** 2 * e(q[0]) - 0.5 * L3 * v[2] ** 2 * e(q[2] + ALPHA)
    return M3 * g3_jacobian(q).T @ jdot_v


@dataclass(frozen=True)
class Effects:
    """The force elements of spec §3 (SI); all off but the paper's spring by default."""

    k: float = K_PAPER  # N·m/rad
    c: float = 0.0  # N·m·s/rad
    g: tuple[float, float] = (0.0, 0.0)  # m/s²
    f: tuple[float, float] = (0.0, 0.0)  # N at the tip

    def force(self, q: Sequence[float], v: Sequence[float], tau: float) -> np.ndarray:
        """Q = motor + spring + damping + gravity + tip force, N·m."""
        b = beta(q)
        bdot = v[2] - v[0]
        # spring: −∂V/∂q with ∂β/∂q = (−1, 0, 1)
        out = np.array([tau + self.k * b, 0.0, -self.k * b])
        # damping: −∂R/∂q', R = ½ c (θ1'² + θ2'² + β'²)
        out += -self.c * (np.array([v[0], v[1], 0.0]) + bdot * np.array([-1.0, 0.0, 1.0]))
        g = np.array(self.g)
        if g.any():
            j1 = np.column_stack([0.5 * R1 * e_perp(q[0]), np.zeros(2), np.zeros(2)])
            j2 = np.column_stack([np.zeros(2), 0.5 * R2 * e_perp(q[1]), np.zeros(2)])
            out += M1 * j1.T @ g + M2 * j2.T @ g + M3 * g3_jacobian(q).T @ g
        f = np.array(self.f)
        if f.any():
            out += tip_jacobian(q).T @ f
        return out

    def potential(self, q: Sequence[float]) -> float:
        """V = ½ k β² − Σ m_i g·r_Gi − F·tip, J."""
        g, f = np.array(self.g), np.array(self.f)
        centres = ((M1, 0.5 * R1 * e(q[0])), (M2, D + 0.5 * R2 * e(q[1])), (M3, g3(q)))
        return 0.5 * self.k * beta(q) ** 2 - sum(m * g @ r for m, r in centres) - f @ tip(q)


def kkt(q: Sequence[float], v: Sequence[float], tau: float, fx: Effects) -> tuple[np.ndarray, np.ndarray]:
    """(q'', λ) from [M −Φ_qᵀ; Φ_q 0][q''; λ] = [Q − h; γ] by a dense 5×5 solve (spec §4)."""
    a = np.zeros((5, 5))
    a[:3, :3] = mass(q)
    g = phi_q(q)
    a[:3, 3:] = -g.T
    a[3:, :3] = g
    rhs = np.concatenate([fx.force(q, v, tau) - coriolis(q, v), gamma(q, v)])
    x = np.linalg.solve(a, rhs)
    return x[:3], x[3:]


def energy(q: Sequence[float], v: Sequence[float], fx: Effects) -> float:
    v = np.asarray(v)
    return 0.5 * v @ mass(q) @ v + fx.potential(q)


# -- torque profiles and trajectories --------------------------------------------------
def ramp(offset: float, slope: float) -> Callable[[float], float]:
    return lambda t: offset + slope * t


def constant(value: float) -> Callable[[float], float]:
    return lambda t: value


def sine(amplitude: float, frequency: float, offset: float = 0.0) -> Callable[[float], float]:
    return lambda t: offset + amplitude * math.sin(2.0 * math.pi * frequency * t)


@dataclass(frozen=True)
class Square:
    """offset ± amplitude, + over the first half period; switches at multiples of 1/(2f)."""

    amplitude: float
    frequency: float
    offset: float = 0.0

    def on(self, a: float, b: float) -> Callable[[float], float]:
        """The constant value on the open interval (a, b) between switches."""
        mid = 0.5 * (a + b)
        sign = 1.0 if (mid * self.frequency) % 1.0 < 0.5 else -1.0
        value = self.offset + sign * self.amplitude
        return lambda t: value

    def switches(self, t_end: float) -> list[float]:
        half = 0.5 / self.frequency
        return [k * half for k in range(1, int(math.floor(t_end / half + 1e-9)) + 1) if k * half < t_end]


def torque_from_dict(d: dict) -> tuple[Callable[[float, float], Callable[[float], float]], Callable[[float], list[float]]]:
    """(τ on a segment, switch times) from a scene's `input.torque` mapping."""
    kind = d["type"]
    if kind == "ramp":
        f = ramp(d["offset"], d["slope"])
    elif kind == "constant":
        f = constant(d["value"])
    elif kind == "sine":
        f = sine(d["amplitude"], d["frequency"], d.get("offset", 0.0))
    elif kind == "square":
        sq = Square(d["amplitude"], d["frequency"], d.get("offset", 0.0))
        return sq.on, sq.switches
    elif kind == "step":
        before, after, at = d["before"], d["after"], d["at"]

        def on(a: float, b: float) -> Callable[[float], float]:
            value = before if b <= at else after
            return lambda t: value

        return on, (lambda t_end: [at] if 0.0 < at < t_end else [])
    else:
        raise NotImplementedError(kind)
    return (lambda a, b: f), (lambda t_end: [])


@dataclass
class Reference:
    """A dense tight solution: `state(t)` → (q, q'), with the pieces between torque switches."""

    pieces: list = field(default_factory=list)  # (t0, t1, OdeSolution)
    effects: Effects = field(default_factory=Effects)
    nfev: int = 0

    def y(self, t: float | np.ndarray) -> np.ndarray:
        """(6,) or (6, n): q, q' at t."""
        ts = np.atleast_1d(np.asarray(t, dtype=float))
        out = np.empty((6, ts.size))
        for i, s in enumerate(ts):
            for t0, t1, sol in self.pieces:
                if s <= t1 + 1e-12:
                    out[:, i] = sol(min(max(s, t0), t1))
                    break
            else:
                raise ValueError(f"t = {s} beyond the reference's end")
        return out[:, 0] if np.ndim(t) == 0 else out


def solve(
    torque_on: Callable[[float, float], Callable[[float], float]],
    switches: Sequence[float],
    y0: Sequence[float],
    t_end: float,
    effects: Effects = Effects(),
    *,
    method: str = "DOP853",
    rtol: float = RTOL,
    atol: float = ATOL,
) -> Reference:
    """Tight solve_ivp of the index-1 equations, restarted at every switch (no drift control)."""
    edges = [0.0, *[s for s in switches if 0.0 < s < t_end], t_end]
    ref = Reference(effects=effects)
    y = np.asarray(y0, dtype=float)
    for a, b in zip(edges, edges[1:]):
        tau = torque_on(a, b)

        def rhs(t: float, y: np.ndarray) -> np.ndarray:
            acc, _ = kkt(y[:3], y[3:], tau(t), effects)
            return np.concatenate([y[3:], acc])

        sol = solve_ivp(rhs, (a, b), y, method=method, rtol=rtol, atol=atol, dense_output=True)
        assert sol.success, sol.message
        ref.pieces.append((a, b, sol.sol))
        ref.nfev += sol.nfev
        y = sol.y[:, -1]
    return ref


def solve_scene(data: dict, t_end: float | None = None, **kw) -> Reference:
    """The reference for a scene mapping as written in config/*.yaml (only the keys it uses)."""
    model = data.get("model", {})
    fx = Effects(
        k=model.get("spring_stiffness", K_PAPER),
        c=model.get("damping", 0.0),
        g=tuple(model.get("gravity", (0.0, 0.0))),
        f=tuple(model.get("tip_force", (0.0, 0.0))),
    )
    assert "joint_limits" not in model, "the reference has no stops"
    init = data.get("initial", {})
    q0 = assemble(init.get("theta1", 0.0))
    v0 = rates(q0, init.get("theta1_dot", 0.0))
    t_end = data.get("duration", 0.3) if t_end is None else t_end
    on, switches = torque_from_dict(data["input"]["torque"])
    return solve(on, switches(t_end), [*q0, *v0], t_end, fx, **kw)
