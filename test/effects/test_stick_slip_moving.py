"""Stick–slip friction against a moving object (spec §7, `friction_model: stick_slip` with a `motion`).

The scene: the fingertip pressed (0.05 N·m) on a table (the plane y = 45 mm) locks there; from 0.3 s the
table is pushed slowly along +x. Locked, the finger rides with it (the tip does not slide on the table),
lifting off as it goes, so the normal force falls while the holding torque the friction must supply
does not: it breaks free where |τ_h| reaches μ_s F_n |j|, then slips (and sticks again) on the moving table.

References, none of them finger_sim's code:
- until the push the table is fixed: `stick_slip_reference` (scipy's DOP853 at rtol 1e-11 and statics);
- riding: the tip's material point stays where it is on the table, tip_x(θ1(t)) − c_x(t) = const, θ1(t)
  by brentq on test/reference.py's kinematics;
- the holding torque of the ride by an augmented KKT solve written here (q'', λ and τ_h unknown; the extra
  row: the tip's tangential acceleration equals the table's, t·(J q'' + J̇ q') = t·c̈), where finger_sim
  differentiates the ride's speed numerically;
- the breakaway at the root of μ_s F_n |j| − |τ_h| along that ride (brentq);
- after it, `table_reference`: sliding pieces by scipy's DOP853 at rtol 1e-11 on test/reference.py's KKT
  equations with the kinetic friction opposing the tip's velocity relative to the table,
  u = t·(J q' − ċ), stopped where u = 0; there the holding test above decides lock (a ride) or slide on.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.integrate import solve_ivp
from scipy.optimize import brentq

import reference as ref
import stick_slip_reference as ssr
from finger_sim.scene import scene_from_dict
from finger_sim.simulate import simulate
from hybrid_reference import _candidates, kkt_with, motion_offset

DT = 0.001
PUSH_START, PUSH_TIME, PUSH_DISTANCE = 0.3, 1.0, 0.01  # s, s, m (along +x)
TORQUE = 0.05  # N·m
MU_K, MU_S = 1.0, 2.0
SPRING, DAMPING = 0.001, 0.005  # N·m/rad, N·m·s/rad
K_C, E_C = 1.0e5, 1.5
#: θ1 of auto's path against the reference until the lock, rad: auto's promise.
THETA_TOLERANCE = 1e-6
TANGENT = np.array([1.0, 0.0])  # t_c of the table (n = (0, −1) turned by +90°)


def data(duration: float, motion: bool = True) -> dict:
    table = {"name": "table", "type": "plane", "point": [0.0, 0.045], "normal": [0.0, -1.0]}
    if motion:
        table["motion"] = {"type": "push", "direction": [1.0, 0.0], "distance": PUSH_DISTANCE, "start": PUSH_START,
                           "duration": PUSH_TIME}
    contact = {"stiffness": K_C, "exponent": E_C, "damping": 0.0, "friction": MU_K, "static_friction": MU_S,
               "friction_model": "stick_slip"}
    return {"model": {"spring_stiffness": SPRING, "damping": DAMPING, "contact": contact}, "objects": [table],
            "input": {"torque": {"type": "constant", "value": TORQUE}}, "duration": duration,
            "integrator": {"method": "auto", "dt": DT}}


def push(t: float) -> tuple[float, float, float]:
    """(s, s', s'') of the table along +x at t: s = L (1 − cos(π x / T)) / 2, x = t − t0."""
    w, x = math.pi / PUSH_TIME, t - PUSH_START
    return (0.5 * PUSH_DISTANCE * (1.0 - math.cos(w * x)), 0.5 * PUSH_DISTANCE * w * math.sin(w * x),
            0.5 * PUSH_DISTANCE * w * w * math.cos(w * x))


def ride(theta_lock: float, t: float) -> float:
    """θ1 at t riding with the table from the pose locked at θ1 = theta_lock: tip_x − s(t) constant."""
    x0 = ref.tip(ref.assemble(theta_lock))[0]
    return brentq(lambda th: ref.tip(ref.assemble(th))[0] - x0 - push(t)[0], theta_lock - 0.2, theta_lock + 0.2,
                  xtol=1e-15, rtol=4 * np.finfo(float).eps)


def holding(theta1: float, t: float) -> tuple[float, float]:
    """(τ_h, μ_s F_n |j|), N·m, riding at θ1 at t: the augmented KKT solve (see the module docstring)."""
    q = ref.assemble(theta1)
    jac = ref.tip_jacobian(q)
    along = ref.rates(q, 1.0)
    j = float(TANGENT @ (jac @ along))
    s, s_dot, s_ddot = push(t)
    v = along * (s_dot / j)  # the tip's tangential speed is the table's
    contacts = [(d, n, jj) for d, n, jj in _candidates(q, data(0.0)["objects"], (0.008, 0.007)) if d > 0.0]
    assert len(contacts) <= 1 and all(np.allclose(c[2], jac) for c in contacts)  # the tip alone touches, if any
    delta, n = (contacts[0][0], contacts[0][1]) if contacts else (0.0, np.array([0.0, -1.0]))
    fn = K_C * delta**E_C  # 0 where the ride has lifted the tip off
    rhs_q = ref.Effects(k=SPRING, c=DAMPING).force(q, v, TORQUE) + jac.T @ (fn * n) - ref.coriolis(q, v)
    jdot_v = -ref.R1 * ref.e(q[0]) * v[0] ** 2 - ref.L3 * ref.e(q[2] + ref.ALPHA) * v[2] ** 2
    a = np.zeros((6, 6))
    a[:3, :3] = ref.mass(q)
    a[:3, 3:5] = -ref.phi_q(q).T
    a[0, 5] = -1.0  # τ_h on θ1
    a[3:5, :3] = ref.phi_q(q)
    a[5, :3] = TANGENT @ jac
    rhs = np.concatenate([rhs_q, ref.gamma(q, v), [TANGENT @ (np.array([s_ddot, 0.0]) - jdot_v)]])
    tau_h = float(np.linalg.solve(a, rhs)[5])
    return tau_h, MU_S * fn * abs(j)


def _ride_breakaway(theta_lock: float, t0: float, t_end: float) -> float | None:
    """When the ride from (t0, θ1 = theta_lock) breaks free, by a scan every ms and brentq; None: it holds."""
    x0 = ref.tip(ref.assemble(theta_lock))[0] - push(t0)[0]

    def margin(t: float) -> float:
        th = brentq(lambda th: ref.tip(ref.assemble(th))[0] - x0 - push(t)[0], theta_lock - 0.2, theta_lock + 0.2,
                    xtol=1e-15, rtol=4 * np.finfo(float).eps)
        tau_h, capacity = holding(th, t)
        return capacity - abs(tau_h)

    grid = np.append(np.arange(t0, t_end, DT), t_end)
    for a, b in zip(grid, grid[1:]):
        if margin(b) < 0.0:
            return brentq(margin, a, b, xtol=1e-13)
    return None


def table_reference(theta_lock: float, t_end: float) -> tuple[list, list]:
    """(pieces (t0, t1, θ1(t) function), mode changes (t, "lock" | "break")) from the lock at the push's start."""
    objects = data(0.0)["objects"]
    fx = ref.Effects(k=SPRING, c=DAMPING)
    pieces, changes = [], []
    t, theta, locked = PUSH_START, theta_lock, True
    while t < t_end - 1e-12:
        if locked:
            x0 = ref.tip(ref.assemble(theta))[0] - push(t)[0]
            track = (lambda x, x0=x0, th0=theta: brentq(lambda th: ref.tip(ref.assemble(th))[0] - x0 - push(x)[0],
                                                        th0 - 0.2, th0 + 0.2, xtol=1e-15))
            end = _ride_breakaway(theta, t, t_end)
            pieces.append((t, t_end if end is None else end, track))
            if end is None:
                break
            changes.append((end, "break"))
            t, theta = end, track(end)
            q = ref.assemble(theta)
            j = float(TANGENT @ (ref.tip_jacobian(q) @ ref.rates(q, 1.0)))
            y = np.concatenate([q, ref.rates(q, push(t)[1] / j)])
            sign = -math.copysign(1.0, holding(theta, t)[0]) * math.copysign(1.0, j)  # of u after the break

        def slip(x, yy):  # u = t·(J q' − ċ) of the tip
            return float(TANGENT @ (ref.tip_jacobian(yy[:3]) @ yy[3:] - motion_offset(objects[0], x)[1]))

        def rhs(x, yy, sign=sign):
            q, v = yy[:3], yy[3:]
            force = np.zeros(3)
            for delta, n, jac in _candidates(q, objects, (0.008, 0.007), x):
                if delta > 0.0:
                    fn = K_C * delta**E_C
                    force += jac.T @ (fn * n - MU_K * fn * sign * TANGENT)
            return np.concatenate([v, kkt_with(q, v, TORQUE, fx, force)])

        stop = (lambda x, yy, sign=sign: sign * slip(x, yy))
        stop.terminal, stop.direction = True, -1
        sol = solve_ivp(rhs, (t, t_end), y, method="DOP853", rtol=1e-11, atol=1e-13, dense_output=True, events=[stop])
        assert sol.success
        pieces.append((t, float(sol.t[-1]), (lambda x, f=sol.sol: float(f(x)[0]))))
        t, y = float(sol.t[-1]), sol.y[:, -1].copy()
        if sol.status == 1:  # u = 0: the holding test
            theta = float(y[0])
            tau_h, capacity = holding(theta, t)
            locked = capacity >= abs(tau_h)
            if locked:
                changes.append((t, "lock"))
            else:
                q = ref.assemble(theta)
                j = float(TANGENT @ (ref.tip_jacobian(q) @ ref.rates(q, 1.0)))
                sign = -math.copysign(1.0, tau_h) * math.copysign(1.0, j)
    return pieces, changes


def changes(traj) -> list[tuple[int, float]]:
    m = traj.outputs["friction_mode"]
    return [(int(i) + 1, float(m[i + 1])) for i in np.nonzero(np.diff(m))[0]]


def row_after(t: float) -> int:
    return math.floor(t / DT) + 1


@pytest.fixture(scope="module")
def pushed():
    return simulate(scene_from_dict(data(0.7)))


def test_a_finger_locked_on_a_moving_table_rides_with_it_then_slips_where_the_cone_gives(pushed):
    traj = pushed
    # until the push: a fixed table, locked at the first turning point, as the reference
    fixed = ssr.solve(data(PUSH_START, motion=False))
    before = traj.t <= PUSH_START
    assert np.abs(fixed.states(traj.t[before])[0] - traj.q[before, 0]).max() < THETA_TOLERANCE
    assert [kind for _, kind in fixed.changes] == ["lock"]
    lock_row = row_after(fixed.changes[0][0])
    assert changes(traj)[0] == (lock_row, 1.0)
    theta_lock = traj.q[lock_row, 0]
    # the ride: the breakaway where the cone no longer holds τ_h
    def margin(t: float) -> float:
        tau_h, capacity = holding(ride(theta_lock, t), t)
        return capacity - abs(tau_h)

    assert margin(PUSH_START) > 0.0 and margin(0.45) < 0.0
    t_break = brentq(margin, PUSH_START, 0.45, xtol=1e-12)
    assert t_break > PUSH_START + 0.05  # it rode a while (θ1 moved by mrad)
    assert changes(traj)[1] == (row_after(t_break), 0.0)
    riding = np.nonzero((traj.t > PUSH_START) & (traj.t < t_break))[0]
    theta_ref = np.array([ride(theta_lock, t) for t in traj.t[riding]])
    assert abs(theta_ref[-1] - theta_lock) > 1e-3
    assert np.abs(traj.q[riding, 0] - theta_ref).max() < 1e-9  # the tip does not slide on the table
    tau_ref = np.array([holding(th, t)[0] for th, t in zip(theta_ref, traj.t[riding])])
    assert traj.outputs["friction_torque"][riding] == pytest.approx(tau_ref, rel=1e-6)
    assert (traj.outputs["friction_mode"][riding] == 1.0).all()
    # after it: sliding on the table, the friction opposing the slip (power ≤ 0), sticking again at times
    after = traj.t > t_break
    assert (traj.outputs["friction_power"][after] <= 0.0).all()
    assert (traj.outputs["friction_mode"][after] == 1.0).any() and (traj.outputs["friction_mode"][after] == 0.0).any()


def test_the_stick_slip_sawtooth_on_the_moving_table_follows_the_reference(pushed):
    """After the breakaway the tip slips on the table, sticks again where its relative velocity vanishes
    and the cone holds, and breaks again: every mode change in the reference's row, θ1 within auto's
    promise throughout."""
    traj = pushed
    lock_row = changes(traj)[0][0]
    pieces, ref_changes = table_reference(traj.q[lock_row, 0], traj.t[-1])
    assert len(ref_changes) >= 5  # a sawtooth: break, lock, break, lock, ...
    assert changes(traj)[1:] == [(row_after(t), 1.0 if kind == "lock" else 0.0) for t, kind in ref_changes]
    rows = np.nonzero(traj.t >= PUSH_START)[0]
    starts = np.array([p[0] for p in pieces])
    theta_ref = np.array([pieces[np.searchsorted(starts, t, side="right") - 1][2](t) for t in traj.t[rows]])
    assert np.abs(traj.q[rows, 0] - theta_ref).max() < THETA_TOLERANCE


def test_the_run_reports_the_error_its_steps_estimated_through_a_ride():
    """The summary's estimate is carried through the ride (its own bound added), not restarted at 0 by the
    states a ride moves: a run that ends riding reports the estimate of the swing that led to the lock."""
    riding = simulate(scene_from_dict(data(0.35)))
    locked = simulate(scene_from_dict(data(0.25)))  # the same path, locked on the table at rest
    assert riding.outputs["friction_mode"][-1] == 1.0 and riding.v[-1, 0] != 0.0
    assert 0.0 < locked.error_estimate <= riding.error_estimate < THETA_TOLERANCE
