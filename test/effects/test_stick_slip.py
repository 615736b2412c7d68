"""Stick–slip friction (spec §7, `model.contact.friction_model: stick_slip`).

References, none of them finger_sim's code:
- `stick_slip_reference.py`: the sliding pieces by scipy's DOP853 at rtol 1e-11 on test/reference.py's
  KKT equations, the locked phases by statics (two KKT solves), lock and breakaway as events;
- the holding test by virtual work, written here: at rest the load on the linkage's one degree of
  freedom is G = Q·n (n = ∂q/∂θ1 on Φ = 0, Q the spring's and the contacts' normal generalized
  forces from hybrid_reference's candidates), the friction must supply τ_h = −(τ + G), and can
  supply μ_s Σ F_n |t·J n|;
- the numbers the regularized law gives today (main at 4dfb02d, full precision);
- the energy balance (sticking does no work, sliding only takes energy out).
"""

from __future__ import annotations

import math

import numpy as np
import pytest

import reference as ref
import stick_slip_reference as ssr
from finger_sim.errors import ConfigError
from finger_sim.scene import load_scene, scene_from_dict
from finger_sim.simulate import Simulator, simulate
from hybrid_reference import _candidates

TABLE = [{"name": "table", "type": "plane", "point": [0.0, 0.045], "normal": [0.0, -1.0]}]
DT = 0.001
#: θ1 of auto's stick–slip path (scipy's DOP853 at auto's tolerances) against the reference, rad: auto's promise.
THETA_TOLERANCE = 1e-6


def data(contact: dict, torque: dict, duration: float, *, damping: float = 0.005, **extra) -> dict:
    """A fingertip-on-a-table scene (the plane y = 45 mm), stick–slip friction unless `contact` says."""
    model = {"spring_stiffness": 0.001, "damping": damping,
             "contact": {"stiffness": 1.0e5, "exponent": 1.5, "damping": 1.5, "friction_model": "stick_slip", **contact}}
    return {"model": model, "objects": TABLE, "input": {"torque": torque}, "duration": duration,
            "integrator": {"method": "auto", "dt": DT}, **extra}


def statics(q, tau: float, d: dict) -> tuple[float, float]:
    """(τ_h, capacity), N·m, at rest at q by virtual work along the linkage (see the module docstring)."""
    model, c = d["model"], d["model"]["contact"]
    mu_s = c.get("static_friction", c["friction"])
    n = ref.rates(q, 1.0)
    load = ref.Effects(k=model["spring_stiffness"]).force(q, np.zeros(3), tau)  # τ and the spring at rest
    capacity = 0.0
    for delta, normal, jac in _candidates(q, d["objects"], (0.008, 0.007)):
        if delta > 0.0:
            fn = c["stiffness"] * delta ** c["exponent"]
            load = load + jac.T @ (fn * normal)
            capacity += mu_s * fn * abs(float(np.array([-normal[1], normal[0]]) @ (jac @ n)))
    return -float(load @ n), capacity


def mode_changes(traj) -> list[tuple[int, float]]:
    """(row, new mode) wherever friction_mode changes."""
    m = traj.outputs["friction_mode"]
    return [(int(i) + 1, float(m[i + 1])) for i in np.nonzero(np.diff(m))[0]]


def row_after(t: float) -> int:
    """The first output row whose time is past t."""
    return math.floor(t / DT) + 1


