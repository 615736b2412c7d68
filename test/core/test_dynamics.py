"""The equations of motion (spec §2-5) against slow references written separately.

- `FingerSystem.accelerations` (the scalar Schur-complement fast path) against a dense
  numpy 5×5 KKT solve of spec §4 (`reference.kkt`) at random states;
- M(q) and h(q, q') against a finite-difference Lagrangian: T(q, q') of spec §2 coded
  from the link velocities (complex-step derivative of the distal centre of mass),
  M = ∂²T/∂q'², h = (∂²T/∂q'∂q) q' − ∂T/∂q;
- every force element against −∂V/∂q (conservative) or −∂R/∂q' (damping) by finite
  differences of the spec's potentials;
- the paper's run: the spec §5 check values, the work-energy balance ΔE = ∫ τ θ1' dt,
  the fixed time grid.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
import yaml
from scipy.integrate import quad

import reference as ref
from finger_sim.dynamics import FingerSystem
from finger_sim.effects.damping import JointDamping
from finger_sim.effects.gravity import Gravity
from finger_sim.effects.spring import PipSpring
from finger_sim.effects.tip_force import TipForce
from finger_sim.kinematics import assemble, assembly_range, distal_offset
from finger_sim.model import FingerParams
from finger_sim.scene import load_scene
from finger_sim.simulate import simulate

P = FingerParams()
ALPHA = distal_offset(P)
LO, HI = assembly_range(P)
#: All four force elements on, with values of a plausible size (SI).
EFFECTS = ref.Effects(k=0.003, c=0.002, g=(3.0, -9.81), f=(0.5, -1.2))
#: Spec §5: θ at t = 0.3 s of the paper's run, deg, to the digits shown.
PAPER_THETA_END_DEG = (34.34, 54.39, -53.02)


def full_system() -> FingerSystem:
    fx = EFFECTS
    return FingerSystem(
        P,
        [PipSpring(fx.k, ALPHA), JointDamping(fx.c), Gravity(*fx.g, P, ALPHA), TipForce(*fx.f, P, ALPHA)],
    )


def random_states(n: int, seed: int, on_manifold: bool = True):
    """(q, v, τ): q on the spec's branch (or anywhere), v anywhere (h and γ are defined for any v).

    States are only sample points; the core's closed-form assembly (checked against the
    reference's Newton solve in test_kinematics) is used because it is 100× faster.
    """
    rng = np.random.default_rng(seed)
    for _ in range(n):
        if on_manifold:
            q = np.array(assemble(P, rng.uniform(LO + 1e-3, HI - 1e-3)))
        else:
            q = rng.uniform(-math.pi, math.pi, 3)
        yield q, rng.normal(0.0, 20.0, 3), rng.normal(0.0, 0.01)


# -- the fast path against the dense KKT solve ------------------------------------------
@pytest.mark.parametrize("on_manifold", [True, False])
def test_accelerations_match_the_dense_kkt_solve(on_manifold):
    """Measured over 1500 states each. Relative to max|q''|: worst 5.0e-12 on the manifold,
    1.8e-11 off it (random q); λ 5e-13; median 1e-14. The worst cases are states where
    the constraint forces cancel most of the applied ones (|M⁻¹(Q − h)| ≈ 700 |q''|); an
    exact rational solve of the same float system shows the dense LU within 3e-14 and the
    fast Schur path within 1.8e-11 there: the range-space elimination loses those digits.
    Relative to max|M⁻¹(Q − h)|, the size of what the solve combines, the fast path is
    within 6.5e-13 everywhere (KKT condition number 1e3-2e4).
    """
    system = full_system()
    worst_a = worst_terms = worst_l = 0.0
    for q, v, tau in random_states(300, seed=1 if on_manifold else 2, on_manifold=on_manifold):
        a, lam = system.accelerations(0.0, tuple(q), tuple(v), tau)
        a_ref, lam_ref = ref.kkt(q, v, tau, EFFECTS)
        unconstrained = np.linalg.solve(ref.mass(q), EFFECTS.force(q, v, tau) - ref.coriolis(q, v))
        err = float(np.max(np.abs(np.array(a) - a_ref)))
        worst_a = max(worst_a, err / np.max(np.abs(a_ref)))
        worst_terms = max(worst_terms, err / np.max(np.abs(unconstrained)))
        worst_l = max(worst_l, float(np.max(np.abs(np.array(lam) - lam_ref)) / np.max(np.abs(lam_ref))))
    assert worst_terms < 2e-12
    assert worst_a < (2e-11 if on_manifold else 5e-11)
    assert worst_l < 5e-12


def test_accelerations_near_the_toggles_stay_accurate():
    """Φ_q keeps rank 2 at the toggles: the index-1 solve does not degrade there (measured 1.4e-13)."""
    system = full_system()
    rng = np.random.default_rng(3)
    for theta1 in (HI - 1e-9, HI, LO + 1e-9, LO):
        q = assemble(P, theta1)
        v = rng.normal(0.0, 20.0, 3)
        a, lam = system.accelerations(0.0, q, tuple(v), 0.01)
        a_ref, lam_ref = ref.kkt(q, v, 0.01, EFFECTS)
        np.testing.assert_allclose(a, a_ref, rtol=0, atol=1e-12 * np.max(np.abs(a_ref)))
        np.testing.assert_allclose(lam, lam_ref, rtol=0, atol=1e-12 * np.max(np.abs(lam_ref)))


def test_accelerations_keep_the_constraints_to_second_order():
    """Φ_q q'' = γ (the acceleration-level constraint), checked with the reference's Φ_q, γ,
    relative to |Φ_q||q''| + |γ| (measured 2.6e-12)."""
    system = full_system()
    for q, v, tau in random_states(100, seed=4):
        a = np.array(system.accelerations(0.0, tuple(q), tuple(v), tau)[0])
        g = ref.phi_q(q)
        scale = np.abs(g) @ np.abs(a) + np.abs(ref.gamma(q, v))
        assert np.all(np.abs(g @ a - ref.gamma(q, v)) < 1e-11 * scale)


# -- M and h against a finite-difference Lagrangian -------------------------------------
def kinetic_energy_spec(q: np.ndarray, v: np.ndarray) -> float:
    """T of spec §2: ½ I_A θ1'² + ½ I_D θ2'² + ½ m3 |v_G3|² + ½ I_G3 θ3'².

    v_G3 = d/dt (B + (L3/2) e(ψ)) by a complex-step derivative along q' (exact to round-off).
    """
    step = 1e-30
    qc = np.asarray(q, dtype=complex) + 1j * step * np.asarray(v, dtype=float)
    g3 = ref.R1 * np.array([np.cos(qc[0]), np.sin(qc[0])]) + 0.5 * ref.L3 * np.array(
        [np.cos(qc[2] + ref.ALPHA), np.sin(qc[2] + ref.ALPHA)]
    )
    v_g3 = g3.imag / step
    return 0.5 * (ref.I_A * v[0] ** 2 + ref.I_D * v[1] ** 2 + ref.M3 * v_g3 @ v_g3 + ref.I_G3 * v[2] ** 2)


def mass_fd(q: np.ndarray) -> np.ndarray:
    """M = ∂²T/∂q'² by polarization (T is exactly quadratic in q', so this is exact to round-off)."""
    eye = np.eye(3)
    m = np.empty((3, 3))
    for i in range(3):
        m[i, i] = 2.0 * kinetic_energy_spec(q, eye[i])
        for j in range(i):
            m[i, j] = m[j, i] = (
                kinetic_energy_spec(q, eye[i] + eye[j]) - kinetic_energy_spec(q, eye[i]) - kinetic_energy_spec(q, eye[j])
            )
    return m


def derivative(f, x: np.ndarray, d: np.ndarray, eps: float = 1e-3):
    """Directional derivative of f at x along d: 5-point central difference of step eps along d/|d|.

    Truncation ~ eps⁴/30 and round-off ~ 1e-16/eps, relative: ~1e-13 at eps = 1e-3 rad.
    """
    norm = float(np.linalg.norm(d))
    u = np.asarray(d) / norm
    return norm * (8.0 * (f(x + eps * u) - f(x - eps * u)) - (f(x + 2 * eps * u) - f(x - 2 * eps * u))) / (12.0 * eps)


def coriolis_fd(q: np.ndarray, v: np.ndarray) -> np.ndarray:
    """h = d/dt(∂T/∂q') − ∂T/∂q at q'' = 0 = (∂(M q')/∂q) q' − ∂T/∂q."""
    dp = derivative(lambda x: mass_fd(x) @ v, q, v)
    dT = np.array([derivative(lambda x: kinetic_energy_spec(x, v), q, e) for e in np.eye(3)])
    return dp - dT


