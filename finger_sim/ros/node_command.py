"""`finger-sim node ...`: talk to a running finger_node or finger_hand through rclpy, where ros2cli is absent.

    finger-sim node torque 0.01          # motor_torque (std_msgs/Float64), like `ros2 topic pub --once`
    finger-sim node voltage 3            # motor_voltage (std_msgs/Float64, V) of a scene with a drive (spec §8)
    finger-sim node pub TOPIC 0.5        # one std_msgs/Float64 on any topic (e.g. /grip_setpoint)
    finger-sim node pause | resume       # ~/pause (std_srvs/SetBool)
    finger-sim node step [N]             # ~/step N times (each advances steps_per_trigger steps)
    finger-sim node reset                # ~/reset (std_srvs/Trigger)
    finger-sim node get PARAM            # like `ros2 param get`
    finger-sim node set PARAM VALUE      # like `ros2 param set`: VALUE is read as YAML (2 int, 2.0 float, true bool)
    finger-sim node echo TOPIC [-n N]    # like `ros2 topic echo`: each message a YAML document

`--node NAME` (default /finger_node; /finger_hand for a hand) names the node; `--finger NAME`
sends a hand's finger its torque (/NAME/motor_torque) or voltage. The command joins the ROS graph as any
ROS process does (ROS_DOMAIN_ID, ROS_AUTOMATIC_DISCOVERY_RANGE), uses only the node's standard
interfaces, so it works beside ros2cli, and waits at most --timeout wall seconds for the node.

A torque (or voltage) is published until the node counts it: its /diagnostics (about 1 Hz) report one more
command received. The command topic is best effort (ros2_control's system default), and a
message sent just after discovery can be lost; counting it is the only proof it arrived.
Errors are one line (exit status 2); Ctrl-C ends `echo` with status 0.
"""

from __future__ import annotations

import argparse
import array
import os
import sys
import time
from collections.abc import Callable
from typing import Any

import yaml

from finger_sim.errors import FingerSimError

SPIN_SLICE_S = 0.05  # wall s of one executor turn while waiting
#: Wall s without the node counting a torque before it is sent again (diagnostics come at about 1 Hz).
RESEND_S = 2.5
ECHO_DEPTH = 100
#: Wall s `pub` stays after publishing, for best-effort subscribers (which acknowledge nothing).
LINGER_S = 0.25
#: Wall s `pub` waits between its publisher's match and the message (the subscribers' side of the match).
MATCH_SETTLE_S = 0.25


class NodeCommandError(FingerSimError):
    """The node did not answer, or refused what was asked."""


def run(args: argparse.Namespace) -> int:
    """Run one action against the node; NodeCommandError for no answer or a refusal."""
    from rclpy.executors import ExternalShutdownException

    client = _Client(args.timeout)
    try:
        return ACTIONS[args.action](client, args)
    except (KeyboardInterrupt, ExternalShutdownException):
        return 0
    finally:
        client.close()


class _Client:
    """A private rclpy context and node, spun only while waiting."""

    def __init__(self, timeout_s: float) -> None:
        import rclpy
        from rclpy.executors import SingleThreadedExecutor

        self.timeout_s = timeout_s
        self.context = rclpy.Context()
        rclpy.init(context=self.context)
        self.node = rclpy.create_node(f"finger_sim_cli_{os.getpid()}", context=self.context,
                                      start_parameter_services=False)
        self.executor = SingleThreadedExecutor(context=self.context)
        self.executor.add_node(self.node)

    def wait_for(self, condition: Callable[[], Any], what: str, timeout_s: float | None = None) -> Any:
        """condition()'s first truthy value, spinning meanwhile; NodeCommandError at the deadline."""
        deadline = time.monotonic() + (self.timeout_s if timeout_s is None else timeout_s)
        while not (value := condition()):
            if time.monotonic() > deadline:
                if timeout_s is not None:
                    return value
                domain = os.environ.get("ROS_DOMAIN_ID", "0")
                raise NodeCommandError(f"no {what} within {self.timeout_s:g} s (is the node running, in "
                                       f"ROS_DOMAIN_ID={domain}?)")
            self.executor.spin_once(timeout_sec=SPIN_SLICE_S)
        return value

    def call(self, srv_type: type, name: str, request: Any) -> Any:
        client = self.node.create_client(srv_type, name)
        try:
            self.wait_for(client.service_is_ready, f"service {name}")
            future = client.call_async(request)
            self.wait_for(future.done, f"answer from {name}")
            return future.result()
        finally:
            self.node.destroy_client(client)

    def close(self) -> None:
        import rclpy

        self.executor.shutdown()
        self.node.destroy_node()
        rclpy.try_shutdown(context=self.context)


