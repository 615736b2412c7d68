"""The fixed-layout CDR writers (finger_sim.log.cdr_writer) against two deserializers written by
others: rclpy's (rclpy.serialization.deserialize_message, the rmw's C code) and rosbags' (pure
Python), on random messages (hypothesis): every alignment case of the frame id and joint names,
any number of joints, any finite or non-finite float, stamps across the whole uint32 range of
nanoseconds. Each decoded field must equal the one written, bit for bit."""

from __future__ import annotations

import functools
import struct

import pytest
from hypothesis import given
from hypothesis import strategies as st

pytest.importorskip("rclpy")

from geometry_msgs.msg import PoseStamped  # noqa: E402
from rclpy.serialization import deserialize_message  # noqa: E402
from rosbags.typesys import Stores, get_typestore  # noqa: E402
from rosgraph_msgs.msg import Clock  # noqa: E402
from sensor_msgs.msg import JointState  # noqa: E402
from std_msgs.msg import Float64  # noqa: E402

from finger_sim.log.cdr_writer import JointStateCdr, PoseStampedCdr, clock_cdr, float64_cdr  # noqa: E402

STORE = get_typestore(Stores.ROS2_JAZZY)
MAX_STAMP_NS = (2**31 - 1) * 1_000_000_000 + 999_999_999  # builtin_interfaces/Time's sec is int32
names = st.text(st.characters(codec="utf-8", exclude_characters="\x00"), max_size=12)
doubles = st.floats(allow_nan=True, allow_infinity=True)
stamps = st.integers(0, MAX_STAMP_NS)


def bits(values) -> list[bytes]:
    """Floats as their bytes: NaN == NaN, 0.0 != -0.0."""
    return [struct.pack("<d", v) for v in values]


def stamp_of(header) -> int:
    return header.stamp.sec * 1_000_000_000 + header.stamp.nanosec


@given(stamp=stamps, frame=names, joints=st.lists(names, max_size=5), data=st.data())
def test_joint_state_round_trips(stamp, frame, joints, data):
    n = len(joints)
    arrays = [data.draw(st.lists(doubles, min_size=n, max_size=n)) for _ in range(3)]
    raw = JointStateCdr(frame, joints)(stamp, *arrays)
    ours = deserialize_message(raw, JointState)
    theirs = STORE.deserialize_cdr(raw, "sensor_msgs/msg/JointState")
    for msg in (ours, theirs):
        assert stamp_of(msg.header) == stamp and msg.header.frame_id == frame and list(msg.name) == joints
        for got, sent in zip((msg.position, msg.velocity, msg.effort), arrays):
            assert bits(got) == bits(sent)
    assert raw == STORE.serialize_cdr(theirs, "sensor_msgs/msg/JointState")  # rosbags writes the same bytes


def test_joint_state_refuses_a_wrong_length():
    with pytest.raises(struct.error, match="expected 2 positions"):
        JointStateCdr("base", ["a", "b"])(0, [1.0], [1.0, 2.0], [1.0, 2.0])


@given(stamp=stamps, frame=names, pose=st.lists(doubles, min_size=7, max_size=7))
def test_pose_stamped_round_trips(stamp, frame, pose):
    raw = PoseStampedCdr(frame)(stamp, pose[:3], pose[3:])
    for msg in (deserialize_message(raw, PoseStamped), STORE.deserialize_cdr(raw, "geometry_msgs/msg/PoseStamped")):
        p, o = msg.pose.position, msg.pose.orientation
        assert stamp_of(msg.header) == stamp and msg.header.frame_id == frame
        assert bits([p.x, p.y, p.z, o.x, o.y, o.z, o.w]) == bits(pose)


@given(stamp=stamps, value=doubles)
def test_clock_and_float64_round_trip(stamp, value):
    clock = clock_cdr(stamp)
    for msg in (deserialize_message(clock, Clock), STORE.deserialize_cdr(clock, "rosgraph_msgs/msg/Clock")):
        assert msg.clock.sec * 1_000_000_000 + msg.clock.nanosec == stamp
    number = float64_cdr(value)
    for msg in (deserialize_message(number, Float64), STORE.deserialize_cdr(number, "std_msgs/msg/Float64")):
        assert bits([msg.data]) == bits([value])


MARKER_SCENES = (("paper_flexion", ""), ("grasp_cylinder", "f1_"), ("press_table", "index_"))  # no object, a circle, a plane
angles = st.floats(-4.0, 4.0)


@pytest.mark.parametrize(("scene", "prefix"), MARKER_SCENES)
@given(q=st.tuples(angles, angles, angles), stamp=stamps)
def test_marker_array_equals_rclpys(scene, prefix, q, stamp):
    """The node's markers (MarkerArrayCdr fed conversions.marker_values) decode, in rclpy and in
    rosbags, to what rclpy's serializer makes of conversions.markers: every field. (rclpy's own
    bytes cannot be compared: its alignment padding is uninitialised memory, different each call.)"""
    from visualization_msgs.msg import MarkerArray

    from finger_sim.log.cdr_writer import MarkerArrayCdr
    from finger_sim.ros import conversions
    from finger_sim.ros.node_command import plain
    from rclpy.serialization import serialize_message

    frames = _frames(scene, prefix)
    raw = MarkerArrayCdr(conversions.markers(frames, (0.1, 0.2, 0.3), 0))(stamp, conversions.marker_values(frames, q))
    reference = serialize_message(conversions.markers(frames, q, stamp))
    assert len(raw) == len(reference)
    assert plain(deserialize_message(raw, MarkerArray)) == plain(deserialize_message(reference, MarkerArray))
    kind = "visualization_msgs/msg/MarkerArray"
    # rosbags writes zeros where rclpy pads: its bytes of either decoding are ours
    assert raw == STORE.serialize_cdr(STORE.deserialize_cdr(raw, kind), kind)
    assert raw == STORE.serialize_cdr(STORE.deserialize_cdr(reference, kind), kind)


@functools.cache
def _frames(scene: str, prefix: str):
    from finger_sim.ros import conversions
    from finger_sim.scene import load_scene
    from finger_sim.scene_paths import resolve_scene
    from finger_sim.simulate import Simulator

    return conversions.FingerFrames.from_system(Simulator(load_scene(resolve_scene(scene))).system, prefix)


def test_marker_array_refuses_a_wrong_count():
    from finger_sim.log.cdr_writer import MarkerArrayCdr
    from finger_sim.ros import conversions

    frames = _frames("paper_flexion", "")
    with pytest.raises(ValueError, match="expected 42 marker coordinates, got 2"):
        MarkerArrayCdr(conversions.markers(frames, (0.1, 0.2, 0.3), 0))(0, [1.0, 2.0])
