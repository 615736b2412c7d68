"""`finger_replay LOG.mcap`: republish a log's topics with their recorded timing, like `ros2 bag play`.

For machines without rosbag2. Usage (`finger_replay --help` for the details):

    finger_replay LOG.mcap [--rate R] [--loop] [--topics T [T ...]] [--start-offset S]
                  [--clock [HZ] | --no-clock] [--delay S] [--wait-for-subscribers S]
                  [--wait-for-all-acked S] [--ros-args ...]

Messages: the recorded CDR bytes are published as they are, through rclpy's
`Publisher.publish(bytes)` (rmw_publish_serialized_message), which is what `ros2 bag play`
does. There is no decode and re-encode: subscribers receive exactly the recorded bytes, every
message type in the installed packages works without per-field conversion code, and a message
costs one C call. A publisher's class comes from the schema name ('sensor_msgs/msg/JointState'
→ `sensor_msgs.msg.JointState`; rosidl_runtime_py is not in the PyPI wheels). The bytes are only
read right if the installed definition is the recorded one, so a topic whose recorded schema
text differs from the installed `.msg` files gets a warning.

Clock: exactly one source of /clock, so that `use_sim_time` nodes never see two interleaved
time lines. By default a recorded /clock topic (the node publishes and logs its own) is
replayed like any other topic: it carries the node's sim time exactly. `--clock [HZ]`
publishes a /clock generated from the log time at HZ wall hertz instead (the recorded /clock
is then not replayed); a log without /clock gets a generated one at DEFAULT_CLOCK_HZ. A
generated tick carries the log time of its wall time, never later than the next message to be
published, and the last message's time ends each pass. `--no-clock` publishes no /clock.
`--topics` selects data topics only: /clock follows these clock options. With `--loop` the
clock jumps back at each pass, as with `ros2 bag play --loop`.

Timing: message i is due at t0 + (log_time_i − origin) / rate on time.monotonic(), where origin
is the log's first log time plus `--start-offset` and t0 the start of the pass. The player
sleeps until each due time (in slices of at most WAIT_SLICE_S, so that a signal delivered to
a DDS thread is acted on promptly), never spins, and publishes late messages at once, so a
slow stretch does not accumulate delay. Messages come in log-time order (mcap's indexed
reader); a truncated log is read in file order, which is recording order. A reader thread
decompresses chunks ahead of the player (ReadAhead), so that reading a chunk does not delay
the messages due meanwhile. docs/replay_performance.md has measured figures.
The plan, the read-ahead and the statistics are ROS-free: finger_sim.log.playback.

QoS: each topic is offered with the reliability and durability its publishers offered when
recorded (the channel's `offered_qos_profiles`, finger_sim.log.qos), as `ros2 bag play` does:
reliable if every recorded publisher was, else best effort; transient local (latched, e.g.
robot_description, which RViz's RobotModel subscribes to transient local) if every one was,
with the largest recorded depth, else volatile; a mix is warned about. Volatile data topics
keep the last QOS_DEPTH (bursts and slow subscribers are absorbed without blocking the
player); a topic recorded without QoS is reliable and volatile. /clock: best effort,
keep-last 1 (rclcpp's ClockQoS, what rosbag2's player and rclpy's TimeSource use).

Delivery: volatile topics reach only subscribers that are matched when a message goes out, so
`--wait-for-subscribers S` holds the start until every publisher has one (or S passes), and
`--delay S` adds a pause as `ros2 bag play --delay` does. After the last message the writers
stay LINGER_S, so that subscribers take the tail before the participant leaves. Otherwise the
last messages can be lost, as in ros2/rosbag2#571. `--wait-for-all-acked S` waits until reliable
subscribers acknowledge everything. With Fast DDS that takes up to its 3 s heartbeat period.

Exit status: 0 replayed to the end, or stopped by SIGINT/SIGTERM; 1 the log cannot be read, or
only in part (a truncated log's intact prefix is replayed after a warning, then exit 1); 2 bad
arguments. Errors are one line on stderr; the summary line goes to stdout.
"""

from __future__ import annotations

