"""Stick–slip friction with a drive (spec §7 and §8): the friction cones and the stuck mesh share one
holding torque τ_h = τ_mesh + Σ j_k F_t,k.

References, none of them finger_sim's code:
- the holding test by virtual work (test_stick_slip.statics: the spring's and the contacts' normal
  generalized forces along the linkage's one degree of freedom; with a drive the scene has no torque
  input, so τ_h = −G), and §8's stuck set written again here: η_b > 0 holds τ_mesh in
  [η_f N τ_a, N τ_a/η_b], η_b ≤ 0 with the motor off holds any τ_mesh; τ_a = k_t u/R at rest (L = 0,
  below the current limit). The linkage holds while τ_h lies within Σ μ_s F_n |j| of that set;
- the energy balance: with the voltage off, T + V + V_c + ½ J_m ω_m² can only fall.
"""

from __future__ import annotations


import numpy as np
import pytest

from finger_sim.scene import scene_from_dict
from finger_sim.simulate import simulate
from test_stick_slip import DT, TABLE, mode_changes, row_after, statics

#: spec §8's defaults: N, k_t (N·m/A), R (Ω), J_m (kg·m²)
N, K_T, R, J_M = 300.0, 4.0e-3, 8.0, 5.0e-9
STUCK = 2.0  # the mesh_mode output's code of `stuck`
BACKDRIVABLE = {"efficiency": 0.8, "backward_efficiency": 0.6}


def data(contact: dict, voltage: dict, duration: float, drive: dict, *, damping: float = 0.005, **extra) -> dict:
    """test_stick_slip's fingertip-on-a-table scene driven by the motor (voltage input, V)."""
    model = {"spring_stiffness": 0.001, "damping": damping, "drive": drive,
             "contact": {"stiffness": 1.0e5, "exponent": 1.5, "damping": 1.5, "friction_model": "stick_slip", **contact}}
    return {"model": model, "objects": TABLE, "input": {"voltage": voltage}, "duration": duration,
            "integrator": {"method": "auto", "dt": DT}, **extra}


def test_a_self_locking_drive_holds_the_grip_with_the_voltage_off_where_the_friction_alone_cannot():
    """2 V drives the tip onto the table; the linkage locks at its first turning point (friction locked,
    mesh stuck, the same row); the voltage drops to 0 at 0.4 s. The cone alone (μ_s = 0.1) cannot hold
    the load there, the self-locking mesh with the motor off holds any: θ stays exactly where it locked,
    with the same grip, and the reported holding torque is the statics' τ_h."""
    d = data({"friction": 0.1}, {"type": "step", "before": 2.0, "after": 0.0, "at": 0.4}, 0.8, {})
    traj = simulate(scene_from_dict(d))
    changes = mode_changes(traj)
    lock_row = changes[-1][0]
    assert changes[-1][1] == 1.0 and traj.t[lock_row] < 0.4
    assert traj.outputs["mesh_mode"][lock_row - 1] != STUCK and (traj.outputs["mesh_mode"][lock_row:] == STUCK).all()
    q_lock = traj.q[lock_row]
    assert (traj.q[lock_row:] == q_lock).all() and (traj.v[lock_row:] == 0.0).all()
    assert (traj.outputs["grip_force"][lock_row:] == traj.outputs["grip_force"][lock_row]).all()
    tau_h, capacity = statics(q_lock, 0.0, d)
    assert abs(tau_h) > capacity  # the friction alone would let it slip
    assert traj.outputs["friction_torque"][-1] == pytest.approx(tau_h, rel=1e-9)
    assert traj.outputs["mesh_torque"][-1] == pytest.approx(tau_h, rel=1e-9)


