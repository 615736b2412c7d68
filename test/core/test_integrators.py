"""Every integrator against the independent tight reference, its order, and the invariants.

References: `reference.py` (scipy DOP853 at rtol 1e-12 on a separately written numpy
KKT right-hand side), the Butcher tableaux' order conditions, closed-form stability
boundaries, conservation of T + V, and Φ = 0.

Measured on the paper's run (errors max|θ − θ_ref| at t = 0.3 s, rad):

    euler   dt 4/2/1 ms          1.0e-2 5.1e-3 2.5e-3     slope 1.00
    rk4     dt 15/10/7.5/5 ms    6.7e-7 … 8.9e-9          slope 3.90
    rattle  dt 20/10/5 ms        1.8e-3 4.5e-4 1.1e-4     slope 2.00
    radau   dt 37.5/25/15 ms     1.0e-7 1.3e-8 1.0e-9     slope 4.99
    at 1 ms: euler 2.5e-3, rk4 1.5e-11, rattle 4.5e-6, radau 6.8e-14, adaptive 6.1e-14
    (radau and adaptive at the reference's own floor, ~1e-13).
"""

from __future__ import annotations

import math

import numpy as np
import pytest
import yaml

import reference as ref
from finger_sim.integrators import METHODS, RK4, PaperEuler, RadauIIA, Rattle
from finger_sim.integrators import radau as radau_module
from finger_sim.integrators.base import STABILITY_SLACK
from finger_sim.scene import load_scene, scene_from_dict
from finger_sim.simulate import Simulator, simulate

PAPER = load_scene(ref.CONFIG / "paper_flexion.yaml")
FREE_SWING = load_scene(ref.CONFIG / "free_swing.yaml")
T_END = 0.3

#: Step sizes (s) where each method's error is in its asymptotic regime and far above
#: the reference's floor (~1e-13 rad). All divide 0.3 s. Radau needs large steps: at
#: 10 ms it is already at 1.3e-10; above 50 ms its Newton iteration fails and the step
#: is halved, which hides the order.
ORDER_STEPS = {
    "euler": (0.004, 0.002, 0.001),
    "rk4": (0.015, 0.01, 0.0075, 0.005),
    "rattle": (0.02, 0.01, 0.005),
    "radau": (0.0375, 0.025, 0.015),
}
#: Error floor of the comparison at t = 0.3 s: the reference and round-off, rad.
FLOOR = 1e-12
FIXED_STEP = ("euler", "rk4", "rattle", "radau")


@pytest.fixture(scope="module")
def paper_ref() -> np.ndarray:
    """(q, q') at t = 0.3 s from the independent reference."""
    sol = ref.solve_scene(yaml.safe_load((ref.CONFIG / "paper_flexion.yaml").read_text()))
    return sol.y(T_END)


def final_error(method: str, dt: float, y_ref: np.ndarray) -> float:
    traj = simulate(PAPER.with_overrides(method=method, dt=dt))
    assert traj.t[-1] == pytest.approx(T_END, abs=1e-12)
    return float(np.max(np.abs(traj.q[-1] - y_ref[:3])))


@pytest.fixture(scope="module")
def order_fits(paper_ref):
    """method → (slope, log C) of log err = p log dt + log C over ORDER_STEPS."""
    fits = {}
    for method, steps in ORDER_STEPS.items():
        errors = [final_error(method, dt, paper_ref) for dt in steps]
        assert min(errors) > 1e3 * FLOOR, (method, errors)  # above the floor: the slope is real
        fits[method] = tuple(np.polyfit(np.log(steps), np.log(errors), 1))
    return fits


@pytest.mark.parametrize("method", FIXED_STEP)
def test_measured_order_matches_theory(method, order_fits):
    slope, _ = order_fits[method]
    assert abs(slope - METHODS[method].order) <= 0.3, slope


@pytest.mark.parametrize("method", FIXED_STEP)
def test_error_at_default_dt_is_what_the_order_predicts(method, order_fits, paper_ref):
    """Extrapolate C·dt^p from the coarse steps to 1 ms: the measured error must be within
    a factor 3 of it (or at the floor, where the prediction is below it)."""
    slope, log_c = order_fits[method]
    predicted = math.exp(log_c) * 0.001**slope
    error = final_error(method, 0.001, paper_ref)
    assert error <= 3.0 * predicted + FLOOR
    if predicted > 100 * FLOOR:
        assert error >= predicted / 3.0


