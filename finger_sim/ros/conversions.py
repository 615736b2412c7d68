"""Core state → ROS messages: pure functions, no node, no I/O (spec §6, REP 103).

Frame `<prefix>finger_base` sits at the MCP pivot A: x along the extended finger, z dorsal,
y = z × x. A model-plane point (X, Y) is (X, 0, −Y) there, and a model angle a is a rotation
by a about +y, the quaternion (w, x, y, z) = (cos a/2, 0, sin a/2, 0). Joint positions are
zero at extension and positive in flexion (finger_sim.joints); efforts are the applied
torques: the motor τ at `mcp_joint`, 0 at `coupler_joint`, the PIP spring's −kβ at `pip_joint`.

Every stamp is sim time in integer nanoseconds, never wall time. Each function returns a new
message, or with `out=` (like numpy's) refills one it returned before for the same frames and
returns it: at 20 000 states per second, building three messages costs more than a physics
step (15 µs against 3 µs refilled). rclpy serializes in publish(), so a refilled message may
be published again at once.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping
from dataclasses import dataclass

from builtin_interfaces.msg import Time
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from geometry_msgs.msg import Point, PoseStamped
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import JointState
from std_msgs.msg import ColorRGBA
from visualization_msgs.msg import Marker, MarkerArray

from finger_sim import joints, kinematics
from finger_sim.dynamics import FingerSystem
from finger_sim.forces import PipSpring
from finger_sim.kinematics import Vec3
from finger_sim.model import FingerParams

BASE_FRAME = "finger_base"
NS_PER_S = 1_000_000_000

#: Line width of the link markers and diameter of the fingertip sphere, m.
LINK_WIDTH = 0.002
TIP_DIAMETER = 0.006
#: Marker colours (r, g, b, a): ground grey, proximal blue, coupler orange, distal green, tip red.
COLORS = {
    "ground": (0.5, 0.5, 0.5, 1.0),
    "proximal": (0.2, 0.4, 0.9, 1.0),
    "coupler": (0.95, 0.55, 0.1, 1.0),
    "distal": (0.2, 0.75, 0.3, 1.0),
    "tip": (0.9, 0.1, 0.1, 1.0),
}
#: The four links as polylines through the named points of `kinematics.points`; the distal
#: phalanx is the ternary link C–B–tip.
LINKS = (
    ("ground", ("D", "A")),
    ("proximal", ("A", "B")),
    ("coupler", ("D", "C")),
    ("distal", ("C", "B", "tip")),
)


@dataclass(frozen=True)
class FingerFrames:
    """What the conversions need from the model, fixed for a run: constants and names.

    prefix: prepended to the frame id and the joint names, so that several fingers can share
    one TF tree (like a URDF's tf_prefix).
    """

    params: FingerParams
    q_ext: Vec3  # θ_ext, rad (spec §1)
    alpha: float  # distal offset α, rad
    stiffness: float  # PIP spring k, N·m/rad (0 when the scene has none)
    prefix: str = ""

    @classmethod
    def from_system(cls, system: FingerSystem, prefix: str = "") -> FingerFrames:
        k = sum(e.stiffness for e in system.elements if isinstance(e, PipSpring))
        return cls(system.params, kinematics.extended_pose(system.params), system.alpha, k, prefix)

    @property
    def base_frame(self) -> str:
        return self.prefix + BASE_FRAME

    @property
    def joint_names(self) -> list[str]:
        return [self.prefix + name for name in joints.JOINT_NAMES]


def to_time(stamp_ns: int, out: Time | None = None) -> Time:
    """builtin_interfaces/Time from non-negative nanoseconds."""
    t = Time() if out is None else out
    t.sec, t.nanosec = divmod(stamp_ns, NS_PER_S)
    return t


def from_time(stamp: Time) -> int:
    """Nanoseconds from builtin_interfaces/Time."""
    return stamp.sec * NS_PER_S + stamp.nanosec


def to_base(x: float, y: float) -> tuple[float, float, float]:
    """A model-plane point (X, Y), m, in `finger_base`: (X, 0, −Y)."""
    return (x, 0.0, -y)


def about_y(angle: float) -> tuple[float, float, float, float]:
    """Quaternion (w, x, y, z) of a rotation by `angle` (rad) about +y."""
    return (math.cos(0.5 * angle), 0.0, math.sin(0.5 * angle), 0.0)


def clock(stamp_ns: int, out: Clock | None = None) -> Clock:
    msg = Clock() if out is None else out
    to_time(stamp_ns, msg.clock)
    return msg


def joint_state(frames: FingerFrames, q: Vec3, v: Vec3, torque: float, stamp_ns: int,
                out: JointState | None = None) -> JointState:
    """sensor_msgs/JointState: positions (rad), velocities (rad/s) and efforts (N·m) of spec §6.

    torque: the motor torque applied over the step that ended in this state, N·m.
    """
    pos = joints.joint_positions(q, frames.q_ext, frames.alpha)
    if out is None:
        msg = JointState()
        msg.header.frame_id = frames.base_frame
        msg.name = frames.joint_names
    else:
        msg = out
    to_time(stamp_ns, msg.header.stamp)
    msg.position = pos
    msg.velocity = joints.joint_velocities(v)
    msg.effort = (float(torque), 0.0, -frames.stiffness * pos[2])
    return msg


def fingertip_pose(frames: FingerFrames, q: Vec3, stamp_ns: int, out: PoseStamped | None = None) -> PoseStamped:
    """geometry_msgs/PoseStamped of the fingertip in `finger_base`, oriented with the distal phalanx."""
    tip = kinematics.fingertip(frames.params, q, frames.alpha)
    if out is None:
        msg = PoseStamped()
        msg.header.frame_id = frames.base_frame
    else:
        msg = out
    to_time(stamp_ns, msg.header.stamp)
    p = msg.pose.position
    p.x, p.y, p.z = to_base(tip.x, tip.y)
    o = msg.pose.orientation
    o.w, o.x, o.y, o.z = about_y(tip.psi)
    return msg


def markers(frames: FingerFrames, q: Vec3, stamp_ns: int) -> MarkerArray:
    """visualization_msgs/MarkerArray: the four links as line strips and the fingertip as a sphere."""
    pts = kinematics.points(frames.params, q, frames.alpha)
    stamp = to_time(stamp_ns)
    out = MarkerArray()
    for marker_id, (link, names) in enumerate(LINKS):
        m = _marker(frames, stamp, marker_id, link, Marker.LINE_STRIP)
        m.scale.x = LINK_WIDTH
        m.points = [Point(x=x, y=y, z=z) for x, y, z in (to_base(*pts[n]) for n in names)]
        out.markers.append(m)
    tip = _marker(frames, stamp, len(LINKS), "tip", Marker.SPHERE)
    tip.scale.x = tip.scale.y = tip.scale.z = TIP_DIAMETER
    tip.pose.position.x, tip.pose.position.y, tip.pose.position.z = to_base(*pts["tip"])
    out.markers.append(tip)
    return out


def _marker(frames: FingerFrames, stamp: Time, marker_id: int, link: str, kind: int) -> Marker:
    m = Marker()
    m.header.stamp = stamp
    m.header.frame_id = frames.base_frame
    m.ns = frames.prefix + "finger"
    m.id = marker_id
    m.type = kind
    m.action = Marker.ADD
    m.pose.orientation.w = 1.0
    r, g, b, a = COLORS[link]
    m.color = ColorRGBA(r=r, g=g, b=b, a=a)
    return m


def key_values(values: Mapping[str, object]) -> list[KeyValue]:
    """diagnostic_msgs/KeyValue list; floats as repr() so that they round-trip exactly."""
    return [KeyValue(key=k, value=repr(v) if isinstance(v, float) else str(v)) for k, v in values.items()]


def status(name: str, hardware_id: str, level: bytes, message: str, values: Mapping[str, object]) -> DiagnosticStatus:
    return DiagnosticStatus(level=level, name=name, message=message, hardware_id=hardware_id, values=key_values(values))


def diagnostic_array(stamp_ns: int, statuses: Iterable[DiagnosticStatus]) -> DiagnosticArray:
    msg = DiagnosticArray()
    msg.header.stamp = to_time(stamp_ns)
    msg.status = list(statuses)
    return msg


def parse_values(msg: DiagnosticStatus) -> dict[str, str]:
    """The key-values of a DiagnosticStatus as a dict (the inverse of `key_values`, as strings)."""
    return {kv.key: kv.value for kv in msg.values}