import argparse
import functools
import importlib
import math
import signal
import sys
import threading
import time
from collections.abc import Callable, Iterable, Sequence
from pathlib import Path
from types import FrameType
from typing import Any

import rclpy
import yaml
from mcap.records import Channel, Schema
from rclpy.duration import Duration
from rclpy.node import Node
from rclpy.publisher import Publisher
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from rclpy.signals import SignalHandlerOptions
from rclpy.utilities import remove_ros_args

from finger_sim.errors import FingerSimError
from finger_sim.log import (
    LogArgumentError,
    LogError,
    LogReader,
    MessageDefinitionNotFoundError,
    MissingTopicsError,
    read_log,
)
from finger_sim.log.definitions import message_definition, normalize_type_name
from finger_sim.log.playback import (CLOCK_TOPIC, CLOCK_TYPE, DEFAULT_CLOCK_HZ, PROG, ClockSource, ReadAhead, ReplayPlan,
                                     ReplayStats, plan_replay, raw_messages)
from finger_sim.log.qos import OFFERED_QOS_PROFILES

QOS_DEPTH = 1000  # keep-last depth of data publishers: 1 s of a 1 kHz topic, 0.1 s of it at --rate 10
WAIT_SLICE_S = 0.1  # longest single sleep; a signal that lands on a DDS thread is seen after at most this
MATCH_POLL_S = 0.01  # poll period while waiting for subscribers (rclpy has no blocking wait for matches)
# After the last message the writers stay this long, so that subscribers take the tail out of shared
# memory before the participant goes (else the last messages can be lost: ros2/rosbag2#571).
LINGER_S = 0.25
# GIL hand-over interval while the reader thread runs: a player waking at a due time waits at most
# this long for the reader to let go (Python's default, 5 ms, would show up as lateness).
SWITCH_INTERVAL_S = 0.0002

EXIT_OK = 0
EXIT_LOG = 1  # the log cannot be read, or only in part
EXIT_USAGE = 2  # argparse's status for bad arguments

DATA_QOS = QoSProfile(
    history=HistoryPolicy.KEEP_LAST,
    depth=QOS_DEPTH,
    reliability=ReliabilityPolicy.RELIABLE,
    durability=DurabilityPolicy.VOLATILE,
)
CLOCK_QOS = QoSProfile(
    history=HistoryPolicy.KEEP_LAST,
    depth=1,
    reliability=ReliabilityPolicy.BEST_EFFORT,
    durability=DurabilityPolicy.VOLATILE,
)


class MessageTypeNotFoundError(FingerSimError, LookupError):
    """A topic's recorded type has no Python message class in this installation."""

    def __init__(self, topic: str, type_name: str, reason: str) -> None:
        self.topic, self.type_name = topic, type_name
        super().__init__(f"{topic}: cannot publish {type_name}: {reason}")


#: rmw's numbers for the policies, as Humble's rosbag2 writes them into offered_qos_profiles.
_RMW_RELIABILITY = {1: "reliable", 2: "best_effort"}
_RMW_DURABILITY = {1: "transient_local", 2: "volatile"}


def recorded_qos(channels: Iterable[dict[str, str]], default: QoSProfile) -> tuple[QoSProfile, str]:
    """The QoS to offer a topic with, from its channels' `offered_qos_profiles` (rosbag2's YAML),
    and a description of mixed recorded policies ('' when they agree).

    rosbag2's player rule: reliable only if every recorded publisher was, transient local only
    if every one was (then with the largest recorded depth). Without a readable record: `default`.
    """
    offers = []
    for metadata in channels:
        try:
            entries = yaml.safe_load(metadata.get(OFFERED_QOS_PROFILES, "") or "[]")
        except yaml.YAMLError:
            continue
        for entry in entries if isinstance(entries, list) else ():
            if isinstance(entry, dict):
                offers.append((_policy_name(entry.get("reliability"), _RMW_RELIABILITY),
                               _policy_name(entry.get("durability"), _RMW_DURABILITY), entry.get("depth")))
    offers = [o for o in offers if o[0] in ("reliable", "best_effort") and o[1] in ("volatile", "transient_local")]
    if not offers:
        return default, ""
    reliabilities, durabilities = {o[0] for o in offers}, {o[1] for o in offers}
    mixed = [", ".join(sorted(p)) for p in (reliabilities, durabilities) if len(p) > 1]
    latched = durabilities == {"transient_local"}
    depths = [d for _, _, d in offers if isinstance(d, int) and d > 0]
    return QoSProfile(
        history=HistoryPolicy.KEEP_LAST,
        depth=max(depths, default=1) if latched else default.depth,
        reliability=ReliabilityPolicy.RELIABLE if reliabilities == {"reliable"} else ReliabilityPolicy.BEST_EFFORT,
        durability=DurabilityPolicy.TRANSIENT_LOCAL if latched else DurabilityPolicy.VOLATILE,
    ), " and ".join(mixed)