# -- holding and slipping ------------------------------------------------------------------
@pytest.mark.parametrize("mu_s, stays", [(2.0, True), (1.0, False)])
def test_a_grip_on_a_table_holds_after_the_torque_drops_when_the_cone_allows(mu_s, stays):
    """Issue 22's case: the torque drops 0.05 → 0.02 N·m at 0.5 s on a fingertip pressed on a table.
    The regularized law creeps to the frictionless rest (16.4928°). Stick–slip locks at the first
    turning point; with μ_s = 2 the cone holds the new load and θ stays exactly where it locked; with
    μ_s = 1 it does not (the holding test fails at the drop), the finger slips back once, located in
    the step, and locks again short of the frictionless rest. Both as the reference predicts."""
    d = data({"friction": 1.0, "static_friction": mu_s}, {"type": "step", "before": 0.05, "after": 0.02, "at": 0.5}, 1.0)
    traj = simulate(scene_from_dict(d))
    reference = ssr.solve(d)
    x = reference.states(traj.t)
    assert np.abs(x[0] - traj.q[:, 0]).max() < THETA_TOLERANCE
    ref_changes = [(row_after(t), 1.0 if kind == "lock" else 0.0) for t, kind in reference.changes]
    assert traj.outputs["friction_mode"][0] == 0.0  # at rest at the start, sliding off it
    assert mode_changes(traj) == ref_changes
    lock_row = ref_changes[0][0]
    q_lock = traj.q[lock_row]
    # the statics by hand at the pose where it locked: it holds 0.05 N·m, and 0.02 N·m only with μ_s = 2
    before, capacity = statics(q_lock, 0.05, d)
    after, _ = statics(q_lock, 0.02, d)
    assert abs(before) <= capacity and (abs(after) <= capacity) == stays
    drop = row_after(0.5)
    assert traj.outputs["friction_torque"][drop - 1] == pytest.approx(before, rel=1e-9)
    if stays:
        assert len(ref_changes) == 1
        assert (traj.q[lock_row:] == q_lock).all() and (traj.v[lock_row:] == 0.0).all()  # exactly still
        assert (traj.outputs["friction_mode"][lock_row:] == 1.0).all()
        assert traj.outputs["friction_torque"][-1] == pytest.approx(after, rel=1e-9)
    else:
        assert [kind for _, kind in reference.changes] == ["lock", "break", "lock"]
        assert reference.changes[1][0] == pytest.approx(0.5, abs=1e-12)  # breaks at the drop itself
        relock = ref_changes[2][0]
        assert (traj.q[relock:] == traj.q[relock]).all()
        frictionless = math.radians(16.4928)
        assert traj.q[-1, 0] - frictionless > math.radians(0.005)  # held short of the frictionless rest
        tau_h, capacity = statics(traj.q[-1], 0.02, d)
        assert abs(tau_h) <= capacity


def test_a_locked_finger_slips_at_the_tangential_load_the_statics_predict():
    """The torque falls slowly (0.05 N·m/s) on a finger locked against the table: the friction must
    hold a rising τ_h = −(τ + G); it breaks free where |τ_h| reaches μ_s Σ F_n |j|. θ1 is exactly
    constant before that instant and has moved (towards extension) at the first row after it."""
    slope = -0.05
    d = data({"friction": 1.0}, {"type": "ramp", "offset": 0.05, "slope": slope}, 0.6)
    traj = simulate(scene_from_dict(d))
    lock_row, mode = mode_changes(traj)[0]
    assert mode == 1.0
    q_lock = traj.q[lock_row]
    # τ_h(t) = −(τ(t) + G) is affine in τ: the breakaway torque solves |−(τ + G)| = capacity
    tau_lock = 0.05 + slope * traj.t[lock_row]
    tau_h, capacity = statics(q_lock, tau_lock, d)
    g = -tau_h - tau_lock
    tau_break = -g - math.copysign(capacity, tau_h)
    t_break = (tau_break - 0.05) / slope
    assert traj.t[lock_row] < t_break < 0.5
    breaks = row_after(t_break)
    assert (traj.q[lock_row:breaks] == q_lock).all()
    assert traj.q[breaks, 0] < q_lock[0]  # towards extension: the torque no longer holds it
    assert mode_changes(traj)[1] == (breaks, 0.0)
    # the holding torque reported while locked is the statics' at each row's torque
    rows = np.arange(lock_row, breaks)
    expected = [statics(q_lock, 0.05 + slope * traj.t[k], d)[0] for k in rows[::50]]
    np.testing.assert_allclose(traj.outputs["friction_torque"][rows[::50]], expected, rtol=1e-9)
    # the reference (KKT statics, brentq in time) breaks free where these statics say at its own locked pose
    reference = ssr.solve(d | {"duration": 0.25})  # past the breakaway (0.21 s)
    (t_lock_ref, _), (t_break_ref, kind) = reference.changes[:2]
    assert kind == "break"
    q_ref = reference.states(np.array([t_lock_ref]))[:3, 0]
    tau_h, capacity = statics(q_ref, 0.05 + slope * t_break_ref, d)
    assert abs(tau_h) == pytest.approx(capacity, rel=1e-9)


