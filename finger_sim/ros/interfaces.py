"""finger_node's topics as tables: a new topic is one entry here.

Publishers, command subscriptions, the log's channels and the acknowledgement wait at a
clean exit are all made from OUTPUTS and COMMAND_INPUTS, so a topic cannot be published
without being registered in the log (no KeyError in the stepping loop).

QoS: state and log topics are reliable, volatile; /clock is rclcpp::ClockQoS(). Commands use
rclcpp::SystemDefaultsQoS() as ros2_control's forward command controller does (with Fast DDS:
best effort, keep last 1, so a flood loses commands in DDS; any publisher's QoS matches it),
or with command_qos 'reliable' a reliable keep-last-command_depth queue that loses none.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
from geometry_msgs.msg import PoseStamped
from rclpy.qos import QoSProfile, ReliabilityPolicy, qos_profile_system_default
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import JointState
from std_msgs.msg import Float64, Float64MultiArray
from visualization_msgs.msg import MarkerArray

from finger_sim.runtime.parameters import CommandQos, NodeSettings

#: History depth of the state and log publishers (reliable, volatile).
STATE_DEPTH = 10
EVENT_DEPTH = 100
#: rclcpp::ClockQoS(): best effort, keep last 1, as rclpy's TimeSource and rosbag2 subscribe.
CLOCK_QOS = QoSProfile(depth=1, reliability=ReliabilityPolicy.BEST_EFFORT)
STATE_QOS = QoSProfile(depth=STATE_DEPTH)
EVENT_QOS = QoSProfile(depth=EVENT_DEPTH)
#: rclcpp::SystemDefaultsQoS(), what ros2_control's forward command controller subscribes with.
COMMAND_QOS = qos_profile_system_default


def command_qos(settings: NodeSettings) -> QoSProfile:
    """The command subscriptions' QoS: the system default, or reliable keep-last command_depth."""
    if settings.command_qos is CommandQos.RELIABLE:
        return QoSProfile(depth=settings.command_depth, reliability=ReliabilityPolicy.RELIABLE)
    return COMMAND_QOS


def _always(settings: NodeSettings) -> bool:
    return True


@dataclass(frozen=True)
class OutputSpec:
    """A published topic: name (relative names go into the node's namespace), type, QoS; recorded:
    also written to the log; acked: a clean exit waits for reliable subscribers to acknowledge it;
    enabled: whether the settings want it at all."""

    topic: str
    msg_type: type
    qos: QoSProfile
    recorded: bool = True
    acked: bool = False
    enabled: Callable[[NodeSettings], bool] = _always


@dataclass(frozen=True)
class InputSpec:
    """A command topic: its message → the command's values (one element: a torque, N·m)."""

    topic: str
    msg_type: type
    values: Callable[[Any], tuple[float, ...]]
    recorded: bool = True


#: Every topic the node publishes, by the key the node publishes it under.
OUTPUTS: dict[str, OutputSpec] = {
    "clock": OutputSpec("/clock", Clock, CLOCK_QOS, enabled=lambda s: s.publish_clock),
    "joint_states": OutputSpec("joint_states", JointState, STATE_QOS, acked=True),
    "fingertip_pose": OutputSpec("fingertip_pose", PoseStamped, STATE_QOS, acked=True),
    "markers": OutputSpec("finger_markers", MarkerArray, STATE_QOS, enabled=lambda s: s.marker_rate_hz > 0),
    "diagnostics": OutputSpec("/diagnostics", DiagnosticArray, STATE_QOS, acked=True),
    "command_log": OutputSpec("~/command_log", DiagnosticStatus, EVENT_QOS, acked=True),
}
#: Every command topic (the motor torque, N·m; the second is ros2_control's forward-command convention).
COMMAND_INPUTS = (
    InputSpec("motor_torque", Float64, lambda msg: (msg.data,)),
    InputSpec("effort_commands", Float64MultiArray, lambda msg: tuple(msg.data)),
)


@dataclass(frozen=True)
class Endpoint:
    """A created publisher or subscription, its resolved topic and type, and whether it is logged."""

    handle: Any
    topic: str
    msg_type: type
    recorded: bool
    acked: bool = False