def test_mass_matrix_matches_the_lagrangian():
    system = FingerSystem(P)
    for q, _, _ in random_states(20, seed=5, on_manifold=False):
        m_fd = mass_fd(q)
        np.testing.assert_allclose(system.mass_matrix(tuple(q)), m_fd, rtol=0, atol=1e-13 * np.max(m_fd))
        np.testing.assert_allclose(ref.mass(q), m_fd, rtol=0, atol=1e-13 * np.max(m_fd))
        assert system.kinetic_energy(tuple(q), (0.3, -1.0, 2.0)) == pytest.approx(
            kinetic_energy_spec(q, np.array([0.3, -1.0, 2.0])), rel=1e-13
        )


def test_coriolis_terms_match_the_lagrangian():
    """h of the fast path, recovered as Φ_qᵀλ − M q'' from a run with no forces, against h_FD.

    Errors are relative to ‖M‖‖q'‖², the size of the velocity-product terms: the finite
    difference of p = M q' loses the digits of p, and h can be much smaller than M q'².
    Measured: h_FD − h_ref 3e-13, h_core − h_FD 3e-13 on that scale; h_core against the
    reference's analytic m3 J_G3ᵀ J̇_G3 q' 5e-12 relative to |h|.
    """
    system = FingerSystem(P)
    worst_core = worst_ref = worst_core_ref = 0.0
    for q, v, _ in random_states(20, seed=6, on_manifold=False):
        h_fd = coriolis_fd(q, v)
        a, lam = system.accelerations(0.0, tuple(q), tuple(v), 0.0)
        g = np.array(system.constraint_jacobian(tuple(q)))
        m = np.array(system.mass_matrix(tuple(q)))
        h_core = g.T @ np.array(lam) - m @ np.array(a)
        h_ref = ref.coriolis(q, v)
        scale = np.max(np.abs(m)) * float(v @ v)
        worst_core = max(worst_core, float(np.max(np.abs(h_core - h_fd))) / scale)
        worst_ref = max(worst_ref, float(np.max(np.abs(h_ref - h_fd))) / scale)
        worst_core_ref = max(worst_core_ref, float(np.max(np.abs(h_core - h_ref) / np.max(np.abs(h_ref)))))
        # the coupler's row of h vanishes (spec §2: h = (c sin u θ3'², 0, −c sin u θ1'²))
        assert abs(h_fd[1]) < 1e-12 * scale
    assert worst_ref < 1e-11
    assert worst_core < 1e-11
    assert worst_core_ref < 5e-11


