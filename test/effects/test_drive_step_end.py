"""A stuck self-locking mesh (spec §8) breaking free exactly on a step's end (`actuators.stepping.advance`).

The finger is held at θ1 = 0.5 rad by the default worm-type drive against the PIP spring; the voltage
ramps up from 0 until the forward flank's η_f N k_t u/R exceeds the load τ_h, and the mesh breaks free.
The ramp's slope is bisected to the float where the breakaway moves from after a step's end to before
it: there it lands on the end itself. Before the fix that step went on with a zero-length step, which
DOP853 refused (SimulationDiverged, dt = 0). Reference for the breakaway: τ_h by virtual work along the
linkage (test/reference.py's spring, the loop's rates), equal to the forward flank's torque at that time.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

import reference as ref
from finger_sim.actuators.drive import DRIVE, STUCK
from finger_sim.scene import scene_from_dict
from finger_sim.simulate import Simulator

DT = 1e-3
#: The step on whose end the breakaway is put.
BREAK_STEP = 45
THETA_HELD = 0.5  # rad, the pose the mesh holds against the spring
K_SPRING = 1e-3  # N·m/rad
#: Slopes (V/s) of the voltage ramp that break free after and before BREAK_STEP's end (near 0.2574).
LATE, EARLY = 0.2, 0.3
#: Spec §8's defaults, typed in again: winding resistance Ω, torque constant N·m/A, ratio, forward efficiency.
R, KT, N, ETA_F = 8.0, 4.0e-3, 300.0, 0.4


def scene(slope: float, method: str):
    return scene_from_dict({"model": {"drive": {}, "spring_stiffness": K_SPRING},
                            "input": {"voltage": {"type": "ramp", "offset": 0.0, "slope": slope}},
                            "initial": {"theta1": THETA_HELD, "theta1_dot": 0.0}, "duration": (BREAK_STEP + 3) * DT,
                            "integrator": {"method": method, "dt": DT}})


def rows(slope: float, method: str, kernel: str = "python") -> list[tuple[tuple, tuple, int]]:
    """(q, q', mesh mode) after each step."""
    sim = Simulator(scene(slope, method), kernel=kernel)
    out = []
    for _ in range(BREAK_STEP + 2):
        sim.step()
        out.append((sim.q, sim.v, sim.system.drive.mode))
    return out


def stuck_at_the_step_end(slope: float, method: str) -> bool:
    return rows(slope, method)[BREAK_STEP - 1][2] == STUCK


def load(q) -> float:
    """τ_h, N·m: the torque on θ1 that holds the spring at rest at q, by virtual work along the loop."""
    return -float(ref.Effects(k=K_SPRING).force(q, np.zeros(3), 0.0) @ ref.rates(q, 1.0))


@pytest.mark.parametrize(("method", "kernel"), [("dop853", "python"), ("dop853", "compiled"), ("rk4", "python")])
def test_a_stuck_mesh_breaking_free_on_a_step_end_goes_on_rolling(method: str, kernel: str) -> None:
    lo, hi = LATE, EARLY
    assert stuck_at_the_step_end(lo, "rk4") and not stuck_at_the_step_end(hi, "rk4")
    while (mid := 0.5 * (lo + hi)) not in (lo, hi):
        lo, hi = (mid, hi) if stuck_at_the_step_end(mid, "rk4") else (lo, mid)
    on_the_end = 0
    for slope in (float(np.nextafter(lo, 0.0)), lo, hi, float(np.nextafter(hi, 1.0))):
        out = rows(slope, method, kernel)
        assert all(math.isfinite(x) for q, v, _ in out for x in (*q, *v))
        q, v, mode = out[BREAK_STEP - 1]
        if mode == DRIVE and v[0] == 0.0:  # broke free on the step's end itself
            on_the_end += 1
            forward = ETA_F * N * KT * slope * BREAK_STEP * DT / R  # at rest i = u/R, below the limit
            assert forward == pytest.approx(load(q), rel=1e-6)  # the flank's edge: here it gives way
            assert q[0] == THETA_HELD and out[BREAK_STEP][1][0] > 0.0  # held until then, then closing
    assert on_the_end >= 1  # the case this test is for did occur
