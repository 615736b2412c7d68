"""finger_node with a drive (spec §8), in its own process over real DDS, against the offline run.

References: `simulate` of the same scene (its drive columns) for the scripted run, read back from
the node's log with rosbags (someone else's reader); a Simulator fed the voltages that
~/command_log says were applied, for the topic-driven run.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import pytest

rclpy = pytest.importorskip("rclpy")

from diagnostic_msgs.msg import DiagnosticStatus  # noqa: E402
from rosbags.highlevel import AnyReader  # noqa: E402
from sensor_msgs.msg import JointState  # noqa: E402
from std_msgs.msg import Float64, String  # noqa: E402

from finger_sim.actuators.drive import MESH_MODES  # noqa: E402
from finger_sim.log import read_log  # noqa: E402
from finger_sim.run_log import load_run, resimulate  # noqa: E402
from finger_sim.runtime.drive_commands import REFUSED_TORQUE  # noqa: E402
from finger_sim.scene import load_scene  # noqa: E402
from finger_sim.simulate import Simulator, simulate  # noqa: E402
from conftest import WAIT_TIMEOUT  # noqa: E402
from helpers import NODE  # noqa: E402
from ros_helpers import resume, stamp, start_when_heard, values  # noqa: E402
from test_node import DT_NS, REPUBLISH_S, publish_until, state_by_step  # noqa: E402

CONFIG = Path(__file__).resolve().parents[2] / "config"
GRASP = CONFIG / "drive_grasp.yaml"
RATE = 1000.0
SUBPROCESS_TIMEOUT_S = 60.0


def test_scripted_drive_run_logs_the_motor_state_and_resims_bit_for_bit(launcher, tmp_path):
    bags = tmp_path / "bags"
    node = launcher.node(NODE, dict(scene=str(GRASP), torque_source="scene", realtime_factor=0.0, record_dir=str(bags)))
    assert node.wait(SUBPROCESS_TIMEOUT_S) == 0
    (path,) = sorted(bags.glob("*.mcap"))
    assert resimulate(load_run(read_log(path))).exact
    with AnyReader([path]) as reader:
        topics = {}
        for c, _, raw in reader.messages():
            topics.setdefault(c.topic, []).append(reader.deserialize(raw, c.msgtype))
    offline = simulate(load_scene(GRASP).with_overrides(dt=1.0 / RATE), kernel="python")
    n = len(offline.t)
    assert len(topics["/joint_states"]) == n
    assert [m.data for m in topics["/motor/current"]] == offline.outputs["motor_current"].tolist()
    assert [m.data for m in topics["/motor/voltage"]] == offline.outputs["motor_voltage"].tolist()
    assert [m.data for m in topics["/motor/angle"]] == offline.outputs["motor_angle"].tolist()
    assert [m.data for m in topics["/motor/mesh_mode"]] == [MESH_MODES[int(k)] for k in offline.outputs["mesh_mode"]]
    assert [m.effort[0] for m in topics["/joint_states"]] == offline.outputs["mesh_torque"].tolist()
    assert topics["/motor/mesh_mode"][-1].data == "stuck" and topics["/motor/current"][-1].data == 0.0


def event(log: list, match) -> Callable[[], dict[str, str] | None]:
    """A check for the first ~/command_log event from now on that satisfies `match` (its values)."""
    seen = len(log)
    return lambda: next((v for v in map(values, log[seen:]) if match(v)), None)


def reached(states: list, step: int) -> bool:
    """A state of `step` or later has arrived (one publisher: the stamps arrive in order). Checks the
    last state only: the wait checks after every callback, and a scan of all states (thousands at
    2 kHz) each time made the client fall further behind the node the longer it waited."""
    return bool(states) and stamp(states[-1]) >= step * DT_NS


def wait_while_stepping(client, states: list, condition, what: str, publish=None) -> Any:
    """condition()'s first truthy value, calling publish() every REPUBLISH_S (best-effort commands).

    Bounded by the node's progress, not the wall clock: it fails only when no new joint state has
    arrived for WAIT_TIMEOUT s. On a loaded machine the node at 2 kHz and this client, which takes
    its messages one callback at a time, both fall behind; that makes the wait longer, not wrong."""
    count = len(states)
    heard = sent = time.monotonic()
    if publish is not None:
        publish()
    while not (value := condition()):
        now = time.monotonic()
        if len(states) != count:
            count, heard = len(states), now
        elif now - heard > WAIT_TIMEOUT:
            raise AssertionError(f"no new joint state for {WAIT_TIMEOUT:g} s while waiting for {what}: the node stopped")
        if publish is not None and now - sent > REPUBLISH_S:
            publish()
            sent = now
        client.spin()
    return value


def test_voltage_command_is_saturated_held_and_torque_topics_are_refused(launcher, ros_client):
    launcher.node(NODE, dict(scene=str(GRASP), realtime_factor=2.0, command_timeout=0.0, start_paused=True))
    states = ros_client.collect(JointState, "/joint_states")
    modes = ros_client.collect(String, "/motor/mesh_mode")
    log = ros_client.collect(DiagnosticStatus, "/finger_node/command_log")
    torque_pub = ros_client.publisher(Float64, "/motor_torque")
    voltage_pub = ros_client.publisher(Float64, "/motor_voltage")
    start_when_heard(ros_client, "/finger_node", states, modes)
    ros_client.wait_for(lambda: torque_pub.get_subscription_count() and voltage_pub.get_subscription_count(),
                        "the command subscriptions")
    refused = publish_until(ros_client, torque_pub, Float64(data=0.01), log, lambda v: v["event"] == "refused",
                            "the torque refused")
    assert (refused["source"], refused["reason"]) == ("/motor_torque", REFUSED_TORQUE)
    resume(ros_client, "/finger_node")
    first = wait_while_stepping(ros_client, states, event(log, lambda v: v["event"] == "accepted"), "100 V accepted",
                                lambda: voltage_pub.publish(Float64(data=100.0)))
    assert (first["torque"], first["requested"], first["saturated"]) == ("6.0", "100.0", "True")  # the supply
    s1 = int(first["step"])
    wait_while_stepping(ros_client, states, lambda: reached(states, s1 + 200), "200 steps at 6 V")
    second = wait_while_stepping(ros_client, states,
                                 event(log, lambda v: v["event"] == "accepted" and v["torque"] == "0.0"),
                                 "0 V accepted", lambda: voltage_pub.publish(Float64(data=0.0)))
    s2 = int(second["step"])
    end = s2 + 100
    wait_while_stepping(ros_client, states, lambda: reached(states, end), f"states up to step {end}")

    sim = Simulator(load_scene(GRASP).with_overrides(dt=1.0 / RATE))
    expected, voltage = [sim.state], 0.0
    efforts = [None]
    for k in range(end):
        voltage = 6.0 if k >= s1 else voltage
        voltage = 0.0 if k >= s2 else voltage
        expected.append(sim.step(voltage))
        efforts.append(sim.system.motor_outputs(sim.time, sim.q, sim.v, sim.torque)["mesh_torque"])
    got = {n: m for n, m in state_by_step(states).items() if 0 < n <= end}
    assert sum(n > s2 for n in got) >= 10
    for n, msg in got.items():
        assert msg.position[0] == expected[n].q[0]
        assert msg.effort[0] == efforts[n]
    assert sim.system.drive.mode == MESH_MODES.index("stuck")  # the gear holds the grip at 0 V
    assert np.ptp([got[n].position[0] for n in got if n > s2]) == 0.0
