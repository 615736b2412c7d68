"""The drive (spec §8) against references written here, not against its own arithmetic.

- the ideal gear (η_f = η_b = 1), and the forward-only run of a self-locking gear: the §4 KKT
  system solved densely (reference.py's M, h, Φ_q, γ) with N²J_m (× η_f) added to M on θ1 and
  N k_t i (× η_f) added to Q, the current clamped at the limit, by DOP853 at rtol 1e-12;
- the back flank: the same KKT system with τ_g as a sixth unknown and the row η_b τ_g + N²J_m θ1'' = N k_t i;
- stall against the cup: the §7 equilibrium with τ = N k_t u/R (test_contact.equilibrium);
- the self-locking grasp: the forward reference up to its first θ1' = 0 (a scipy event), then
  the pose held bit for bit after the voltage drops;
- the energy balance: electrical work = copper + mesh + ΔE_rotor + Δ(T + V) + dissipated, and mesh loss ≥ 0.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.integrate import solve_ivp

import reference as ref
from finger_sim.actuators.drive import BACK, DRIVE, STUCK, DriveParams, DrivenSystem
from finger_sim.effects.contact import Contact
from finger_sim.errors import ConfigError, SimulationDiverged
from finger_sim.scene import Scene, load_scene, scene_from_dict
from finger_sim.simulate import Simulator, simulate
from test_contact import equilibrium

CUP = {"name": "cup", "type": "circle", "center": [0.065, 0.040], "radius": 0.012}
#: Spec §8's defaults, typed in again.
R, KT, JM, UMAX, IMAX, N, ETA_F = 8.0, 4.0e-3, 5.0e-9, 6.0, 0.5, 300.0, 0.4


def drive_scene(drive: dict | None = None, voltage: dict | None = None, **top) -> Scene:
    data = {"model": {"drive": drive or {}, **top.pop("model", {})},
            "input": {"voltage": voltage or {"type": "constant", "value": 6.0}}, **top}
    return scene_from_dict(data)


def run(scene: Scene) -> tuple[np.ndarray, np.ndarray, list[int]]:
    """(t, states (N+1, 6), mesh mode after each step) on the Python path."""
    sim = Simulator(scene, kernel="python")
    xs, modes = [(*sim.q, *sim.v)], [sim.system.drive.mode]
    for _ in range(scene.step_count):
        s = sim.step()
        xs.append((*s.q, *s.v))
        modes.append(sim.system.drive.mode)
    return np.arange(len(xs)) * scene.dt, np.array(xs), modes


def current(u: float, theta1_dot: float) -> float:
    return min(IMAX, max(-IMAX, (min(UMAX, max(-UMAX, u)) - KT * N * theta1_dot) / R))


def kkt_drive(scene: Scene, t: float, y: np.ndarray, gain: float, u: float) -> np.ndarray:
    """q'' of [M + gain N²J_m e1e1ᵀ, −Φ_qᵀ; Φ_q, 0] = [Q + gain N k_t i e1 − h; γ]: the rolling drive
    flank as an inertia and a torque. Q from the scene's force elements (spring, contact)."""
    q, v = y[:3], y[3:]
    system = scene.build_system()
    a = np.zeros((5, 5))
    a[:3, :3] = ref.mass(q)
    a[0, 0] += gain * N * N * JM
    g = ref.phi_q(q)
    a[:3, 3:], a[3:, :3] = -g.T, g
    force = np.array(super(DrivenSystem, system).generalized_force(t, tuple(q), tuple(v), 0.0))
    force[0] += gain * N * KT * current(u, v[0])
    rhs = np.concatenate([force - ref.coriolis(q, v), ref.gamma(q, v)])
    return np.linalg.solve(a, rhs)[:3]


