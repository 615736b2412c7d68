"""Four-bar kinematics in the paper's coordinates q = (θ1, θ2, θ3), rad.

Planar frame of spec §1: origin at the MCP pivot A, angles from +X towards +Y,
e(a) = (cos a, sin a). D = −r4 e(θ4), B = r1 e(θ1), C = D + r2 e(θ2), B = C + r3 e(θ3).
Scalar `math` throughout: for 2- and 3-vectors it is several times faster than numpy.
"""

from __future__ import annotations

import math
from typing import NamedTuple

from finger_sim.errors import ConfigError
from finger_sim.model import FingerParams

Vec3 = tuple[float, float, float]
#: q' = 0: the one tuple a resting or held state's velocity is set to, shared by every module, so that
#: `v is ZERO` tells such a state wherever it was set (the drive keeps its holding torque for it).
ZERO: Vec3 = (0.0, 0.0, 0.0)

#: Assembly branch of spec §1 (the distal phalanx flexes with the proximal one):
#: θ2 = φ + BRANCH·acos(...), where φ is the direction of D→B.
BRANCH = +1
#: |sin(θ3 − θ2)| below which a pose counts as the toggle (θ2 ∥ θ3), where the dependent
#: rates are singular: the rates' condition number there exceeds 1e12.
TOGGLE_SINE = 1e-12


class Pose(NamedTuple):
    """Fingertip position (m, model plane) and distal-phalanx direction ψ (rad)."""

    x: float
    y: float
    psi: float


def constraint(p: FingerParams, q: Vec3) -> tuple[float, float]:
    """Loop closure Φ(q) of the paper's equations (2)-(3), m."""
    t1, t2, t3 = q
    return (
        p.r1 * math.cos(t1) + p.r4 * math.cos(p.theta4) - p.r2 * math.cos(t2) - p.r3 * math.cos(t3),
        p.r1 * math.sin(t1) + p.r4 * math.sin(p.theta4) - p.r2 * math.sin(t2) - p.r3 * math.sin(t3),
    )


def constraint_norm(p: FingerParams, q: Vec3) -> float:
    """|Φ(q)|, m: the loop-closure residual."""
    f1, f2 = constraint(p, q)
    return math.hypot(f1, f2)


def assemble(p: FingerParams, theta1: float, branch: int = BRANCH) -> Vec3:
    """Closed-form (θ1, θ2, θ3) on the given branch; ConfigError outside the assemblable range."""
    dx = p.r1 * math.cos(theta1) + p.r4 * math.cos(p.theta4)
    dy = p.r1 * math.sin(theta1) + p.r4 * math.sin(p.theta4)
    rho = math.hypot(dx, dy)
    cos_a = (rho * rho + p.r2 * p.r2 - p.r3 * p.r3) / (2.0 * p.r2 * rho)
    if not -1.0 <= cos_a <= 1.0:
        lo, hi = assembly_range(p)
        raise ConfigError(
            "initial.theta1",
            f"an MCP angle in the assemblable range [{lo:.6f}, {hi:.6f}] rad",
            theta1,
        )
    theta2 = math.atan2(dy, dx) + branch * math.acos(cos_a)
    theta3 = math.atan2(dy - p.r2 * math.sin(theta2), dx - p.r2 * math.cos(theta2))
    return (theta1, theta2, theta3)


def dependent_rates(p: FingerParams, q: Vec3, theta1_dot: float) -> Vec3:
    """(θ1', θ2', θ3') with Φ_q q' = 0 for a given θ1', rad/s. Singular at the toggle."""
    _, t2, t3 = q
    # Φ_q[:, 1:] (θ2', θ3')ᵀ = −Φ_q[:, 0] θ1'; its determinant is r2 r3 sin(θ3 − θ2).
    det = p.r2 * p.r3 * math.sin(t3 - t2)
    if abs(det) < TOGGLE_SINE * p.r2 * p.r3:
        raise ConfigError("initial.theta1", "a pose away from the toggle (θ2 ∥ θ3)", q[0])
    b1 = p.r1 * math.sin(q[0]) * theta1_dot
    b2 = -p.r1 * math.cos(q[0]) * theta1_dot
    # Solve [[r2 s2, r3 s3], [−r2 c2, −r3 c3]] x = (b1, b2) by Cramer's rule.
    s2, c2, s3, c3 = math.sin(t2), math.cos(t2), math.sin(t3), math.cos(t3)
    d = p.r2 * s2 * (-p.r3 * c3) - p.r3 * s3 * (-p.r2 * c2)
    t2d = (b1 * (-p.r3 * c3) - p.r3 * s3 * b2) / d
    t3d = (p.r2 * s2 * b2 - b1 * (-p.r2 * c2)) / d
    return (theta1_dot, t2d, t3d)


