"""Contact force element (spec §7): each number against an independent reference.

The references here are written again from the spec in numpy: the material points of the
phalanges, the penetration δ of a circle (closest point of a segment) and of a plane (its
ends), V_c = k δ^(e+1)/(e+1), finite differences of those, tight `solve_ivp` runs for the
energy, and a 1-D root find for the static equilibrium onto the cup.
"""

from __future__ import annotations

import math
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest
import yaml
from scipy.integrate import solve_ivp
from scipy.optimize import brentq

from finger_sim import kinematics as kin
from finger_sim.dynamics import FingerSystem
from finger_sim.effects.contact import DESIGN_FORCE, OVERLAP_TOLERANCE, Contact, build_contact
from finger_sim.effects.contact_geometry import (
    PHALANX_RADII,
    Circle,
    ContactParams,
    Plane,
    contact_params_from_dict,
    objects_from_list,
    phalanx_radii_from_value,
)
from finger_sim.errors import ConfigError
from finger_sim.effects.spring import PipSpring
from finger_sim.model import FingerParams
from finger_sim.scene import Scene

CONFIG = Path(__file__).resolve().parents[2] / "config"
P = FingerParams()
ALPHA = kin.distal_offset(P)
CUP = Circle("cup", (0.065, 0.040), 0.012)
TABLE = Plane("table", (0.0, 0.045), (0.0, -1.0))
#: touches the proximal phalanx by 0.5 mm at extension
KNUCKLE = Circle("knuckle", (0.025, 0.0195), 0.012)
#: beyond the tip on the extended axis: the closest point is clamped at the tip (0.5 mm deep)
END_CAP = Circle("end_cap", (0.0885 + 0.012 + 0.007 - 0.0005, 0.0), 0.012)
#: above B at θ1 = 85°: the proximal phalanx's B end touches it (0.5 mm deep)
SHELF = Plane("shelf", (0.0, 0.046 * math.sin(math.radians(85.0)) + 0.0075), (0.0, -1.0))
CONTACT_SCENES = ("grasp_cylinder", "grasp_impact", "grasp_rigid", "press_table")


# -- independent reference geometry (numpy, spec §1 and §7) ---------------------------------
def e(a: float) -> np.ndarray:
    return np.array([math.cos(a), math.sin(a)])


def joint_b(q) -> np.ndarray:
    return P.r1 * e(q[0])


def material_point(q, phalanx: str, coord: float) -> np.ndarray:
    """The phalanx's material point at coordinate `coord`: fraction s of A→B, or distance ℓ from B."""
    if phalanx == "proximal":
        return coord * joint_b(q)
    return joint_b(q) + coord * e(q[2] + ALPHA)


def material_coordinate(q, phalanx: str, point) -> float:
    point = np.asarray(point)
    if phalanx == "proximal":
        return float(np.linalg.norm(point)) / P.r1
    return float(np.linalg.norm(point - joint_b(q)))


def jacobian_fd(q, phalanx: str, coord: float, h: float = 1e-6) -> np.ndarray:
    """∂p/∂q of a material point by central differences, 2×3 (m/rad)."""
    cols = []
    for i in range(3):
        qp, qm = list(q), list(q)
        qp[i] += h
        qm[i] -= h
        cols.append((material_point(qp, phalanx, coord) - material_point(qm, phalanx, coord)) / (2 * h))
    return np.column_stack(cols)


def segment(q, phalanx: str) -> tuple[np.ndarray, np.ndarray, float]:
    b = joint_b(q)
    if phalanx == "proximal":
        return np.zeros(2), b, PHALANX_RADII[0]
    return b, b + P.L3 * e(q[2] + ALPHA), PHALANX_RADII[1]


def penetrations(q, objects) -> list[float]:
    """δ of every (phalanx, object) candidate (spec §7), contact or not."""
    out = []
    for obj in objects:
        for phalanx in ("proximal", "distal"):
            a, b, rho = segment(q, phalanx)
            if isinstance(obj, Circle):
                c = np.array(obj.center)
                s = np.clip(np.dot(c - a, b - a) / np.dot(b - a, b - a), 0.0, 1.0)
                out.append(rho + obj.radius - float(np.linalg.norm(a + s * (b - a) - c)))
            else:
                o, n = np.array(obj.point), np.array(obj.normal)
                ends = (b,) if phalanx == "proximal" else (a, b)  # A is fixed: no work
                out += [rho - float(n @ (end - o)) for end in ends]
    return out