def kkt_back(scene: Scene, t: float, y: np.ndarray, eta_b: float, u: float) -> np.ndarray:
    """q'' of the back flank: unknowns (q'', λ, τ_g), rows [M q'' − Φ_qᵀλ − e1 τ_g = Q − h; Φ_q q'' = γ;
    N²J_m θ1'' + η_b τ_g = N k_t i]."""
    q, v = y[:3], y[3:]
    system = scene.build_system()
    a = np.zeros((6, 6))
    a[:3, :3] = ref.mass(q)
    g = ref.phi_q(q)
    a[:3, 3:5], a[3:5, :3] = -g.T, g
    a[0, 5] = -1.0
    a[5, 0], a[5, 5] = N * N * JM, eta_b
    force = np.array(super(DrivenSystem, system).generalized_force(t, tuple(q), tuple(v), 0.0))
    rhs = np.concatenate([force - ref.coriolis(q, v), ref.gamma(q, v), [N * KT * current(u, v[0])]])
    return np.linalg.solve(a, rhs)[:3]


def reference(scene: Scene, accel, ts: np.ndarray, events=()) -> tuple[np.ndarray, object]:
    """DOP853 at rtol 1e-12 on y' = (q', accel(t, y)), with dense output at ts; restarted at each
    contact gap change and at the current limit's kink."""
    q0, v0 = scene.initial_state()
    contact = next((e for e in scene.build_system().elements if isinstance(e, Contact)), None)

    def rhs(t, y):
        return [*y[3:], *accel(t, y)]

    def limit(t, y):
        return IMAX * R - abs(min(UMAX, max(-UMAX, scene.torque(t))) - KT * N * y[3])

    guards = [limit] + ([lambda t, y, i=i: contact.gaps(tuple(y[:3]))[i] for i in range(len(contact.gaps(q0)))]
                        if contact else [])
    for fn in guards:
        fn.terminal = True
    y, t, out, hit = np.array([*q0, *v0]), 0.0, {}, None
    while t < ts[-1] and hit is None:
        sol = solve_ivp(rhs, (t, ts[-1]), y, method="DOP853", rtol=1e-12, atol=1e-14,
                        events=[*guards, *events], dense_output=True)
        assert sol.success
        for k in np.flatnonzero((ts >= t) & (ts <= sol.t[-1])):
            out.setdefault(int(k), sol.sol(ts[k]))
        if any(sol.t_events[len(guards) + j].size for j in range(len(events))):
            hit = sol
        # step just past a located kink, so the restart does not see it again at once
        t, y = sol.t[-1], sol.y[:, -1]
        if t < ts[-1] and hit is None:
            nxt = min(ts[-1], t + 1e-9)
            y = solve_ivp(rhs, (t, nxt), y, method="DOP853", rtol=1e-12, atol=1e-14).y[:, -1]
            t = nxt
    return np.array([out[k] for k in sorted(out)]), hit


# -- schema ----------------------------------------------------------------------------------
def test_empty_drive_takes_the_spec_defaults_and_voltage_is_the_input():
    scene = drive_scene()
    assert scene.drive == DriveParams(8.0, 4.0e-3, 5.0e-9, 0.0, 6.0, 0.5, 300.0, 0.4, -0.5, 0)
    assert scene.to_dict()["input"] == {"voltage": {"type": "constant", "value": 6.0}}
    assert scene_from_dict(scene.to_dict()) == scene
    assert scene_from_dict({"model": {"drive": {"efficiency": 0.8}}}).drive.backward_efficiency == pytest.approx(0.75)


@pytest.mark.parametrize(("data", "message"), [
    ({"model": {"drive": {}}, "input": {"torque": {"type": "constant", "value": 0.01}}},
     "input.torque: expected no torque with model.drive (the drive's input is input.voltage, V), got {'type': 'constant', 'value': 0.01}"),
    ({"input": {"voltage": {"type": "constant", "value": 6.0}}},
     "input.voltage: expected a voltage only with model.drive (without it the input is input.torque, N·m), got {'type': 'constant', 'value': 6.0}"),
    ({"model": {"drive": {"efficiency": 1.5}}}, "model.drive.efficiency: expected a number ≤ 1, got 1.5"),
    ({"model": {"drive": {"resistance": 0.0}}}, "model.drive.resistance: expected a number > 0, got 0.0"),
    ({"model": {"drive": {"backward_efficiency": 1.2}}}, "model.drive.backward_efficiency: expected a number ≤ 1, got 1.2"),
    ({"model": {"drive": {"encoder_counts": -4}}},
     "model.drive.encoder_counts: expected an integer in [0, 1000000000] (0: no encoder), got -4"),
    ({"model": {"drive": {"gear": 300}}}, "model.drive: expected only the keys ['backward_efficiency', 'current_limit', "
     "'efficiency', 'encoder_counts', 'gear_ratio', 'inductance', 'resistance', 'rotor_inertia', 'supply_voltage', "
     "'torque_constant'], got 'gear'"),
])
def test_bad_drive_values_are_refused_naming_the_key(data, message):
    with pytest.raises(ConfigError) as info:
        scene_from_dict(data)
    assert str(info.value) == message


