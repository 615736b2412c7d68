"""The bench's scipy hybrid solve of a drive scene (`bench.reference.solve_drive`) against test_drive's independent
reference (the §4 KKT system with the drive written again, DOP853 at rtol 1e-12): the self-locking grasp's forward
run up to its first turning point, then the pose held bit for bit."""

from __future__ import annotations

import numpy as np

import reference as ref
from finger_sim.bench.reference import solve_drive
from finger_sim.scene import load_scene
from test_drive import ETA_F, kkt_drive, reference


def test_the_hybrid_solve_follows_the_grasp_and_holds_where_the_tight_solve_turns():
    scene = load_scene(ref.CONFIG / "drive_grasp.yaml")
    times = np.arange(scene.step_count + 1) * scene.dt
    theta = solve_drive(scene, method="DOP853", rtol=1e-10).states(times)[:, :3]
    turn = lambda t, y: y[3]  # noqa: E731
    turn.terminal, turn.direction = True, -1.0
    rolling, hit = reference(scene, lambda t, y: kkt_drive(scene, t, y, ETA_F, 6.0), times[times < 0.3], events=[turn])
    t_stick, q_stick = hit.t_events[-1][0], hit.y_events[-1][0][:3]
    k = len(rolling)  # the samples up to the turn
    assert times[k - 1] <= t_stick < times[k]
    assert np.max(np.abs(theta[:k] - rolling[:, :3])) < 1e-8  # measured 7.3e-12 (rtol 1e-10)
    held = theta[times > t_stick]
    assert np.max(np.abs(held - q_stick)) < 1e-8 and np.all(held == held[0])  # measured 1.1e-12; held through 0 V
