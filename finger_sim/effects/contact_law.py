"""The contact law of spec §7 as plain float functions: the candidates' geometry and the force.

`Contact` (effects/contact.py) calls them as they are; the compiled kernel compiles these same
functions (`kernel.numerics`, numba `njit`, inlined into its candidate loops), so the law is
written once. Floats in, tuples of floats out: no classes, no containers.

A candidate's geometry is (δ m, p m, n_c, j1 = ∂p/∂θ1, j3 = ∂p/∂θ3 m/rad), flat:
(delta, px, py, nx, ny, j1x, j1y, j3x, j3y). B = r1 e(θ1) = (bx, by) is the joint, e(ψ) = (ux, uy)
the distal direction (ψ = θ3 + α).
"""

from __future__ import annotations

import math

#: Below this distance (m) from a circle's centre the phalanx axis has no closest direction;
#: the normal then falls back to the phalanx's own normal (only reachable deep inside an object).
MIN_DISTANCE = 1e-12

Geometry = tuple[float, float, float, float, float, float, float, float, float]


def circle_depth(px: float, py: float, cx: float, cy: float, rad: float, fx: float, fy: float) -> tuple[float, float, float]:
    """(δ = rad − |p − c| m, n_c = (p − c)/|p − c|) of a phalanx's closest point p to a circle's centre c;
    n_c = (fx, fy), the phalanx's own normal, where p is on c."""
    dx, dy = px - cx, py - cy
    dist = math.sqrt(dx * dx + dy * dy)  # not hypot: CPython's and libm's differ in the last bit
    if dist > MIN_DISTANCE:
        return rad - dist, dx / dist, dy / dist
    return rad - dist, fx, fy


def proximal_circle(cx: float, cy: float, rad: float, r1: float, bx: float, by: float, s1: float, c1: float) -> Geometry:
    """A circle (centre c, radius ρ1 + R: rad, m) and the proximal phalanx A→B ((s1, c1) = sin, cos θ1)
    at its closest point p = s B (material coordinate s along A→B): ∂p/∂θ1 = s r1 e'(θ1)."""
    s = (cx * bx + cy * by) / (r1 * r1)
    s = 0.0 if s < 0.0 else (1.0 if s > 1.0 else s)
    px, py = s * bx, s * by
    delta, nx, ny = circle_depth(px, py, cx, cy, rad, -s1, c1)
    return delta, px, py, nx, ny, -s * by, s * bx, 0.0, 0.0


def distal_circle(cx: float, cy: float, rad: float, l3: float, bx: float, by: float, ux: float, uy: float) -> Geometry:
    """A circle (rad = ρ3 + R) and the distal phalanx B → B + L3 e(ψ) at its closest point p = B + ℓ e(ψ):
    ∂p/∂θ1 = r1 e'(θ1), ∂p/∂θ3 = ℓ e'(ψ)."""
    dx, dy = cx - bx, cy - by
    ell = dx * ux + dy * uy
    ell = 0.0 if ell < 0.0 else (l3 if ell > l3 else ell)
    px, py = bx + ell * ux, by + ell * uy
    delta, nx, ny = circle_depth(px, py, cx, cy, rad, -uy, ux)
    return delta, px, py, nx, ny, -by, bx, -ell * uy, ell * ux


def joint_plane(ox: float, oy: float, nx: float, ny: float, rho: float, bx: float, by: float) -> Geometry:
    """A plane (point o, outward normal n) and the joint B (capsule radius rho, m): p = B."""
    return rho - (nx * (bx - ox) + ny * (by - oy)), bx, by, nx, ny, -by, bx, 0.0, 0.0


def tip_plane(ox: float, oy: float, nx: float, ny: float, rho: float, l3: float, bx: float, by: float, ux: float,
              uy: float) -> Geometry:
    """A plane and the fingertip p = B + L3 e(ψ)."""
    px, py = bx + l3 * ux, by + l3 * uy
    return rho - (nx * (px - ox) + ny * (py - oy)), px, py, nx, ny, -by, bx, -l3 * uy, l3 * ux


def point_velocity(j1x: float, j1y: float, j3x: float, j3y: float, v0: float, v2: float) -> tuple[float, float]:
    """ṗ = J_p q' (m/s) of the phalanx's material point at p, from θ1' = v0 and θ3' = v2 (rad/s)."""
    return j1x * v0 + j3x * v2, j1y * v0 + j3y * v2


def along_tangent(fx: float, fy: float, ft: float, nx: float, ny: float) -> tuple[float, float]:
    """(fx, fy) + ft t_c, N: a tangential force ft added along t_c = n_c turned by +90° = (−ny, nx)."""
    return fx - ft * ny, fy + ft * nx


def normal_force(delta: float, nx: float, ny: float, vx: float, vy: float, k: float, e: float, d: float) -> float:
    """k δ^e (1 + d δ'), N, δ' = −n_c·ṗ (Hunt–Crossley; ṗ = (vx, vy) m/s relative to the object): F_n where > 0,
    else no force (the object pulls nothing)."""
    return k * delta**e * (1.0 - d * (nx * vx + ny * vy))


def contact_force(delta: float, nx: float, ny: float, vx: float, vy: float, k: float, e: float, d: float, mu: float,
                  vs: float) -> tuple[float, float, float]:
    """(F_n, Fx, Fy), N, of a candidate in contact (δ > 0) whose point moves at (vx, vy) m/s relative to the
    object: F_n = max(0, k δ^e (1 + d δ')) with δ' = −n_c·ṗ (Hunt–Crossley), F_t = −μ F_n tanh(v_t / v_s)
    with v_t = t_c·ṗ (μ = 0: none), F = F_n n_c + F_t t_c."""
    fn = normal_force(delta, nx, ny, vx, vy, k, e, d)
    if fn <= 0.0:
        return 0.0, 0.0, 0.0
    fx, fy = fn * nx, fn * ny
    if mu != 0.0:
        fx, fy = along_tangent(fx, fy, -mu * fn * math.tanh((nx * vy - ny * vx) / vs), nx, ny)
    return fn, fx, fy


def generalized(j1x: float, j1y: float, j3x: float, j3y: float, fx: float, fy: float) -> tuple[float, float]:
    """(Q1, Q3) = J_pᵀ F, N·m, of a force F = (fx, fy) N at p (virtual work; J_p has no θ2 column)."""
    return j1x * fx + j1y * fy, j3x * fx + j3y * fy


def gap_gradient(nx: float, ny: float, j1x: float, j1y: float, j3x: float, j3y: float) -> tuple[float, float]:
    """(∂gap/∂θ1, ∂gap/∂θ3) = n_cᵀ J_p, m/rad: gap = −δ, δ' = −n_c·J_p q'."""
    return nx * j1x + ny * j1y, nx * j3x + ny * j3y
