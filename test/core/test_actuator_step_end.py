"""A stick–slip breakaway on a step's end with a stateful actuator (the test file's torque lag, Python path).

The locked fingertip holds a lagged torque τ_a = u (1 − e^(−t/T)) rising towards the command u until the
friction cone gives way. The command is bisected to the float where the breakaway moves from after a
step's end to before it: there it lands on the end itself. Every row then has a friction mode (it was
NaN: the step ended with a zero-length step, the state at rest unrecorded), and a row at rest that
slides carries the kinetic friction torque the statics give at the lag's closed-form τ_a
(`test_stick_slip.statics`, virtual work).
"""

from __future__ import annotations

import math
import sys
from pathlib import Path

import numpy as np
import pytest

from finger_sim import stick_slip
from finger_sim.scene import scene_from_dict
from finger_sim.simulate import Simulator
from test_state_layout import LAG, TorqueLag

sys.path.append(str(Path(__file__).resolve().parents[1] / "effects"))  # test_stick_slip, for its scene and statics
from test_stick_slip import data, statics  # noqa: E402

DT = 1e-3
#: The step on whose end the breakaway is put.
BREAK_STEP = 45
#: θ1 of the fingertip pressed into the table at rest, rad (as test_stick_slip_step_end); μ = 3 there holds
#: τ in about [−0.005, 0.0205] N·m, so the lag's τ_a(0) = 0 is held.
THETA_PRESSED, MU = 0.2873, 3.0
#: Commands (N·m) that break free after and before BREAK_STEP's end (τ_a reaches 0.0205 at ≈ 0.045 s near 0.0229).
LATE, EARLY = 0.0215, 0.025


def scene_data(u: float) -> dict:
    d = data({"friction": MU}, {"type": "constant", "value": u}, (BREAK_STEP + 3) * DT,
             initial={"theta1": THETA_PRESSED, "theta1_dot": 0.0})
    return d | {"integrator": {"method": "rk6", "dt": DT}}


def rows(u: float) -> list[tuple[tuple, tuple, dict]]:
    """(q, q', the friction's outputs) after each step of the lag under the command u."""
    sim = Simulator(scene_from_dict(scene_data(u)), actuator=TorqueLag(LAG), kernel="python")
    friction = stick_slip.element(sim.system)
    out = []
    for _ in range(BREAK_STEP + 2):
        sim.step()
        out.append((sim.q, sim.v, dict(friction.outputs(sim.step_index * DT, sim.q, sim.v))))
    return out


def locked_at_the_step_end(u: float) -> bool:
    return rows(u)[BREAK_STEP - 1][2]["friction_mode"] == 1.0


def test_a_breakaway_on_a_step_end_through_the_lag_reports_the_sliding_mode():
    lo, hi = LATE, EARLY
    assert locked_at_the_step_end(lo) and not locked_at_the_step_end(hi)
    while (mid := 0.5 * (lo + hi)) not in (lo, hi):
        lo, hi = (mid, hi) if locked_at_the_step_end(mid) else (lo, mid)
    on_the_end = 0
    for u in (np.nextafter(lo, 0.0), lo, hi, np.nextafter(hi, 1.0)):
        out = rows(float(u))
        modes = [o["friction_mode"] for _, _, o in out]
        assert all(math.isfinite(m) for m in modes), modes
        q, v, o = out[BREAK_STEP - 1]
        if o["friction_mode"] == 0.0 and v[0] == 0.0:  # broke free on the step's end itself
            on_the_end += 1
            t = BREAK_STEP * DT
            tau_h, capacity = statics(np.array(q), float(u) * (1.0 - math.exp(-t / LAG)), scene_data(float(u)))
            assert abs(tau_h) == pytest.approx(capacity, rel=1e-6)  # the cone's edge: here it gives way
            assert o["friction_torque"] == pytest.approx(-capacity, rel=1e-6)  # now kinetic (μ_k = μ_s)
    assert on_the_end >= 1  # the case this test is for did occur
