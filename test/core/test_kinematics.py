"""Four-bar kinematics against spec §1's check values and an independent Newton assembly.

References: the spec's numbers (θ_ext, toggles, PIP range, tip at extension) to the
digits it prints; `reference.py`'s Newton solve of Φ = 0 continued from the spec's
extended pose and its brentq toggle search; closed-form link lengths; and central
finite differences for the rate and Jacobian functions.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

import reference as ref
from finger_sim import kinematics as kin
from finger_sim.errors import ConfigError
from finger_sim.model import FingerParams

P = FingerParams()
ALPHA = kin.distal_offset(P)
FLEX_TOGGLE, EXT_TOGGLE = kin.toggle_angles(P)
#: θ1 samples strictly inside the assemblable range (rad), both toggles avoided by 1e-3 rad.
THETA1 = np.linspace(EXT_TOGGLE + 1e-3, FLEX_TOGGLE - 1e-3, 41)


def agrees_to_shown_digits(value: float, shown: float, decimals: int) -> bool:
    """`value` rounds to `shown` at `decimals` places (the spec's 'to the digits shown')."""
    return abs(value - shown) <= 0.5 * 10.0**-decimals


# -- spec §1 check values ---------------------------------------------------------------
def test_extended_pose_matches_spec():
    deg = np.degrees(kin.extended_pose(P))
    for got, shown in zip(deg, ref.THETA_EXT_DEG):
        assert agrees_to_shown_digits(got, shown, 4), (got, shown)
    # and the independent Newton assembly to round-off
    np.testing.assert_allclose(kin.extended_pose(P), ref.theta_ext(), rtol=0, atol=1e-13)


def test_toggle_angles_match_spec_and_reference():
    assert agrees_to_shown_digits(math.degrees(FLEX_TOGGLE), ref.TOGGLES_DEG[0], 4)
    assert agrees_to_shown_digits(math.degrees(EXT_TOGGLE), ref.TOGGLES_DEG[1], 4)
    assert (FLEX_TOGGLE, EXT_TOGGLE) == pytest.approx(ref.toggles(), abs=1e-12)
    assert kin.assembly_range(P) == (EXT_TOGGLE, FLEX_TOGGLE)


@pytest.mark.parametrize("toggle", [0, 1])
def test_at_a_toggle_coupler_and_short_edge_are_collinear(toggle):
    """Closed form: at a toggle |D→B| = r2 + r3 and θ2 = θ3 (mod 2π); Φ_q keeps rank 2."""
    theta1 = kin.toggle_angles(P)[toggle]
    d = np.array([-P.r4 * math.cos(P.theta4), -P.r4 * math.sin(P.theta4)])
    b = P.r1 * np.array([math.cos(theta1), math.sin(theta1)])
    assert np.linalg.norm(b - d) == pytest.approx(P.r2 + P.r3, rel=1e-14)
    q = kin.assemble(P, theta1)
    assert math.sin(q[2] - q[1]) == pytest.approx(0.0, abs=1e-7)  # sqrt(round-off) of the acos at ±1
    sv = np.linalg.svd(ref.phi_q(q), compute_uv=False)
    assert sv[1] > 1e-3  # m; rank 2 with margin (measured 3.9e-3): the DAE is regular at the toggle
    with pytest.raises(ConfigError, match="away from the toggle"):
        kin.dependent_rates(P, (theta1, q[1], q[1]), 1.0)


def test_pip_range_over_mcp_0_to_90_degrees():
    beta0 = kin.pip_angle(kin.assemble(P, 0.0), ALPHA)
    beta90 = kin.pip_angle(kin.assemble(P, math.pi / 2), ALPHA)
    assert beta0 == pytest.approx(0.0, abs=1e-15)
    assert agrees_to_shown_digits(math.degrees(beta90 - beta0), 102.4, 1)
    assert beta90 == pytest.approx(ref.beta(ref.assemble(math.pi / 2)), abs=1e-12)


def test_fingertip_at_extension_is_the_straight_finger():
    tip = kin.fingertip(P, kin.extended_pose(P), ALPHA)
    # closed form: straight finger along +X, |A tip| = r1 + L3 = 88.5 mm
    assert (tip.x, tip.y) == pytest.approx((0.0885, 0.0), abs=1e-15)
    assert tip.psi == pytest.approx(0.0, abs=1e-15)
    assert ALPHA == pytest.approx(math.radians(128.0309), abs=0.5e-4 * math.pi / 180)


# -- the assembly against the independent Newton solve ----------------------------------
def test_assembly_matches_newton_continuation_over_the_range():
    worst = 0.0
    for theta1 in THETA1:
        q = kin.assemble(P, float(theta1))
        assert kin.constraint_norm(P, q) < 5e-17
        diff = np.array(q) - ref.assemble(float(theta1))
        worst = max(worst, float(np.max(np.abs(np.angle(np.exp(1j * diff))))))  # equal modulo 2π
    # measured 1.2e-13 rad (the acos near the toggles amplifies round-off)
    assert worst < 1e-11


def test_the_spec_branch_flexes_the_distal_joint_and_the_other_does_not():
    beta = [kin.pip_angle(kin.assemble(P, a), ALPHA) for a in np.linspace(0.0, math.pi / 2, 19)]
    assert np.all(np.diff(beta) > 0.0)  # PIP flexes monotonically with the MCP
    other = kin.assemble(P, math.pi / 2, branch=-1)
    other0 = kin.assemble(P, 0.0, branch=-1)
    assert kin.constraint_norm(P, other) < 5e-17
    # the mirror branch turns the distal joint the wrong way (measured −97.2°)
    assert kin.pip_angle(other, ALPHA) - kin.pip_angle(other0, ALPHA) < -math.radians(90)


@pytest.mark.parametrize("theta1", [math.radians(105.0), math.radians(-161.0), 3.0])
def test_assemble_refuses_outside_the_assemblable_range(theta1):
    with pytest.raises(ConfigError) as info:
        kin.assemble(P, theta1)
    msg = str(info.value)
    assert msg.startswith("initial.theta1: expected an MCP angle in the assemblable range")
    assert f"[{EXT_TOGGLE:.6f}, {FLEX_TOGGLE:.6f}] rad" in msg
    assert msg.endswith(f"got {theta1!r}")


def test_dependent_rates_against_finite_differences_and_the_reference():
    worst_fd = worst_ref = 0.0
    for theta1 in THETA1[1:-1:4]:
        theta1 = float(theta1)
        q = kin.assemble(P, theta1)
        w = np.array(kin.dependent_rates(P, q, 2.5))
        h = 1e-6
        fd = (np.array(kin.assemble(P, theta1 + h)) - np.array(kin.assemble(P, theta1 - h))) / (2 * h) * 2.5
        worst_fd = max(worst_fd, float(np.max(np.abs(w - fd)) / np.max(np.abs(w))))
        worst_ref = max(worst_ref, float(np.max(np.abs(w - ref.rates(q, 2.5)))) / float(np.max(np.abs(w))))
        assert np.max(np.abs(ref.phi_q(q) @ w)) < 1e-15  # tangent to Φ = 0
    assert worst_fd < 1e-7  # central difference: h² truncation plus round-off/h
    assert worst_ref < 1e-12


def test_fingertip_jacobian_against_finite_differences():
    rng = np.random.default_rng(7)
    for _ in range(10):
        q = rng.uniform(-math.pi, math.pi, 3)
        jac = np.array(kin.fingertip_jacobian(P, tuple(q), ALPHA))
        fd = np.empty((2, 3))
        for j in range(3):
            dq = np.zeros(3)
            dq[j] = 1e-6
            plus = kin.fingertip(P, tuple(q + dq), ALPHA)
            minus = kin.fingertip(P, tuple(q - dq), ALPHA)
            fd[:, j] = (np.array(plus[:2]) - np.array(minus[:2])) / 2e-6
        np.testing.assert_allclose(jac, fd, rtol=0, atol=1e-10)
        np.testing.assert_allclose(jac, ref.tip_jacobian(q), rtol=0, atol=1e-15)


def test_points_have_the_link_lengths():
    for theta1 in THETA1[::5]:
        q = kin.assemble(P, float(theta1))
        pts = {k: np.array(v) for k, v in kin.points(P, q, ALPHA).items()}
        dist = lambda a, b: float(np.linalg.norm(pts[a] - pts[b]))  # noqa: E731
        assert dist("A", "B") == pytest.approx(P.r1, rel=1e-14)
        assert dist("D", "C") == pytest.approx(P.r2, rel=1e-14)
        assert dist("C", "B") == pytest.approx(P.r3, rel=1e-12)
        assert dist("D", "A") == pytest.approx(P.r4, rel=1e-14)
        assert dist("B", "tip") == pytest.approx(P.L3, rel=1e-14)
        np.testing.assert_allclose(pts["tip"], ref.tip(q), rtol=0, atol=1e-15)


def test_fingertip_trajectory_spans_the_mcp_range():
    """The workspace curve starts at the extended tip (0.0885, 0) m and ends at the θ1 = 90°
    pose computed independently by the reference's Newton assembly."""
    from finger_sim.kinematics import fingertip_trajectory

    poses = fingertip_trajectory(FingerParams(), (0.0, math.pi / 2), samples=31)
    assert len(poses) == 31
    assert (poses[0].x, poses[0].y, poses[0].psi) == pytest.approx((0.0885, 0.0, 0.0), abs=1e-15)
    q90 = ref.assemble(math.pi / 2)
    psi = q90[2] + ref.ALPHA
    tip = (ref.R1 * math.cos(q90[0]) + ref.L3 * math.cos(psi), ref.R1 * math.sin(q90[0]) + ref.L3 * math.sin(psi))
    assert (poses[-1].x, poses[-1].y) == pytest.approx(tip, abs=1e-12)


# -- geometries whose folded toggle bounds the range (issue 8.4) -----------------------
@pytest.mark.parametrize("r1", [0.0451, 0.045, 0.0448])
def test_assembly_range_is_bounded_by_the_folded_toggle_when_r1_is_short(r1):
    """Below r1 = r4 + |r2 − r3| = 45.2 mm the dyad cannot fold short enough near θ1 = θ4 − π:
    the extension side ends where |D→B| = |r2 − r3|. The range used to ignore that limit
    (r1 = 45 mm failed late, inside the stability check's assembly)."""
    from scipy.optimize import brentq

    p = FingerParams(r1=r1)
    lo, hi = kin.assembly_range(p)

    def distance(theta1: float) -> float:  # |B − D| from the points, m
        b, d = (r1 * math.cos(theta1), r1 * math.sin(theta1)), (-p.r4 * math.cos(p.theta4), -p.r4 * math.sin(p.theta4))
        return math.dist(b, d)

    folded, stretched = abs(p.r2 - p.r3), p.r2 + p.r3
    # independent ends: the roots of |D→B| − limit between extension and the shortest (θ1 = θ4 − π)
    # and the longest (θ1 = θ4) distance
    ref_lo = brentq(lambda a: distance(a) - folded, p.theta4 - math.pi, 0.0, xtol=1e-14)
    ref_hi = brentq(lambda a: distance(a) - stretched, 0.0, p.theta4, xtol=1e-14)
    assert (lo, hi) == pytest.approx((ref_lo, ref_hi), abs=1e-9)
    for end in (lo, hi):  # assembles just inside, not just outside, and is a toggle there
        q = kin.assemble(p, end + math.copysign(1e-7, -end))
        assert abs(math.sin(q[2] - q[1])) < 1e-3
        with pytest.raises(ConfigError):
            kin.assemble(p, end + math.copysign(1e-7, end))
    # the whole range assembles now, e.g. for the stability check's sweep
    from finger_sim.scene import scene_from_dict
    from finger_sim.stability import fastest_mode

    scene = scene_from_dict({"model": {"geometry": {"r1": r1}, "spring_stiffness": 0.001}})
    assert abs(fastest_mode(scene.build_system(), (lo, hi))) > 0.0
