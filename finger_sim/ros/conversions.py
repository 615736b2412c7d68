"""Core state → ROS messages: pure functions, no node, no I/O (spec §6, REP 103).

Frame `<prefix>finger_base` sits at the MCP pivot A: x along the extended finger, z dorsal,
y = z × x. A model-plane point (X, Y) is (X, 0, −Y) there, and a model angle a is a rotation
by a about +y, the quaternion (w, x, y, z) = (cos a/2, 0, sin a/2, 0). Joint positions are
zero at extension and positive in flexion (finger_sim.joints); efforts are the applied
torques: the motor τ at `mcp_joint`, 0 at `coupler_joint`, the PIP spring's −kβ at `pip_joint`.

Contact (spec §7): the force on a phalanx, model (Fx, Fy), is (Fx, 0, −Fy) in `finger_base`,
and a moment Mz about the model's z axis is a torque about +y: the model's axes are X = x and
Y = −z, so Z = X × Y = x × (−z) = +y (the axis a model angle turns about). Objects are markers:
a circle is a cylinder along y, a plane a thin slab on the side of −normal.

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
from geometry_msgs.msg import Point, PoseStamped, WrenchStamped
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import JointState
from std_msgs.msg import ColorRGBA, Float64
from visualization_msgs.msg import Marker, MarkerArray

from finger_sim import joints, kinematics
from finger_sim.dynamics import FingerSystem
from finger_sim.effects import ForceElement, contact_outputs
from finger_sim.effects.base import declared_wrenches, reported_wrenches
from finger_sim.effects.contact_geometry import Circle, SceneObject
from finger_sim.effects.spring import spring_force
from finger_sim.kinematics import Vec3
from finger_sim.model import FingerParams

BASE_FRAME = "finger_base"
NS_PER_S = 1_000_000_000
#: A pure PIP rotation in q = (θ1, θ2, θ3): β = θ3 + α − θ1 changes by 1 rad.

#: The element output that marks a scene with contact (N): its elements' reports become the
#: grip_force and contact_wrench topics (keys of finger_sim.ros.interfaces.OUTPUTS).
GRIP_FORCE = contact_outputs.GRIP_FORCE.name
#: grip_force with its state's stamp: geometry_msgs/WrenchStamped whose wrench.force.x is Σ F_n
#: (N, a magnitude, not a direction of header.frame_id), every other field 0; a stamped type of
#: common_interfaces that a controller pairs with its time (std_msgs has no stamped Float64).
GRIP_FORCE_STAMPED = "grip_force_stamped"
#: The declared wrenches (`effects.base.Wrench`) and their topics (keys of OUTPUTS), each one's sum over elements.
WRENCHES = declared_wrenches()
WRENCH_KEYS = tuple(w.topic for w in WRENCHES)

#: Line width of the link markers and diameter of the fingertip sphere, m.
LINK_WIDTH = 0.002
TIP_DIAMETER = 0.006
#: Object markers: extent normal to the model plane (a cup's height), a plane's thickness and
#: its width along the model plane, m; colour (r, g, b, a), translucent so the finger shows.
OBJECT_DEPTH = 0.04
PLANE_THICKNESS = 0.002
PLANE_WIDTH = 0.2
OBJECT_COLOR = (0.8, 0.8, 0.85, 0.6)
#: A cylinder marker's axis is its z: a quarter turn about x lays it along finger_base y, the
#: axis of a circle object (normal to the model plane). Quaternion (w, x, y, z).
CYLINDER_ALONG_Y = (math.sqrt(0.5), math.sqrt(0.5), 0.0, 0.0)
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
    objects: tuple[SceneObject, ...] = ()  # the scene's fixed objects (spec §7), drawn as markers

    @classmethod
    def from_system(cls, system: FingerSystem, prefix: str = "") -> FingerFrames:
        q_ext = kinematics.extended_pose(system.params)
        k = joints.pip_stiffness(system)
        objects = tuple(obj for e in system.elements for obj in getattr(e, "objects", ()))
        return cls(system.params, q_ext, system.alpha, k, prefix, objects)

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


def joint_values(frames: FingerFrames, q: Vec3, v: Vec3, torque: float) -> tuple[Vec3, Vec3, Vec3]:
    """The positions (rad), velocities (rad/s) and efforts (N·m) of the three joints (spec §6).

    torque: the motor torque applied over the step that ended in this state, N·m.
    """
    pos = joints.joint_positions(q, frames.q_ext, frames.alpha)
    pip_effort = spring_force(frames.stiffness, frames.alpha, q[0], q[2])[2]  # −kβ
    return pos, joints.joint_velocities(v), (float(torque), 0.0, pip_effort)


def joint_state(frames: FingerFrames, q: Vec3, v: Vec3, torque: float, stamp_ns: int,
                out: JointState | None = None) -> JointState:
    """sensor_msgs/JointState: positions (rad), velocities (rad/s) and efforts (N·m) of spec §6
    (`joint_values`)."""
    if out is None:
        msg = JointState()
        msg.header.frame_id = frames.base_frame
        msg.name = frames.joint_names
    else:
        msg = out
    to_time(stamp_ns, msg.header.stamp)
    msg.position, msg.velocity, msg.effort = joint_values(frames, q, v, torque)
    return msg


def fingertip_values(frames: FingerFrames, q: Vec3) -> tuple[tuple[float, float, float], tuple[float, float, float, float]]:
    """The fingertip's position in `finger_base` (m) and the distal phalanx's orientation as the
    quaternion (x, y, z, w)."""
    tip = kinematics.fingertip(frames.params, q, frames.alpha)
    w, x, y, z = about_y(tip.psi)
    return to_base(tip.x, tip.y), (x, y, z, w)


def fingertip_pose(frames: FingerFrames, q: Vec3, stamp_ns: int, out: PoseStamped | None = None) -> PoseStamped:
    """geometry_msgs/PoseStamped of the fingertip in `finger_base`, oriented with the distal phalanx."""
    if out is None:
        msg = PoseStamped()
        msg.header.frame_id = frames.base_frame
    else:
        msg = out
    to_time(stamp_ns, msg.header.stamp)
    position, orientation = fingertip_values(frames, q)
    p = msg.pose.position
    p.x, p.y, p.z = position
    o = msg.pose.orientation
    o.x, o.y, o.z, o.w = orientation
    return msg


def markers(frames: FingerFrames, q: Vec3, stamp_ns: int) -> MarkerArray:
    """visualization_msgs/MarkerArray: the four links as line strips, the fingertip as a sphere,
    then each object (namespace: its name) as a cylinder (circle) or a thin cube (plane)."""
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
    out.markers += [object_marker(frames, stamp, i, obj) for i, obj in enumerate(frames.objects)]
    return out


def marker_values(frames: FingerFrames, q: Vec3) -> list[float]:
    """What moves in `markers(frames, q, ·)`, in its order: each marker's pose.position (x, y, z)
    then its points' (x, y, z), m; the floats of finger_sim.log.cdr_writer.MarkerArrayCdr."""
    pts = kinematics.points(frames.params, q, frames.alpha)
    values: list[float] = []
    for _, names in LINKS:
        values += (0.0, 0.0, 0.0)  # a line strip's pose: the origin
        for n in names:
            values += to_base(*pts[n])
    values += to_base(*pts["tip"])
    for obj in frames.objects:
        values += to_base(*_object_pose(obj)[0])
    return values