def test_accelerations_match_the_kkt_solve_built_from_the_lagrangian():
    system = FingerSystem(P)
    for q, v, tau in random_states(10, seed=8):
        kkt = np.zeros((5, 5))
        kkt[:3, :3] = mass_fd(q)
        kkt[:3, 3:] = -ref.phi_q(q).T
        kkt[3:, :3] = ref.phi_q(q)
        rhs = np.concatenate([np.array([tau, 0.0, 0.0]) - coriolis_fd(q, v), ref.gamma(q, v)])
        sol = np.linalg.solve(kkt, rhs)
        a, _ = system.accelerations(0.0, tuple(q), tuple(v), tau)
        np.testing.assert_allclose(a, sol[:3], rtol=0, atol=1e-10 * np.max(np.abs(sol[:3])))


# -- force elements ---------------------------------------------------------------------
@pytest.mark.parametrize(
    ("element", "effects"),
    [
        (PipSpring(0.003, ALPHA), ref.Effects(k=0.003)),
        (Gravity(3.0, -9.81, P, ALPHA), ref.Effects(k=0.0, g=(3.0, -9.81))),
        (TipForce(0.5, -1.2, P, ALPHA), ref.Effects(k=0.0, f=(0.5, -1.2))),
    ],
    ids=["spring", "gravity", "tip_force"],
)
def test_conservative_forces_are_minus_the_potential_gradient(element, effects):
    for q, v, _ in random_states(10, seed=9, on_manifold=False):
        grad = np.array([derivative(effects.potential, q, e) for e in np.eye(3)])
        force = np.array(element.force(0.0, tuple(q), tuple(v)))
        np.testing.assert_allclose(force, -grad, rtol=0, atol=1e-10 * max(1e-6, np.max(np.abs(grad))))
        # the element's own potential is the spec's (up to the constant of the gravity datum)
        assert element.potential(tuple(q)) == pytest.approx(effects.potential(q), rel=1e-12, abs=1e-18)