def test_a_method_that_cannot_step_the_drive_is_refused():
    with pytest.raises(ConfigError, match="integrator.method"):
        Simulator(drive_scene(integrator={"method": "rattle"}))


# -- rolling against the §4 solve ------------------------------------------------------------------
@pytest.mark.parametrize(("drive", "gain"), [({"efficiency": 1.0, "backward_efficiency": 1.0}, 1.0), ({}, ETA_F)])
def test_free_run_equals_the_section4_solve_with_reflected_inertia_and_motor_torque(drive, gain):
    """Ideal gear: N²J_m on M, N k_t i on Q. Self-locking gear driving forward: η_f times both.
    The current limit acts for the first ~8 ms (6 V / 8 Ω > 0.5 A) and is a located kink."""
    scene = drive_scene(drive, integrator={"method": "rk6", "dt": 1e-4}, duration=0.2)
    ts, xs, modes = run(scene)
    expected, _ = reference(scene, lambda t, y: kkt_drive(scene, t, y, gain, scene.torque(t)), ts)
    assert set(modes) == {DRIVE}
    assert np.max(np.abs(xs[:, :3] - expected[:, :3])) < 1e-9
    assert xs[-1, 0] > 0.5  # it did move: ~0.8 rad in 0.2 s


def test_back_flank_opens_a_self_locking_finger_while_the_spring_helps():
    """A flexed finger with a stiff spring opened by u < 0: the link outruns the motor, the mesh
    brakes (back flank, η_b < 0), and the run equals the KKT solve with τ_g as an unknown."""
    scene = drive_scene({}, {"type": "constant", "value": -3.0}, model={"spring_stiffness": 0.2},
                        initial={"theta1": 1.0}, integrator={"method": "rk6", "dt": 1e-4}, duration=0.01)
    ts, xs, modes = run(scene)
    assert set(modes) == {BACK}
    expected, _ = reference(scene, lambda t, y: kkt_back(scene, t, y, -0.5, scene.torque(t)), ts)
    assert np.max(np.abs(xs[:, :3] - expected[:, :3])) < 1e-9
    assert xs[-1, 0] < 1.0 - 1e-3


def test_the_back_flank_is_refused_where_it_is_not_unique():
    """N²J_m + η_b M_eff ≤ 0: a rotor too light for η_b = −0.5 (M_eff ≈ 1e-4 kg·m²)."""
    scene = drive_scene({"rotor_inertia": 1e-10})
    system = scene.build_system()
    q, v = scene.initial_state()
    with pytest.raises(SimulationDiverged, match="not unique"):
        system.mesh(0.0, q, v, -3.0, BACK)


# -- stall and the self-locking hold ---------------------------------------------------------------
def test_ideal_gear_stall_on_the_cup_is_the_section7_equilibrium():
    """With η = 1 the rest state against the cup minimizes −τθ1 + ½kβ² + V_c, τ = N k_t u/R (ω = 0)."""
    u = 2.0
    scene = drive_scene({"efficiency": 1.0, "backward_efficiency": 1.0}, {"type": "constant", "value": u},
                        objects=[CUP], duration=1.0)
    traj = simulate(scene, kernel="python")
    raw = scene.to_dict()
    raw["input"] = {"torque": {"type": "constant", "value": N * KT * u / R}}
    theta, delta = equilibrium(raw)
    assert traj.q[-1, 0] == pytest.approx(theta, abs=1e-8)
    assert traj.outputs["grip_force"][-1] == pytest.approx(1e5 * delta**1.5, rel=1e-6)
    # i − u/R = −k_e N θ1'/R: auto's dop853 (rtol 1e-9) leaves θ1' ≈ 2e-9 rad/s of the settling after 1 s
    assert traj.outputs["motor_current"][-1] == pytest.approx(u / R, rel=1e-8)