def potential_ref(q, objects, k: float = 1e5, ex: float = 1.5) -> float:
    return sum(k * d ** (ex + 1) / (ex + 1) for d in penetrations(q, objects) if d > 0)


def pose(deg: float, d2: float = 0.0, d3: float = 0.0):
    q = kin.assemble(P, math.radians(deg))
    return (q[0], q[1] + d2, q[2] + d3)


def element(objects, **contact) -> Contact:
    return Contact(P, ALPHA, PHALANX_RADII, ContactParams(**contact), objects)


# (objects, pose) pairs covering each kind of candidate: circle on the distal axis, clamped at
# the tip, on the proximal phalanx; the plane at the tip and at B.
CASES = [
    ((CUP,), pose(12.5)),
    ((CUP,), pose(14.0, 1e-3, -2e-3)),
    ((CUP, TABLE), pose(17.0)),
    ((END_CAP,), pose(0.0, 0.0, 1e-3)),
    ((KNUCKLE,), pose(3.0)),
    ((TABLE,), pose(18.0, 0.0, 1e-3)),
    ((SHELF,), pose(85.0)),
]


# -- the generalized force -------------------------------------------------------------------
@pytest.mark.parametrize(("objects", "q"), CASES)
def test_virtual_work_equals_minus_gradient_of_potential(objects, q):
    c = element(objects, damping=0.0)
    assert potential_ref(q, objects) > 0.0
    assert c.potential(q) == pytest.approx(potential_ref(q, objects), rel=1e-12)
    h = 1e-7
    grad = []
    for i in range(3):
        qp, qm = list(q), list(q)
        qp[i] += h
        qm[i] -= h
        grad.append((potential_ref(qp, objects) - potential_ref(qm, objects)) / (2 * h))
    force = c.force(0.0, q, (0.0, 0.0, 0.0))
    scale = max(abs(g) for g in grad)
    assert force[1] == 0.0
    for i in range(3):
        assert force[i] == pytest.approx(-grad[i], rel=1e-6, abs=1e-6 * scale)


@pytest.mark.parametrize(("objects", "q"), CASES)
def test_generalized_force_is_jacobian_transpose_of_contact_forces(objects, q):
    """Q_c = Σ J_pᵀ F with J_p by finite differences of the material point (damping, friction on)."""
    c = element(objects, friction=0.4)
    v = kin.dependent_rates(P, q, 0.05)
    expected = np.zeros(3)
    contacts = c.contacts(0.0, q, v)
    assert contacts
    for cp in contacts:
        coord = material_coordinate(q, cp.phalanx, cp.point)
        np.testing.assert_allclose(material_point(q, cp.phalanx, coord), cp.point, atol=1e-15)
        expected += jacobian_fd(q, cp.phalanx, coord).T @ np.array(cp.force)
    np.testing.assert_allclose(c.force(0.0, q, v), expected, rtol=1e-8, atol=1e-9 * np.abs(expected).max())


@pytest.mark.parametrize(("objects", "q"), CASES)
def test_normal_force_at_rest_is_k_delta_to_the_e(objects, q):
    k, ex = 3.0e5, 1.7
    c = element(objects, stiffness=k, exponent=ex)
    deltas = sorted(d for d in penetrations(q, objects) if d > 0)
    contacts = c.contacts(0.0, q, (0.0, 0.0, 0.0))
    assert sorted(cp.penetration for cp in contacts) == pytest.approx(deltas, abs=1e-15)
    for cp in contacts:
        assert cp.normal_force == pytest.approx(k * cp.penetration**ex, rel=1e-12)
        assert math.hypot(*cp.force) == pytest.approx(cp.normal_force, rel=1e-12)
    assert c.outputs(0.0, q, (0.0, 0.0, 0.0))["grip_force"] == pytest.approx(sum(k * d**ex for d in deltas), rel=1e-12)