@pytest.mark.parametrize("stribeck", [None, 0.002])
def test_stick_slip_under_a_slowly_rising_pull_has_the_sawtooth_the_reference_predicts(stribeck):
    """A torque rising at 0.1 N·m/s presses the tip along the table with μ_k = 0.5, μ_s = 1: the finger
    locks, holds a rising τ_h until μ_s Σ F_n |j|, slips (kinetic friction is lower), the deeper
    contact stops it and it locks again: a staircase in θ1, a sawtooth in the friction torque (with a
    Stribeck velocity of 2 mm/s too, where the friction falls from μ_s to μ_k with the speed). Every
    lock and breakaway falls in the step the reference puts it in, and θ1 follows it to THETA_TOLERANCE."""
    contact = {"friction": 0.5, "static_friction": 1.0} | ({} if stribeck is None else {"stribeck_velocity": stribeck})
    duration = 0.9 if stribeck is None else 0.6  # two teeth; one with Stribeck, whose reference is slow (stiff)
    d = data(contact, {"type": "ramp", "offset": 0.02, "slope": 0.1}, duration, damping=0.0)
    traj = simulate(scene_from_dict(d))
    reference = ssr.solve(d)
    kinds = [kind for _, kind in reference.changes]
    assert kinds == ["lock", "break", "lock", "break", "lock"][:len(kinds)] and len(kinds) >= (5 if stribeck is None else 3)
    assert mode_changes(traj) == [(row_after(t), 1.0 if kind == "lock" else 0.0) for t, kind in reference.changes]
    x = reference.states(traj.t)
    assert np.abs(x[0] - traj.q[:, 0]).max() < THETA_TOLERANCE
    torque = traj.outputs["friction_torque"]
    for (t_lock, _), (t_break, _) in zip(reference.changes[::2], reference.changes[1::2]):
        a, b = row_after(t_lock), row_after(t_break)
        assert (traj.q[a:b] == traj.q[a]).all()  # stuck: exactly still
        # the reference breaks free at the edge of the cone (these statics at its locked pose)
        tau_h, capacity = statics(reference.states(np.array([t_lock]))[:3, 0], 0.02 + 0.1 * t_break, d)
        assert abs(tau_h) == pytest.approx(capacity, rel=1e-9)
        # the sawtooth's tooth: the holding torque grows with the load, within the cone until the break
        # (the statics at the finger's own pose), then drops to the kinetic μ_k F_n |j| < μ_s F_n |j|
        tau_h, capacity = statics(traj.q[a], 0.02 + 0.1 * traj.t[b - 1], d)
        assert torque[b - 1] == pytest.approx(tau_h, rel=1e-9) and abs(tau_h) <= capacity
        assert abs(statics(traj.q[a], 0.02 + 0.1 * traj.t[b], d)[0]) > capacity
        assert abs(torque[a]) < abs(torque[b - 1])
        if stribeck is None:  # with Stribeck the friction falls to μ_k only with the speed
            assert abs(torque[b]) < abs(torque[b - 1])


# -- energy ----------------------------------------------------------------------------------
def test_energy_never_increases_in_a_damped_scene_and_friction_work_closes_the_balance():
    """Under a constant torque, H = T + V + V_c − τ θ1 can only fall (sticking does no work, sliding
    and the dampers only take energy out). Without the dampers its fall is the friction's work
    ∫ friction_power dt, to the quadrature of the sampled power."""
    torque = {"type": "constant", "value": 0.02}
    damped = data({"friction": 0.3, "static_friction": 0.5}, torque, 0.6, initial={"theta1": 0.25, "theta1_dot": 3.0})
    traj = simulate(scene_from_dict(damped))
    h = traj.energy - 0.02 * traj.q[:, 0]
    assert np.diff(h).max() <= 1e-12
    assert h[-1] < h[0] - 1e-4
    lossless = data({"friction": 0.3, "static_friction": 0.5, "damping": 0.0}, torque, 0.6, damping=0.0,
                    initial={"theta1": 0.25, "theta1_dot": 3.0})
    traj = simulate(scene_from_dict(lossless))
    h = traj.energy - 0.02 * traj.q[:, 0]
    work = np.concatenate([[0.0], np.cumsum(0.5 * DT * (traj.outputs["friction_power"][1:] + traj.outputs["friction_power"][:-1]))])
    assert (traj.outputs["friction_power"] <= 0.0).all()
    assert work[-1] < -1e-4
    assert np.abs(h - h[0] - work).max() < 0.02 * abs(work[-1])


