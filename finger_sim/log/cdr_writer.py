"""Fixed-layout CDR writers for the hot messages of a stepping node: sensor_msgs/msg/JointState,
geometry_msgs/msg/PoseStamped, rosgraph_msgs/msg/Clock and std_msgs/msg/Float64.

A node publishes the same joint names and frame id every step; only the stamp and the floats
change. So the constant bytes (encapsulation header, frame id, names, array lengths) are laid
out once, and each message is the stamp and the floats packed by one precompiled `struct`
into that frame: a few µs, against ~20 µs for filling an rclpy message and serializing it
with rclpy. The bytes go to `Publisher.publish` (rclpy publishes bytes as they are) and to the
log unchanged, so what is published and what is logged are the same bytes.

Layout: little-endian plain CDR (XCDR1, encapsulation 0x0001), as every ROS 2 rmw writes it and
finger_sim.log.cdr reads it: primitives aligned to their size counted from the end of the
4-byte encapsulation header; a string is a uint32 length that counts its closing NUL, then the
bytes and the NUL; a sequence is a uint32 count, then its elements. No trailing padding.
test_cdr_writer round-trips random messages through rclpy's deserializer and rosbags'.
"""

from __future__ import annotations

import struct
from collections.abc import Sequence

_ENCAPSULATION = b"\x00\x01\x00\x00"  # CDR_LE, options 0
NS_PER_S = 1_000_000_000
_STAMP = struct.Struct("<iI")  # builtin_interfaces/Time: sec int32, nanosec uint32, at offset 0


class _Frame:
    """Constant bytes laid out from a CDR offset (counted from the end of the encapsulation)."""

    def __init__(self, offset: int) -> None:
        self.offset = offset
        self.data = bytearray()

    def align(self, size: int) -> None:
        pad = -self.offset % size
        self.data += bytes(pad)
        self.offset += pad

    def u32(self, value: int) -> None:
        self.align(4)
        self.data += struct.pack("<I", value)
        self.offset += 4

    def string(self, text: str) -> None:
        raw = text.encode() + b"\x00"
        self.u32(len(raw))
        self.data += raw
        self.offset += len(raw)


def _doubles_format(offset: int, count: int) -> tuple[str, int]:
    """struct format (without byte order) of `count` float64 at `offset`, and the offset after them."""
    pad = -offset % 8 if count else 0
    return (f"{pad}x" if pad else "") + f"{count}d", offset + pad + 8 * count


def _header(frame_id: str) -> _Frame:
    """std_msgs/Header after its stamp: the frame id."""
    frame = _Frame(_STAMP.size)
    frame.string(frame_id)
    return frame


class JointStateCdr:
    """sensor_msgs/msg/JointState with fixed frame id and joint names; `len(names)` positions,
    velocities and efforts each."""

    def __init__(self, frame_id: str, names: Sequence[str]) -> None:
        self.count = n = len(names)
        frame = _header(frame_id)
        frame.u32(n)
        for name in names:
            frame.string(name)
        fmt, offset = "<", frame.offset
        for _ in range(3):  # position, velocity, effort: a count, then the doubles
            pad = -offset % 4
            fmt += (f"{pad}x" if pad else "") + "I"
            doubles, offset = _doubles_format(offset + pad + 4, n)
            fmt += doubles
        self._head = bytes(frame.data)
        self._arrays = struct.Struct(fmt)

    def __call__(self, stamp_ns: int, position: Sequence[float], velocity: Sequence[float],
                 effort: Sequence[float]) -> bytes:
        """The CDR bytes of one JointState stamped `stamp_ns` (≥ 0); struct.error if a length differs."""
        n = self.count
        if not len(position) == len(velocity) == len(effort) == n:
            raise struct.error(f"expected {n} positions, velocities and efforts, got "
                               f"{len(position)}, {len(velocity)}, {len(effort)}")
        sec, nanosec = divmod(stamp_ns, NS_PER_S)
        return b"".join((_ENCAPSULATION, _STAMP.pack(sec, nanosec), self._head,
                         self._arrays.pack(n, *position, n, *velocity, n, *effort)))


class PoseStampedCdr:
    """geometry_msgs/msg/PoseStamped with a fixed frame id."""

    def __init__(self, frame_id: str) -> None:
        frame = _header(frame_id)
        doubles, _ = _doubles_format(frame.offset, 7)  # Point x, y, z; Quaternion x, y, z, w
        self._head = bytes(frame.data)
        self._pose = struct.Struct("<" + doubles)

    def __call__(self, stamp_ns: int, position: Sequence[float], orientation_xyzw: Sequence[float]) -> bytes:
        """The CDR bytes of one pose: position (m), orientation as the quaternion (x, y, z, w)."""
        sec, nanosec = divmod(stamp_ns, NS_PER_S)
        return b"".join((_ENCAPSULATION, _STAMP.pack(sec, nanosec), self._head,
                         self._pose.pack(*position, *orientation_xyzw)))


def clock_cdr(stamp_ns: int) -> bytes:
    """rosgraph_msgs/msg/Clock at `stamp_ns` (≥ 0)."""
    return _ENCAPSULATION + _STAMP.pack(*divmod(stamp_ns, NS_PER_S))


_FLOAT64 = struct.Struct("<d")


def float64_cdr(value: float) -> bytes:
    """std_msgs/msg/Float64."""
    return _ENCAPSULATION + _FLOAT64.pack(value)


_INT64 = struct.Struct("<q")
_LENGTH = struct.Struct("<I")


def int64_cdr(value: int) -> bytes:
    """std_msgs/msg/Int64."""
    return _ENCAPSULATION + _INT64.pack(value)


def string_cdr(value: str) -> bytes:
    """std_msgs/msg/String: the length with its NUL, the UTF-8 bytes, the NUL."""
    data = value.encode()
    return _ENCAPSULATION + _LENGTH.pack(len(data) + 1) + data + b"\0"