def assembly_range(p: FingerParams) -> tuple[float, float]:
    """The MCP interval (lo, hi) around extension (θ1 = 0), rad, on which the linkage assembles.

    Its ends are toggles, where r2 and r3 are collinear: stretched (|D→B| = r2 + r3) or
    folded (|D→B| = |r2 − r3|). Spec §1 gives 104.2116° and −160.3615° (both stretched) for
    the paper's geometry; with r1 below r4 + |r2 − r3| (45.2 mm) a folded toggle bounds the
    extension side instead. (−inf, inf) when the crank turns fully.
    """
    # |D→B|² = r1² + r4² + 2 r1 r4 cos φ with φ = θ1 − θ4: the dyad reaches B where
    # cos φ lies in [c_folded, c_stretched], i.e. |φ| in [a_stretched, a_folded].
    a_stretched = _limit_angle(p, p.r2 + p.r3, 0.0)
    a_folded = _limit_angle(p, abs(p.r2 - p.r3), math.pi)
    if a_stretched == 0.0 and a_folded == math.pi:  # the dyad reaches every D→B distance
        return (-math.inf, math.inf)
    side = 1.0 if _wrap(-p.theta4) >= 0.0 else -1.0  # φ at extension lies on this side
    if a_folded == math.pi:  # one interval through φ = π (the paper's linkage)
        hi, lo = _wrap(p.theta4 - a_stretched), _wrap(p.theta4 + a_stretched)
    elif a_stretched == 0.0:  # one interval through φ = 0
        hi, lo = _wrap(p.theta4 + a_folded), _wrap(p.theta4 - a_folded)
    elif side > 0:  # φ in [a_stretched, a_folded]
        hi, lo = _wrap(p.theta4 + a_folded), _wrap(p.theta4 + a_stretched)
    else:  # φ in [−a_folded, −a_stretched]
        hi, lo = _wrap(p.theta4 - a_stretched), _wrap(p.theta4 - a_folded)
    if lo > hi:  # the interval crosses θ1 = ±π: unwrap the end on the far side of 0
        if hi >= 0.0:
            lo -= 2.0 * math.pi
        else:
            hi += 2.0 * math.pi
    return (lo, hi)


def _limit_angle(p: FingerParams, length: float, unreached: float) -> float:
    """|φ| in [0, π] at which |D→B| = length; `unreached` when no φ gives that length."""
    c = (length * length - p.r1 * p.r1 - p.r4 * p.r4) / (2.0 * p.r1 * p.r4)
    return unreached if not -1.0 < c < 1.0 else math.acos(c)


def toggle_angles(p: FingerParams) -> tuple[float, float]:
    """(flexion toggle, extension toggle) MCP angles, rad: (104.2116°, −160.3615°) for the paper."""
    lo, hi = assembly_range(p)
    return (hi, lo)


def extended_pose(p: FingerParams) -> Vec3:
    """θ_ext: the assembly at θ1 = 0 on the spec's branch (constants of the model)."""
    return assemble(p, 0.0)


def distal_offset(p: FingerParams) -> float:
    """α = θ1_ext − θ3_ext, rad: the distal phalanx points along ψ = θ3 + α (straight at extension)."""
    return -extended_pose(p)[2]


def fingertip(p: FingerParams, q: Vec3, alpha: float) -> Pose:
    """Fingertip position B + L3 e(ψ), m, and ψ = θ3 + α, rad."""
    psi = q[2] + alpha
    return Pose(
        p.r1 * math.cos(q[0]) + p.L3 * math.cos(psi),
        p.r1 * math.sin(q[0]) + p.L3 * math.sin(psi),
        psi,
    )


def fingertip_jacobian(p: FingerParams, q: Vec3, alpha: float) -> tuple[Vec3, Vec3]:
    """∂tip/∂q as two rows (∂x/∂q, ∂y/∂q), m/rad."""
    psi = q[2] + alpha
    return (
        (-p.r1 * math.sin(q[0]), 0.0, -p.L3 * math.sin(psi)),
        (p.r1 * math.cos(q[0]), 0.0, p.L3 * math.cos(psi)),
    )


def fingertip_trajectory(p: FingerParams, mcp_range: tuple[float, float], samples: int = 181) -> list[Pose]:
    """Fingertip poses over evenly spaced MCP angles in mcp_range (rad): the finger's workspace
    curve (the paper's Fig. 4; the finger has one degree of freedom)."""
    alpha = distal_offset(p)
    lo, hi = mcp_range
    return [fingertip(p, assemble(p, lo + (hi - lo) * i / (samples - 1)), alpha) for i in range(samples)]


def pip_angle(q: Vec3, alpha: float) -> float:
    """PIP flexion β = θ3 + α − θ1, rad (0 at extension, positive in flexion)."""
    return q[2] + alpha - q[0]


def points(p: FingerParams, q: Vec3, alpha: float) -> dict[str, tuple[float, float]]:
    """Joint and tip positions A, B, C, D, tip in the model plane, m (for drawings and markers)."""
    t1, t2, _ = q
    dx, dy = -p.r4 * math.cos(p.theta4), -p.r4 * math.sin(p.theta4)
    tip = fingertip(p, q, alpha)
    return {
        "A": (0.0, 0.0),
        "B": (p.r1 * math.cos(t1), p.r1 * math.sin(t1)),
        "C": (dx + p.r2 * math.cos(t2), dy + p.r2 * math.sin(t2)),
        "D": (dx, dy),
        "tip": (tip.x, tip.y),
    }


def _wrap(a: float) -> float:
    """Angle wrapped to (−π, π]."""
    return math.atan2(math.sin(a), math.cos(a))