@pytest.mark.parametrize("theta1_dot", [0.3, -0.2])
@pytest.mark.parametrize(("objects", "q"), CASES)
def test_penetration_rate_matches_finite_difference(objects, q, theta1_dot):
    """F_n = k δ^e (1 + d δ') with δ' against a central difference of δ along q'."""
    k, d_c = 1e5, 1.5
    c = element(objects, stiffness=k, damping=d_c)
    v = kin.dependent_rates(P, q, theta1_dot)
    h = 1e-7
    plus = penetrations([q[i] + h * v[i] for i in range(3)], objects)
    minus = penetrations([q[i] - h * v[i] for i in range(3)], objects)
    rates = [(d, (a - b) / (2 * h)) for d, a, b in zip(penetrations(q, objects), plus, minus) if d > 0]
    contacts = c.contacts(0.0, q, v)
    assert len(contacts) == len(rates)
    for cp in contacts:
        _, rate = min(rates, key=lambda dr: abs(dr[0] - cp.penetration))
        expected = k * cp.penetration**1.5 * (1 + d_c * rate)
        assert cp.normal_force == pytest.approx(max(0.0, expected), rel=1e-6, abs=1e-9)


def test_friction_opposes_sliding_with_regularized_coulomb_magnitude():
    mu, vs = 0.4, 1e-3
    q = pose(13.0)
    c = element((CUP,), friction=mu, slip_velocity=vs, damping=0.0)
    for theta1_dot in (1e-3, 0.02, -0.05, 1.0):
        v = kin.dependent_rates(P, q, theta1_dot)
        (cp,) = c.contacts(0.0, q, v)
        n = np.array(cp.normal)
        t = np.array([-n[1], n[0]])
        coord = material_coordinate(q, cp.phalanx, cp.point)
        v_t = float(t @ jacobian_fd(q, cp.phalanx, coord) @ np.array(v))
        f = np.array(cp.force)
        assert f @ n == pytest.approx(cp.normal_force, rel=1e-12)
        assert f @ t == pytest.approx(-mu * cp.normal_force * math.tanh(v_t / vs), rel=1e-6)
        assert (f @ t) * v_t < 0.0


def test_gaps_are_minus_penetration_and_change_sign_at_onset():
    c = element((CUP, TABLE))
    for deg in (0.0, 11.0, 12.5, 17.0, 40.0):
        q = pose(deg)
        gaps = c.gaps(q)
        assert len(gaps) == len(c.gaps(pose(0.0)))
        assert sorted(-g for g in gaps if g < 0) == pytest.approx(sorted(d for d in penetrations(q, (CUP, TABLE)) if d > 0), abs=1e-15)
        # ∂gap/∂q against a central difference of the gaps
        h = 1e-7
        for i in range(len(gaps)):
            fd = [(c.gaps(tuple(q[j] + h * (j == m) for j in range(3)))[i] - c.gaps(tuple(q[j] - h * (j == m) for j in range(3)))[i]) / (2 * h) for m in range(3)]
            assert c.gap_gradient(i, q) == pytest.approx(fd, rel=1e-6, abs=1e-9)
        assert c.impact(0) is None


def test_wrench_is_force_and_moment_about_a():
    c = element((CUP, TABLE), friction=0.3)
    q = pose(17.0)
    v = kin.dependent_rates(P, q, 0.1)
    (prox, dist) = c.wrenches(0.0, q, v)
    expected = {"proximal": np.zeros(3), "distal": np.zeros(3)}
    for cp in c.contacts(0.0, q, v):
        fx, fy = cp.force
        expected[cp.phalanx] += (fx, fy, cp.point[0] * fy - cp.point[1] * fx)
    np.testing.assert_allclose(prox, expected["proximal"], atol=1e-15)
    np.testing.assert_allclose(dist, expected["distal"], rtol=1e-12)
    out = c.outputs(0.0, q, v)
    assert (out["contact_force_distal_x"], out["contact_force_distal_y"]) == pytest.approx(dist[:2], rel=1e-12)


# -- the stability check's view -----------------------------------------------------------------
def null_direction(q) -> tuple[float, float, float]:
    g1, g2 = FingerSystem(P).constraint_jacobian(q)
    return (g1[1] * g2[2] - g1[2] * g2[1], g1[2] * g2[0] - g1[0] * g2[2], g1[0] * g2[1] - g1[1] * g2[0])


def modal_inertia(q, n) -> float:
    m = FingerSystem(P).mass_matrix(q)
    return sum(n[i] * m[i][j] * n[j] for i in range(3) for j in range(3))


