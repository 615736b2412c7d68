"""A stick–slip breakaway located exactly on a step's end (spec §7).

The locked linkage breaks free at the root of its holding margin in time (brentq); that root can be the
step's end itself. The finger then leaves the step at rest, sliding: no zero-length integrator step
(DOP853 refused it as a non-finite state), and the row reports the sliding mode, not NaN.

References, none of them finger_sim's code: the statics by virtual work (`test_stick_slip.statics`),
which give the torque at which the cone gives way and the kinetic friction torque there, and
stick_slip_reference's hybrid solve for θ1 after the breakaway.
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy.optimize import brentq

import stick_slip_reference as ssr
from finger_sim import stick_slip
from finger_sim.scene import scene_from_dict
from finger_sim.simulate import Simulator, simulate
from test_stick_slip import DT, THETA_TOLERANCE, data, statics

#: θ1 of a fingertip pressed into the table at rest (rad): an overlap the scene still accepts (< 0.1 mm).
THETA_PRESSED = 0.2873
#: The rising torque, N·m/s, and the step on whose end the breakaway is put.
SLOPE = 0.05
BREAK_STEP = 45
#: A torque the cone holds at THETA_PRESSED, N·m (it holds τ in about [0.0036, 0.0120]).
HELD_TORQUE = 0.01
#: Ramp offsets tried on each side of the one whose breakaway lands on the step's end (in ulps).
ULPS = 4


def scene_data(offset: float, method: str) -> dict:
    """The fingertip locked on the table under τ = offset + SLOPE·t, μ_s = μ_k = 1, for a few steps past BREAK_STEP."""
    d = data({"friction": 1.0}, {"type": "ramp", "offset": offset, "slope": SLOPE}, (BREAK_STEP + 4) * DT,
             initial={"theta1": THETA_PRESSED, "theta1_dot": 0.0})
    return d | {"integrator": {"method": method, "dt": DT}}


def offsets_around_the_step_end(method: str) -> list[float]:
    """Ramp offsets whose breakaway the simulator puts within a few ulps of BREAK_STEP's end. The root
    of the simulator's own holding margin places them (its τ_h differs from the statics' in the 12th
    digit, more than the ulps that decide on which side of the step end its brentq lands)."""
    sim = Simulator(scene_from_dict(scene_data(HELD_TORQUE, method)))
    friction = stick_slip.element(sim.system)
    assert friction.mode == stick_slip.LOCKED

    def margin(tau: float) -> float:
        return stick_slip.holding_test(sim, friction, 0.0, sim.q, lambda s: tau)[0]

    tau_break = brentq(margin, HELD_TORQUE, 0.05, xtol=1e-20, rtol=4 * np.finfo(float).eps)
    centre = tau_break - SLOPE * BREAK_STEP * DT
    out = [centre]
    for _ in range(ULPS):
        out = [np.nextafter(out[0], -1.0), *out, np.nextafter(out[-1], 1.0)]
    return [float(x) for x in out]


@pytest.mark.parametrize("method", ["auto", "rk4"])
def test_a_breakaway_on_a_step_end_leaves_the_finger_sliding_from_rest(method):
    """Under a rising torque the locked fingertip breaks free where |τ_h| reaches μ_s Σ F_n |j| (the
    statics). For ramp offsets that put that instant within ulps of a step's end, every row has a
    mode: locked and exactly still before the breakaway, sliding after; a breakaway on the end itself
    reports that row at rest and sliding, with the kinetic friction torque −μ_k Σ F_n |j| the statics
    give, and θ1 then follows the reference's slide."""
    k = BREAK_STEP
    on_the_end = 0
    for offset in offsets_around_the_step_end(method):
        d = scene_data(offset, method)
        traj = simulate(scene_from_dict(d))
        mode, torque = traj.outputs["friction_mode"], traj.outputs["friction_torque"]
        assert np.isfinite(mode).all() and np.isfinite(torque).all()
        q0 = traj.q[0]
        tau_h, capacity = statics(q0, offset + SLOPE * k * DT, d)
        assert abs(tau_h) == pytest.approx(capacity, rel=1e-9)  # the statics break free at this step's end
        assert (mode[:k] == 1.0).all() and (traj.q[:k] == q0).all()
        assert (mode[k + 1:] == 0.0).all() and (np.diff(traj.q[k:, 0]) > 0.0).all()  # towards flexion: −sgn τ_h
        if mode[k] == 0.0 and traj.v[k, 0] == 0.0:  # broke free on the step's end itself
            on_the_end += 1
            assert (traj.q[k] == q0).all()
            assert torque[k] == pytest.approx(-capacity, rel=1e-9)  # μ_k = μ_s: the cone's edge, now kinetic
            x = ssr.solve(d).states(traj.t)
            assert np.abs(x[0] - traj.q[:, 0]).max() < THETA_TOLERANCE
    assert on_the_end >= 1  # the case this test is for did occur
