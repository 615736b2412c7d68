"""finger_node's topics as tables: a new topic is one entry here.

Publishers, command subscriptions, the log's channels and the acknowledgement wait at a
clean exit are all made from OUTPUTS and COMMAND_INPUTS, so a topic cannot be published
without being registered in the log (no KeyError in the stepping loop).

QoS: state and log topics are reliable, volatile; /clock is rclcpp::ClockQoS(). Commands use
rclcpp::SystemDefaultsQoS() as ros2_control's forward command controller does (with Fast DDS:
best effort, keep last 1, so a flood loses commands in DDS; any publisher's QoS matches it),
or with command_qos 'reliable' a reliable keep-last-command_depth queue that loses none.
robot_description is transient local, reliable, depth 1, as robot_state_publisher offers it,
so a subscriber that joins later still gets it.

Per finger or per run: finger_hand steps several fingers in one node; each finger's topics
(`per_finger`) go into its own namespace (`finger_topic`), the run's (/clock, /diagnostics,
robot_description) exist once.
"""

from __future__ import annotations

from collections.abc import Callable, Collection
from dataclasses import dataclass
from typing import Any

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
from geometry_msgs.msg import PoseStamped, WrenchStamped
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy, qos_profile_system_default
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import JointState
from std_msgs.msg import Float64, Float64MultiArray, Int64, String
from visualization_msgs.msg import MarkerArray

from finger_sim.actuators.drive_outputs import ENCODER, MESH_MODE, MOTOR_ANGLE, MOTOR_CURRENT, MOTOR_VOLTAGE
from finger_sim.effects.base import declared_wrenches
from finger_sim.effects.contact_outputs import GRIP_FORCE

from finger_sim.runtime.commands import joint_effort
from finger_sim.runtime.parameters import CommandQos, HandSettings, RunSettings

#: History depth of the state and log publishers (reliable, volatile).
STATE_DEPTH = 10
EVENT_DEPTH = 100
#: rclcpp::ClockQoS(): best effort, keep last 1, as rclpy's TimeSource and rosbag2 subscribe.
CLOCK_QOS = QoSProfile(depth=1, reliability=ReliabilityPolicy.BEST_EFFORT)
STATE_QOS = QoSProfile(depth=STATE_DEPTH)
EVENT_QOS = QoSProfile(depth=EVENT_DEPTH)
#: robot_state_publisher's robot_description QoS: reliable, transient local, keep last 1.
DESCRIPTION_QOS = QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE, durability=DurabilityPolicy.TRANSIENT_LOCAL)
#: rclcpp::SystemDefaultsQoS(), what ros2_control's forward command controller subscribes with.
COMMAND_QOS = qos_profile_system_default


def command_qos(settings: RunSettings) -> QoSProfile:
    """The command subscriptions' QoS: the system default, or reliable keep-last command_depth."""
    if settings.command_qos is CommandQos.RELIABLE:
        return QoSProfile(depth=settings.command_depth, reliability=ReliabilityPolicy.RELIABLE)
    return COMMAND_QOS


def _always(settings: RunSettings) -> bool:
    return True


def finger_topic(topic: str, finger: str) -> str:
    """A finger's topic in a hand: `topic` in the namespace `finger` ("" for finger_node's one
    finger: unchanged); "~/x" becomes "<finger>/x"."""
    if not finger:
        return topic
    return f"{finger}/{topic.removeprefix('~/')}"


@dataclass(frozen=True)
class OutputSpec:
    """A published topic: name (relative names go into the node's namespace), type, QoS; recorded:
    also written to the log; acked: a clean exit waits for reliable subscribers to acknowledge it;
    enabled: whether the settings want it at all; per_finger: one for each finger of a hand (in
    its namespace), else one for the run; reported_by: published only when a force element of
    the scene reports this output (grip_force: a scene with contact)."""

    topic: str
    msg_type: type
    qos: QoSProfile
    recorded: bool = True
    acked: bool = False
    enabled: Callable[[RunSettings], bool] = _always
    per_finger: bool = True
    reported_by: str | None = None

    def wanted(self, settings: RunSettings, reported: Collection[str]) -> bool:
        """Whether it is published: the settings want it and the scene's elements report it."""
        return self.enabled(settings) and (self.reported_by is None or self.reported_by in reported)


@dataclass(frozen=True)
class InputSpec:
    """A command topic: (its message, the actuated joint's name) → the command's values (one
    element: a torque, N·m) and the reason it is refused for (None: the stepping loop checks it)."""

    topic: str
    msg_type: type
    read: Callable[[Any, str], tuple[tuple[float, ...], str | None]]
    recorded: bool = True
    stamped: bool = False  # it has a header whose stamp names the state it answers (lockstep)
    #: subscribed only for a finger with a drive (spec §8: its voltage command)
    driven_only: bool = False


