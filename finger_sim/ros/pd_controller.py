"""`finger_pd_controller`: PD control of the MCP angle — how a controller drives the simulated finger.

Subscribes `joint_states` (sensor_msgs/JointState, from finger_node) and `mcp_setpoint`
(std_msgs/Float64, rad, the spec §6 `mcp_joint` position: 0 at extension, flexion positive);
publishes `motor_torque` (std_msgs/Float64, N·m) once for every joint state it receives:

    τ = clamp(kp·(θ* − θ) − kd·θ', ±max_torque)

Event-driven, no timer: the loop closes at the node's publish rate whatever its
realtime_factor, and each torque answers the newest state (keep-last-1 subscription).
The derivative acts on the measured rate, not on the error, so a setpoint step gives no kick.

The PIP spring pulls the finger back, so PD settles slightly short of θ*: where
kp·(θ* − θ) = kβ·dβ/dθ1 (5 mrad short at θ* = 0.8 rad with the defaults).

Run it beside the node (same namespace), then command a setpoint:

    ros2 run finger_sim finger_node
    ros2 run finger_sim finger_pd_controller --ros-args -p setpoint:=0.8
    ros2 topic pub --once /mcp_setpoint std_msgs/msg/Float64 "{data: 1.2}"
"""

from __future__ import annotations

import math
import sys

from rclpy.node import Node
from rclpy.qos import QoSProfile
from sensor_msgs.msg import JointState
from std_msgs.msg import Float64

from finger_sim.ros import parameters
from finger_sim.ros.controller_main import AnswerPublisher, spin_controller
from finger_sim.runtime.parameters import Param

NODE_NAME = "finger_pd_controller"
#: Defaults: critically damped-ish on the paper's finger (no overshoot, |θ − θ_eq| < 5 mrad
#: within 0.25 s of a 0.8 rad step with up to 10 ms of loop delay; see test_pd_controller).
KP = 0.2  # N·m/rad
KD = 0.01  # N·m·s/rad
MAX_TORQUE = 0.05  # N·m, as finger_node's default saturation
#: Newest state only: a controller should answer the latest state, not work off a backlog.
STATE_QOS = QoSProfile(depth=1)
COMMAND_QOS = QoSProfile(depth=10)


#: The controller's parameters (read once at start).
PARAMETERS = (
    Param("kp", KP, "proportional gain, N·m/rad", (0.0, 100.0)),
    Param("kd", KD, "derivative gain on the measured rate, N·m·s/rad", (0.0, 100.0)),
    Param("setpoint", 0.0, "initial MCP setpoint, rad (then the mcp_setpoint topic)", (-math.pi, math.pi)),
    Param("max_torque", MAX_TORQUE, "output saturation, N·m", (0.0, 100.0)),
    Param("joint", "mcp_joint", "the controlled joint's name in joint_states (with the node's frame_prefix)"),
)


def pd_torque(setpoint: float, position: float, velocity: float, kp: float, kd: float, limit: float) -> float:
    """τ = clamp(kp (setpoint − position) − kd velocity, ±limit), N·m (rad, rad/s in)."""
    tau = kp * (setpoint - position) - kd * velocity
    return min(max(tau, -limit), limit)


class PdController(Node):
    def __init__(self, **kwargs) -> None:
        super().__init__(NODE_NAME, **kwargs)
        values = parameters.declare(self, PARAMETERS)
        self.kp, self.kd, self.setpoint = values["kp"], values["kd"], values["setpoint"]
        self.max_torque, self.joint = values["max_torque"], values["joint"]
        self._index: int | None = None
        self._warned = False
        self._pub = AnswerPublisher(self.create_publisher(Float64, "motor_torque", COMMAND_QOS))
        self.create_subscription(JointState, "joint_states", self._on_state, STATE_QOS)
        self.create_subscription(Float64, "mcp_setpoint", self._on_setpoint, COMMAND_QOS)
        self.get_logger().info(f"PD on {self.joint}: kp {self.kp:g} N·m/rad, kd {self.kd:g} N·m·s/rad, "
                               f"|τ| ≤ {self.max_torque:g} N·m, setpoint {self.setpoint:g} rad")

    def _on_setpoint(self, msg: Float64) -> None:
        if math.isfinite(msg.data):
            self.setpoint = msg.data
        else:
            self.get_logger().warning(f"ignored a non-finite setpoint {msg.data!r}", throttle_duration_sec=1.0)

    def _on_state(self, msg: JointState) -> None:
        i = self._index
        if i is None or i >= len(msg.name) or msg.name[i] != self.joint:
            try:
                i = self._index = list(msg.name).index(self.joint)
            except ValueError:
                if not self._warned:
                    self.get_logger().warning(f"joint_states has no joint '{self.joint}' (got {list(msg.name)})")
                    self._warned = True
                return
        tau = pd_torque(self.setpoint, msg.position[i], msg.velocity[i], self.kp, self.kd, self.max_torque)
        self._pub.publish(Float64(data=tau))


def main(args: list[str] | None = None) -> int:
    return spin_controller(PdController, NODE_NAME, args)


if __name__ == "__main__":
    sys.exit(main())