# -- the regularized law and the keys -----------------------------------------------------------
def test_the_regularized_law_still_gives_todays_numbers():
    """main at 4dfb02d, full precision: friction_table (μ 0.6) and the issue's held grip with μ = 1.

    Moved ≤ 3e-12 rad since contact onsets and releases end an internal step (`DormandPrince853.cut_at`),
    re-derived against test/hybrid_reference.py (2026-11-26): friction_table's max |θ − θ_ref| over the run
    1.8e-10 → 9.5e-11 rad, at the last row 2.8e-14 → 7.9e-13; the held grip's max 6.3e-11 (unchanged), at
    row 500 2.2e-12 → 8.5e-13, at the last 7.8e-13 → 1.8e-12. Moved ≤ 6e-12 rad since the internal step after a
    cut at an onset is the one taken past it before the cut (`dop853.restart_step`), re-derived the same way
    (2026-11-27): friction_table's max 9.5e-11 → 2.1e-10 rad, at the last row 7.9e-13 → 6.6e-13; the held
    grip's max 6.3e-11 (unchanged), at row 500 8.5e-13 → 1.3e-12, at the last 1.8e-12 → 7.4e-12. Moved ≤ 3e-12
    rad since a step's internal steps stop one past the first whose end shows a gap crossed
    (`crossings.step_to_crossing`), re-derived the same way (2026-11-27): friction_table's max 2.1e-10 → 9.5e-11
    rad, at the last row 6.6e-13 → 9.3e-13; the held grip's max 6.3e-11 (unchanged), at row 500 1.3e-12 →
    6.3e-13, at the last 7.4e-12 → 4.6e-12. Moved ≤ 2e-12 rad since a rejected trial that lands inside a contact is
    retried at its interpolated onset (`numerics.crossing_retry`), re-derived the same way (2026-11-27):
    friction_table's max 9.5e-11 (unchanged), at the last row 9.3e-13 → 1.4e-12; the held grip's max 6.3e-11
    (unchanged), at row 500 6.3e-13 → 2.3e-12, at the last 4.6e-12 → 6.7e-12."""
    traj = simulate(load_scene(ref.CONFIG / "hard" / "friction_table.yaml"))
    assert tuple(traj.q[-1]) == (0.2877195031787894, 0.5912739003397292, -1.603658898348246)
    assert traj.outputs["grip_force"][-1] == 0.13642616130965354
    d = data({"friction": 1.0}, {"type": "step", "before": 0.05, "after": 0.02, "at": 0.5}, 1.0)
    del d["model"]["contact"]["friction_model"]
    scene = scene_from_dict(d)
    assert scene_from_dict(data({"friction": 1.0, "friction_model": "regularized"}, d["input"]["torque"], 1.0)) == scene
    traj = simulate(scene)
    # DOP853 continues across output steps on each level of the step profile (`inputs.held_level`; it restarted
    # at every step before): θ moved ≤ 2e-12 rad from main's numbers, against a tolerance of 1e-6
    assert tuple(traj.q[500]) == (0.2888559022348713, 0.5926506246161213, -1.6011581859283284)
    assert tuple(traj.q[-1]) == (0.28785376137426383, 0.5914365769719706, -1.6033634499476956)  # crept to 16.49°
    assert (traj.outputs["grip_force"][500], traj.outputs["grip_force"][-1]) == (0.41617073584102476, 0.16376072059344124)
    assert "friction_mode" not in traj.outputs


@pytest.mark.parametrize("contact, key, allowed", [
    ({"friction_model": "coulomb"}, "model.contact.friction_model", "one of ['regularized', 'stick_slip']"),
    ({"friction_model": "stick_slip", "friction": 0.5, "static_friction": 0.4}, "model.contact.static_friction",
     "[friction = 0.5, 10]"),
    ({"friction_model": "stick_slip", "static_friction": 11.0}, "model.contact.static_friction", "[friction = 0, 10]"),
    ({"friction_model": "stick_slip", "stribeck_velocity": 0.0}, "model.contact.stribeck_velocity", "[1e-09, 10] m/s"),
    ({"friction_model": "stick_slip", "static_friction": "high"}, "model.contact.static_friction", "[friction = 0, 10]"),
    ({"static_friction": 1.0}, "model.contact.static_friction", "no value with friction_model: regularized"),
])
def test_bad_friction_keys_are_refused_in_one_line_naming_the_key_and_range(contact, key, allowed):
    d = data({}, {"type": "constant", "value": 0.02}, 0.1)
    d["model"]["contact"] = contact
    with pytest.raises(ConfigError) as err:
        scene_from_dict(d)
    message = str(err.value)
    assert message.startswith(key + ":") and allowed in message and "\n" not in message