#: Every topic the node publishes, by the key the node publishes it under.
OUTPUTS: dict[str, OutputSpec] = {
    "clock": OutputSpec("/clock", Clock, CLOCK_QOS, enabled=lambda s: s.publish_clock, per_finger=False),
    "joint_states": OutputSpec("joint_states", JointState, STATE_QOS, acked=True),
    # finger_hand: every finger's joints (prefixed names) in one message per state, for robot_state_publisher
    "hand_joint_states": OutputSpec("joint_states", JointState, STATE_QOS, acked=True, per_finger=False,
                                    enabled=lambda s: isinstance(s, HandSettings)),
    "fingertip_pose": OutputSpec("fingertip_pose", PoseStamped, STATE_QOS, acked=True),
    "markers": OutputSpec("finger_markers", MarkerArray, STATE_QOS, enabled=lambda s: s.marker_rate_hz > 0),
    "diagnostics": OutputSpec("/diagnostics", DiagnosticArray, STATE_QOS, acked=True, per_finger=False),
    "robot_description": OutputSpec("robot_description", String, DESCRIPTION_QOS, per_finger=False),
    "command_log": OutputSpec("~/command_log", DiagnosticStatus, EVENT_QOS, acked=True),
    # an object crushed (its break_force exceeded; finger_sim.runtime.crushing): one record per crush
    "crush_log": OutputSpec("~/crush_log", DiagnosticStatus, EVENT_QOS, acked=True, reported_by="crush_log"),
    # contact (spec §7; conversions.ContactReport): Σ F_n (N) and each phalanx's wrench in finger_base
    GRIP_FORCE.topic: OutputSpec(GRIP_FORCE.topic, Float64, STATE_QOS, acked=True, reported_by=GRIP_FORCE.name),
    # grip_force with the state's stamp (conversions.GRIP_FORCE_STAMPED: wrench.force.x = Σ F_n, N)
    "grip_force_stamped": OutputSpec("grip_force_stamped", WrenchStamped, STATE_QOS, acked=True,
                                     reported_by=GRIP_FORCE.name),
    # every declared wrench (effects.base.Wrench): contact_wrench/proximal, contact_wrench/distal
    **{w.topic: OutputSpec(w.topic, WrenchStamped, STATE_QOS, acked=True, reported_by=GRIP_FORCE.name)
       for w in declared_wrenches()},
    # the drive (spec §8; finger_sim.ros.motor): what a prosthetic controller reads from the device
    **{o.topic: OutputSpec(o.topic, Float64, STATE_QOS, acked=True, reported_by=MOTOR_CURRENT.name)
       for o in (MOTOR_CURRENT, MOTOR_VOLTAGE, MOTOR_ANGLE)},  # motor/current, motor/voltage, motor/angle
    ENCODER.topic: OutputSpec(ENCODER.topic, Int64, STATE_QOS, acked=True, reported_by=ENCODER.name),
    MESH_MODE.topic: OutputSpec(MESH_MODE.topic, String, STATE_QOS, acked=True, reported_by=MOTOR_CURRENT.name),
    "motor/current_measured": OutputSpec("motor/current_measured", Float64, STATE_QOS, acked=True,
                                         reported_by="motor_current_measured"),  # scene sensors: the reading
}
#: Every command topic (the motor torque, N·m): plain; the message ros2_control's forward command
#: controller receives on <controller>/commands; what ros2_control's topic-based hardware interface
#: (and Isaac Sim) publishes as joint commands.
COMMAND_INPUTS = (
    InputSpec("motor_torque", Float64, lambda msg, joint: ((msg.data,), None)),
    InputSpec("effort_commands", Float64MultiArray, lambda msg, joint: (tuple(msg.data), None)),
    InputSpec("joint_command", JointState,
              lambda msg, joint: joint_effort(msg.name, len(msg.position), len(msg.velocity), msg.effort, joint),
              stamped=True),
    # the voltage command of a finger with a drive (V; finger_sim.runtime.drive_commands)
    InputSpec("motor_voltage", Float64, lambda msg, joint: ((msg.data,), None), driven_only=True),
)


@dataclass(frozen=True)
class Endpoint:
    """A created publisher or subscription, its resolved topic and type, and whether it is logged;
    send: a publisher's CDR bytes out as they are (`raw_sender`), None for a subscription."""

    handle: Any
    topic: str
    msg_type: type
    recorded: bool
    acked: bool = False
    send: Callable[[bytes], None] | None = None


def raw_sender(publisher: Any) -> Callable[[bytes], None]:
    """Publish CDR bytes through `publisher` (an rclpy Publisher) as rclpy's publish(bytes) does,
    without its per-call type checks and use guard: the C publisher's publish_raw itself. The
    guard (which defers a concurrent destroy) is the caller's to hold: a stepping node's stepping
    thread holds every publisher's for its whole run (finger_sim.ros.node), instead of entering
    and leaving it around each message (two calls, about a third of a paced message's cost)."""
    return publisher.handle.publish_raw