def _policy_name(value: Any, numbers: dict[int, str]) -> str:
    """A policy as rmw's string ('reliable'), from Jazzy's string or Humble's number."""
    return numbers.get(value, "") if isinstance(value, int) else str(value)


@functools.cache
def node_topic_types() -> dict[str, str]:
    """finger_node's topics by their relative name (`joint_states`, `contact_wrench/distal`) → type ('pkg/msg/Type')."""
    from finger_sim.ros.interfaces import COMMAND_INPUTS, OUTPUTS

    specs = [(spec.topic, spec.msg_type) for spec in OUTPUTS.values()] + [(i.topic, i.msg_type) for i in COMMAND_INPUTS]
    return {topic.removeprefix("~").lstrip("/"): f"{cls.__module__.split('.')[0]}/msg/{cls.__name__}" for topic, cls in specs}


def message_class(topic: str, type_name: str) -> type:
    """The rclpy message class of 'pkg/msg/Type' (importlib: rosidl_runtime_py is not in the wheels)."""
    try:
        package, _, name = normalize_type_name(type_name).split("/")
    except LogArgumentError:
        raise MessageTypeNotFoundError(topic, type_name, "not a ROS 2 message type name") from None
    try:
        return getattr(importlib.import_module(f"{package}.msg"), name)
    except (ImportError, AttributeError):
        hint = f"install its package (pip: ros-jazzy-{package.replace('_', '-')}) or source a ROS setup"
        reason = f"no Python class {package}.msg.{name}; {hint}"
        raise MessageTypeNotFoundError(topic, type_name, reason) from None


