"""The MuJoCo peer is the spec's finger: closure, extended pose, mass matrix, energy, the paper's run."""

from __future__ import annotations

import numpy as np
import pytest

mujoco = pytest.importorskip("mujoco", reason="the MuJoCo peer needs the `mujoco` package (pip install .[bench])")

from scipy.integrate import solve_ivp  # noqa: E402

from finger_sim.bench.mujoco_peer import (  # noqa: E402
    DEFAULT_EQUALITY,
    INTEGRATORS,
    TIGHT_SOLIMP,
    EqualitySetting,
    MujocoFinger,
    run_mujoco,
    tight_equality,
)
from finger_sim.dynamics import FingerSystem  # noqa: E402
from finger_sim.errors import ConfigError, SimulationDiverged  # noqa: E402
from finger_sim.effects.spring import PipSpring  # noqa: E402
from finger_sim.kinematics import assemble, dependent_rates, distal_offset, extended_pose, points  # noqa: E402
from finger_sim.model import FingerParams  # noqa: E402

P = FingerParams()
K_SPRING = 0.001  # N·m/rad, the paper's PIP spring
T_END = 0.3  # s, the paper's run
SMALLEST_TIMESTEP = 1e-5  # s
REPORT_TIMESTEP = 1e-3  # s
#: Measured max |θ − θ_ref| over 0..0.3 s at 1e-5 s with the tight equality (rad):
#: RK4 2.39e-10, Euler and implicitfast 1.94e-5. Bounds about twice that.
TRACKING_BOUND = {"RK4": 5e-10, "Euler": 4e-5, "implicitfast": 4e-5}
#: θ at t = 0.3 s to the digits spec §5 shows, deg.
SPEC_THETA_AT_END_DEG = (34.34, 54.39, -53.02)
#: θ_ext to the digits spec §1 shows, deg.
SPEC_THETA_EXT_DEG = (0.0, 13.1028, -128.0309)
#: θ' = T q' maps MuJoCo's (mcp, coupler, pip) rates to the paper's (θ1', θ2', θ3').
T_MAP = np.array([[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [1.0, 0.0, 1.0]])


def paper_torque(t: float) -> float:
    """τ(t) = 0.01 t + 0.001 N·m (the paper's input, spec §5)."""
    return 0.01 * t + 0.001


@pytest.fixture(scope="module")
def reference():
    """Dense tight solution of paper_flexion: DOP853 at rtol 1e-12 on the index-1 equations."""
    system = FingerSystem(P, [PipSpring(K_SPRING, distal_offset(P))])

    y0 = [*extended_pose(P), 0.0, 0.0, 0.0]  # rest at θ_ext
    sol = solve_ivp(system.rhs, (0.0, T_END), y0, args=(paper_torque,), method="DOP853", rtol=1e-12, atol=1e-14, dense_output=True)
    assert sol.success
    return sol.sol


def site_gap(finger: MujocoFinger, data) -> float:
    """|C_coupler − C_distal| from MuJoCo's own site positions, m."""
    a, b = finger.site_ids
    return float(np.linalg.norm(data.site_xpos[a] - data.site_xpos[b]))


@pytest.mark.parametrize("equality", [DEFAULT_EQUALITY, tight_equality(1e-3)], ids=lambda e: e.name)
@pytest.mark.parametrize("integrator", INTEGRATORS)
def test_rest_keeps_the_loop_closed_at_the_extended_pose(integrator: str, equality: EqualitySetting) -> None:
    finger = MujocoFinger(P, timestep=1e-3, integrator=integrator, equality=equality)
    data = finger.make_data()
    np.testing.assert_allclose(data.qpos, 0.0, atol=1e-15)  # qpos0 is the extended pose
    for _ in range(10):  # zero torque, spring at rest, zero velocity
        mujoco.mj_step(finger.model, data)
    mujoco.mj_forward(finger.model, data)
    theta = finger.to_paper(data.qpos)
    assert site_gap(finger, data) < 1e-6
    assert finger.loop_violation(theta)[0] < 1e-6
    # MuJoCo's solver stops at its tolerance (1e-8 on the cost), which leaves ~1e-11 rad of noise.
    np.testing.assert_allclose(theta, extended_pose(P), rtol=0.0, atol=1e-10)
    np.testing.assert_allclose(np.degrees(theta), SPEC_THETA_EXT_DEG, rtol=0.0, atol=5e-5)


def test_loop_violation_is_the_gap_between_mujocos_sites() -> None:
    finger = MujocoFinger(P, timestep=1e-3, integrator="RK4")
    theta = np.array(assemble(P, 0.6)) + (0.0, 2e-3, -1e-3)  # an open loop
    data = finger.make_data(theta)
    np.testing.assert_allclose(finger.to_paper(data.qpos), theta, rtol=0.0, atol=1e-15)
    gap = site_gap(finger, data)
    assert gap > 1e-5
    assert finger.loop_violation(theta)[0] == pytest.approx(gap, rel=1e-9)


def test_total_mass_is_the_spec_links() -> None:
    model = MujocoFinger(P, timestep=1e-3, integrator="RK4").model
    assert mujoco.mj_getTotalmass(model) == pytest.approx(P.m1 + P.m2 + P.m3, rel=1e-12)


@pytest.mark.parametrize("theta1", [0.0, 0.6, 1.4])
def test_mass_matrix_and_energy_are_the_specs(theta1: float) -> None:
    finger = MujocoFinger(P, timestep=1e-3, integrator="RK4", spring_stiffness=K_SPRING)
    finger.model.opt.enableflags |= mujoco.mjtEnableBit.mjENBL_ENERGY
    system = FingerSystem(P, [PipSpring(K_SPRING, distal_offset(P))])
    q = assemble(P, theta1)
    v = dependent_rates(P, q, 2.0)  # a velocity consistent with the loop, rad/s
    data = finger.make_data(q, v)

    full = np.zeros((finger.model.nv, finger.model.nv))
    mujoco.mj_fullM(finger.model, data, full)
    idx = finger.dof_index
    expected = T_MAP.T @ np.array(system.mass_matrix(q)) @ T_MAP  # M in MuJoCo's coordinates
    np.testing.assert_allclose(full[np.ix_(idx, idx)], expected, rtol=1e-9, atol=1e-9 * np.abs(expected).max())

    kinetic, potential = data.energy[1], data.energy[0]
    assert kinetic == pytest.approx(system.kinetic_energy(q, v), rel=1e-9)
    assert potential == pytest.approx(system.potential_energy(q), rel=1e-9, abs=1e-18)


@pytest.mark.parametrize("integrator", INTEGRATORS)
def test_tracks_the_tight_reference_at_the_smallest_timestep(integrator: str, reference) -> None:
    run = run_mujoco(
        P,
        torque=paper_torque,
        t_end=T_END,
        timestep=SMALLEST_TIMESTEP,
        integrator=integrator,
        equality=tight_equality(SMALLEST_TIMESTEP),
        spring_stiffness=K_SPRING,
        sample_times=np.linspace(0.0, T_END, 3001),
    )
    error = np.abs(run.theta - reference(run.t)[:3].T).max()
    print(f"{integrator}: max |θ − θ_ref| = {error:.3e} rad, max loop violation {run.loop_violation.max():.3e} m")
    assert error < TRACKING_BOUND[integrator]
    assert run.t[-1] == pytest.approx(T_END, abs=1e-15)
    np.testing.assert_allclose(np.degrees(run.theta[-1]), SPEC_THETA_AT_END_DEG, rtol=0.0, atol=0.005)


def test_default_and_tight_equality_at_one_millisecond(reference) -> None:
    """Prints max angle error, max loop violation and µs/step; asserts only that tight beats default."""
    errors = {}
    for integrator in ("RK4", "implicitfast"):
        for equality in (DEFAULT_EQUALITY, tight_equality(REPORT_TIMESTEP)):
            run = run_mujoco(
                P,
                torque=paper_torque,
                t_end=T_END,
                timestep=REPORT_TIMESTEP,
                integrator=integrator,
                equality=equality,
                spring_stiffness=K_SPRING,
            )
            assert (run.t[0], run.t[-1], run.t.size) == (0.0, pytest.approx(T_END), 301)  # default samples
            errors[integrator, equality.name] = np.abs(run.theta - reference(run.t)[:3].T).max()
            print(
                f"{integrator:12s} {equality.name:7s} solref {equality.solref}: "
                f"max |θ − θ_ref| {errors[integrator, equality.name]:.3e} rad, "
                f"max loop {run.loop_violation.max():.3e} m, {run.us_per_step:.2f} µs/step"
            )
        assert errors[integrator, "tight"] < errors[integrator, "default"]


def test_a_too_stiff_loop_raises_instead_of_mujocos_silent_reset(tmp_path, monkeypatch) -> None:
    # The direct form escapes refsafe; timeconst dt/2 diverges under implicitfast and MuJoCo
    # would reset the state to qpos0 and carry on.
    monkeypatch.chdir(tmp_path)  # MuJoCo logs the warning to ./MUJOCO_LOG.TXT
    timeconst = 0.5 * REPORT_TIMESTEP
    too_stiff = EqualitySetting("too stiff", (-1.0 / timeconst**2, -2.0 / timeconst), TIGHT_SOLIMP)
    with pytest.raises(SimulationDiverged, match="bad-acceleration"):
        run_mujoco(
            P,
            torque=paper_torque,
            t_end=T_END,
            timestep=REPORT_TIMESTEP,
            integrator="implicitfast",
            equality=too_stiff,
        )


@pytest.mark.parametrize(
    ("kwargs", "key"),
    [
        ({"integrator": "implicit"}, "integrator"),
        ({"timestep": -1e-3}, "timestep"),
        ({"t_end": 0.30005}, "t_end"),
        ({"sample_times": [0.0, 0.0105]}, "sample_times"),
        ({"sample_times": [0.2, 0.1]}, "sample_times"),
        ({"sample_times": [0.0, 0.4]}, "sample_times"),
    ],
)
def test_bad_arguments_name_themselves(kwargs: dict, key: str) -> None:
    args = {"torque": paper_torque, "t_end": T_END, "timestep": 1e-3, "integrator": "RK4"} | kwargs
    with pytest.raises(ConfigError) as info:
        run_mujoco(P, **args)
    assert info.value.key == key


@pytest.mark.parametrize("theta1", [0.0, 0.6])
def test_sites_are_where_the_spec_puts_c_and_the_tip(theta1: float) -> None:
    # Catches frames turned in degrees (MJCF's compiler/angle default) or a mirrored distal link.
    finger = MujocoFinger(P, timestep=1e-3, integrator="Euler")
    q = assemble(P, theta1)
    data = finger.make_data(q)
    spec = points(P, q, distal_offset(P))
    for site in ("C_coupler", "C_distal"):
        np.testing.assert_allclose(data.site(site).xpos, (*spec["C"], 0.0), rtol=0.0, atol=1e-15)
    np.testing.assert_allclose(data.site("tip").xpos, (*spec["tip"], 0.0), rtol=0.0, atol=1e-15)