# -- actions ---------------------------------------------------------------------------------
def _service(args: argparse.Namespace, name: str) -> str:
    return f"{args.node.rstrip('/')}/{name}"


def _trigger(client: _Client, args: argparse.Namespace, name: str, request: Any = None) -> str:
    from std_srvs.srv import SetBool, Trigger

    srv = SetBool if request is not None else Trigger
    answer = client.call(srv, _service(args, name), request if request is not None else Trigger.Request())
    if not answer.success:
        raise NodeCommandError(f"{_service(args, name)} refused: {answer.message}")
    return answer.message


def _pause(client: _Client, args: argparse.Namespace) -> int:
    from std_srvs.srv import SetBool

    print(_trigger(client, args, "pause", SetBool.Request(data=args.action == "pause")))
    return 0


def _step(client: _Client, args: argparse.Namespace) -> int:
    message = ""
    for _ in range(args.n):
        message = _trigger(client, args, "step")
    print(message)
    return 0


def _reset(client: _Client, args: argparse.Namespace) -> int:
    print(_trigger(client, args, "reset"))
    return 0


#: action → (command topic, what it is, unit): a finger's held command (std_msgs/Float64)
COMMAND_TOPICS = {"torque": ("motor_torque", "motor torque", "N·m"), "voltage": ("motor_voltage", "motor voltage", "V")}


def _command(client: _Client, args: argparse.Namespace) -> int:
    """The torque (motor_torque) or, for a finger with a drive, the voltage (motor_voltage), sent
    until the node counts it."""
    from diagnostic_msgs.msg import DiagnosticArray
    from rclpy.qos import QoSProfile, ReliabilityPolicy
    from std_msgs.msg import Float64

    leaf, what, unit = COMMAND_TOPICS[args.action]
    namespace = args.node.rstrip("/").rsplit("/", 1)[0]
    topic = f"{namespace}/{args.finger + '/' if args.finger else ''}{leaf}"
    status = f"{args.node.rstrip('/')}: {args.finger + ' ' if args.finger else ''}simulation"
    counts: list[int] = []

    def on_diagnostics(msg: DiagnosticArray) -> None:
        for s in msg.status:
            if s.name == status:
                counts.append(int(next(kv.value for kv in s.values if kv.key == "commands_received")))

    client.node.create_subscription(DiagnosticArray, "/diagnostics", on_diagnostics, 10)
    publisher = client.node.create_publisher(Float64, topic, QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE))
    client.wait_for(publisher.get_subscription_count, f"subscriber on {topic}")
    client.wait_for(lambda: counts, f"/diagnostics status '{status}'")
    before = counts[-1]
    deadline = time.monotonic() + client.timeout_s
    while time.monotonic() < deadline:
        publisher.publish(Float64(data=args.value))
        if client.wait_for(lambda: counts[-1] > before, "", timeout_s=min(RESEND_S, deadline - time.monotonic())):
            print(f"{what} {args.value!r} {unit} sent to {topic} (the node counts {counts[-1]} commands received)")
            return 0
    raise NodeCommandError(f"{args.node} did not count the {what} on {topic} within {client.timeout_s:g} s")


def _pub(client: _Client, args: argparse.Namespace) -> int:
    """One std_msgs/Float64 on TOPIC, reliable, once every subscriber has matched and acknowledged."""
    from rclpy.duration import Duration
    from rclpy.qos import QoSProfile, ReliabilityPolicy
    from std_msgs.msg import Float64

    publisher = client.node.create_publisher(Float64, args.topic, QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE))

    def all_matched() -> int:
        """The matched subscriptions once every one the graph knows of has matched (not only the first); else 0."""
        matched = publisher.get_subscription_count()
        return matched if matched >= max(1, client.node.count_subscribers(args.topic)) else 0

    subscribers = client.wait_for(all_matched, f"subscriber on {args.topic}")
    # a moment for the subscribers' side of the match, without which a best-effort reader drops the message
    client.wait_for(lambda: False, "", timeout_s=MATCH_SETTLE_S)
    publisher.publish(Float64(data=args.value))
    if not publisher.wait_for_all_acked(Duration(seconds=client.timeout_s)):
        raise NodeCommandError(f"the subscribers of {args.topic} did not acknowledge within {client.timeout_s:g} s")
    time.sleep(LINGER_S)  # a best-effort subscriber acknowledges nothing: give it the message's way there
    print(f"published {args.value!r} on {args.topic} ({subscribers} subscribers)")
    return 0


