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


class _Layout:
    """One message's bytes as one `struct` format: constants packed as given, float64 slots filled per call."""

    def __init__(self) -> None:
        self.format = "<"
        self.args: list[object] = []
        self.offset = 0  # from the end of the encapsulation header
        self.slots: list[int] = []  # indexes into args of the float64 filled per call
        self.stamps: list[int] = []  # indexes into args of the stamps' sec (nanosec follows)

    def _put(self, code: str, size: int, value: object) -> int:
        pad = -self.offset % size
        self.format += (f"{pad}x" if pad else "") + code
        self.offset += pad + size
        self.args.append(value)
        return len(self.args) - 1

    def i32(self, value: int) -> None:
        self._put("i", 4, value)

    def u32(self, value: int) -> None:
        self._put("I", 4, value)

    def f32(self, value: float) -> None:
        self._put("f", 4, value)

    def f64(self, value: float) -> None:
        self._put("d", 8, value)

    def slot(self) -> None:
        self.slots.append(self._put("d", 8, 0.0))

    def boolean(self, value: bool) -> None:
        self._put("?", 1, value)

    def string(self, text: str) -> None:
        raw = text.encode() + b"\x00"
        self.u32(len(raw))
        self.format += f"{len(raw)}s"
        self.offset += len(raw)
        self.args.append(raw)

    def stamp(self) -> None:
        self.stamps.append(self._put("i", 4, 0))
        self.u32(0)


class MarkerArrayCdr:
    """visualization_msgs/msg/MarkerArray (Jazzy's Marker) with every field fixed as in `template`
    (a MarkerArray, e.g. finger_sim.ros.conversions.markers at any state) except the markers'
    header stamps, pose positions and points: those come with each call, as floats in marker
    order, each marker's pose.position (x, y, z) then its points' (x, y, z). Textures, meshes,
    per-point colours and UV coordinates must be empty (ValueError otherwise)."""

    def __init__(self, template: object) -> None:
        lay = _Layout()
        markers = template.markers  # type: ignore[attr-defined]
        lay.u32(len(markers))
        for m in markers:
            if m.colors or m.uv_coordinates or m.texture.data or m.mesh_file.data:
                raise ValueError(f"marker {m.ns}/{m.id}: per-point colours, UV coordinates, a texture or a mesh")
            lay.stamp()
            lay.string(m.header.frame_id)
            lay.string(m.ns)
            for value in (m.id, m.type, m.action):
                lay.i32(value)
            for _ in range(3):  # pose.position
                lay.slot()
            o, s, c = m.pose.orientation, m.scale, m.color
            for value in (o.x, o.y, o.z, o.w, s.x, s.y, s.z):
                lay.f64(value)
            for value in (c.r, c.g, c.b, c.a):
                lay.f32(value)
            lay.i32(m.lifetime.sec)
            lay.u32(m.lifetime.nanosec)
            lay.boolean(m.frame_locked)
            lay.u32(len(m.points))
            for _ in range(3 * len(m.points)):
                lay.slot()
            lay.u32(0)  # colors
            lay.string(m.texture_resource)
            lay.i32(m.texture.header.stamp.sec)
            lay.u32(m.texture.header.stamp.nanosec)
            lay.string(m.texture.header.frame_id)
            lay.string(m.texture.format)
            lay.u32(0)  # texture.data
            lay.u32(0)  # uv_coordinates
            lay.string(m.text)
            lay.string(m.mesh_resource)
            lay.string(m.mesh_file.filename)
            lay.u32(0)  # mesh_file.data
            lay.boolean(m.mesh_use_embedded_materials)
        self._struct = struct.Struct(lay.format)
        self._args = lay.args
        self._slots = lay.slots
        self._stamps = lay.stamps
        self.count = len(lay.slots)

    def __call__(self, stamp_ns: int, values: Sequence[float]) -> bytes:
        """The CDR bytes stamped `stamp_ns` with `values` (self.count floats); ValueError if fewer or more."""
        if len(values) != self.count:
            raise ValueError(f"expected {self.count} marker coordinates, got {len(values)}")
        args = self._args
        sec, nanosec = divmod(stamp_ns, NS_PER_S)
        for i in self._stamps:
            args[i], args[i + 1] = sec, nanosec
        for i, value in zip(self._slots, values):
            args[i] = value
        return _ENCAPSULATION + self._struct.pack(*args)