def test_modal_stiffness_in_deep_contact_is_k_e_delta_to_e_minus_1():
    q = pose(13.5)
    c = element((CUP,), stiffness=1e5)
    n = null_direction(q)
    (cp,) = c.contacts(0.0, q, (0.0, 0.0, 0.0))
    assert cp.normal_force > DESIGN_FORCE
    jn = jacobian_fd(q, cp.phalanx, material_coordinate(q, cp.phalanx, cp.point)) @ np.array(n)
    a = float(np.array(cp.normal) @ jn)
    stiffness, damping = c.modal(q, n)
    assert stiffness == pytest.approx(1e5 * 1.5 * cp.penetration**0.5 * a * a, rel=1e-6)
    assert damping == pytest.approx(1.5 * cp.normal_force * a * a, rel=1e-6)


@pytest.mark.parametrize(("stiffness", "band"), [(1e5, (400.0, 800.0)), (1e7, (2000.0, 4000.0))])
def test_modal_floor_shows_the_contact_mode_out_of_contact(stiffness, band):
    """Spec §7: ~400–700 rad/s at k_c = 1e5, 2000–4000 rad/s at k_c = 1e7, seen at every pose."""
    c = element((CUP,), stiffness=stiffness)
    for deg in (0.0, 5.0, 11.0, 11.75):  # out of contact, then touching lightly (onset ≈ 11.72°)
        q = pose(deg)
        n = null_direction(q)
        omega = math.sqrt(c.modal(q, n)[0] / modal_inertia(q, n))
        assert band[0] < omega < band[1]


# -- energy through a bounce (tight solve_ivp of the index-1 equations, restarted at events) ----
def bounce(contact: ContactParams, t_end: float = 0.08):
    """Swing from extension at θ1' = 5 rad/s into the cup, τ = 0: samples of T + V + V_c."""
    c = Contact(P, ALPHA, PHALANX_RADII, contact, (CUP,))
    system = FingerSystem(P, [PipSpring(1e-3, ALPHA), c])
    q0 = kin.assemble(P, 0.0)
    y = np.array([*q0, *kin.dependent_rates(P, q0, 5.0)])

    def rhs(t, y):
        acc, _ = system.accelerations(t, tuple(y[:3]), tuple(y[3:]), 0.0)
        return [*y[3:], *acc]

    n_gaps = len(c.gaps(q0))
    inside = [False] * n_gaps
    t, energies, events = 0.0, [], []
    while t < t_end:
        fns = []
        for i in range(n_gaps):
            fn = lambda t, y, i=i: c.gaps(tuple(y[:3]))[i]  # noqa: E731
            fn.terminal, fn.direction = True, (1.0 if inside[i] else -1.0)
            fns.append(fn)
        sol = solve_ivp(rhs, (t, t_end), y, method="DOP853", rtol=1e-12, atol=1e-14, events=fns, dense_output=True)
        assert sol.success
        for s in np.linspace(t, sol.t[-1], 400):
            ys = sol.sol(s)
            energies.append(system.energy(tuple(ys[:3]), tuple(ys[3:])))
        hit = [i for i in range(n_gaps) if sol.t_events[i].size]
        if hit:
            inside[hit[0]] = not inside[hit[0]]
            events.append((sol.t[-1], inside[hit[0]]))
        t, y = sol.t[-1], sol.y[:, -1]
    return np.array(energies), events


def test_energy_is_conserved_through_a_bounce_without_damping():
    energies, events = bounce(ContactParams(damping=0.0, friction=0.0))
    assert [inside for _, inside in events] == [True, False]  # onset, then release
    assert np.max(np.abs(energies - energies[0])) / energies[0] < 1e-8


def test_energy_never_increases_with_hunt_crossley_damping():
    energies, events = bounce(ContactParams(damping=1.5))
    assert [inside for _, inside in events] == [True, False]
    assert np.all(np.diff(energies) <= 1e-10 * energies[0])
    assert energies[-1] < 0.9 * energies[0]  # the damping took energy out


