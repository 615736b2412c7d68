"""finger_hand's merged /joint_states: every finger's joints in one message per state (issue 19, item 5).

References: each finger's own /<name>/joint_states at the same stamp, as received by an rclpy
subscriber and as read back from the log by rosbags (an independent MCAP reader), and the
movable joints of the hand's URDF (robot_description), which robot_state_publisher needs
positions for.
"""

from __future__ import annotations

import xml.etree.ElementTree as ET

import pytest

rclpy = pytest.importorskip("rclpy")

from diagnostic_msgs.msg import DiagnosticArray  # noqa: E402
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy  # noqa: E402
from sensor_msgs.msg import JointState  # noqa: E402
from std_msgs.msg import Float64, String  # noqa: E402
from std_srvs.srv import Trigger  # noqa: E402

from finger_sim.ros import conversions  # noqa: E402
from finger_sim.runtime.hand_config import load_hand, resolve_hand  # noqa: E402
from ros_helpers import stamp  # noqa: E402

HAND = "finger_sim.ros.hand"
STEPS = 50
DT_NS = 1_000_000  # 1 kHz
TORQUES = {"index": 0.003, "middle": 0.0, "ring": 0.01}  # N·m, so that the fingers' states differ
RELIABLE = QoSProfile(depth=100, reliability=ReliabilityPolicy.RELIABLE)


def fields(msg) -> tuple:
    return list(msg.name), msg.header.frame_id, list(msg.position), list(msg.velocity), list(msg.effort)


def merge(parts: list[tuple]) -> tuple:
    """The fingers' (names, frame, positions, velocities, efforts) concatenated, in hand order."""
    return ([x for p in parts for x in p[0]], "hand_base", *([x for p in parts for x in p[i]] for i in (2, 3, 4)))


def test_merged_joint_states_are_the_fingers_own_at_the_same_stamp(launcher, ros_client, tmp_path):
    fingers = [f.name for f in load_hand(resolve_hand("three_fingers"))]
    assert fingers == list(TORQUES)
    hand = launcher.node(HAND, dict(hand="three_fingers", realtime_factor=0.0, start_paused=True, command_timeout=0.0,
                                    command_qos="reliable", steps_per_trigger=STEPS, marker_rate_hz=0.0,
                                    physics_rate_hz=1000.0))
    merged = ros_client.collect(JointState, "/joint_states")
    own = {name: ros_client.collect(JointState, f"/{name}/joint_states") for name in fingers}
    publishers = {name: ros_client.publisher(Float64, f"/{name}/motor_torque", RELIABLE) for name in fingers}
    ros_client.wait_for(lambda: all(p.get_subscription_count() for p in publishers.values())
                        and ros_client.node.count_publishers("/joint_states") == 1, "the hand's topics")
    diagnostics = ros_client.collect(DiagnosticArray, "/diagnostics")

    def received(name: str) -> int:
        counts = [int(conversions.parse_values(s)["commands_received"]) for d in diagnostics for s in d.status
                  if s.name == f"/finger_hand: {name} simulation"]
        return max(counts, default=-1)

    for name, torque in TORQUES.items():
        publishers[name].publish(Float64(data=torque))
    ros_client.wait_for(lambda: all(received(n) == 1 for n in fingers), "every finger's command counted (about 1 Hz)")
    answer = ros_client.call(Trigger, "/finger_hand/step")
    assert answer.success, answer.message
    end = round(float(answer.message.split("clock=")[1].split()[0]) * 1e9)
    ros_client.wait_for(lambda: any(stamp(m) == end for m in merged)
                        and all(any(stamp(m) == end for m in s) for s in own.values()), "every state at the last step")

    # what reached the rclpy subscriber: at each stamp, the fingers' own messages concatenated
    by_stamp = {name: {stamp(m): fields(m) for m in s} for name, s in own.items()}
    common = [t for t in (stamp(m) for m in merged) if all(t in by_stamp[n] for n in fingers)]
    assert end in common
    for m in merged:
        if stamp(m) in common:
            assert fields(m) == merge([by_stamp[n][stamp(m)] for n in fingers]), stamp(m)
    assert len({tuple(by_stamp[n][end][2]) for n in fingers}) == 3  # the fingers really differ

    # robot_state_publisher: a position for every movable joint of robot_description, none else
    description = ros_client.collect(String, "/robot_description",
                                     QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE,
                                                durability=DurabilityPolicy.TRANSIENT_LOCAL))
    ros_client.wait_for(lambda: description, "robot_description")
    movable = {j.get("name") for j in ET.fromstring(description[0].data).iter("joint") if j.get("type") != "fixed"}
    assert sorted(merged[-1].name) == sorted(movable) and len(merged[-1].name) == len(movable)

    # the log, read by rosbags: one merged message per state, equal to the fingers' at its stamp
    assert hand.stop() == 0, hand.log_path.read_text()
    from rosbags.highlevel import AnyReader

    (path,) = (tmp_path / "bags").glob("three_fingers_*.mcap")
    logged: dict[str, dict[int, tuple]] = {}
    with AnyReader([path]) as reader:
        for c, _, raw in reader.messages(connections=[c for c in reader.connections if c.topic.endswith("joint_states")]):
            m = reader.deserialize(raw, c.msgtype)
            topic_states = logged.setdefault(c.topic, {})
            t = stamp(m)
            assert t not in topic_states or c.topic != "/joint_states", f"two merged messages at {t}"
            topic_states[t] = fields(m)
    assert set(logged) == {"/joint_states", *(f"/{n}/joint_states" for n in fingers)}
    assert set(logged["/joint_states"]) == set(logged["/index/joint_states"]) >= set(range(end - STEPS * DT_NS, end + 1, DT_NS))
    for t, got in logged["/joint_states"].items():
        assert got == merge([logged[f"/{n}/joint_states"][t] for n in fingers]), t
