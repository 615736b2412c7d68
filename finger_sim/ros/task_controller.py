"""`finger_task_controller`: any Python task controller (`module:callable`) as a ROS 2 controller node.

The controller is a factory of finger_sim.tasks.controllers' shape, `factory(sample_period,
**params) -> control(t, setpoint, measured)`, named by the `controller` parameter; every other
parameter given on the command line (a number) is passed to the factory as a keyword. The node
subscribes `grip_force` (std_msgs/Float64, N) and `grip_setpoint` (std_msgs/Float64, N) and,
once for every grip_force sample, publishes the controller's answer on `motor_torque` (N·m), or
on `motor_voltage` (V) when the factory commands a voltage (`factory.input == "voltage"`, a drive
scene). Sample k is taken at t = k·sample_period (s): the node counts samples, as the offline task
runner's clock does, and the controller measures `grip_force` only.

    finger-sim tasks config/tasks/hold_voltage_off.yaml --ros-controller ros=finger_sim.tasks.controllers:grip_voltage
"""

from __future__ import annotations

import sys
from typing import Any

from rclpy.node import Node
from rclpy.qos import QoSProfile
from std_msgs.msg import Float64

from finger_sim.effects.contact_outputs import GRIP_FORCE
from finger_sim.errors import ConfigError, shown
from finger_sim.ros.controller_main import AnswerPublisher, spin_controller
from finger_sim.runtime.parameters import ParameterError
from finger_sim.tasks.controllers import commanded_input, load_factory

NODE_NAME = "finger_task_controller"
#: Newest sample only: a controller answers the latest grip force, not a backlog.
SENSOR_QOS = QoSProfile(depth=1)
COMMAND_QOS = QoSProfile(depth=10)
#: The node's own parameters and rclpy's; any other is the controller's.
OWN = ("controller", "setpoint", "sample_period", "use_sim_time", "start_type_description_service")
#: The command topic of each scene input.
TOPICS = {"torque": "motor_torque", "voltage": "motor_voltage"}


class TaskControllerNode(Node):
    def __init__(self, **kwargs: Any) -> None:
        super().__init__(NODE_NAME, allow_undeclared_parameters=True,
                         automatically_declare_parameters_from_overrides=True, **kwargs)
        values = {name: p.value for name, p in self._parameters.items()}
        try:
            spec = values.get("controller")
            if not isinstance(spec, str):
                raise ConfigError("parameter controller", "module:callable of a task controller factory", spec)
            try:
                factory = load_factory(spec)
            except ConfigError as exc:  # load_factory names the command-line option
                raise ConfigError("parameter controller", exc.allowed, exc.got) from None
            self.sample_period = _number(values.get("sample_period", 0.001), "sample_period")
            self.setpoint = _number(values.get("setpoint", 0.0), "setpoint")
            params = {k: _number(v, k) for k, v in values.items() if k not in OWN}
            self.control = factory(self.sample_period, **params)
        except ConfigError as exc:
            raise ParameterError(exc.key.removeprefix("parameter "), f"expected {exc.allowed}, got {shown(exc.got)}") from None
        self.samples = 0
        topic = TOPICS[commanded_input(factory)]
        self._pub = AnswerPublisher(self.create_publisher(Float64, topic, COMMAND_QOS))
        # the setpoint first: rclpy's executor serves ready subscriptions in creation order, so a
        # setpoint and a sample waiting together are taken setpoint first (the task runner's order)
        self.create_subscription(Float64, "grip_setpoint", self._on_setpoint, COMMAND_QOS)
        self.create_subscription(Float64, GRIP_FORCE.topic, self._on_grip_force, SENSOR_QOS)
        self.get_logger().info(f"{spec} ({params}) every {self.sample_period:g} s, answering on {topic}")

    def _on_setpoint(self, msg: Float64) -> None:
        self.setpoint = msg.data

    def _on_grip_force(self, msg: Float64) -> None:
        t = self.samples * self.sample_period
        self.samples += 1
        self._pub.publish(Float64(data=float(self.control(t, self.setpoint, {GRIP_FORCE.name: msg.data}))))


def _number(value: Any, key: str) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise ConfigError(f"parameter {key}", "a number", value)
    return float(value)


def main(args: list[str] | None = None) -> int:
    return spin_controller(TaskControllerNode, NODE_NAME, args)


if __name__ == "__main__":
    sys.exit(main())