def test_adaptive_reference_agrees_with_the_independent_one(paper_ref):
    """Same equations, different code (scalar Schur path vs numpy KKT): measured 6e-14 rad."""
    traj = simulate(PAPER.with_overrides(method="adaptive"))
    assert np.max(np.abs(traj.q[-1] - paper_ref[:3])) < FLOOR
    assert np.max(np.abs(traj.v[-1] - paper_ref[3:])) < 10 * FLOOR


#: Every torque profile, with every force element on. The step at 0.1234 s and the 30 Hz
#: square's switches (every 16.7 ms) fall inside steps.
PROFILES = {
    "constant": {"type": "constant", "value": 0.003},
    "ramp": {"type": "ramp", "offset": 0.001, "slope": 0.01},
    "sine": {"type": "sine", "amplitude": 0.004, "frequency": 7.0, "offset": 0.001},
    "step": {"type": "step", "before": 0.0, "after": 0.006, "at": 0.1234},
    "square": {"type": "square", "amplitude": 0.004, "frequency": 30.0, "offset": 0.001},
}


@pytest.mark.parametrize("profile", sorted(PROFILES))
def test_every_effect_and_profile_end_to_end(profile):
    """Spring, damping, gravity and a tip force from θ1 = 0.3 rad, θ1' = 1 rad/s, 0.3 s:
    the scene → elements → RK4 path against the reference with the same effects (restarted
    at switches). Measured max|θ − θ_ref| 1.2e-9 … 1.9e-9 rad (radau: 1.6e-12 … 1.5e-11)."""
    data = {
        "model": {"spring_stiffness": 0.002, "damping": 0.001, "gravity": [0.0, -9.81], "tip_force": [0.05, -0.1]},
        "input": {"torque": PROFILES[profile]},
        "initial": {"theta1": 0.3, "theta1_dot": 1.0},
        "duration": 0.3,
        "integrator": {"method": "rk4", "dt": 0.001},
    }
    traj = simulate(scene_from_dict(data))
    y = ref.solve_scene(data).y(traj.t)
    assert np.max(np.abs(traj.q - y[:3].T)) < 5e-9
    assert np.max(np.abs(traj.v - y[3:].T)) < 2e-7
    assert np.ptp(traj.q[:, 0]) > 1.0  # it moves: 70-80° of MCP travel


# -- constraints ---------------------------------------------------------------------------
@pytest.mark.parametrize("scene", ["paper_flexion", "toggle_passage"])
@pytest.mark.parametrize("method", [m for m, cls in METHODS.items() if cls.keeps_constraints])
def test_constraint_keeping_methods_stay_on_the_manifold(method, scene):
    """|Φ| < 1e-10 m and |Φ_q q'| < 1e-10 m/s at every step (measured ≤ 1e-15 for all)."""
    traj = simulate(load_scene(ref.CONFIG / f"{scene}.yaml").with_overrides(method=method))
    assert np.all(np.isfinite(traj.q))
    assert traj.residual.max() < 1e-10
    # independent check of both levels with the reference's Φ and Φ_q
    assert max(np.linalg.norm(ref.phi(q)) for q in traj.q) < 1e-10
    assert max(np.linalg.norm(ref.phi_q(q) @ v) for q, v in zip(traj.q, traj.v)) < 1e-10


def test_paper_euler_drift_is_the_documented_baseline():
    """The paper's (6)-(7) has no drift control: max|Φ| on the paper's run is 2.20e-5 m at
    1 ms and scales linearly with dt (measured 4.37e-5 / 2.20e-5 / 1.10e-5 m at 2 / 1 / 0.5 ms)."""
    assert not PaperEuler.keeps_constraints
    drift = {dt: simulate(PAPER.with_overrides(method="euler", dt=dt)).residual.max() for dt in (0.002, 0.001, 0.0005)}
    assert 1e-5 <= drift[0.001] <= 1e-4
    slope = np.polyfit(np.log(list(drift)), np.log(list(drift.values())), 1)[0]
    assert abs(slope - 1.0) < 0.1
    # and the drift is real: the reference's Φ agrees with the core's residual
    traj = simulate(PAPER.with_overrides(method="euler"))
    assert np.linalg.norm(ref.phi(traj.q[-1])) == pytest.approx(traj.residual[-1], rel=1e-6)