# -- static equilibrium onto the cup (grasp_cylinder), independent of the element -------------
def equilibrium(scene: dict) -> tuple[float, float]:
    """(θ1, δ) at rest against the circle: the root of dU/dθ1, U = −τθ1 + ½kβ² + V_c along the
    linkage (spec §7), on closed-form kinematics and the numpy geometry above."""
    model = scene["model"]
    tau = scene["input"]["torque"]["value"]
    k_spring = model["spring_stiffness"]
    kc, ex = model["contact"]["stiffness"], model["contact"]["exponent"]
    (obj,) = objects_from_list(scene["objects"])
    c = np.array(obj.center)
    rho = model["phalanx_radius"][1]

    def delta_and_rate(theta1: float) -> tuple[float, float]:
        """δ of the distal capsule and dδ/dθ1 along the linkage (its material point moves)."""
        q = kin.assemble(P, theta1)
        rates = kin.dependent_rates(P, q, 1.0)
        b, u = joint_b(q), e(q[2] + ALPHA)
        ell = float(np.clip((c - b) @ u, 0.0, P.L3))
        p = b + ell * u
        n = (p - c) / np.linalg.norm(p - c)
        dp = P.r1 * rates[0] * np.array([-math.sin(q[0]), math.cos(q[0])]) + ell * rates[2] * np.array([-u[1], u[0]])
        return rho + obj.radius - float(np.linalg.norm(p - c)), -float(n @ dp)

    def du(theta1: float) -> float:
        q = kin.assemble(P, theta1)
        beta = q[2] + ALPHA - q[0]
        dbeta = kin.dependent_rates(P, q, 1.0)[2] - 1.0
        d, dd = delta_and_rate(theta1)
        return -tau + k_spring * beta * dbeta + (kc * d**ex * dd if d > 0 else 0.0)

    onset = brentq(lambda t1: delta_and_rate(t1)[0], 0.0, math.radians(20.0), xtol=1e-15)
    theta = brentq(du, onset, onset + 0.1, xtol=1e-15, rtol=4 * np.finfo(float).eps)
    return theta, delta_and_rate(theta)[0]


def test_equilibrium_reference_is_the_minimum_and_balances_the_element():
    scene = yaml.safe_load((CONFIG / "grasp_cylinder.yaml").read_text())
    theta, delta = equilibrium(scene)
    model = scene["model"]
    tau, k_spring = scene["input"]["torque"]["value"], model["spring_stiffness"]

    def energy(theta1: float) -> float:
        q = kin.assemble(P, theta1)
        beta = q[2] + ALPHA - q[0]
        return -tau * theta1 + 0.5 * k_spring * beta**2 + potential_ref(q, (CUP,))

    for h in (1e-3, 1e-5):
        assert energy(theta - h) > energy(theta) < energy(theta + h)
    assert 0.0 < delta < 1e-3
    # the element at that pose: τ e1 + Q_spring + Q_c has no component along the linkage's motion
    q = kin.assemble(P, theta)
    contact = Contact(P, ALPHA, tuple(model["phalanx_radius"]), contact_params_from_dict(model["contact"]), (CUP,))
    total = np.array([tau, 0.0, 0.0]) + PipSpring(k_spring, ALPHA).force(0.0, q, (0, 0, 0)) + contact.force(0.0, q, (0, 0, 0))
    n = np.array(null_direction(q))
    assert abs(total @ n) < 1e-9 * abs(tau * n[0])
    grip = contact.outputs(0.0, q, (0.0, 0.0, 0.0))["grip_force"]
    assert grip == pytest.approx(model["contact"]["stiffness"] * delta ** model["contact"]["exponent"], rel=1e-12)


# -- scenes ------------------------------------------------------------------------------------
@pytest.mark.parametrize("name", CONTACT_SCENES)
def test_contact_scene_objects_are_reachable_and_clear_at_start(name):
    data = yaml.safe_load((CONFIG / f"{name}.yaml").read_text())
    assert data["description"]
    model = data["model"]
    c = Contact(
        P,
        ALPHA,
        phalanx_radii_from_value(model["phalanx_radius"]),
        contact_params_from_dict(model["contact"]),
        objects_from_list(data["objects"]),
    )
    q0 = kin.assemble(P, data["initial"]["theta1"])
    c.check_clearance(q0)
    assert min(c.gaps(q0)) > 0.0
    # some MCP angle in 0..90° touches every object
    touching = {cp.object for deg in range(91) for cp in c.contacts(0.0, pose(float(deg)), (0.0, 0.0, 0.0))}
    assert touching == {obj["name"] for obj in data["objects"]}