def test_stick_slip_with_a_moving_object_and_joint_limits_is_refused():
    """A moving object is covered (test_stick_slip_moving), with joint stops not yet: one line."""
    d = data({"friction": 0.5}, {"type": "constant", "value": 0.02}, 0.1)
    d["objects"] = [dict(TABLE[0], motion={"type": "push", "direction": [1.0, 0.0], "distance": 0.01, "start": 0.0,
                                           "duration": 0.1})]
    d["model"]["joint_limits"] = {"mcp": [0.0, 1.5]}
    with pytest.raises(ConfigError, match=r"^model\.contact\.friction_model: .*covers neither yet"):
        scene_from_dict(d)


def test_a_stick_slip_scene_round_trips_and_auto_says_what_it_runs():
    """The law's keys survive to_dict; auto steps it with our error-controlled DOP853 on the compiled law
    and says so; the CSV has the friction columns."""
    d = data({"friction": 0.5, "static_friction": 0.8, "stribeck_velocity": 0.001}, {"type": "constant", "value": 0.02}, 0.05)
    scene = scene_from_dict(d)
    assert scene_from_dict(scene.to_dict()) == scene
    assert scene.to_dict()["model"]["contact"]["friction_model"] == "stick_slip"
    assert "friction_model" not in load_scene(ref.CONFIG / "press_table.yaml").to_dict()["model"]["contact"]
    sim = Simulator(scene)
    assert sim.kernel.startswith("numba-") and sim.method == "dop853" and sim.integrator.compiled
    assert "restarted at every friction mode change" in sim.method_reason and "rtol = atol = 1e-09" in sim.method_reason
    traj = simulate(scene)
    assert {"friction_mode", "friction_torque", "friction_power"} <= set(traj.outputs)


@pytest.mark.parametrize("contact, torque, duration", [
    ({"friction": 1.0}, {"type": "step", "before": 0.05, "after": 0.02, "at": 0.5}, 1.0),  # slips back once
    ({"friction": 0.5, "static_friction": 1.0, "stribeck_velocity": 0.002}, {"type": "ramp", "offset": 0.02, "slope": 0.1},
     0.6),  # the sawtooth with Stribeck
])
def test_the_compiled_law_steps_as_the_python_law(contact, torque, duration):
    """rk4 on the compiled kernel (the friction law compiled from the same plain functions) against rk4 in
    Python: the same locks and breakaways in the same rows, θ within 1e-12 rad; held exactly still."""
    d = data(contact, torque, duration) | {"integrator": {"method": "rk4", "dt": DT}}
    runs = [simulate(scene_from_dict(d), kernel=k) for k in ("python", "compiled")]
    assert mode_changes(runs[0]) == mode_changes(runs[1]) and len(mode_changes(runs[0])) >= 3
    assert np.abs(runs[0].q - runs[1].q).max() < 1e-12
    lock_row = mode_changes(runs[1])[0][0]
    assert (runs[1].q[lock_row:mode_changes(runs[1])[1][0]] == runs[1].q[lock_row]).all()


@pytest.mark.parametrize("restitution", [0.0, 0.5])
def test_sliding_into_a_stop_never_adds_energy_and_rests_on_it(restitution):
    """The tip slides along the table into the MCP stop at 0.2875 rad: the impact (−e θ1') reverses the sliding
    direction, the stop then holds the load. H = T + V + V_c − τθ1 (constant τ) never rises; the finger ends
    at rest exactly on the stop."""
    stop = 0.2875
    d = data({"friction": 0.3, "static_friction": 0.5, "damping": 0.0}, {"type": "constant", "value": 0.02}, 0.5,
             damping=0.0, initial={"theta1": 0.25, "theta1_dot": 3.0})
    d["model"] |= {"restitution": restitution, "joint_limits": {"mcp": [-0.1, stop]}}
    traj = simulate(scene_from_dict(d))
    h = traj.energy - 0.02 * traj.q[:, 0]
    # auto's DOP853 (rtol = atol = 1e-9) answers the rows from its dense output: in free flight after the
    # rebound H drifts by its error, of the order of rtol·|H| (measured 6.6e-12 J, |H| = 4.3e-3 J); the
    # friction's work is 1e-4 J a step
    assert np.diff(h).max() <= 1e-11 and h[-1] < h[0] - 1e-3
    assert traj.q[:, 0].max() <= stop + 1e-12
    assert traj.q[-1, 0] == pytest.approx(stop, abs=1e-12) and (traj.v[-1] == 0.0).all()
    assert traj.outputs["friction_torque"][-1] == 0.0  # the stop holds the load, the friction is idle