# -- energy ------------------------------------------------------------------------------
@pytest.mark.parametrize(("method", "measured"), [("rk4", 5.3e-10), ("radau", 8.6e-13), ("adaptive", 3.7e-14)])
def test_accurate_methods_conserve_energy_on_the_free_swing(method, measured):
    """τ = 0, spring only: T + V is conserved; max relative error over 2 s at dt = 1 ms < 1e-8."""
    traj = simulate(FREE_SWING.with_overrides(method=method))
    e0 = traj.energy[0]
    # the initial energy is the closed-form kinetic energy of θ1' = 5 rad/s at extension
    q0, v0 = ref.theta_ext(), ref.rates(ref.theta_ext(), 5.0)
    assert e0 == pytest.approx(0.5 * v0 @ ref.mass(q0) @ v0, rel=1e-12)
    assert np.max(np.abs(traj.energy - e0)) / e0 < 1e-8


#: RATTLE's long run: 1e5 steps of DT on the free swing (500 s, ≈ 290 swing periods;
#: a swing period is ≈ 1.7 s). About 20 s on 2 shared cores.
LONG_DT = 0.005
LONG_STEPS = 100_000
BLOCKS = 10


def long_energy_error(method: str) -> np.ndarray:
    """Relative energy error after each of LONG_STEPS steps (integrator called directly)."""
    system = FREE_SWING.build_system()
    integrator = METHODS[method](system)
    q, v = FREE_SWING.initial_state()
    e0 = system.energy(q, v)
    out = np.empty(LONG_STEPS)
    zero = lambda t: 0.0  # noqa: E731
    step, energy = integrator.step, system.energy
    for i in range(LONG_STEPS):
        q, v = step(i * LONG_DT, q, v, LONG_DT, zero)
        out[i] = energy(q, v)
    return (out - e0) / e0


@pytest.mark.slow  # 2e4 steps of the Python rattle: about 30 s
def test_rattle_energy_error_is_bounded_and_does_not_drift():
    """Measured at dt = 5 ms over 2e4 steps (the same picture over 1e5): max |ΔE/E| 2.686e-4 in every tenth of the run
    (equal to 4 digits), a linear fit's drift over the whole run −6e-7 (0.2% of the bound
    oscillation), block means within ±4e-6."""
    err = long_energy_error("rattle")
    assert np.all(np.isfinite(err))
    block_max = np.abs(err).reshape(BLOCKS, -1).max(axis=1)
    half = LONG_STEPS // 2
    assert np.abs(err[half:]).max() <= 1.01 * np.abs(err[:half]).max()
    assert block_max.max() <= 1.01 * block_max.min()
    drift = np.polyfit(np.arange(LONG_STEPS), err, 1)[0] * LONG_STEPS
    assert abs(drift) < 0.01 * np.abs(err).max()
    assert np.abs(err).max() < 1e-3  # O(dt²) bound of the shadow Hamiltonian