def _object_pose(obj: SceneObject) -> tuple[tuple[float, float], tuple[float, float, float, float]]:
    """An object marker's centre in the model plane (m) and orientation (w, x, y, z) (`object_marker`)."""
    if isinstance(obj, Circle):
        return obj.center, CYLINDER_ALONG_Y
    (ox, oy), (nx, ny) = obj.point, obj.normal
    return (ox - 0.5 * PLANE_THICKNESS * nx, oy - 0.5 * PLANE_THICKNESS * ny), about_y(math.atan2(ny, nx))


def object_marker(frames: FingerFrames, stamp: Time, marker_id: int, obj: SceneObject) -> Marker:
    """A circle as a cylinder along y (diameter 2R, OBJECT_DEPTH long) at its centre; a plane as a
    PLANE_THICKNESS slab whose face lies on the plane, on the side of −normal: the cube's x along
    the normal (a rotation by the normal's model angle about +y), y along finger_base y."""
    if isinstance(obj, Circle):
        m = _marker(frames, stamp, marker_id, obj.name, Marker.CYLINDER, ns=frames.prefix + obj.name)
        m.scale.x = m.scale.y = 2.0 * obj.radius
        m.scale.z = OBJECT_DEPTH
    else:
        m = _marker(frames, stamp, marker_id, obj.name, Marker.CUBE, ns=frames.prefix + obj.name)
        m.scale.x, m.scale.y, m.scale.z = PLANE_THICKNESS, OBJECT_DEPTH, PLANE_WIDTH
    center, orientation = _object_pose(obj)
    p, o = m.pose.position, m.pose.orientation
    p.x, p.y, p.z = to_base(*center)
    o.w, o.x, o.y, o.z = orientation
    return m


