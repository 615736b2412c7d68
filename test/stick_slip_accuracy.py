"""θ1 of `auto` on stick–slip scenes against the independent reference (stick_slip_reference.py), and the
lock and breakaway rows of both: the table of docs/stick_slip.md.

    cd test && ../.venv/bin/python stick_slip_accuracy.py
"""

from __future__ import annotations

import math
import time

import numpy as np

import stick_slip_reference as ssr
from effects.test_stick_slip import data, mode_changes, row_after

from finger_sim.scene import scene_from_dict
from finger_sim.simulate import simulate

STEP = {"type": "step", "before": 0.05, "after": 0.02, "at": 0.5}
SCENES = {
    "hold, μ_k = 1, μ_s = 2, torque 0.05 → 0.02 N·m": data({"friction": 1.0, "static_friction": 2.0}, STEP, 1.0),
    "hold, μ_k = μ_s = 1, torque 0.05 → 0.02 N·m": data({"friction": 1.0}, STEP, 1.0),
    "falling torque 0.05 − 0.05 t, μ = 1": data({"friction": 1.0}, {"type": "ramp", "offset": 0.05, "slope": -0.05}, 0.6),
    "sawtooth, μ_k = 0.5, μ_s = 1": data({"friction": 0.5, "static_friction": 1.0},
                                         {"type": "ramp", "offset": 0.02, "slope": 0.1}, 1.0, damping=0.0),
    "sawtooth with Stribeck v_st = 2 mm/s": data({"friction": 0.5, "static_friction": 1.0, "stribeck_velocity": 0.002},
                                                 {"type": "ramp", "offset": 0.02, "slope": 0.1}, 1.0, damping=0.0),
}

if __name__ == "__main__":
    print("| scene | auto's method | max \\|Δθ1\\| (rad) | mode changes (sim rows = reference's) | sim CPU (s) |")
    print("|---|---|---|---|---|")
    for name, d in SCENES.items():
        start = time.process_time()
        traj = simulate(scene_from_dict(d))
        cpu = time.process_time() - start
        reference = ssr.solve(d)
        err = float(np.abs(reference.states(traj.t)[0] - traj.q[:, 0]).max())
        same = mode_changes(traj) == [(row_after(t), 1.0 if k == "lock" else 0.0) for t, k in reference.changes]
        print(f"| {name} | {traj.method} | {err:.1e} | {len(reference.changes)} ({'yes' if same else 'NO'}) | {cpu:.2f} |")
        assert math.isfinite(err)