def _get(client: _Client, args: argparse.Namespace) -> int:
    print(f"{args.param} = {_read_parameter(client, args)!r}")
    return 0


def _read_parameter(client: _Client, args: argparse.Namespace) -> Any:
    from rcl_interfaces.srv import GetParameters
    from rclpy.parameter import parameter_value_to_python

    answer = client.call(GetParameters, _service(args, "get_parameters"), GetParameters.Request(names=[args.param]))
    value = answer.values[0] if answer.values else None
    if value is None or value.type == 0:  # PARAMETER_NOT_SET
        raise NodeCommandError(f"{args.node} has no parameter {args.param!r}")
    return parameter_value_to_python(value)


def _set(client: _Client, args: argparse.Namespace) -> int:
    from rcl_interfaces.msg import Parameter as ParameterMsg
    from rcl_interfaces.srv import SetParameters
    from rclpy.parameter import Parameter

    try:
        value = yaml.safe_load(args.value)
    except yaml.YAMLError:
        value = args.value
    if not isinstance(value, (bool, int, float, str)):
        value = args.value
    msg = ParameterMsg(name=args.param, value=Parameter(args.param, value=value).get_parameter_value())
    answer = client.call(SetParameters, _service(args, "set_parameters"), SetParameters.Request(parameters=[msg]))
    result = answer.results[0]
    if not result.successful:
        raise NodeCommandError(f"{args.node} refused {args.param} = {args.value}: {result.reason}")
    print(f"{args.param} = {_read_parameter(client, args)!r}")
    return 0


def _echo(client: _Client, args: argparse.Namespace) -> int:
    from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy

    from finger_sim.ros.replay import message_class

    topic = args.topic
    infos = client.wait_for(lambda: client.node.get_publishers_info_by_topic(topic), f"publisher on {topic}")
    types = {i.topic_type for i in infos}
    if len(types) != 1:
        raise NodeCommandError(f"{topic} is published with several types: {sorted(types)}")
    offered = [i.qos_profile for i in infos]
    qos = QoSProfile(
        depth=ECHO_DEPTH,
        reliability=ReliabilityPolicy.RELIABLE if all(q.reliability == ReliabilityPolicy.RELIABLE for q in offered)
        else ReliabilityPolicy.BEST_EFFORT,
        durability=DurabilityPolicy.TRANSIENT_LOCAL if all(q.durability == DurabilityPolicy.TRANSIENT_LOCAL for q in offered)
        else DurabilityPolicy.VOLATILE)
    printed = [0]

    def on_message(msg: Any) -> None:
        if args.count is None or printed[0] < args.count:
            sys.stdout.write(yaml.safe_dump(plain(msg), sort_keys=False, allow_unicode=True) + "---\n")
            sys.stdout.flush()
            printed[0] += 1

    client.node.create_subscription(message_class(topic, types.pop()), topic, on_message, qos)
    while args.count is None or printed[0] < args.count:
        client.executor.spin_once(timeout_sec=SPIN_SLICE_S)
    return 0


def plain(value: Any) -> Any:
    """A ROS message as nested dicts and lists of Python values (what `ros2 topic echo` prints)."""
    if hasattr(value, "get_fields_and_field_types"):
        return {name: plain(getattr(value, name)) for name in value.get_fields_and_field_types()}
    if hasattr(value, "tolist"):  # numpy arrays and scalars (fixed-size array fields)
        return value.tolist()
    if isinstance(value, (list, tuple, array.array)):
        return [plain(v) for v in value]
    if isinstance(value, bytes):
        return list(value)
    return value


ACTIONS: dict[str, Callable[[_Client, argparse.Namespace], int]] = {
    "torque": _command, "voltage": _command, "pub": _pub, "pause": _pause, "resume": _pause, "step": _step, "reset": _reset,
    "get": _get, "set": _set, "echo": _echo,
}
