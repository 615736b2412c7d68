"""Projection onto the constraint manifold Φ(q) = 0, Φ_q q' = 0.

Minimum-norm (Euclidean) Gauss-Newton: q ← q − Φ_qᵀ (Φ_q Φ_qᵀ)⁻¹ Φ(q) until |Φ| is at
round-off, then the exact linear velocity projection. Φ_q keeps rank 2 everywhere on
the assemblable range, the toggle included, so this never breaks down there.
"""

from __future__ import annotations

import math

from finger_sim.errors import SimulationDiverged
from finger_sim.kinematics import Vec3
from finger_sim.model import FingerParams

#: Position projection stops when |Φ| (m) is below this: a few ulps of the link lengths.
POSITION_TOLERANCE = 1e-15
#: Gauss-Newton converges quadratically; more iterations than this means q is far off.
MAX_ITERATIONS = 8
#: Without reaching POSITION_TOLERANCE, a residual up to this many times it (scaled by the
#: angles' size) is still round-off of the last iteration; beyond it q was too far off.
ACCEPTED_RESIDUAL_FACTOR = 1e3


#: Status codes of `project_state` (the compiled kernel raises none: it returns them).
OK = 0
NON_FINITE = 1  # the iteration met a non-finite state
NOT_CONVERGED = 2  # |Φ| stayed above the accepted residual


def project(p: FingerParams, q: Vec3, v: Vec3) -> tuple[Vec3, Vec3]:
    """(q, v) projected onto Φ = 0 and Φ_q v = 0; rad, rad/s."""
    status, residual, t1, t2, t3, w1, w2, w3 = project_state(
        p.r1, p.r2, p.r3, p.r4 * math.cos(p.theta4), p.r4 * math.sin(p.theta4), *q, *v)
    if status == NON_FINITE:
        raise SimulationDiverged(f"state became non-finite: q = {q}")
    if status == NOT_CONVERGED:
        raise SimulationDiverged(f"projection did not converge: |Φ| = {residual:.3e} m at q = {q}")
    return (t1, t2, t3), (w1, w2, w3)


def project_state(r1: float, r2: float, r3: float, k1: float, k2: float, t1: float, t2: float, t3: float,
                  w1: float, w2: float, w3: float) -> tuple[int, float, float, float, float, float, float, float]:
    """(status, |Φ|, q, v) with (q, v) projected onto Φ = 0 and Φ_q v = 0; rad, rad/s, m.

    The one definition of the projection: `project` calls it plainly, and the compiled kernel compiles
    it (`finger_sim.kernel.numerics.project`). r: link lengths, (k1, k2) = r4 (cos θ4, sin θ4), m.
    Status OK, or NON_FINITE / NOT_CONVERGED (then q and v are not meaningful); |Φ| is the last
    residual when not converged, else 0.
    """
    converged = False
    f1 = f2 = g11 = g12 = g13 = g21 = g22 = g23 = 0.0
    for _ in range(MAX_ITERATIONS):
        s1, c1, s2, c2, s3, c3 = math.sin(t1), math.cos(t1), math.sin(t2), math.cos(t2), math.sin(t3), math.cos(t3)
        f1 = r1 * c1 + k1 - r2 * c2 - r3 * c3
        f2 = r1 * s1 + k2 - r2 * s2 - r3 * s3
        g11, g12, g13 = -r1 * s1, r2 * s2, r3 * s3
        g21, g22, g23 = r1 * c1, -r2 * c2, -r3 * c3
        if abs(f1) + abs(f2) <= POSITION_TOLERANCE:
            converged = True
            break
        a11 = g11 * g11 + g12 * g12 + g13 * g13
        a12 = g11 * g21 + g12 * g22 + g13 * g23
        a22 = g21 * g21 + g22 * g22 + g23 * g23
        det = a11 * a22 - a12 * a12
        l1 = (a22 * f1 - a12 * f2) / det
        l2 = (a11 * f2 - a12 * f1) / det
        t1 -= g11 * l1 + g21 * l2
        t2 -= g12 * l1 + g22 * l2
        t3 -= g13 * l1 + g23 * l2
    residual = 0.0
    if not converged:
        if not (math.isfinite(t1) and math.isfinite(t2) and math.isfinite(t3)):
            return NON_FINITE, residual, t1, t2, t3, w1, w2, w3
        residual = math.hypot(f1, f2)
        if residual > ACCEPTED_RESIDUAL_FACTOR * POSITION_TOLERANCE * (1.0 + max(abs(t1), abs(t2), abs(t3))):
            return NOT_CONVERGED, residual, t1, t2, t3, w1, w2, w3
    # velocity: v ← v − Φ_qᵀ (Φ_q Φ_qᵀ)⁻¹ Φ_q v, with Φ_q at the projected q
    a11 = g11 * g11 + g12 * g12 + g13 * g13
    a12 = g11 * g21 + g12 * g22 + g13 * g23
    a22 = g21 * g21 + g22 * g22 + g23 * g23
    det = a11 * a22 - a12 * a12
    e1 = g11 * w1 + g12 * w2 + g13 * w3
    e2 = g21 * w1 + g22 * w2 + g23 * w3
    l1 = (a22 * e1 - a12 * e2) / det
    l2 = (a11 * e2 - a12 * e1) / det
    return OK, residual, t1, t2, t3, w1 - g11 * l1 - g21 * l2, w2 - g12 * l1 - g22 * l2, w3 - g13 * l1 - g23 * l2
