"""finger_replay offers each topic with its recorded QoS (issue 19, item 1), as `ros2 bag play` does:
a latched robot_description reaches a TRANSIENT_LOCAL subscriber (RViz's RobotModel) that joins
after it was replayed.

References: the QoS the replay's publishers show in the ROS graph (DDS discovery), the recorded
profiles (finger_sim.ros.interfaces' tables, what the node offers), and the recorded URDF text.
"""

from __future__ import annotations

import sys
from pathlib import Path

import pytest

rclpy = pytest.importorskip("rclpy")

from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy  # noqa: E402
from rosgraph_msgs.msg import Clock  # noqa: E402
from sensor_msgs.msg import JointState  # noqa: E402
from std_msgs.msg import String  # noqa: E402

from finger_sim.log import McapRecorder  # noqa: E402
from finger_sim.ros.interfaces import CLOCK_QOS, DESCRIPTION_QOS, STATE_QOS  # noqa: E402
from finger_sim.ros.replay import DATA_QOS, recorded_qos  # noqa: E402
from finger_sim.log.qos import OFFERED_QOS_PROFILES, offered_qos_profiles  # noqa: E402

REPLAY = Path(sys.executable).with_name("finger_replay")
URDF = "<robot name='latched'/>"
STEP_NS = 10_000_000  # 100 Hz states
STATES = 1000  # 10 s of log time: the replay still runs when the late subscriber joins, even on a slow start
LATCHED_SUB = QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE, durability=DurabilityPolicy.TRANSIENT_LOCAL)


def write_log(path: Path) -> Path:
    """robot_description once at the start (latched, as the node offers it), then joint states and /clock."""
    with McapRecorder(path) as rec:
        rec.register_channel("/robot_description", String, qos=DESCRIPTION_QOS)
        rec.register_channel("/joint_states", JointState, qos=STATE_QOS)
        rec.register_channel("/clock", Clock, qos=CLOCK_QOS)
        rec.write("/robot_description", String(data=URDF), 0)
        for k in range(STATES):
            t = (k + 1) * STEP_NS
            clock = Clock()
            clock.clock.sec, clock.clock.nanosec = divmod(t, 10**9)
            rec.write("/clock", clock, t)
            msg = JointState(name=["mcp_joint"], position=[0.001 * k])
            msg.header.stamp.sec, msg.header.stamp.nanosec = divmod(t, 10**9)
            rec.write("/joint_states", msg, t)
    return path


def offered(node, topic: str) -> tuple[ReliabilityPolicy, DurabilityPolicy]:
    (info,) = node.get_publishers_info_by_topic(topic)
    return info.qos_profile.reliability, info.qos_profile.durability


def test_a_late_transient_local_subscriber_gets_the_replayed_description(launcher, ros_client, tmp_path):
    log = write_log(tmp_path / "latched.mcap")
    command = [str(REPLAY)] if REPLAY.exists() else [sys.executable, "-m", "finger_sim.ros.replay"]
    launcher.start([*command, str(log)], "replay", separate_stderr=True)
    node = ros_client.node
    states = ros_client.collect(JointState, "/joint_states")
    ros_client.wait_for(lambda: len(states) >= 10, "replayed joint states (robot_description went out before them)")
    assert offered(node, "/robot_description") == (ReliabilityPolicy.RELIABLE, DurabilityPolicy.TRANSIENT_LOCAL)
    assert offered(node, "/joint_states") == (ReliabilityPolicy.RELIABLE, DurabilityPolicy.VOLATILE)
    assert offered(node, "/clock") == (ReliabilityPolicy.BEST_EFFORT, DurabilityPolicy.VOLATILE)

    description = ros_client.collect(String, "/robot_description", LATCHED_SUB)  # joins late
    ros_client.wait_for(lambda: description, "the latched robot_description")
    assert [m.data for m in description] == [URDF]


def test_recorded_qos_follows_rosbag2s_rule() -> None:
    latched, state, clock = (offered_qos_profiles(q) for q in (DESCRIPTION_QOS, STATE_QOS, CLOCK_QOS))
    qos, mix = recorded_qos([{OFFERED_QOS_PROFILES: latched}], DATA_QOS)
    assert (qos.reliability, qos.durability, qos.depth, mix) == \
        (ReliabilityPolicy.RELIABLE, DurabilityPolicy.TRANSIENT_LOCAL, 1, "")
    qos, mix = recorded_qos([{OFFERED_QOS_PROFILES: clock}], CLOCK_QOS)
    assert (qos.reliability, qos.durability, qos.depth, mix) == \
        (ReliabilityPolicy.BEST_EFFORT, DurabilityPolicy.VOLATILE, 1, "")
    # two publishers, one latched and one not: volatile (every subscriber matches), said so
    qos, mix = recorded_qos([{OFFERED_QOS_PROFILES: latched + "\n" + state}], DATA_QOS)
    assert (qos.reliability, qos.durability, qos.depth) == (ReliabilityPolicy.RELIABLE, DurabilityPolicy.VOLATILE, DATA_QOS.depth)
    assert mix == "transient_local, volatile"
    # Humble's numbers; no record, or an unreadable one: the default
    qos, _ = recorded_qos([{OFFERED_QOS_PROFILES: "- reliability: 2\n  durability: 1\n  depth: 3"}], DATA_QOS)
    assert (qos.reliability, qos.durability, qos.depth) == (ReliabilityPolicy.BEST_EFFORT, DurabilityPolicy.TRANSIENT_LOCAL, 3)
    assert recorded_qos([{}], DATA_QOS) == (DATA_QOS, "")
    assert recorded_qos([{OFFERED_QOS_PROFILES: "[: not yaml"}], DATA_QOS) == (DATA_QOS, "")
