"""Stick–slip friction with an inductive drive (spec §7 and §8, L > 0): the current is a state, and the
friction cones and the stuck mesh share one holding torque τ_h = τ_mesh + Σ j_k F_t,k.

References, none of them finger_sim's code:
- the holding test by virtual work (test_stick_slip.statics) and §8's stuck set written again here
  (test_stick_slip_drive's docstring), with τ_a = k_t i;
- the winding's equation solved by hand: locked, θ1' = 0, so L i' = u − R i alone. With u constant
  the current relaxes as i(t) = u/R + (i(t0) − u/R) e^(−R (t − t0)/L); under a ramp u = u0 + s t it
  follows (u(t) − s L/R)/R once the transient has died, i.e. the L = 0 current L/R later;
- the energy balance: with the voltage off (u = 0), T + V + V_c + ½ J_m ω_m² + ½ L i² can only fall.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from finger_sim.scene import scene_from_dict
from finger_sim.simulate import simulate
from test_stick_slip import mode_changes, row_after, statics
from test_stick_slip_drive import BACKDRIVABLE, J_M, K_T, N, R, STUCK, data

#: rk4 in auto's electrical substeps against the closed-form current, relative (measured: 2e-8)
CURRENT_TOLERANCE = 1e-6


def test_a_self_locking_inductive_drive_holds_the_grip_while_the_current_decays_as_its_equation_says():
    """2 V through L = 20 mH (L/R = 2.5 ms) drives the tip onto the table; the linkage locks at its first
    turning point (friction locked, mesh stuck). Locked, the current relaxes to u/R and, after the
    voltage drops to 0 at 0.4 s, decays as e^(−R t/L): the closed form, row by row. The cone alone
    (μ_s = 0.1) cannot hold the load; the self-locking mesh holds it with any current below the
    forward band: θ stays exactly where it locked and the reported holding torque is the statics' τ_h."""
    inductance, drop = 0.02, 0.4
    d = data({"friction": 0.1}, {"type": "step", "before": 2.0, "after": 0.0, "at": drop}, 0.8,
             {"inductance": inductance})
    traj = simulate(scene_from_dict(d), kernel="python")  # the compiled inductive stick–slip step compiles for minutes
    assert traj.method == "rk4"
    lock_row, mode = mode_changes(traj)[-1]
    assert mode == 1.0 and traj.t[lock_row] < drop
    assert traj.outputs["mesh_mode"][lock_row - 1] != STUCK and (traj.outputs["mesh_mode"][lock_row:] == STUCK).all()
    q_lock = traj.q[lock_row]
    assert (traj.q[lock_row:] == q_lock).all() and (traj.v[lock_row:] == 0.0).all()
    tau_h, capacity = statics(q_lock, 0.0, d)
    assert abs(tau_h) > capacity  # the friction alone would let it slip
    assert traj.outputs["friction_torque"][-1] == pytest.approx(tau_h, rel=1e-9)
    current = traj.outputs["motor_current"]
    tau = inductance / R
    rows = np.arange(lock_row + 1, row_after(drop))  # locked at 2 V: relaxing to u/R from the lock row
    k0 = lock_row
    expected = 2.0 / R + (current[k0] - 2.0 / R) * np.exp(-(traj.t[rows] - traj.t[k0]) / tau)
    np.testing.assert_allclose(current[rows], expected, rtol=CURRENT_TOLERANCE)
    k0 = row_after(drop) - 1  # the row at the drop: the voltage is 0 after it
    rows = np.arange(k0 + 1, k0 + 40)
    expected = current[k0] * np.exp(-(traj.t[rows] - traj.t[k0]) / tau)
    np.testing.assert_allclose(current[rows], expected, rtol=CURRENT_TOLERANCE)
    assert abs(current[-1]) < 1e-30


