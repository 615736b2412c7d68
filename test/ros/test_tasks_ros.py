"""A ROS 2 controller node scored by a task (`finger_sim.tasks.ros_runner`): finger_node in lockstep.

References: a second ROS run of the same task, whose samples and metrics must equal the first's
bit for bit; the offline path (`run_task`) with the same law (`grip_pi`) at the lockstep timing
(sample every step, the answer acting over the next step), an independent simulation in this
process, whose grip force and metrics the ROS run must match within TOLERANCE; the task's
setpoint changes, which must show in the ROS controller's behaviour (a staircase).
"""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("rclpy")

from finger_sim.errors import ConfigError  # noqa: E402
from finger_sim.tasks.controllers import grip_pi  # noqa: E402
from finger_sim.tasks.ros_runner import lockstep_task, run_ros_task  # noqa: E402
from finger_sim.tasks.runner import run_task  # noqa: E402
from finger_sim.tasks.schema import load_task  # noqa: E402

TASKS = Path(__file__).resolve().parents[2] / "config" / "tasks"
#: Agreement of ROS and offline metrics, relative (the same law, scene and float arithmetic: the
#: two runs differ only by where the numbers travel, so they agree far below any limit).
TOLERANCE = 1e-9
#: A short staircase: two setpoint changes within 1 s of sim time (contact comes at ≈ 0.25 s).
STAIRS = ((0.0, 0.5), (0.5, 0.7), (0.75, 0.35))
DURATION = 1.0


def short_staircase():
    task = load_task(TASKS / "staircase.yaml")
    scene = dataclasses.replace(task.scene, duration=DURATION)
    return dataclasses.replace(task, scene=scene, setpoints=STAIRS, hold_after=0.1)


def close(a, b) -> bool:
    if a is None or b is None or isinstance(a, bool):
        return a == b
    return (math.isinf(a) and a == b) or math.isclose(a, b, rel_tol=TOLERANCE, abs_tol=TOLERANCE)


def test_ros_grip_controller_scores_repeat_bit_for_bit_and_match_offline(ros_domain, tmp_path):
    task = short_staircase()
    first = run_ros_task(task, "finger_grip_controller", tmp_path / "a", label="ros")
    second = run_ros_task(task, "finger_grip_controller", tmp_path / "b", label="ros")
    for name in first.samples:
        assert np.array_equal(first.samples[name], second.samples[name]), name
    assert first.scores == second.scores

    offline = run_task(lockstep_task(task), grip_pi, label="offline")
    assert len(offline.samples["t"]) == len(first.samples["t"])
    np.testing.assert_allclose(first.samples["grip_force"], offline.samples["grip_force"], rtol=0, atol=1e-9)
    for name, value in offline.scores.items():
        assert close(first.scores[name], value), (name, first.scores[name], value)
    # the setpoint changes reached the ROS controller: it held each step of the staircase
    t, force = first.samples["t"], first.samples["grip_force"]
    for (t0, value), end in zip(STAIRS, [s[0] for s in STAIRS[1:]] + [DURATION]):
        assert abs(force[np.searchsorted(t, end) - 1] - value) < 0.05 * value, (t0, value)


def test_ros_runner_refuses_what_finger_node_cannot_do(tmp_path):
    with pytest.raises(ConfigError, match="break_force"):
        run_ros_task(load_task(TASKS / "fragile.yaml"), "finger_grip_controller", tmp_path)
    with pytest.raises(ConfigError, match="tip-force"):
        run_ros_task(load_task(TASKS / "tip_pull.yaml"), "finger_grip_controller", tmp_path)