def test_a_backdrivable_drive_and_the_friction_share_the_load_and_break_free_where_the_statics_predict():
    """η_f = 0.8, η_b = 0.6: the stuck mesh holds τ_mesh in [η_f N τ_a, N τ_a/η_b]. The voltage falls
    slowly (2 − 2t V) on the linkage locked against the table: τ_h is fixed (q is), the band falls with
    τ_a = k_t u/R, and the linkage breaks free (towards extension) where N τ_a/η_b + μ_s Σ F_n |j| = τ_h:
    later than the mesh alone would, and the friction alone could not hold it at all."""
    u0, slope, eta_f, eta_b = 2.0, -2.0, BACKDRIVABLE["efficiency"], BACKDRIVABLE["backward_efficiency"]
    d = data({"friction": 0.1, "static_friction": 0.2}, {"type": "ramp", "offset": u0, "slope": slope}, 0.9,
             BACKDRIVABLE)
    traj = simulate(scene_from_dict(d))
    changes = mode_changes(traj)
    lock = next(k for k, (row, mode) in enumerate(changes) if mode == 1.0 and traj.t[row] > 0.1)
    lock_row, (break_row, mode) = changes[lock][0], changes[lock + 1]
    assert mode == 0.0
    q_lock = traj.q[lock_row]
    tau_h, capacity = statics(q_lock, 0.0, d)
    tau_a = K_T * (u0 + slope * traj.t[lock_row]) / R
    assert eta_f * N * tau_a - capacity <= tau_h <= N * tau_a / eta_b + capacity  # it holds where it locked
    assert tau_h > capacity  # the friction alone cannot
    u_break = R * eta_b * (tau_h - capacity) / (N * K_T)  # N τ_a/η_b + capacity = τ_h
    u_mesh_alone = R * eta_b * tau_h / (N * K_T)
    t_break, t_mesh_alone = (u_break - u0) / slope, (u_mesh_alone - u0) / slope
    assert traj.t[lock_row] < t_mesh_alone < t_break < traj.t[-1]
    assert abs(u_break) / R < 0.5  # below the current limit: τ_a = k_t u/R
    assert break_row == row_after(t_break)
    assert (traj.q[lock_row:break_row] == q_lock).all()
    assert (traj.outputs["mesh_mode"][lock_row:break_row] == STUCK).all()
    assert traj.q[break_row, 0] < q_lock[0] and traj.outputs["mesh_mode"][break_row] != STUCK


@pytest.mark.parametrize("drive", [{}, BACKDRIVABLE])
def test_energy_never_rises_with_the_voltage_off(drive):
    """The finger swings into the table with the motor off (u = 0, so the electrical input v·i is 0) and
    slides along it: T + V + V_c + ½ J_m ω_m² only falls (copper, mesh, friction and damping losses), and
    the drive's energy report closes against that fall (to its Gauss quadrature over the contact mode:
    measured 1.2e-5). The self-locking mesh stops the finger for good at its first turning point."""
    d = data({"friction": 0.3, "static_friction": 0.5}, {"type": "constant", "value": 0.0}, 0.5, drive,
             initial={"theta1": 0.286, "theta1_dot": 3.0})
    traj = simulate(scene_from_dict(d))
    h = traj.energy + 0.5 * J_M * (N * traj.v[:, 0]) ** 2
    assert np.diff(h).max() <= 1e-12
    assert h[-1] < h[0] - 1e-3
    assert traj.outputs["friction_power"].min() < -1e-3  # it slid in contact
    assert abs(traj.energy_report["residual"]) < 1e-4 * (h[0] - h[-1])
    if drive == {}:
        lock_row, mode = mode_changes(traj)[-1]
        assert mode == 1.0 and (traj.q[lock_row:] == traj.q[lock_row]).all()
        assert traj.outputs["grip_force"][-1] > 0.5


def test_the_compiled_law_with_a_drive_steps_as_the_python_law():
    """rk4 on the compiled kernel (friction law and mesh compiled) against rk4 in Python on the falling
    voltage above: the same locks, breakaways and mesh modes in the same rows, θ within 1e-12 rad."""
    d = data({"friction": 0.1, "static_friction": 0.2}, {"type": "ramp", "offset": 2.0, "slope": -2.0}, 0.7,
             BACKDRIVABLE) | {"integrator": {"method": "rk4", "dt": DT}}
    runs = [simulate(scene_from_dict(d), kernel=k) for k in ("python", "compiled")]
    assert mode_changes(runs[0]) == mode_changes(runs[1]) and len(mode_changes(runs[0])) >= 2
    assert (runs[0].outputs["mesh_mode"] == runs[1].outputs["mesh_mode"]).all()
    assert np.abs(runs[0].q - runs[1].q).max() < 1e-12
