"""The arguments of `finger-sim node ...` (the command itself: finger_sim.ros.node_command).

Here, apart from the command, so that finger-sim's parser is built without importing ROS.
"""

from __future__ import annotations

import argparse
from collections.abc import Callable
from typing import Any

DEFAULT_NODE = "/finger_node"
DEFAULT_TIMEOUT_S = 10.0


def add_parser(sub: Any, handler: Callable[[argparse.Namespace], int]) -> None:
    """The `node` subcommand on finger-sim's subparsers, run by `handler`."""
    node = sub.add_parser("node", help="talk to a running finger_node or finger_hand (torque, voltage, pause, resume, step, "
                                       "reset, get/set a parameter, echo a topic) without ros2cli")
    node.add_argument("--node", default=DEFAULT_NODE, metavar="NAME",
                      help=f"the node's full name (default {DEFAULT_NODE}; /finger_hand for a hand)")
    node.add_argument("--finger", default="", metavar="NAME", help="a hand's finger, for torque and voltage (/NAME/motor_torque)")
    node.add_argument("--timeout", type=float, default=DEFAULT_TIMEOUT_S, metavar="S",
                      help=f"wall seconds to wait for the node (default {DEFAULT_TIMEOUT_S:g})")
    actions = node.add_subparsers(dest="action", required=True)
    torque = actions.add_parser("torque", help="hold this motor torque, N·m (motor_torque)")
    torque.add_argument("value", type=float)
    voltage = actions.add_parser("voltage", help="hold this motor voltage, V, on a scene with a drive (motor_voltage)")
    voltage.add_argument("value", type=float)
    pub = actions.add_parser("pub", help="publish one std_msgs/Float64 on a topic, e.g. /grip_setpoint 0.5")
    pub.add_argument("topic")
    pub.add_argument("value", type=float)
    actions.add_parser("pause", help="pause stepping (~/pause true)")
    actions.add_parser("resume", help="resume stepping (~/pause false)")
    step = actions.add_parser("step", help="advance a paused node: ~/step N times (default 1)")
    step.add_argument("n", type=positive_int, nargs="?", default=1)
    actions.add_parser("reset", help="back to the scene's initial state (~/reset)")
    get = actions.add_parser("get", help="print a parameter's value")
    get.add_argument("param")
    put = actions.add_parser("set", help="set a run-time parameter (VALUE read as YAML)")
    put.add_argument("param")
    put.add_argument("value")
    echo = actions.add_parser("echo", help="print a topic's messages as YAML documents")
    echo.add_argument("topic")
    echo.add_argument("-n", "--count", type=positive_int, metavar="N", help="stop after N messages (default: Ctrl-C)")
    node.set_defaults(func=handler)


def positive_int(text: str) -> int:
    """argparse type: an integer > 0, else a one-line usage error naming what came."""
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected an integer > 0, got {text!r}") from None
    if value <= 0:
        raise argparse.ArgumentTypeError(f"expected an integer > 0, got {value}")
    return value
