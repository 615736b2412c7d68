"""The contact law written once (`effects.contact_law`): the kernel's functions are those plain
functions compiled, equal bit for bit on random inputs; the geometry agrees with a brute-force
closest point (numpy, a dense sampling of the phalanx's axis), the force with spec §7 written here."""

from __future__ import annotations

import math

import numpy as np
import pytest

from finger_sim.effects import contact_law

pytest.importorskip("numba")
from finger_sim.kernel import numerics  # noqa: E402  (needs numba to mean "compiled")

#: The law's functions and the kernel's compiled names for them.
LAWS = ("circle_depth", "proximal_circle", "distal_circle", "joint_plane", "tip_plane", "point_velocity",
        "along_tangent", "normal_force", "contact_force", "generalized", "gap_gradient")
R1, L3 = 0.04, 0.03  # m, a phalanx pair of the spec's size
#: Points sampled along a phalanx's axis for the brute-force closest point (spacing ≈ 4e-8 m).
SAMPLES = 1_000_001


def random_args(rng: np.random.Generator, name: str) -> tuple[float, ...]:
    """Plausible arguments of law `name` (m, rad, m/s, N/m^e), as `Contact` passes them."""
    th1, psi = rng.uniform(-0.5, 2.0, 2)
    bx, by, ux, uy = R1 * math.cos(th1), R1 * math.sin(th1), math.cos(psi), math.sin(psi)
    cx, cy = rng.uniform(-0.02, 0.08, 2)
    nx, ny = math.cos(rng.uniform(0, 2 * math.pi)), math.sin(rng.uniform(0, 2 * math.pi))
    u = rng.uniform(-1.0, 1.0, 8).tolist()
    return {
        "circle_depth": (*u[:4], 0.02, nx, ny),
        "proximal_circle": (cx, cy, 0.025, R1, bx, by, math.sin(th1), math.cos(th1)),
        "distal_circle": (cx, cy, 0.025, L3, bx, by, ux, uy),
        "joint_plane": (cx, cy, nx, ny, 0.008, bx, by),
        "tip_plane": (cx, cy, nx, ny, 0.007, L3, bx, by, ux, uy),
        "point_velocity": tuple(u[:6]),
        "along_tangent": (*u[:3], nx, ny),
        "normal_force": (abs(u[0]) * 1e-3, nx, ny, u[1], u[2], 1e5, 1.5, 1.5),
        "contact_force": (abs(u[0]) * 1e-3, nx, ny, u[1] * 0.1, u[2] * 0.1, 1e5, 1.5, 1.5, 0.6, 1e-3),
        "generalized": tuple(u[:6]),
        "gap_gradient": tuple(u[:6]),
    }[name]


@pytest.mark.parametrize("name", LAWS)
def test_kernel_compiles_the_one_law(name: str) -> None:
    compiled = getattr(numerics, name)
    assert compiled.py_func.__code__ is getattr(contact_law, name).__code__  # the same function, not a copy
    rng = np.random.default_rng(11)
    for _ in range(300):
        args = random_args(rng, name)
        assert compiled(*args) == getattr(contact_law, name)(*args)  # bit for bit


def closest(a: np.ndarray, b: np.ndarray, c: np.ndarray) -> tuple[float, np.ndarray]:
    """Distance (m) from c to the segment a→b and its closest point, by dense sampling."""
    points = a + np.linspace(0.0, 1.0, SAMPLES)[:, None] * (b - a)
    dist = np.hypot(*(points - c).T)
    i = int(np.argmin(dist))
    return float(dist[i]), points[i]


def test_circle_geometry_is_the_closest_point_of_the_phalanx() -> None:
    """δ = rad − distance to the segment and p the closest point, both phalanges; n_c ⟂ p's tangent sliding."""
    rng = np.random.default_rng(3)
    for _ in range(20):
        th1, psi = rng.uniform(-0.5, 2.0, 2)
        b, u = R1 * np.array([math.cos(th1), math.sin(th1)]), np.array([math.cos(psi), math.sin(psi)])
        c = rng.uniform(-0.02, 0.08, 2)
        for got, (a, end) in ((contact_law.proximal_circle(*c, 0.025, R1, *b, math.sin(th1), math.cos(th1)), (0 * b, b)),
                              (contact_law.distal_circle(*c, 0.025, L3, *b, *u), (b, b + L3 * u))):
            delta, px, py, nx, ny = got[:5]
            dist, p = closest(a, end, c)
            assert abs((0.025 - dist) - delta) < 1e-9 and np.hypot(*(p - (px, py))) < 1e-7
            assert np.allclose((nx, ny), (p - c) / dist, atol=1e-7 / dist)  # the sampling's spacing over the distance


def test_contact_force_is_spec_hunt_crossley_with_regularized_friction() -> None:
    """F_n = k δ^e (1 + d δ'), δ' = −n·ṗ; F_t = −μ F_n tanh(t·ṗ / v_s), t = n turned +90°; F_n ≤ 0: no force."""
    k, e, d, mu, vs = 1e5, 1.5, 1.5, 0.6, 1e-3
    rng = np.random.default_rng(5)
    for _ in range(200):
        delta = rng.uniform(0.0, 2e-3)
        phi = rng.uniform(0.0, 2 * math.pi)
        n, t = np.array([math.cos(phi), math.sin(phi)]), np.array([-math.sin(phi), math.cos(phi)])
        vel = rng.uniform(-0.5, 0.5, 2)
        fn = k * delta**e * (1.0 - d * n @ vel)
        force = (fn * n - mu * fn * math.tanh(t @ vel / vs) * t) if fn > 0 else np.zeros(2)
        got = contact_law.contact_force(delta, *n, *vel, k, e, d, mu, vs)
        assert got[0] == pytest.approx(max(fn, 0.0), rel=1e-12, abs=1e-12)
        assert np.allclose(got[1:], force, rtol=1e-12, atol=1e-12)
