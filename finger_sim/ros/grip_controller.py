"""`finger_grip_controller`: closes the finger on an object and holds a grip force (an example node).

Subscribes `grip_force` (std_msgs/Float64, N, from finger_node on a scene with objects) and
`grip_setpoint` (std_msgs/Float64, N); publishes `motor_torque` (std_msgs/Float64, N·m) once for
every grip_force sample it receives. The law is finger_sim.runtime.grip (ROS-free, tested
without DDS): a setpoint > 0 closes the finger with `closing_torque` until contact, then a PI
law with anti-windup holds grip_force at the setpoint; a setpoint of 0 opens it (a small
backward torque for `opening_time`, then 0). Defaults tuned on the `grasp_cylinder` scene.

Event-driven, no timer: each torque answers the newest sample (keep-last-1 subscription). The
law advances by the sim time between two samples, read from /clock (so a sample lost under load
does not slow the integral down); without /clock, by `sample_period` per sample.

    ros2 run finger_sim finger_node --ros-args -p scene:=grasp_cylinder -p max_torque:=0.1
    ros2 run finger_sim finger_grip_controller
    ros2 topic pub --once /grip_setpoint std_msgs/msg/Float64 "{data: 0.5}"
"""

from __future__ import annotations

import sys

from rclpy.node import Node
from rclpy.qos import QoSProfile, ReliabilityPolicy
from rosgraph_msgs.msg import Clock
from std_msgs.msg import Float64

from finger_sim.effects.contact_outputs import GRIP_FORCE
from finger_sim.ros import parameters
from finger_sim.ros.controller_main import AnswerPublisher, spin_controller
from finger_sim.runtime.grip import GRIP_PARAMETERS, GripController, GripSettings

NODE_NAME = "finger_grip_controller"
#: Newest sample only: a controller answers the latest grip force, not a backlog.
SENSOR_QOS = QoSProfile(depth=1)
COMMAND_QOS = QoSProfile(depth=10)
#: rclcpp::ClockQoS(), as finger_node publishes /clock.
CLOCK_QOS = QoSProfile(depth=1, reliability=ReliabilityPolicy.BEST_EFFORT)
NS_PER_S = 1_000_000_000
#: Minimum wall time between two warnings about refused setpoints, s.
WARN_THROTTLE_S = 1.0


class GripControllerNode(Node):
    def __init__(self, **kwargs) -> None:
        super().__init__(NODE_NAME, **kwargs)
        self.settings = s = GripSettings.from_values(parameters.declare(self, GRIP_PARAMETERS))
        self.law = GripController(s)
        self._clock_ns: int | None = None  # the newest /clock, ns
        self._sampled_ns: int | None = None  # /clock at the last sample, ns
        self._pub = AnswerPublisher(self.create_publisher(Float64, "motor_torque", COMMAND_QOS))
        # the setpoint first: rclpy's executor serves ready subscriptions in creation order, so a
        # setpoint and a sample waiting together are taken setpoint first (the task runner's order)
        self.create_subscription(Float64, "grip_setpoint", self._on_setpoint, COMMAND_QOS)
        self.create_subscription(Float64, GRIP_FORCE.topic, self._on_grip_force, SENSOR_QOS)
        self.create_subscription(Clock, "/clock", self._on_clock, CLOCK_QOS)
        self.get_logger().info(
            f"grip-force PI: kp {s.kp:g} N·m/N, ki {s.ki:g} N·m/(N·s), |τ| ≤ {s.max_torque:g} N·m; closing "
            f"{s.closing_torque:g} N·m until {s.contact_threshold:g} N; setpoint {s.setpoint:g} N")

    def _on_setpoint(self, msg: Float64) -> None:
        try:
            self.law.set_setpoint(msg.data)
        except ValueError as exc:
            self.get_logger().warning(f"ignored: {exc}", throttle_duration_sec=WARN_THROTTLE_S)

    def _on_clock(self, msg: Clock) -> None:
        self._clock_ns = msg.clock.sec * NS_PER_S + msg.clock.nanosec

    def _on_grip_force(self, msg: Float64) -> None:
        now = self._clock_ns
        if now is None:
            dt = self.settings.sample_period
        else:  # 0 when /clock has not moved on since the last sample: the sum over samples stays exact
            dt = max(now - (self._sampled_ns if self._sampled_ns is not None else now), 0) / NS_PER_S
            self._sampled_ns = now
        self._pub.publish(Float64(data=self.law.update(msg.data, dt)))


def main(args: list[str] | None = None) -> int:
    return spin_controller(GripControllerNode, NODE_NAME, args)


if __name__ == "__main__":
    sys.exit(main())