def test_builder_is_absent_without_objects_and_uses_the_spec_defaults():
    assert build_contact(Scene()) is None
    built = build_contact(SimpleNamespace(params=P, objects=(CUP,)))
    assert isinstance(built, Contact)
    assert built.contact == ContactParams(1.0e5, 1.5, 1.5, 0.0, 1.0e-3)
    assert built.radii == (0.008, 0.007)


# -- validation ----------------------------------------------------------------------------------
@pytest.mark.parametrize(
    ("objects", "key"),
    [
        ([{"name": "a", "type": "circle", "center": [0, 0.05], "radius": 0.01}, {"name": "b", "type": "circle", "center": [0, 0.05], "radius": 0.0}], "objects[1].radius"),
        ([{"name": "a", "type": "circle", "center": [0, 0.05], "radius": -1}], "objects[0].radius"),
        ([{"name": "t", "type": "plane", "point": [0, 0.05], "normal": [0, 0]}], "objects[0].normal"),
        ([{"name": "t", "type": "box", "point": [0, 0.05]}], "objects[0].type"),
        ([{"name": "t", "type": "plane", "point": [0, 0.05]}], "objects[0].normal"),
        ([{"name": "t", "type": "plane", "point": [0, "x"], "normal": [0, 1]}], "objects[0].point[1]"),
        ([{"name": "a", "type": "circle", "center": [0, 0.05], "radius": 0.01, "colour": "red"}], "objects[0]"),
        ([{"name": "a", "type": "circle", "center": [0, 0.05], "radius": 0.01}, {"name": "a", "type": "plane", "point": [0, 0.05], "normal": [0, 1]}], "objects[1].name"),
        ({"name": "a"}, "objects"),
    ],
)
def test_bad_objects_are_refused_naming_the_key(objects, key):
    with pytest.raises(ConfigError) as info:
        objects_from_list(objects)
    assert info.value.key == key
    assert str(info.value).startswith(f"{key}: expected ")


def test_plane_normal_is_normalized_and_empty_lists_mean_no_objects():
    (plane,) = objects_from_list([{"name": "t", "type": "plane", "point": [0, 0.05], "normal": [0, -2.0]}])
    assert plane.normal == (0.0, -1.0)
    assert objects_from_list(None) == () == objects_from_list([])


@pytest.mark.parametrize(
    ("value", "key"),
    [({"stiffness": 0.0}, "model.contact.stiffness"), ({"exponent": 0.5}, "model.contact.exponent"), ({"damping": -1.0}, "model.contact.damping"), ({"slip_velocity": 0}, "model.contact.slip_velocity"), ({"friction": "high"}, "model.contact.friction"), ({"stifness": 1.0}, "model.contact")],
)
def test_bad_contact_parameters_are_refused_naming_the_key(value, key):
    with pytest.raises(ConfigError) as info:
        contact_params_from_dict(value)
    assert info.value.key == key


@pytest.mark.parametrize(("value", "key"), [([0.008], "model.phalanx_radius"), ([0.008, 0.0], "model.phalanx_radius[1]"), ([-1, 0.007], "model.phalanx_radius[0]")])
def test_bad_phalanx_radii_are_refused_naming_the_key(value, key):
    with pytest.raises(ConfigError) as info:
        phalanx_radii_from_value(value)
    assert info.value.key == key


@pytest.mark.parametrize(("obj", "phalanx"), [(Circle("mug", (0.075, 0.005), 0.012), "distal"), (Plane("palm", (-0.007, 0.0), (1.0, 0.0)), "proximal")])
def test_an_object_overlapping_a_phalanx_at_the_start_is_refused(obj, phalanx):
    c = element((CUP, obj))
    with pytest.raises(ConfigError) as info:
        c.check_clearance(kin.assemble(P, 0.0))
    assert info.value.key == "objects[1]" and phalanx in str(info.value)
    # within the tolerance it is accepted
    touching = element((Circle("cup", (0.0885 + 0.019 - 0.5 * OVERLAP_TOLERANCE, 0.0), 0.012),))
    touching.check_clearance(kin.assemble(P, 0.0))