def test_self_locking_finger_sticks_at_its_first_turning_point_and_holds_after_the_voltage_drops():
    scene = drive_scene({}, {"type": "step", "before": 6.0, "after": 0.0, "at": 0.2}, objects=[CUP],
                        integrator={"method": "rk6", "dt": 1e-4}, duration=0.3)
    traj = simulate(scene, kernel="python")
    turn = lambda t, y: y[3]  # noqa: E731
    turn.terminal, turn.direction = True, -1.0
    ts = traj.t[traj.t < 0.2]
    _, hit = reference(scene, lambda t, y: kkt_drive(scene, t, y, ETA_F, 6.0), ts, events=[turn])
    assert hit is not None
    t_stick, y_stick = hit.t_events[-1][0], hit.y_events[-1][0]
    stuck = np.flatnonzero(traj.outputs["mesh_mode"] == STUCK)
    assert stuck[0] * scene.dt == pytest.approx(t_stick, abs=scene.dt)  # stuck from the step it turned in
    assert np.all(np.diff(stuck) == 1) and stuck[-1] == len(traj.t) - 1  # and never again free
    assert traj.q[stuck[0], 0] == pytest.approx(y_stick[0], abs=1e-8)  # measured 4.5e-9 (rk6, 0.1 ms, in contact)
    # held bit for bit before and after the drop to 0 V, with the same grip
    assert np.all(traj.q[stuck] == traj.q[stuck[0]]) and np.all(traj.v[stuck] == 0.0)
    assert np.all(traj.outputs["grip_force"][stuck] == traj.outputs["grip_force"][stuck[0]])
    assert traj.outputs["grip_force"][-1] > 1.0  # newtons, as in real hands
    assert np.all(traj.outputs["motor_current"][traj.t > 0.2] == 0.0)


def test_back_drivable_finger_opens_when_the_voltage_drops():
    scene = drive_scene({"efficiency": 0.9, "backward_efficiency": 0.8}, {"type": "step", "before": 6.0, "after": 0.0, "at": 0.15},
                        objects=[CUP], duration=0.4)
    traj = simulate(scene, kernel="python")
    held = traj.q[traj.t <= 0.15, 0].max()
    assert traj.q[-1, 0] < held - 0.01  # it opened (slowly: the weak paper spring back-drives the motor)
    assert traj.outputs["grip_force"][-1] == 0.0
    assert BACK in set(traj.outputs["mesh_mode"][traj.t > 0.15])
    assert traj.outputs["mesh_loss"].min() >= -1e-12


# -- energy -------------------------------------------------------------------------------------
DRIVES = [{}, {"efficiency": 0.9, "backward_efficiency": 0.8}, {"efficiency": 1.0, "backward_efficiency": 1.0}]


@pytest.mark.parametrize("drive", DRIVES)
@pytest.mark.parametrize("voltage", [{"type": "square", "amplitude": 4.0, "frequency": 10.0},
                                     {"type": "square", "amplitude": 2.0, "offset": 2.0, "frequency": 10.0}])
def test_energy_balance_closes_through_repeated_mode_changes(drive, voltage):
    """Reversals (drive ↔ back), and for the self-locking gear stick and break-away at 0 V ↔ 4 V:
    electrical work = copper + mesh + ΔE_rotor + Δ(T + V) to 1e-9 of the work; the mesh never gives energy."""
    scene = drive_scene(drive, voltage, model={"spring_stiffness": 0.2}, integrator={"method": "rk6", "dt": 1e-4},
                        duration=0.2)
    traj = simulate(scene, kernel="python")
    report = traj.energy_report
    assert report["electrical_work"] > 0.01
    assert abs(report["residual"]) <= 1e-9 * report["electrical_work"]  # measured ≤ 4e-13
    assert traj.outputs["mesh_loss"].min() >= -1e-12
    modes = set(traj.outputs["mesh_mode"])
    if drive.get("efficiency") == 1.0:
        assert modes == {DRIVE} and abs(report["mesh_loss"]) <= 1e-15
    else:
        assert report["mesh_loss"] > 0.0 and BACK in modes
    if not drive and voltage.get("offset"):
        assert STUCK in modes and DRIVE in modes  # grasp and release, repeated


