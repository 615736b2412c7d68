"""Channel QoS metadata as rosbag2 writes it (finger_sim.log.qos), read back by rosbags' MCAP
reader; and the recorder's log-time offset (the node's record_time 'wall_start')."""

from __future__ import annotations

from pathlib import Path

import pytest

pytest.importorskip("rclpy")

from rclpy.duration import Duration  # noqa: E402
from rclpy.qos import (  # noqa: E402
    DurabilityPolicy,
    HistoryPolicy,
    LivelinessPolicy,
    QoSProfile,
    ReliabilityPolicy,
    qos_profile_system_default,
)
from rosbags.rosbag2 import Reader  # noqa: E402
from rosbags.interfaces import (  # noqa: E402
    QosDurability,
    QosHistory,
    QosLiveliness,
    QosReliability,
)
from rosgraph_msgs.msg import Clock  # noqa: E402
from sensor_msgs.msg import JointState  # noqa: E402
from std_msgs.msg import Float64, String  # noqa: E402

from finger_sim.log import LogArgumentError, McapRecorder, read_log  # noqa: E402
from finger_sim.log.qos import offered_qos_profiles  # noqa: E402

INFINITE = (9223372036, 854775807)  # RMW_DURATION_INFINITE as sec, nsec
# robot_state_publisher's robot_description; rclcpp::ClockQoS; the node's state topics
LATCHED = QoSProfile(depth=1, durability=DurabilityPolicy.TRANSIENT_LOCAL, reliability=ReliabilityPolicy.RELIABLE)
CLOCK = QoSProfile(depth=1, reliability=ReliabilityPolicy.BEST_EFFORT)
STATE = QoSProfile(depth=10)

# What `ros2 bag record` (Jazzy) stores for a default reliable publisher, apart from history and
# depth (which DDS discovery does not carry: rosbag2 writes unknown/0 there; the player ignores them).
ROSBAG2_TEXT = """- history: keep_last
  depth: 10
  reliability: reliable
  durability: volatile
  deadline:
    sec: 9223372036
    nsec: 854775807
  lifespan:
    sec: 9223372036
    nsec: 854775807
  liveliness: automatic
  liveliness_lease_duration:
    sec: 9223372036
    nsec: 854775807
  avoid_ros_namespace_conventions: false"""


def test_the_text_is_rosbag2s_yaml() -> None:
    assert offered_qos_profiles(STATE) == ROSBAG2_TEXT
    # system_default policies are written as the rmw resolves them
    assert offered_qos_profiles(qos_profile_system_default) == ROSBAG2_TEXT.replace("depth: 10", "depth: 0")
    finite = QoSProfile(depth=5, history=HistoryPolicy.KEEP_ALL, deadline=Duration(seconds=1, nanoseconds=5),
                        liveliness=LivelinessPolicy.MANUAL_BY_TOPIC, lifespan=Duration(nanoseconds=7))
    text = offered_qos_profiles(finite, CLOCK)
    assert text.count("- history:") == 2
    assert text.startswith("- history: keep_all\n  depth: 5\n")
    assert "  deadline:\n    sec: 1\n    nsec: 5\n  lifespan:\n    sec: 0\n    nsec: 7\n  liveliness: manual_by_topic\n" in text


def test_a_misfit_profile_names_the_field() -> None:
    with pytest.raises(LogArgumentError, match="qos.history: expected an rclpy history policy"):
        offered_qos_profiles(object())
    with pytest.raises(LogArgumentError, match="qos.depth"):
        offered_qos_profiles(type("Q", (), {"history": HistoryPolicy.KEEP_LAST, "depth": -1})())


def test_rosbags_reads_the_offered_qos_back(tmp_path: Path) -> None:
    path = tmp_path / "qos.mcap"
    with McapRecorder(path) as rec:
        rec.register_channel("/robot_description", String, qos=LATCHED)
        rec.register_channel("/clock", Clock, qos=CLOCK)
        rec.register_channel("/joint_states", JointState, qos=STATE)
        rec.register_channel("/motor_torque", Float64)  # a received topic: no publisher QoS known
        rec.write("/robot_description", String(data="<robot/>"), 0)
        rec.write("/clock", Clock(), 0)
        rec.write("/joint_states", JointState(), 0)
        rec.write("/motor_torque", Float64(data=1.0), 0)
    with Reader(path) as reader:
        qos = {c.topic: c.ext.offered_qos_profiles for c in reader.connections}
    assert qos["/motor_torque"] == []
    expected = {
        "/robot_description": (QosHistory.KEEP_LAST, 1, QosReliability.RELIABLE, QosDurability.TRANSIENT_LOCAL),
        "/clock": (QosHistory.KEEP_LAST, 1, QosReliability.BEST_EFFORT, QosDurability.VOLATILE),
        "/joint_states": (QosHistory.KEEP_LAST, 10, QosReliability.RELIABLE, QosDurability.VOLATILE),
    }
    for topic, (history, depth, reliability, durability) in expected.items():
        (profile,) = qos[topic]
        assert (profile.history, profile.depth, profile.reliability, profile.durability) == \
            (history, depth, reliability, durability), topic
        assert profile.liveliness == QosLiveliness.AUTOMATIC
        for duration in (profile.deadline, profile.lifespan, profile.liveliness_lease_duration):
            assert (duration.sec, duration.nsec) == INFINITE
        assert profile.avoid_ros_namespace_conventions is False


def test_time_offset_shifts_log_and_publish_times(tmp_path: Path) -> None:
    start = 1_790_000_000_123_456_789  # a Unix time in ns
    path = tmp_path / "offset.mcap"
    with McapRecorder(path, time_offset_ns=start) as rec:
        rec.register_channel("/motor_torque", Float64)
        rec.write("/motor_torque", Float64(data=1.0), 0)
        rec.write("/motor_torque", Float64(data=2.0), 5_000_000, publish_time_ns=4_000_000)
        with pytest.raises(LogArgumentError, match="log_time_ns: expected 0 <= ns < 2\\*\\*64 - time_offset_ns"):
            rec.write("/motor_torque", Float64(data=3.0), (1 << 64) - start)
    records = [m for _, _, m in read_log(path).raw_messages()]
    assert [(m.log_time, m.publish_time) for m in records] == [(start, start), (start + 5_000_000, start + 4_000_000)]
    with pytest.raises(LogArgumentError, match="time_offset_ns"):
        McapRecorder(tmp_path / "bad.mcap", time_offset_ns=-1)
