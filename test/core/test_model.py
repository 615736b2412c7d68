"""FingerParams: the paper's Table II in SI, the spec's rod inertias, and the refusals.

References: the paper's numbers in mm and g converted here (spec §1-2), the uniform-rod
moments of inertia integrated numerically (scipy.integrate.quad of ∫ x² dm), and the
assembly condition of a four-bar written from the triangle inequality.
"""

from __future__ import annotations

import dataclasses
import math

import pytest
from scipy.integrate import quad

import reference as ref
from finger_sim.errors import ConfigError
from finger_sim.model import PAPER_THETA4, FingerParams

MM, G = 1e-3, 1e-3  # m per mm, kg per g


def test_defaults_are_the_paper_table_in_si():
    p = FingerParams()
    # paper Table II / Table I, in mm and g
    expected = {
        "r1": 46 * MM,
        "r2": 44.4 * MM,
        "r3": 7.7 * MM,
        "r4": 8.5 * MM,
        "theta4": math.pi - 0.49,
        "L3": 42.5 * MM,
        "m1": 16.91 * G,
        "m2": 2 * 0.86 * G,
        "m3": 14.16 * G,
    }
    for name, value in expected.items():
        assert getattr(p, name) == pytest.approx(value, rel=1e-15, abs=0.0), name
    assert PAPER_THETA4 == pytest.approx(math.pi - 0.49, rel=1e-16)
    # the independent reference typed the same spec numbers in
    assert (p.r1, p.r2, p.r3, p.r4, p.L3) == pytest.approx((ref.R1, ref.R2, ref.R3, ref.R4, ref.L3), rel=1e-15)
    assert (p.m1, p.m2, p.m3) == pytest.approx((ref.M1, ref.M2, ref.M3), rel=1e-15)


def _rod_inertia(mass: float, a: float, b: float) -> float:
    """∫ x² dm for a uniform rod occupying [a, b] on the x axis (x = 0 is the axis), kg·m²."""
    density = mass / (b - a)
    value, _ = quad(lambda x: density * x * x, a, b, epsabs=0.0, epsrel=1e-13)
    return value


def test_inertias_are_uniform_rods_integrated():
    p = FingerParams()
    assert p.inertia_A == pytest.approx(_rod_inertia(p.m1, 0.0, p.r1), rel=1e-13)
    assert p.inertia_D == pytest.approx(_rod_inertia(p.m2, 0.0, p.r2), rel=1e-13)
    assert p.inertia_G3 == pytest.approx(_rod_inertia(p.m3, -p.L3 / 2, p.L3 / 2), rel=1e-13)
    # magnitudes in kg·m², from the paper's masses: I_A = 16.91 g · (46 mm)² / 3
    assert p.inertia_A == pytest.approx(1.19271866667e-5, rel=1e-11)
    assert p.inertia_D == pytest.approx(1.1302464e-6, rel=1e-12)  # 1.72 g · (44.4 mm)² / 3
    assert p.inertia_G3 == pytest.approx(2.131375e-6, rel=1e-12)  # 14.16 g · (42.5 mm)² / 12


def test_params_are_frozen():
    p = FingerParams()
    with pytest.raises(dataclasses.FrozenInstanceError):
        p.r1 = 0.05  # type: ignore[misc]


@pytest.mark.parametrize(
    ("field", "value"),
    [("r1", -0.046), ("r2", 0.0), ("L3", math.nan), ("m3", -1e-3), ("m1", math.inf)],
)
def test_refuses_non_positive_or_non_finite_values(field, value):
    with pytest.raises(ConfigError) as info:
        FingerParams(**{field: value})
    assert info.value.key == f"model.geometry.{field}"
    assert str(info.value) == f"model.geometry.{field}: expected a finite value > 0, got {value!r}"


def test_refuses_non_finite_ground_angle_but_takes_any_finite_one():
    with pytest.raises(ConfigError, match=r"^model\.geometry\.theta4: expected a finite angle in rad, got nan$"):
        FingerParams(theta4=math.nan)
    assert FingerParams(theta4=-3.0).theta4 == -3.0


@pytest.mark.parametrize(
    "lengths",
    [
        {"r2": 0.010, "r3": 0.001},  # |r1 − r4| = 37.5 mm > r2 + r3 = 11 mm: the dyad never reaches B
        {"r1": 0.002, "r4": 0.002, "r2": 0.05, "r3": 0.005},  # r1 + r4 = 4 mm < |r2 − r3| = 45 mm
        {"r1": 0.03},  # assembles only far from extension: |D→B| at θ1 = 0 is below |r2 − r3|
    ],
)
def test_refuses_a_linkage_that_cannot_assemble_at_extension(lengths):
    p = {**dataclasses.asdict(FingerParams()), **lengths}
    # D = −r4 e(θ4), B = (r1, 0): the dyad r2, r3 must span D→B at θ1 = 0 (triangle inequality)
    reach = math.hypot(p["r1"] + p["r4"] * math.cos(p["theta4"]), p["r4"] * math.sin(p["theta4"]))
    assert not abs(p["r2"] - p["r3"]) < reach < p["r2"] + p["r3"]
    with pytest.raises(ConfigError) as info:
        FingerParams(**lengths)
    msg = str(info.value)
    assert info.value.key == "model.geometry"
    assert msg.startswith(f"model.geometry: the linkage cannot be assembled: at extension (θ1 = 0) the distance D→B is {reach * 1e3:.4g} mm, ")
    assert "r2 + r3" in msg if reach >= p["r2"] + p["r3"] else "|r2 − r3|" in msg
    assert msg.endswith(f"got {dict((k, p[k]) for k in ('r1', 'r2', 'r3', 'r4', 'theta4'))!r}")


def test_r1_of_30_mm_names_the_real_problem():
    """Issue 8.4: `geometry: {r1: 0.03}` used to report an assemblable range [-inf, inf] rad."""
    with pytest.raises(ConfigError) as info:
        FingerParams(r1=0.03)
    assert str(info.value) == (
        "model.geometry: the linkage cannot be assembled: at extension (θ1 = 0) the distance D→B is 22.85 mm, "
        "below the dyad's folded length |r2 − r3| = 36.7 mm; expected r1, r2, r3, r4, theta4 with "
        f"|r2 − r3| < |D→B| < r2 + r3 at θ1 = 0, got {{'r1': 0.03, 'r2': 0.0444, 'r3': 0.0077, 'r4': 0.0085, 'theta4': {PAPER_THETA4!r}}}"
    )


@pytest.mark.parametrize(
    ("field", "value", "allowed"),
    [("r1", 1e200, "[0.0001, 1] m"), ("r3", 1e-300, "[0.0001, 1] m"), ("m2", 1e300, "[1e-06, 10] kg"), ("m1", 1e-12, "[1e-06, 10] kg")],
)
def test_refuses_lengths_and_masses_beyond_any_finger(field, value, allowed):
    """r1 = 1e200 used to overflow in r1² (an OverflowError traceback); 1e-300 made the inertias 0."""
    with pytest.raises(ConfigError) as info:
        FingerParams(**{field: value})
    assert str(info.value) == f"model.geometry.{field}: expected a value in {allowed}, got {value!r}"
