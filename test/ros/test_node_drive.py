"""finger_node with a drive (spec §8), in its own process over real DDS, against the offline run.

References: `simulate` of the same scene (its drive columns) for the scripted run, read back from
the node's log with rosbags (someone else's reader); a Simulator fed the voltages that
~/command_log says were applied, for the topic-driven run.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

rclpy = pytest.importorskip("rclpy")

from diagnostic_msgs.msg import DiagnosticStatus  # noqa: E402
from rosbags.highlevel import AnyReader  # noqa: E402
from sensor_msgs.msg import JointState  # noqa: E402
from std_msgs.msg import Float64, String  # noqa: E402
from std_srvs.srv import SetBool  # noqa: E402

from finger_sim.actuators.drive import MESH_MODES  # noqa: E402
from finger_sim.log import read_log  # noqa: E402
from finger_sim.run_log import load_run, resimulate  # noqa: E402
from finger_sim.runtime.drive_commands import REFUSED_TORQUE  # noqa: E402
from finger_sim.scene import load_scene  # noqa: E402
from finger_sim.simulate import Simulator, simulate  # noqa: E402
from helpers import NODE  # noqa: E402
from ros_helpers import start_when_heard, stamp, values  # noqa: E402
from test_node import DT_NS, publish_until, state_by_step  # noqa: E402

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
    assert ros_client.call(SetBool, "/finger_node/pause", SetBool.Request(data=False)).success
    first = publish_until(ros_client, voltage_pub, Float64(data=100.0), log, lambda v: v["event"] == "accepted",
                          "100 V accepted")
    assert (first["torque"], first["requested"], first["saturated"]) == ("6.0", "100.0", "True")  # the supply
    s1 = int(first["step"])
    later = (s1 + 200) * DT_NS
    ros_client.wait_for(lambda: any(stamp(m) >= later for m in states), "200 steps at 6 V")
    second = publish_until(ros_client, voltage_pub, Float64(data=0.0), log,
                           lambda v: v["event"] == "accepted" and v["torque"] == "0.0", "0 V accepted")
    s2 = int(second["step"])
    end = s2 + 100
    ros_client.wait_for(lambda: any(stamp(m) >= end * DT_NS for m in states), f"states up to step {end}")

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