@pytest.mark.parametrize("drive", DRIVES)
def test_energy_balance_in_contact(drive):
    """In contact the balance is limited by the contact law's kinks (onset δ^1.5, the Hunt–Crossley
    clamp), not by the drive: measured ≤ 2.6e-7 of the work at 0.1 ms."""
    scene = drive_scene(drive, {"type": "step", "before": 6.0, "after": 0.0, "at": 0.1}, objects=[CUP],
                        integrator={"method": "rk6", "dt": 1e-4}, duration=0.2)
    traj = simulate(scene, kernel="python")
    report = traj.energy_report
    assert abs(report["residual"]) <= 1e-6 * report["electrical_work"]
    assert report["mesh_loss"] >= -1e-15 and report["dissipated"] >= 0.0
    assert traj.outputs["mesh_loss"].min() >= -1e-12


def test_batch_runs_drive_scenes_as_simulate_does():
    """The compiled batch has no drive: a drive scene's finger runs through its own Simulator, not
    as a torque-driven finger fed volts."""
    from finger_sim.batch import run_batch

    scenes = [drive_scene({}, {"type": "constant", "value": u}, duration=0.05) for u in (3.0, 6.0)]
    result = run_batch(scenes)
    for i, scene in enumerate(scenes):
        assert result.q[i].tolist() == simulate(scene, kernel="python").q[-1].tolist()
    assert not result.compiled.any()


@pytest.mark.parametrize("method", ["rk4", "rk6", "euler"])
@pytest.mark.parametrize("drive", [{}, {"efficiency": 0.9, "backward_efficiency": 0.8}])
def test_compiled_and_python_kernels_agree_through_grasp_hold_and_release(method, drive):
    """Both kernels apply the one law (drive.py's functions, njit-compiled for the kernel): the
    same states to 1e-13 rad through rolling, sticking, breaking free and reversing."""
    pytest.importorskip("numba")
    scene = drive_scene(drive, {"type": "square", "amplitude": 4.0, "offset": 1.0, "frequency": 5.0}, objects=[CUP],
                        integrator={"method": method, "dt": 1e-3 if method != "euler" else 1e-4}, duration=0.4)
    runs = {}
    for kernel in ("python", "compiled"):
        sim = Simulator(scene, kernel=kernel)
        assert sim.kernel.startswith("numba") == (kernel == "compiled")
        runs[kernel] = [(sim.step(), sim.system.drive.mode) for _ in range(scene.step_count)]
    modes = {mode for _, mode in runs["python"]}
    assert [m for _, m in runs["python"]] == [m for _, m in runs["compiled"]]
    assert {DRIVE, BACK} <= modes or STUCK in modes
    worst = max(abs(a - b) for (s, _), (r, _) in zip(runs["python"], runs["compiled"]) for a, b in zip((*s.q, *s.v), (*r.q, *r.v)))
    assert worst <= 1e-13


def test_self_locking_mesh_holds_the_finger_on_its_stop_after_the_voltage_drops():
    """Driven into the MCP stop, the finger rests there; at 0 V the spring pulls it off the stop,
    but the self-locking mesh sticks at once: it stays on the stop, bit for bit."""
    scene = drive_scene({}, {"type": "step", "before": 6.0, "after": 0.0, "at": 0.3},
                        model={"joint_limits": {"mcp": [0.0, 0.5]}, "spring_stiffness": 0.05}, duration=0.5)
    traj = simulate(scene, kernel="python")
    after = traj.t > 0.3
    assert traj.q[-1, 0] == pytest.approx(0.5, abs=1e-9)
    assert np.all(traj.outputs["mesh_mode"][after] == STUCK)
    assert np.all(traj.q[after] == traj.q[-1]) and np.all(traj.v[after] == 0.0)
    back = drive_scene({"efficiency": 0.9, "backward_efficiency": 0.8}, {"type": "step", "before": 6.0, "after": 0.0, "at": 0.3},
                       model={"joint_limits": {"mcp": [0.0, 0.5]}, "spring_stiffness": 0.05}, duration=0.5)
    assert simulate(back, kernel="python").q[-1, 0] < 0.5 - 1e-3  # a back-drivable one leaves it


