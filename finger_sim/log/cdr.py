"""Fixed-layout CDR readers for sensor_msgs/msg/JointState and diagnostic_msgs/msg/DiagnosticStatus,
for tools that read long logs.

rosbags' compiled deserializer builds a dataclass and three numpy arrays per message
(~30 µs for a node's JointState); reading a 1 kHz log for resim needs only the stamp, the
names and three float arrays, which `struct` reads in a few µs. The layout is the one of
the ROS 2 definitions (JointState: std_msgs/Header header; string[] name; float64[] position,
velocity, effort. DiagnosticStatus: byte level; string name, message, hardware_id;
KeyValue[] values, each string key, string value) in little-endian plain CDR (XCDR1, encapsulation 0x0001), which every ROS 2 rmw
writes: primitives aligned to their size counted from the end of the 4-byte encapsulation
header; strings as a uint32 length that counts a closing NUL, then the bytes. A payload in
another encapsulation or that does not fit raises LogArgumentError naming what was found;
Bytes after the effort array are ignored (rmw buffers may carry some).
test_log_cdr checks the results against rosbags' deserializer.
"""

from __future__ import annotations

import struct
from typing import NamedTuple

from .errors import LogArgumentError

_CDR_LE = b"\x00\x01"  # encapsulation kind CDR_LE (the options bytes after it are ignored)
_ORIGIN = 4  # alignment is counted from the end of the encapsulation header
_U32 = struct.Struct("<I")
_STAMP = struct.Struct("<iI")  # builtin_interfaces/Time: sec int32, nanosec uint32
_NAMES_AT = _ORIGIN + _STAMP.size  # the frame id's length, where the variable part begins


class JointStateFields(NamedTuple):
    """The fields of one sensor_msgs/msg/JointState: stamp (s, ns), frame id, joint names, and
    positions (rad or m), velocities (rad/s or m/s), efforts (N·m or N) as tuples of floats."""

    sec: int
    nanosec: int
    frame_id: str
    name: tuple[str, ...]
    position: tuple[float, ...]
    velocity: tuple[float, ...]
    effort: tuple[float, ...]

    @property
    def stamp_ns(self) -> int:
        """The header stamp, ns."""
        return self.sec * 1_000_000_000 + self.nanosec


class JointStateDecoder:
    """decode_joint_state for a stream of JointStates that repeat their frame id, names and
    array lengths (a node's): when the bytes from the frame id to the end of the names equal
    the last message's, the arrays are read with one precompiled struct whose array lengths
    are checked. Not thread-safe; one per reading loop."""

    def __init__(self) -> None:
        self._block = b""  # bytes from the frame id to the end of the names
        self._frame_id, self._names, self._tail_at = "", (), 0
        self._tail: struct.Struct | None = None  # the three arrays with their counts, as last seen
        self._counts: tuple[int, int, int] = (0, 0, 0)

    def __call__(self, data: bytes) -> JointStateFields:
        """The fields of a CDR-encoded JointState; LogArgumentError if `data` is not one."""
        if data[:2] != _CDR_LE:
            raise LogArgumentError("JointState CDR", "little-endian plain CDR (encapsulation 00 01)", data[:4].hex(" "))
        try:
            sec, nanosec = _STAMP.unpack_from(data, _ORIGIN)
            block, tail = self._block, self._tail
            if tail is not None and data[_NAMES_AT:_NAMES_AT + len(block)] == block \
                    and len(data) >= self._tail_at + tail.size:
                values = tail.unpack_from(data, self._tail_at)
                n1, n2, _ = self._counts
                if (values[0], values[1 + n1], values[2 + n1 + n2]) == self._counts:
                    return JointStateFields(sec, nanosec, self._frame_id, self._names, values[1:1 + n1],
                                            values[2 + n1:2 + n1 + n2], values[3 + n1 + n2:])
            return self._parse(data, sec, nanosec)
        except (struct.error, UnicodeDecodeError, ValueError) as exc:
            raise LogArgumentError("JointState CDR", "a complete sensor_msgs/msg/JointState",
                                   f"{len(data)} bytes ({exc})") from None

    def _parse(self, data: bytes, sec: int, nanosec: int) -> JointStateFields:
        """Read the message field by field and remember its layout for the next one."""
        frame_id, names, pos = _names(data, _NAMES_AT)
        tail_at, layout, arrays, counts = pos, "<", [], []
        for _ in range(3):
            start = pos
            n, pos = _count(data, pos)
            layout += "x" * (pos - 4 - start) + "I"
            if n:
                start, pos = pos, _aligned(pos, 8)
                layout += "x" * (pos - start) + f"{n}d"
            arrays.append(struct.unpack_from(f"<{n}d", data, pos))
            counts.append(n)
            pos += 8 * n
        self._block, self._frame_id, self._names, self._tail_at = data[_NAMES_AT:tail_at], frame_id, names, tail_at
        self._tail, self._counts = struct.Struct(layout), (counts[0], counts[1], counts[2])
        return JointStateFields(sec, nanosec, frame_id, names, *arrays)


