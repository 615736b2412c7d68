"""Properties of contact stepping over random scenes (issue 12: no NaN, no energy gain,
penetration bounded), searched by Hypothesis.

A scene: one circle placed where a phalanx will be a little further along its flexion (a
random point of the proximal or distal axis at θ1 + ahead, the circle's centre ρ + R away in a
direction within ±70° of that point's motion), random k_c 1e4..1e7, d_c 0..3, μ 0..1, initial
θ1' 0..8 rad/s towards it, τ = 0, no joint damping, `auto` at dt = 1 ms, 0.08 s.

The reference is the conservation law: with τ = 0, d_c ≥ 0 and μ ≥ 0, E = T + V + V_c never
increases, and since V = ½kβ² ≥ 0, V_c ≤ E₀ bounds the penetration of any candidate:
δ ≤ δ_E = ((e+1) E₀ / k_c)^(1/(e+1)). Numerically, E may rise by the integration error of the
step in contact (auto: rk4 substeps with |s|·h ≤ 0.25): ENERGY_SLACK. A missed contact (a step
straddling a whole bounce) gained 35 % (θ1' 4.9 → 5.7 rad/s on grasp_rigid).

Friction whose regularized slope μF/v_s makes the contact too stiff for 32 rk4 substeps (μ ≳ 0.1
at v_s = 1 mm/s) gets radau, in substeps that resolve the contact's oscillatory mode
(auto.IMPLICIT_CONTACT_MODE_DT); without them radau at 1 ms gained up to 2.6e-4 E₀, and its
simplified Newton failed in the stick phase (now retried with a refreshed Jacobian).

`pytest --hypothesis-profile=long test/effects/test_contact_properties.py` searches far more scenes.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import assume, event, given
from hypothesis import strategies as st

from finger_sim import kinematics
from finger_sim.effects.contact import Contact
from finger_sim.errors import ConfigError
from finger_sim.kinematics import distal_offset
from finger_sim.model import FingerParams
from finger_sim.scene import Scene, scene_from_dict
from finger_sim.simulate import Simulator

#: Relative energy rise allowed over E₀ (max over the run of (E − E₀)/E₀), ~3× the worst measured
#: over 600 scenes: 6.4e-5 with d_c = 0, 1.1e-5 with d_c > 0 (rk4's truncation error in contact,
#: |s|·h ≤ 0.25; it converges with the substep).
ENERGY_SLACK = 2e-4
#: Safety factor on the energy bound δ_E of the penetration (sampled states; measured ≤ 0.9998 δ_E).
PENETRATION_SAFETY = 1.1
#: Energy below this (J) is round-off of a finger at rest: the relative test is against max(E₀, this).
ENERGY_FLOOR = 1e-12
RHO = (0.008, 0.007)  # phalanx capsule radii, m (the spec's defaults)
DT = 1e-3
DURATION = 0.08


def axis_point(p: FingerParams, alpha: float, theta1: float, distal: bool, frac: float) -> tuple[float, float]:
    """The point at fraction `frac` of the proximal (A→B) or distal (B→tip) axis at pose θ1, m."""
    q = kinematics.assemble(p, theta1)
    bx, by = p.r1 * math.cos(q[0]), p.r1 * math.sin(q[0])
    if not distal:
        return frac * bx, frac * by
    psi = q[2] + alpha
    return bx + frac * p.L3 * math.cos(psi), by + frac * p.L3 * math.sin(psi)


@st.composite
def contact_scenes(draw: st.DrawFn) -> Scene:
    theta0 = draw(st.floats(-0.3, 0.6))
    speed = draw(st.floats(0.0, 8.0))
    time_to_contact = draw(st.floats(0.005, 0.05))  # s, at the initial speed
    distal = draw(st.booleans())
    frac = draw(st.floats(0.3, 1.0))
    angle = draw(st.floats(-1.2, 1.2))  # rad, of the centre's direction from the point's motion
    radius = draw(st.floats(0.002, 0.03))
    stiffness = 10.0 ** draw(st.floats(4.0, 7.0))
    damping = draw(st.one_of(st.just(0.0), st.floats(0.0, 3.0)))
    friction = draw(st.one_of(st.just(0.0), st.floats(0.0, 1.0)))
    base = scene_from_dict({"model": {}})
    p, alpha = base.params, distal_offset(base.params)
    theta_c = theta0 + max(0.03, speed * time_to_contact)
    x0, y0 = axis_point(p, alpha, theta_c, distal, frac)
    x1, y1 = axis_point(p, alpha, theta_c + 1e-6, distal, frac)
    norm = math.hypot(x1 - x0, y1 - y0)
    ux, uy = (x1 - x0) / norm, (y1 - y0) / norm  # the point's direction of motion
    reach = RHO[distal] + radius
    center = [x0 + reach * (math.cos(angle) * ux - math.sin(angle) * uy),
              y0 + reach * (math.sin(angle) * ux + math.cos(angle) * uy)]
    try:
        return scene_from_dict({
            "model": {"spring_stiffness": 0.001, "phalanx_radius": list(RHO),
                      "contact": {"stiffness": stiffness, "exponent": 1.5, "damping": damping,
                                  "friction": friction, "slip_velocity": 1e-3}},
            "objects": [{"name": "cup", "type": "circle", "center": center, "radius": radius}],
            "input": {"torque": {"type": "constant", "value": 0.0}},
            "initial": {"theta1": theta0, "theta1_dot": speed},
            "duration": DURATION,
            "integrator": {"method": "auto", "dt": DT},
        })
    except ConfigError:  # the circle overlaps a phalanx at the initial pose
        assume(False)
        raise


@given(contact_scenes())
def test_contact_stepping_is_finite_gains_no_energy_and_bounds_penetration(scene: Scene):
    sim = Simulator(scene, kernel="python")
    contact = next(e for e in sim.system.elements if isinstance(e, Contact))
    xs = [(*sim.q, *sim.v)]
    for _ in range(scene.step_count):
        s = sim.step()
        xs.append((*s.q, *s.v))
    states = np.array(xs)
    assert np.all(np.isfinite(states))
    energy = np.array([sim.system.energy(tuple(x[:3]), tuple(x[3:])) for x in states])
    e0 = max(energy[0], ENERGY_FLOOR)
    assert energy.max() - energy[0] <= ENERGY_SLACK * e0
    depth = max(-min(contact.gaps(tuple(x[:3]))) for x in states)
    c = scene.contact
    bound = ((c.exponent + 1.0) * e0 * (1.0 + ENERGY_SLACK) / c.stiffness) ** (1.0 / (c.exponent + 1.0))
    assert depth <= PENETRATION_SAFETY * bound
    event(f"{sim.method}{' substeps' if sim.substeps > 1 else ''}, {'contact' if depth > 0 else 'no contact'}")


def test_a_circle_radius_of_true_is_refused():
    """YAML's `true` is an int to Python: refused where a length is expected, naming the key."""
    with pytest.raises(ConfigError, match=r"objects\[0\]\.radius: expected a finite radius > 0 \(m\), got True"):
        scene_from_dict({"objects": [{"name": "cup", "type": "circle", "center": [0.065, 0.04], "radius": True}]})