class Player:
    """Publishers for a plan, and the timed loop that feeds them the log's bytes."""

    def __init__(
        self,
        node: Node,
        reader: LogReader,
        plan: ReplayPlan,
        *,
        rate: float,
        stop: threading.Event,
        warn: Callable[[str], None],
    ) -> None:
        self._reader, self._plan, self._rate, self._stop, self._warn = reader, plan, rate, stop, warn
        self._publishers: dict[str, Publisher] = {}
        for topic, type_name in plan.topics.items():
            qos, mix = recorded_qos(reader.channel_metadata(topic), CLOCK_QOS if topic == CLOCK_TOPIC else DATA_QOS)
            if mix:
                warn(f"{topic}: its recorded publishers offered {mix}; offering the policy every subscriber matches")
            self._publishers[topic] = node.create_publisher(message_class(topic, type_name), topic, qos)
        self._clock_publisher: Publisher | None = None
        if plan.clock is ClockSource.GENERATED:
            self._clock_publisher = node.create_publisher(message_class(CLOCK_TOPIC, CLOCK_TYPE),
                                                          CLOCK_TOPIC, CLOCK_QOS)
        self._by_channel: dict[int, Publisher] = {}
        self._node_types = node_topic_types()  # imported here, not at the first message: it would delay the pass
        self.stats = ReplayStats()

    @property
    def publishers(self) -> list[Publisher]:
        every = list(self._publishers.values())
        return every + [self._clock_publisher] if self._clock_publisher is not None else every

    def wait_for_subscribers(self, timeout_s: float) -> None:
        """Wait until every publisher has a matched subscription, at most `timeout_s` (then warn)."""
        deadline = time.monotonic() + timeout_s
        while not self._stop.is_set():
            missing = [p.topic_name for p in self.publishers if p.get_subscription_count() == 0]
            if not missing:
                return
            if time.monotonic() >= deadline:
                self._warn(f"no subscriber on {', '.join(missing)} after {timeout_s:g} s; replaying anyway")
                return
            self._stop.wait(MATCH_POLL_S)

    def sleep(self, duration_s: float) -> None:
        """Sleep `duration_s` wall seconds unless stopped."""
        self._wait_until(time.monotonic() + duration_s)

    def play(self, *, loop: bool = False) -> ReplayStats:
        """Publish the plan's messages on schedule, once or until stopped; returns the stats."""
        start = time.monotonic()
        while not self._stop.is_set():
            end = self._play_pass(start)
            if end is None or not loop:  # None: the pass published nothing; looping would spin
                break
            start = end
        return self.stats

    def wait_for_acks(self, timeout_s: float) -> bool:
        """Give subscribers up to `timeout_s` to acknowledge every message; False if some did not.

        Only reliable publishers wait. Fast DDS readers acknowledge when the writer's periodic
        heartbeat asks (every 3 s by default), so this usually takes up to that long.
        """
        deadline = time.monotonic() + timeout_s
        reliable = ReliabilityPolicy.RELIABLE
        pending = [p for p in self._publishers.values() if p.qos_profile.reliability is reliable]
        while pending and not self._stop.is_set():
            slice_s = min(WAIT_SLICE_S, max(0.0, deadline - time.monotonic()))
            pending = [p for p in pending if not p.wait_for_all_acked(Duration(seconds=slice_s))]
            if time.monotonic() >= deadline:
                break
        return not pending

    # -- internals ----------------------------------------------------------------------------

    def _play_pass(self, start: float) -> float | None:
        """One pass through the log from the origin; returns the last message's due time."""
        plan, stats = self._plan, self.stats
        origin, scale = plan.origin_ns, 1e-9 / self._rate
        period = None if plan.clock_hz is None else 1.0 / plan.clock_hz
        next_tick = start
        last_due: float | None = None
        last_ns = origin
        with ReadAhead(raw_messages(self._reader, plan.topics, origin)) as records:
            for schema, channel, message in records:
                due = start + (message.log_time - origin) * scale
                if period is not None:
                    while next_tick <= due:
                        now = self._wait_until(next_tick)
                        if now is None:
                            return None
                        self._publish_clock(origin + round((next_tick - start) / scale))
                        next_tick = max(next_tick + period, now)  # behind schedule: skip ticks, no burst
                now = self._wait_until(due)
                if now is None:
                    return None
                publisher = self._by_channel.get(channel.id) or self._publisher_for(schema, channel)
                data = message.data
                publisher.publish(data if type(data) is bytes else bytes(data))
                stats.record(due, now)
                if last_due is None:
                    stats.passes += 1
                last_due, last_ns = due, message.log_time
        if last_due is None:
            return None
        if period is not None:
            self._publish_clock(last_ns)  # the pass ends at the last message's time
        return last_due

    def _wait_until(self, due: float) -> float | None:
        """Sleep until time.monotonic() >= due; returns that time, or None if stopped first."""
        while not self._stop.is_set():
            now = time.monotonic()
            if now >= due:
                return now
            self._stop.wait(min(due - now, WAIT_SLICE_S))
        return None

    def _publish_clock(self, log_ns: int) -> None:
        assert self._clock_publisher is not None
        msg = self._clock_publisher.msg_type()
        msg.clock.sec, msg.clock.nanosec = divmod(log_ns, 10**9)
        self._clock_publisher.publish(msg)
        self.stats.clock_ticks += 1

    def _publisher_for(self, schema: Schema | None, channel: Channel) -> Publisher:
        """The publisher of a channel met for the first time; warns if its definition differs."""
        publisher = self._publishers[channel.topic]
        self._by_channel[channel.id] = publisher
        expected = next((t for name, t in self._node_types.items() if f"/{channel.topic.lstrip('/')}".endswith(f"/{name}")),
                        None)
        recorded = schema.name if schema is not None else "(no schema)"
        if expected is not None and recorded != expected:  # republished as recorded, but not silently
            self._warn(f"{channel.topic}: recorded as {recorded}, not {expected} as finger_node's topic of that name; "
                       f"republished as {recorded}, so subscribers expecting {expected} will not receive it")
        if schema is not None and schema.encoding == "ros2msg":
            try:
                installed = message_definition(schema.name)
            except (MessageDefinitionNotFoundError, LogArgumentError):
                return publisher  # the class imported, its .msg text is just not installed
            if schema.data.decode(errors="replace").strip() != installed.strip():
                self._warn(f"{channel.topic}: the log's definition of {schema.name} differs from the "
                           "installed one; subscribers may misread the recorded bytes")
        return publisher