def test_rk4_energy_error_drifts_at_the_same_dt():
    """The contrast: RK4 at dt = 5 ms loses no accuracy per step but drifts monotonically
    (measured: block maxima 3.7e-7, 6.0e-7 … 2.5e-6, each above the last; fitted drift
    2.3e-6 ≈ the final error)."""
    err = long_energy_error("rk4")
    block_max = np.abs(err).reshape(BLOCKS, -1).max(axis=1)
    assert np.all(np.diff(block_max) > 0.0)
    drift = np.polyfit(np.arange(LONG_STEPS), err, 1)[0] * LONG_STEPS
    assert drift == pytest.approx(err[-1], rel=0.1)
    assert np.abs(err[LONG_STEPS // 2 :]).max() > 1.5 * np.abs(err[: LONG_STEPS // 2]).max()


# -- bookkeeping -------------------------------------------------------------------------
@pytest.mark.parametrize("method", sorted(METHODS))
def test_reset_reruns_bit_for_bit(method):
    """The same torques at the same steps give bit-identical states, after a reset too."""
    sim = Simulator(PAPER.with_overrides(method=method))
    first = [sim.step() for _ in range(60)]
    sim.reset()
    assert sim.state.t == 0.0
    second = [sim.step() for _ in range(60)]
    assert first == second
    fresh = Simulator(PAPER.with_overrides(method=method))
    assert [fresh.step() for _ in range(60)] == first


def test_each_method_declares_its_family():
    assert {"euler", "rk4", "rattle", "radau", "adaptive"} <= set(METHODS)
    assert [METHODS[m].order for m in FIXED_STEP] == [1, 4, 2, 5]
    assert [METHODS[m].keeps_constraints for m in ("euler", "rk4", "rattle", "radau", "adaptive")] == [False] + [True] * 4
    assert RadauIIA.implicit and not RK4.implicit


# -- tableaux and stability regions (closed forms) ---------------------------------------
def test_rk4_tableau_order_conditions():
    a = np.zeros((4, 4))
    for i, row in enumerate(RK4.A):
        a[i, : len(row)] = row
    b, c = np.array(RK4.B), np.array(RK4.C)
    np.testing.assert_allclose(a.sum(axis=1), c, atol=1e-16)
    conditions = [b.sum() - 1, b @ c - 1 / 2, b @ c**2 - 1 / 3, b @ a @ c - 1 / 6, b @ c**3 - 1 / 4,
                  b @ (c * (a @ c)) - 1 / 8, b @ a @ c**2 - 1 / 12, b @ a @ a @ c - 1 / 24]  # fmt: skip
    np.testing.assert_allclose(conditions, 0.0, atol=1e-15)


def test_radau_tableau_is_order_5_and_l_stable():
    a, c = radau_module.A, radau_module.C
    b = a[-1]  # stiffly accurate
    for k in range(1, 6):  # B(5): Σ b c^(k−1) = 1/k
        assert b @ c ** (k - 1) == pytest.approx(1 / k, abs=1e-15)
    for k in range(1, 4):  # C(3): Σ_j a_ij c_j^(k−1) = c_i^k / k
        np.testing.assert_allclose(a @ c ** (k - 1), c**k / k, atol=1e-15)

    def stability(z: complex) -> complex:
        return 1 + z * b @ np.linalg.solve(np.eye(3) - z * a, np.ones(3))

    assert abs(stability(-1e8)) < 1e-7  # L-stable: R(−∞) = 0
    for y in (0.1, 1.0, 10.0, 1e3):  # A-stable: |R(iy)| ≤ 1
        assert abs(stability(1j * y)) <= 1.0 + 1e-14
    assert RadauIIA.is_stable(-1e6 + 1e6j)


def test_rk4_stability_boundary_is_the_closed_form():
    """|1 + z + z²/2 + z³/6 + z⁴/24| = 1 at z = ±2√2 i and z = −2.7853 on the axes."""
    assert RK4.is_stable(2.80j) and not RK4.is_stable(2.90j)
    assert RK4.is_stable(-2.78 + 0j) and not RK4.is_stable(-2.80 + 0j)
    r = lambda z: abs(1 + z + z**2 / 2 + z**3 / 6 + z**4 / 24)  # noqa: E731
    assert r(2 * math.sqrt(2) * 1j) == pytest.approx(1.0, abs=1e-14)


@pytest.mark.parametrize("z", [0.05j, 0.3j, 1.5j, 2.5j, -0.2 + 0.4j, -1.0 + 1.0j, -3.0 + 0j])
def test_paper_euler_stability_matches_its_amplification_matrix(z):
    """The step on q'' = a q + b q' (roots z, z̄ per dt) is linear; its spectral radius decides."""
    a, b = (z * z.conjugate()).real, -2 * z.real  # q'' = −|z|² q + 2 Re z q' (per dt)
    # one step on (q, v·dt): q1 = q + v + ½ a'', v1 = v + a'' with a'' = −a q − b v
    step = np.array([[1 - a / 2, 1 - b / 2], [-a, 1 - b]])
    radius = max(abs(np.linalg.eigvals(step)))
    assert PaperEuler.is_stable(z) == (radius <= 1 + STABILITY_SLACK)


def test_rattle_stability_is_stormer_verlet():
    """Störmer-Verlet on ω: amplification eigenvalues on the unit circle iff ω dt < 2."""
    for w in (0.5, 1.9, 2.1, 5.0):
        step = np.array([[1 - w * w / 2, 1.0], [-w * w * (1 - w * w / 4), 1 - w * w / 2]])
        radius = max(abs(np.linalg.eigvals(step)))
        assert Rattle.is_stable(complex(0, w)) == (radius <= 1 + 1e-12)
