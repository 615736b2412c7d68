"""The fixed-layout JointState and DiagnosticStatus readers (finger_sim.log.cdr) against rosbags'
deserializer and serializer, on bytes made by rclpy's serializer (what the node logs) and by rosbags: every alignment case of the variable
part (frame id and name lengths, empty and unequal arrays), a decoder whose cached layout
must be dropped when the next message differs, and refusals of what is not a JointState."""

from __future__ import annotations

import itertools
import math

import numpy as np
import pytest

pytest.importorskip("rclpy")

from diagnostic_msgs.msg import DiagnosticStatus, KeyValue  # noqa: E402
from rclpy.serialization import serialize_message  # noqa: E402
from rosbags.typesys import Stores, get_typestore  # noqa: E402
from sensor_msgs.msg import JointState  # noqa: E402

from finger_sim.log import LogArgumentError  # noqa: E402
from finger_sim.log.cdr import JointStateDecoder, decode_diagnostic_status, decode_joint_state  # noqa: E402

STORE = get_typestore(Stores.ROS2_JAZZY)


def values(frame: str, names: list[str], arrays: tuple[int, int, int], k: int) -> tuple:
    """The fields of test message k, in JointStateFields order: distinct, not round in binary."""
    return (-3 + k, 999_999_999 - k, frame, tuple(names), tuple(math.sin(k + i) for i in range(arrays[0])),
            tuple(1.0 / (k + i + 3) for i in range(arrays[1])), tuple(-(2.0 ** -(k + i)) for i in range(arrays[2])))


def joint_state(frame: str, names: list[str], arrays: tuple[int, int, int], k: int) -> bytes:
    """rclpy's CDR (what the node logs; rmw may leave bytes after the last array)."""
    sec, nanosec, frame, names, position, velocity, effort = values(frame, names, arrays, k)
    msg = JointState(name=list(names), position=list(position), velocity=list(velocity), effort=list(effort))
    msg.header.stamp.sec, msg.header.stamp.nanosec, msg.header.frame_id = sec, nanosec, frame
    return serialize_message(msg)


def rosbags_cdr(fields: tuple) -> bytes:
    """rosbags' CDR of the same fields (exactly sized, as rosbags' strict reader wants)."""
    sec, nanosec, frame, names, position, velocity, effort = fields
    cls = STORE.types
    header = cls["std_msgs/msg/Header"](stamp=cls["builtin_interfaces/msg/Time"](sec=sec, nanosec=nanosec), frame_id=frame)
    msg = cls["sensor_msgs/msg/JointState"](header=header, name=list(names), position=np.array(position, float),
                                            velocity=np.array(velocity, float), effort=np.array(effort, float))
    return bytes(STORE.serialize_cdr(msg, "sensor_msgs/msg/JointState"))


def expected(data: bytes) -> tuple:
    ref = STORE.deserialize_cdr(data, "sensor_msgs/msg/JointState")
    return (ref.header.stamp.sec, ref.header.stamp.nanosec, ref.header.frame_id, tuple(ref.name),
            tuple(ref.position.tolist()), tuple(ref.velocity.tolist()), tuple(ref.effort.tolist()))


CASES = [
    (frame, names, arrays)
    for frame in ("", "a", "base", "finger_base__")
    for names in ([], ["j"], ["mcp_joint", "coupler_joint", "pip_joint"], ["ab", "abc", "abcd", "abcde"])
    for arrays in ((0, 0, 0), (3, 3, 3), (1, 0, 2), (len(names),) * 3)
]


def test_every_layout_matches_rosbags() -> None:
    decoder = JointStateDecoder()  # one decoder over all cases: each layout change must be noticed
    for k, (frame, names, arrays) in enumerate(CASES):
        fields = values(frame, names, arrays, k)
        reference = rosbags_cdr(fields)
        assert expected(reference) == fields  # rosbags reads its own bytes back: the reference holds
        for data in (joint_state(frame, names, arrays, k), reference):
            assert tuple(decoder(data)) == fields, (frame, names, arrays)
            assert tuple(decode_joint_state(data)) == fields


def test_a_stream_of_one_layout_is_read_by_the_cached_struct() -> None:
    decoder = JointStateDecoder()
    names = ["mcp_joint", "coupler_joint", "pip_joint"]
    for k in range(50):
        fields = decoder(joint_state("finger_base", names, (3, 3, 3), k))
        assert tuple(fields) == values("finger_base", names, (3, 3, 3), k)
        assert fields.stamp_ns == fields.sec * 10**9 + fields.nanosec
    # same names, other lengths, then back: the counts are checked, not assumed
    for arrays in ((3, 0, 3), (3, 3, 3), (2, 3, 1)):
        assert tuple(decoder(joint_state("finger_base", names, arrays, 7))) == values("finger_base", names, arrays, 7)


@pytest.mark.parametrize("cut", [3, 8, 13, 40, -1])
def test_a_cut_message_is_refused(cut: int) -> None:
    data = joint_state("finger_base", ["mcp_joint", "pip_joint"], (2, 2, 2), 1)
    decoder = JointStateDecoder()
    decoder(data)  # a cached layout must not accept the cut message either
    with pytest.raises(LogArgumentError, match="JointState CDR: expected a complete sensor_msgs/msg/JointState"):
        decoder(data[:cut])


def test_other_encapsulations_are_refused() -> None:
    data = joint_state("", ["j"], (1, 1, 1), 0)
    with pytest.raises(LogArgumentError, match="little-endian plain CDR.*got '00 00"):
        decode_joint_state(b"\x00\x00" + data[2:])


def test_arrays_keep_their_order_and_values_bit_for_bit() -> None:
    values = [0.1, -0.0, 5e-324, 1.7976931348623157e308, math.inf]
    msg = JointState(name=["a", "b", "c", "d", "e"], position=values, velocity=values[::-1], effort=[])
    fields = decode_joint_state(serialize_message(msg))
    pairs = itertools.chain(zip(fields.position, values), zip(fields.velocity, values[::-1]))
    assert all(math.copysign(1, a) == math.copysign(1, b) and a == b for a, b in pairs)
    assert fields.effort == ()


@pytest.mark.parametrize("pairs", [[], [("event", "accepted")], [("a", ""), ("", "bc"), ("stamp_ns", "1274000000")] * 3])
@pytest.mark.parametrize("texts", [("", "", ""), ("/finger_node: command", "accepted", "finger")])
def test_diagnostic_status_matches_rosbags(pairs: list[tuple[str, str]], texts: tuple[str, str, str]) -> None:
    cls = STORE.types
    ref = cls["diagnostic_msgs/msg/DiagnosticStatus"](
        level=2, name=texts[0], message=texts[1], hardware_id=texts[2],
        values=[cls["diagnostic_msgs/msg/KeyValue"](key=k, value=v) for k, v in pairs])
    from_rosbags = bytes(STORE.serialize_cdr(ref, "diagnostic_msgs/msg/DiagnosticStatus"))
    msg = DiagnosticStatus(level=b"\x02", name=texts[0], message=texts[1], hardware_id=texts[2],
                           values=[KeyValue(key=k, value=v) for k, v in pairs])
    for data in (from_rosbags, serialize_message(msg)):
        assert tuple(decode_diagnostic_status(data)) == (2, *texts, tuple(pairs))
    with pytest.raises(LogArgumentError, match="DiagnosticStatus CDR: expected a complete"):
        decode_diagnostic_status(from_rosbags[:-3] if pairs else from_rosbags[:6])