# -- command line -----------------------------------------------------------------------------


class _Parser(argparse.ArgumentParser):
    """argparse with a one-line error (no usage block), exit status EXIT_USAGE."""

    def error(self, message: str) -> None:  # type: ignore[override]
        self.exit(EXIT_USAGE, f"{self.prog}: error: {message} (see --help)\n")


def _number(*, minimum: float, inclusive: bool) -> Callable[[str], float]:
    relation = ">=" if inclusive else ">"

    def parse(text: str) -> float:
        try:
            value = float(text)
        except ValueError:
            value = math.nan
        if not (math.isfinite(value) and (value >= minimum if inclusive else value > minimum)):
            expected = f"expected a finite number {relation} {minimum:g}"
            raise argparse.ArgumentTypeError(f"{expected}, got {text!r}")
        return value

    return parse


_positive = _number(minimum=0.0, inclusive=False)
_non_negative = _number(minimum=0.0, inclusive=True)


def build_parser() -> argparse.ArgumentParser:
    parser = _Parser(
        prog=PROG,
        description="Republish the topics of an MCAP log with their recorded timing (ros2 bag play "
        "for machines without rosbag2), and /clock from the log's time for use_sim_time nodes.",
        epilog="ROS arguments go after --ros-args (e.g. --ros-args -r /joint_states:=/replayed). "
        "Exit status: 0 done or stopped by SIGINT/SIGTERM, 1 unreadable or truncated log "
        "(the intact part is replayed), 2 bad arguments.",
    )
    parser.add_argument("log", type=Path, help="the .mcap file")
    parser.add_argument("--rate", type=_positive, default=1.0, metavar="R",
                        help="playback speed factor, e.g. 10 for ten times faster (default 1)")
    parser.add_argument("--loop", action="store_true", help="replay again from the start until stopped")
    parser.add_argument("--topics", nargs="+", metavar="TOPIC",
                        help="replay only these topics (default: all); /clock follows --clock/--no-clock")
    parser.add_argument("--start-offset", type=_non_negative, default=0.0, metavar="S",
                        help="skip the first S seconds of log time (default 0)")
    clock = parser.add_mutually_exclusive_group()
    clock.add_argument("--clock", type=_positive, nargs="?", const=DEFAULT_CLOCK_HZ, metavar="HZ",
                       help="publish /clock generated from the log time at HZ wall hertz (default "
                       f"{DEFAULT_CLOCK_HZ:g}) instead of the log's own /clock; a log without /clock "
                       "always gets a generated one")
    clock.add_argument("--no-clock", action="store_true", help="publish no /clock at all")
    parser.add_argument("--delay", type=_non_negative, default=0.0, metavar="S",
                        help="sleep S wall seconds before playing (default 0)")
    parser.add_argument("--wait-for-subscribers", type=_non_negative, default=0.0, metavar="S",
                        help="before playing, wait up to S s until every replayed topic has a "
                        "subscriber (default 0: do not wait)")
    parser.add_argument("--wait-for-all-acked", type=_non_negative, default=0.0, metavar="S",
                        help="after the last message, wait up to S s until reliable subscribers have "
                        "acknowledged every message (default 0: do not wait; with Fast DDS this takes "
                        "up to its 3 s heartbeat period)")
    return parser