def test_spring_closed_form_and_damping_is_minus_the_rayleigh_gradient():
    spring, damper = PipSpring(0.001, ALPHA), JointDamping(0.05)
    for q, v, _ in random_states(10, seed=10):
        beta = q[2] + ref.ALPHA - q[0]
        assert spring.force(0.0, tuple(q), tuple(v)) == pytest.approx((1e-3 * beta, 0.0, -1e-3 * beta), abs=1e-17)

        def rayleigh(w: np.ndarray) -> float:
            return 0.5 * 0.05 * (w[0] ** 2 + w[1] ** 2 + (w[2] - w[0]) ** 2)

        grad = np.array([derivative(rayleigh, v, e, eps=0.5) for e in np.eye(3)])  # R is quadratic: exact
        np.testing.assert_allclose(damper.force(0.0, tuple(q), tuple(v)), -grad, rtol=1e-12, atol=1e-14)
        # damping only dissipates: Q_damp·q' = −2R ≤ 0
        assert np.dot(damper.force(0.0, tuple(q), tuple(v)), v) == pytest.approx(-2 * rayleigh(v), rel=1e-12)


def test_energy_is_kinetic_plus_all_potentials():
    system = full_system()
    for q, v, _ in random_states(10, seed=11):
        assert system.energy(tuple(q), tuple(v)) == pytest.approx(ref.energy(q, v, EFFECTS), rel=1e-12)


# -- the paper's run (spec §5) ----------------------------------------------------------
@pytest.fixture(scope="module")
def paper_reference() -> ref.Reference:
    return ref.solve_scene(yaml.safe_load((ref.CONFIG / "paper_flexion.yaml").read_text()))


@pytest.fixture(scope="module")
def paper_run():
    return simulate(load_scene(ref.CONFIG / "paper_flexion.yaml"))


def test_paper_run_gives_the_spec_check_values(paper_run, paper_reference):
    assert paper_run.t[-1] == pytest.approx(0.3, abs=1e-15)
    deg = np.degrees(paper_run.q[-1])
    for got, shown in zip(deg, PAPER_THETA_END_DEG):
        assert abs(got - shown) <= 0.005, (got, shown)
    # the independent reference gives the same digits, and the run agrees with it to
    # RK4's error at 1 ms (measured 1.5e-11 rad)
    ref_deg = np.degrees(paper_reference.y(0.3)[:3])
    for got, shown in zip(ref_deg, PAPER_THETA_END_DEG):
        assert abs(got - shown) <= 0.005
    np.testing.assert_allclose(paper_run.q[-1], paper_reference.y(0.3)[:3], rtol=0, atol=1e-10)


def test_paper_run_energy_gain_is_the_motor_work(paper_run, paper_reference):
    """Work-energy theorem: T + V rises by ∫ τ θ1' dt (no damping; the spring is in V).

    The work is integrated from the reference's dense output (1.868e-3 J); measured agreement
    8e-12 relative for the RK4 run, 4e-13 for the reference's own energy.
    """
    work, _ = quad(lambda t: (0.001 + 0.01 * t) * paper_reference.y(t)[3], 0.0, 0.3, epsabs=0.0, epsrel=1e-12, limit=200)
    gain = paper_run.energy[-1] - paper_run.energy[0]
    assert paper_run.energy[0] == pytest.approx(0.0, abs=1e-30)  # rest at extension, spring relaxed
    assert gain == pytest.approx(work, rel=1e-9)
    y = paper_reference.y(0.3)
    assert ref.energy(y[:3], y[3:], ref.Effects()) == pytest.approx(work, rel=1e-9)


def test_time_grid_is_n_dt_exactly(paper_run):
    n = len(paper_run.t) - 1
    assert n == 300
    assert np.array_equal(paper_run.t, np.arange(n + 1) * 0.001)
    assert paper_run.method == "rk6"  # auto on a smooth scene at 1 kHz