def test_a_backdrivable_inductive_drive_and_the_friction_break_free_one_l_over_r_after_the_resistive_drive():
    """η_f = 0.8, η_b = 0.6, L = 80 mH (L/R = 10 ms): the voltage falls slowly (2 − 2t V) on the linkage
    locked against the table; the current lags it (u(t − L/R)/R), so the linkage breaks free where
    N k_t i/η_b + μ_s Σ F_n |j| = τ_h, L/R later than with L = 0, in the row that predicts."""
    u0, slope, eta_f, eta_b, inductance = 2.0, -2.0, BACKDRIVABLE["efficiency"], BACKDRIVABLE["backward_efficiency"], 0.08
    d = data({"friction": 0.1, "static_friction": 0.2}, {"type": "ramp", "offset": u0, "slope": slope}, 0.9,
             BACKDRIVABLE | {"inductance": inductance})
    traj = simulate(scene_from_dict(d), kernel="python")  # the compiled inductive stick–slip step compiles for minutes
    changes = mode_changes(traj)
    lock = next(k for k, (row, mode) in enumerate(changes) if mode == 1.0 and traj.t[row] > 0.1)
    lock_row, (break_row, mode) = changes[lock][0], changes[lock + 1]
    assert mode == 0.0
    q_lock = traj.q[lock_row]
    tau_h, capacity = statics(q_lock, 0.0, d)
    i_lock = traj.outputs["motor_current"][lock_row]
    assert eta_f * N * K_T * i_lock - capacity <= tau_h <= N * K_T * i_lock / eta_b + capacity
    assert tau_h > capacity  # the friction alone cannot
    lag = inductance / R
    u_break = R * eta_b * (tau_h - capacity) / (N * K_T)  # N k_t i/η_b + capacity = τ_h with i = u(t − L/R)/R
    t_break = (u_break - u0) / slope + lag
    assert math.exp(-(t_break - traj.t[lock_row]) / lag) < 1e-9  # the lock's transient has died by then
    assert abs(u_break) / R < 0.5  # below the current limit
    assert break_row == row_after(t_break)
    assert break_row - row_after(t_break - lag) >= 9  # not where the resistive drive would break
    current, rows = traj.outputs["motor_current"], np.arange(lock_row + 1, break_row)

    def lagging(t):  # the ramp's particular solution of L i' = u − R i
        return (u0 + slope * t - slope * lag) / R

    expected = lagging(traj.t[rows]) + (current[lock_row] - lagging(traj.t[lock_row])) * np.exp(
        -(traj.t[rows] - traj.t[lock_row]) / lag)
    np.testing.assert_allclose(current[rows], expected, rtol=CURRENT_TOLERANCE)
    assert (traj.q[lock_row:break_row] == q_lock).all()
    assert (traj.outputs["mesh_mode"][lock_row:break_row] == STUCK).all()
    assert traj.q[break_row, 0] < q_lock[0] and traj.outputs["mesh_mode"][break_row] != STUCK


@pytest.mark.parametrize("drive", [{}, BACKDRIVABLE, {"efficiency": 1.0, "backward_efficiency": 1.0}])
def test_energy_never_rises_with_the_voltage_off_and_an_inductive_winding(drive):
    """The finger swings into the table with the motor off (u = 0: no electrical input) through
    L = 20 mH and slides along it: T + V + V_c + ½ J_m ω_m² + ½ L i² only falls (copper, mesh,
    friction and damping losses). The self-locking mesh stops the finger for good at its first turning
    point; the backdrivable and the ideal gear (no mesh modes) slide on."""
    inductance = 0.02
    d = data({"friction": 0.3, "static_friction": 0.5}, {"type": "constant", "value": 0.0}, 0.5,
             drive | {"inductance": inductance}, initial={"theta1": 0.286, "theta1_dot": 3.0})
    traj = simulate(scene_from_dict(d), kernel="python")  # the compiled inductive stick–slip step compiles for minutes
    i = traj.outputs["motor_current"]
    h = traj.energy + 0.5 * J_M * (N * traj.v[:, 0]) ** 2 + 0.5 * inductance * i**2
    assert np.diff(h).max() <= 1e-12
    assert h[-1] < h[0] - 1e-3
    assert traj.outputs["friction_power"].min() < -1e-3  # it slid in contact
    assert np.abs(i).max() > 1e-3  # the back-EMF drove a current through the winding
    if drive == {}:
        lock_row, mode = mode_changes(traj)[-1]
        assert mode == 1.0 and (traj.q[lock_row:] == traj.q[lock_row]).all()
        assert (traj.outputs["mesh_mode"][lock_row:] == STUCK).all()