def _rcl_message(exc: Exception) -> str:
    """rcl's message without its trail of C source locations ('..., at src/rcl/x.c:42')."""
    text = (str(exc).splitlines() or [repr(exc)])[0]
    return text.split(". Error:")[0].split(", at ")[0]


def _print_error(text: str) -> None:
    print(f"{PROG}: error: {text}", file=sys.stderr, flush=True)


def _print_warning(text: str) -> None:
    print(f"{PROG}: warning: {text}", file=sys.stderr, flush=True)


def main(argv: Sequence[str] | None = None) -> int:
    """Run the command line (`argv` without the program name; default sys.argv); returns the exit status."""
    full_argv = list(sys.argv) if argv is None else [PROG, *argv]
    try:
        own_argv = remove_ros_args(args=full_argv)[1:]
    except Exception as exc:  # rcl's RCLInvalidROSArgsError for a bad --ros-args section
        _print_error(_rcl_message(exc))
        return EXIT_USAGE
    args = build_parser().parse_args(own_argv)

    stop = threading.Event()
    received: list[str] = []

    def on_signal(signum: int, _frame: FrameType | None) -> None:
        received.append(signal.Signals(signum).name)
        stop.set()

    previous = {s: signal.signal(s, on_signal) for s in (signal.SIGINT, signal.SIGTERM)}
    previous_interval = sys.getswitchinterval()
    sys.setswitchinterval(SWITCH_INTERVAL_S)  # see ReadAhead
    try:
        return _run(args, full_argv, stop, received)
    finally:
        sys.setswitchinterval(previous_interval)
        for signum, handler in previous.items():
            signal.signal(signum, handler)


def _run(args: argparse.Namespace, full_argv: list[str], stop: threading.Event, received: list[str]) -> int:
    try:
        reader = read_log(args.log)
        plan = plan_replay(reader, topics=args.topics, start_offset_s=args.start_offset,
                           clock_hz=args.clock, no_clock=args.no_clock)
        for topic, type_name in plan.topics.items():
            message_class(topic, type_name)  # before any ROS call: a missing package is one line
    except (MissingTopicsError, LogArgumentError) as exc:  # the arguments do not fit this log
        _print_error(str(exc))
        return EXIT_USAGE
    except (LogError, MessageTypeNotFoundError) as exc:
        _print_error(str(exc))
        return EXIT_LOG
    if reader.truncation is not None:
        _print_warning(f"{reader.truncation}; replaying those")

    try:
        rclpy.init(args=full_argv, signal_handler_options=SignalHandlerOptions.NO)
    except Exception as exc:  # rcl's own exception types (the --ros-args were checked above)
        _print_error(f"cannot initialise ROS: {_rcl_message(exc)}")
        return EXIT_LOG
    topic_count = len(plan.topics) + (1 if plan.clock is ClockSource.GENERATED else 0)
    node: Node | None = None
    player: Player | None = None
    try:
        node = Node(PROG, start_parameter_services=False)
        player = Player(node, reader, plan, rate=args.rate, stop=stop, warn=_print_warning)
        if args.wait_for_subscribers > 0:
            player.wait_for_subscribers(args.wait_for_subscribers)
        player.sleep(args.delay)
        try:
            player.play(loop=args.loop)
        finally:
            timeout_s = args.wait_for_all_acked
            if timeout_s > 0 and not stop.is_set() and not player.wait_for_acks(timeout_s):
                _print_warning(f"some subscribers had not acknowledged every message after {timeout_s:g} s")
            if player.stats.published:
                player.sleep(LINGER_S)  # returns at once after a signal
    except (LogError, FingerSimError) as exc:  # a damaged record mid-log, a type that is not installed
        if player is not None and player.stats.published:
            print(player.stats.summary(args.rate, topic_count), flush=True)  # what got out before it
        _print_error(str(exc))
        return EXIT_LOG
    finally:
        if node is not None:
            node.destroy_node()
        rclpy.try_shutdown()
    player.stats.stopped_by = received[0] if received else None
    print(player.stats.summary(args.rate, topic_count), flush=True)
    return EXIT_LOG if reader.truncation is not None else EXIT_OK


if __name__ == "__main__":
    sys.exit(main())
