"""A ROS 2 controller node scored by a task (`finger_sim.tasks.ros_runner`): finger_node in lockstep.

References: a second ROS run of the same task, whose samples and metrics must equal the first's
bit for bit; for a task of each kind (a breakable object, a tip-force pull, a drive), the offline
run, whose samples, crushes and metrics the ROS run must equal bit for bit; the offline path (`run_task`) with the same law (`grip_pi`) at the lockstep timing
(sample every step, the answer acting over the next step), an independent simulation in this
process, whose grip force and metrics the ROS run must match within TOLERANCE; the task's
setpoint changes, which must show in the ROS controller's behaviour (a staircase).
"""

from __future__ import annotations

import dataclasses
import math
import sys
from pathlib import Path

import numpy as np
import pytest
import yaml

pytest.importorskip("rclpy")

from finger_sim.errors import ConfigError, FingerSimError  # noqa: E402
from finger_sim.log import read_log  # noqa: E402
from finger_sim.run_log import load_run, resimulate  # noqa: E402
from finger_sim.tasks.controllers import AGGRESSIVE, grip_pi, grip_pi_aggressive, grip_voltage  # noqa: E402
from finger_sim.tasks.ros_runner import lockstep_task, run_ros_task  # noqa: E402
from finger_sim.tasks.runner import run_task  # noqa: E402
from finger_sim.tasks.schema import Task, load_task  # noqa: E402

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


def short_task(tmp_path: Path, name: str, **changes) -> Task:
    """A shipped task made shorter (its scene path made absolute), written to `tmp_path` and loaded."""
    data = yaml.safe_load((TASKS / f"{name}.yaml").read_text())
    data["scene"] = str((TASKS / data["scene"]).resolve())
    data.update(changes)
    path = tmp_path / f"{name}.yaml"
    path.write_text(yaml.safe_dump(data))
    return load_task(path)


@pytest.mark.parametrize("kind", ["crush", "tip_pull", "drive"])
def test_ros_path_runs_every_kind_of_task_and_scores_equal_the_offline_path(kind, ros_domain, tmp_path):
    """One task of each kind the ROS path refused before: a breakable object (an overshooting PI
    crushes it), a tip-force pull while holding, a drive commanded by voltage (a Python controller
    run as a node). The ROS run's samples, crushes and metrics equal the offline run's bit for bit."""
    if kind == "crush":
        task = short_task(tmp_path, "fragile", duration=0.3)
        executable, params, offline_law = "finger_grip_controller", AGGRESSIVE, grip_pi_aggressive
    elif kind == "tip_pull":
        task = short_task(tmp_path, "tip_pull", duration=1.0,
                          disturbances=[{"type": "tip_force", "start": 0.5, "end": 0.7, "force": [0.0, -0.2]}])
        executable, params, offline_law = "finger_grip_controller", {}, grip_pi
    else:
        task = short_task(tmp_path, "hold_voltage_off", duration=0.6)
        executable, params, offline_law = "finger_sim.tasks.controllers:grip_voltage", {}, grip_voltage
    ros = run_ros_task(task, executable, tmp_path / "ros", label="ros", params=params)
    offline = run_task(lockstep_task(task), offline_law, label="offline")
    assert ros.samples.keys() == offline.samples.keys()
    for name in offline.samples:
        assert np.array_equal(ros.samples[name], offline.samples[name]), name
    assert ros.scores == offline.scores and ros.crushes == offline.crushes
    (log,) = (tmp_path / "ros").glob("log_*/*.mcap")  # the node's log re-simulates with its scene changes
    resim = resimulate(load_run(read_log(log)))
    assert resim.exact and [(c.step, c.object, c.force) for c in resim.crushes] == [
        (c.step, c.object, c.force) for c in ros.crushes]
    if kind == "crush":
        assert ros.scores["crushed"] and not ros.ok  # the overshoot broke the egg: the task is failed
        (crush,) = ros.crushes
        assert crush.object == "egg" and crush.force > crush.break_force == 0.6
        assert ros.samples["grip_force"][crush.step] == crush.force  # the state at the crush shows the force
        assert not ros.samples["grip_force"][crush.step + 1:].any()  # and then there is no egg
    elif kind == "tip_pull":
        t, pull = ros.samples["t"], ros.samples["tip_force_y"]
        assert np.array_equal(pull, np.where((t >= 0.5 - 1e-12) & (t < 0.7 - 1e-12), -0.2, 0.0))
        assert not ros.samples["tip_force_x"].any()
    else:
        assert ros.scores["electrical_energy"] > 0 and ros.samples["motor_voltage"][-1] == 0.0  # held unpowered


def test_a_drive_scene_refuses_scene_changes_it_cannot_carry_over(tmp_path):
    with pytest.raises(ConfigError, match="mesh mode"):
        run_task(short_task(tmp_path, "hold_voltage_off", disturbances=[
            {"type": "tip_force", "start": 0.5, "end": 0.7, "force": [0.0, -0.2]}]), grip_voltage)


@pytest.mark.parametrize("params, message", [
    ({"controller": "no_such_module:law"}, "parameter 'controller': expected an importable module"),
    ({"controller": "finger_sim.tasks.controllers:grip_pi", "kp": "high"}, "parameter 'kp': expected a number"),
])
def test_task_controller_node_refuses_a_bad_controller_in_one_line(params, message, launcher):
    node = launcher.node("finger_sim.ros.task_controller", params)
    assert node.wait(60.0) == 2
    (line,) = [l for l in node.output().splitlines() if "cannot start" in l]
    assert message in line


#: A controller node (with the setpoint subscription the runner waits for) that never answers the
#: first grip_force sample, then answers 0 N·m to every other (finger_node in lockstep holds the
#: last command once lockstep_timeout has passed).
SKIPS_FIRST = """\
import sys
import rclpy
from rclpy.qos import QoSProfile
from std_msgs.msg import Float64
from finger_sim.ros.controller_main import AnswerPublisher

rclpy.init(args=sys.argv)
node = rclpy.create_node("skips_first")
pub = AnswerPublisher(node.create_publisher(Float64, "motor_torque", QoSProfile(depth=10)))
seen = []

def on_force(msg):
    seen.append(msg.data)
    if len(seen) > 1:
        pub.publish(Float64(data=0.0))

node.create_subscription(Float64, "grip_setpoint", lambda msg: None, QoSProfile(depth=10))
node.create_subscription(Float64, "grip_force", on_force, QoSProfile(depth=1))
try:
    rclpy.spin(node)
except BaseException:
    pass
"""


def test_a_run_in_which_the_node_held_a_command_for_want_of_an_answer_is_refused(ros_domain, tmp_path, monkeypatch):
    """The node stepped without the controller's answer (after lockstep_timeout): the run is not the
    controller's, and the runner says so instead of scoring it."""
    import finger_sim.tasks.ros_runner as ros_runner

    script = tmp_path / "skips_first"
    script.write_text(f"#!{sys.executable}\n{SKIPS_FIRST}")
    script.chmod(0o755)
    monkeypatch.setattr(ros_runner, "LOCKSTEP_TIMEOUT", 0.5)
    task = dataclasses.replace(short_staircase(), scene=dataclasses.replace(short_staircase().scene, duration=0.05))
    # the first state at least (a loaded machine may hold later ones too: 0.5 s of wall time is short)
    with pytest.raises(FingerSimError, match=r"stepped [1-9]\d* time\(s\) on the last command: no answer came "
                                             r"within lockstep_timeout \(0.5 s\)"):
        run_ros_task(task, str(script), tmp_path / "ros", label="ros")