def test_drive_grasp_at_1khz_with_auto_sticks_where_the_tight_solve_turns():
    """The shipped scene as users run it (auto: the error-controlled dop853 with the mesh's mode changes
    located inside the step, 1 ms) against the forward reference's first turning point, to auto's
    target of 1e-6 rad; the run reports its error estimate, within the target."""
    scene = load_scene(ref.CONFIG / "drive_grasp.yaml")
    traj = simulate(scene)
    assert traj.method == "dop853" and 0.0 < traj.error_estimate < 1e-6
    turn = lambda t, y: y[3]  # noqa: E731
    turn.terminal, turn.direction = True, -1.0
    _, hit = reference(scene, lambda t, y: kkt_drive(scene, t, y, ETA_F, 6.0), traj.t[traj.t < 0.3], events=[turn])
    assert traj.q[-1, 0] == pytest.approx(hit.y_events[-1][0][0], abs=1e-6)
    assert traj.outputs["mesh_mode"][-1] == STUCK and traj.outputs["motor_current"][-1] == 0.0


@pytest.mark.parametrize("drive", DRIVES)
@pytest.mark.parametrize("voltage", [{"type": "square", "amplitude": 2.0, "offset": 2.0, "frequency": 5.0},
                                     {"type": "sine", "amplitude": 6.0, "frequency": 3.0}, None])
def test_lean_compiled_step_equals_the_event_loop_bit_for_bit(drive, voltage):
    """Without stops or contact a rolling step is one kernel call (`kernel.drive.driven_fast_step`):
    the same bits as the event loop (`actuators.stepping.advance`, the Python kernel's path) through
    current-limit kinks, reversals, sticking and breaking free; voltage=None: a held command per step
    (the node's path)."""
    pytest.importorskip("numba")
    scene = drive_scene(drive, voltage, model={"spring_stiffness": 0.2}, integrator={"method": "rk6", "dt": 1e-3},
                        duration=0.6)
    lean, loop, python = (Simulator(scene, kernel=k) for k in ("compiled", "compiled", "python"))
    assert lean._lean is not None
    loop._lean = None
    held = [4.0 * math.sin(2.0 * math.pi * 2.0 * k * scene.dt) + 2.0 for k in range(scene.step_count)]
    modes = set()
    for k in range(scene.step_count):
        u = held[k] if voltage is None else None
        a, b, c = lean.step(u), loop.step(u), python.step(u)
        assert (a.q, a.v, lean.system.drive.mode) == (b.q, b.v, loop.system.drive.mode)
        assert max(abs(x - y) for x, y in zip((*a.q, *a.v), (*c.q, *c.v))) <= 1e-13
        modes.add(lean.system.drive.mode)
    assert len(modes) >= 2 or drive.get("efficiency") == 1.0


def test_carrying_a_drive_run_over_to_the_same_scene_changes_nothing():
    """A task's scene change (a crush, a tip-force disturbance) carries the run over to a new Simulator:
    the mesh mode and direction go with it, so carrying over to the same scene is no change at all,
    through grasp, voltage drop and back-driven opening (modes drive, stuck, back). A fixed-step method:
    auto's dop853 restarts its step-size control at a carry-over, as at any change of the scene."""
    from finger_sim.grasp_objects import carry_over

    scene = load_scene(ref.CONFIG / "drive_grasp_backdrivable.yaml").with_overrides(method="rk4")
    straight, carried = Simulator(scene, kernel="python"), Simulator(scene, kernel="python")
    modes = set()
    for k in range(scene.step_count):
        if k % 50 == 25:
            carried = carry_over(carried, carried.scene)
        a, b = straight.step(), carried.step()
        assert (a.q, a.v, straight.system.drive.mode) == (b.q, b.v, carried.system.drive.mode)
        modes.add(straight.system.drive.mode)
    assert BACK in modes