def _marker(frames: FingerFrames, stamp: Time, marker_id: int, link: str, kind: int, ns: str | None = None) -> Marker:
    m = Marker()
    m.header.stamp = stamp
    m.header.frame_id = frames.base_frame
    m.ns = frames.prefix + "finger" if ns is None else ns
    m.id = marker_id
    m.type = kind
    m.action = Marker.ADD
    m.pose.orientation.w = 1.0
    r, g, b, a = COLORS.get(link, OBJECT_COLOR)
    m.color = ColorRGBA(r=r, g=g, b=b, a=a)
    return m


def moment_to_base(mz: float) -> tuple[float, float, float]:
    """A moment Mz about the model's z axis (N·m) in `finger_base`: (0, Mz, 0), since Z = +y."""
    return (0.0, mz, 0.0)


def contact_wrench(frames: FingerFrames, wrench: Vec3, stamp_ns: int, out: WrenchStamped | None = None) -> WrenchStamped:
    """geometry_msgs/WrenchStamped in `finger_base` from a model-plane (Fx, Fy, Mz): the contact
    force on a phalanx (N) and its moment about the frame origin A (N·m)."""
    if out is None:
        msg = WrenchStamped()
        msg.header.frame_id = frames.base_frame
    else:
        msg = out
    to_time(stamp_ns, msg.header.stamp)
    f, m = msg.wrench.force, msg.wrench.torque
    f.x, f.y, f.z = to_base(wrench[0], wrench[1])
    m.x, m.y, m.z = moment_to_base(wrench[2])
    return msg


class ContactReport:
    """The contact topics' messages of a state, from the elements that report a grip force.

    Summed over those elements: grip_force (Σ F_n, N) from their `outputs`, and each declared wrench
    (`WRENCHES`: (Fx, Fy, Mz about A) on a phalanx) from their `wrenches(t, q, q')`. Messages are refilled
    in place (as `out=` does above).
    """

    def __init__(self, frames: FingerFrames, elements: Iterable[ForceElement]) -> None:
        zero = (0.0, 0.0, 0.0)
        self.frames = frames
        self.elements = tuple(e for e in elements if GRIP_FORCE in e.outputs(0.0, frames.q_ext, zero))
        #: per element, the index in WRENCHES of each wrench it reports, in the order of its `wrenches`
        self._slots = tuple(tuple(WRENCHES.index(w) for w in reported_wrenches(e, frames.q_ext)) for e in self.elements)
        self._grip = Float64()
        self._grip_stamped = WrenchStamped()
        self._grip_stamped.header.frame_id = frames.base_frame
        self._wrenches: list[WrenchStamped | None] = [None] * len(WRENCHES)

    @classmethod
    def of(cls, frames: FingerFrames, elements: Iterable[ForceElement]) -> ContactReport | None:
        """The report of a scene with contact; None (nothing to publish, no cost) without any."""
        report = cls(frames, elements)
        return report if report.elements else None

    def messages(self, t: float, q: Vec3, v: Vec3, stamp_ns: int) -> list[tuple[str, Float64 | WrenchStamped]]:
        """[(output key, message)]: grip_force, grip_force_stamped, then each declared wrench's topic
        (contact_wrench/proximal and /distal)."""
        grip, sums = 0.0, [[0.0, 0.0, 0.0] for _ in WRENCH_KEYS]
        for e, slots in zip(self.elements, self._slots):
            grip += e.outputs(t, q, v)[GRIP_FORCE]
            for slot, wrench in zip(slots, e.wrenches(t, q, v)):
                acc = sums[slot]
                acc[0] += wrench[0]
                acc[1] += wrench[1]
                acc[2] += wrench[2]
        self._grip.data = self._grip_stamped.wrench.force.x = grip
        to_time(stamp_ns, self._grip_stamped.header.stamp)
        out: list[tuple[str, Float64 | WrenchStamped]] = [(GRIP_FORCE, self._grip), (GRIP_FORCE_STAMPED, self._grip_stamped)]
        for i, (key, acc) in enumerate(zip(WRENCH_KEYS, sums)):
            self._wrenches[i] = contact_wrench(self.frames, (acc[0], acc[1], acc[2]), stamp_ns, out=self._wrenches[i])
            out.append((key, self._wrenches[i]))
        return out


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