def decode_joint_state(data: bytes) -> JointStateFields:
    """The fields of a CDR-encoded JointState; LogArgumentError if `data` is not one."""
    return JointStateDecoder()(data)


class DiagnosticStatusFields(NamedTuple):
    """The fields of one diagnostic_msgs/msg/DiagnosticStatus; values as (key, value) pairs."""

    level: int
    name: str
    message: str
    hardware_id: str
    values: tuple[tuple[str, str], ...]


def decode_diagnostic_status(data: bytes) -> DiagnosticStatusFields:
    """The fields of a CDR-encoded DiagnosticStatus; LogArgumentError if `data` is not one."""
    if data[:2] != _CDR_LE:
        raise LogArgumentError("DiagnosticStatus CDR", "little-endian plain CDR (encapsulation 00 01)", data[:4].hex(" "))
    try:
        if len(data) <= _ORIGIN:
            raise ValueError("no level byte")
        level, pos = data[_ORIGIN], _ORIGIN + 1
        (name, message, hardware_id), pos = _strings(data, pos, 3)
        count, pos = _count(data, pos)
        texts, pos = _strings(data, pos, 2 * count)
        values = list(zip(texts[::2], texts[1::2]))
    except (struct.error, UnicodeDecodeError, ValueError) as exc:
        raise LogArgumentError("DiagnosticStatus CDR", "a complete diagnostic_msgs/msg/DiagnosticStatus",
                               f"{len(data)} bytes ({exc})") from None
    return DiagnosticStatusFields(level, name, message, hardware_id, tuple(values))


def _names(data: bytes, pos: int) -> tuple[str, tuple[str, ...], int]:
    """Frame id and joint names from `pos` on, and the offset after them."""
    frame_id, pos = _string(data, pos)
    count, pos = _count(data, pos)
    names, pos = _strings(data, pos, count)
    return frame_id, tuple(names), pos


def _aligned(pos: int, size: int) -> int:
    return _ORIGIN + ((pos - _ORIGIN + size - 1) & -size)


def _count(data: bytes, pos: int) -> tuple[int, int]:
    pos = _aligned(pos, 4)
    (n,) = _U32.unpack_from(data, pos)
    if n > len(data) - pos - 4:  # every element takes at least a byte: bound it before anything is built
        raise ValueError(f"an array of {n} elements in a message of {len(data)} bytes")
    return n, pos + 4


def _string(data: bytes, pos: int) -> tuple[str, int]:
    (text,), pos = _strings(data, pos, 1)
    return text, pos


def _strings(data: bytes, pos: int, count: int) -> tuple[list[str], int]:
    """`count` consecutive CDR strings from `pos` on, and the offset after them (the hot loop of
    both readers, kept inline: the origin is 4-aligned, so 4-alignment is absolute)."""
    unpack, size, texts = _U32.unpack_from, len(data), []
    for _ in range(count):
        pos = (pos + 3) & -4
        (n,) = unpack(data, pos)
        start, pos = pos + 4, pos + 4 + n
        if n == 0 or pos > size or data[pos - 1] != 0:
            raise ValueError(f"a string of {n} bytes at byte {start - 4} without its closing NUL")
        texts.append(data[start:pos - 1].decode())
    return texts, pos
