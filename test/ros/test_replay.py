"""finger_replay against real rclpy and DDS: the replay runs in its own process, the test subscribes.

The log is built with McapRecorder from known values (log time = sim time): 1 s of JointState
at 200 Hz, Float64 at 50 Hz between them, and /clock at 200 Hz. The subscriber compares every
field with the recorded value and times arrivals with DDS reception timestamps (`msg_info`),
so executor latency in this process does not enter the timing checks. The timing checks use
the writer's DDS source timestamps (when the replayer published) with a slack of the lateness the
replayer reports (a loaded machine makes it late, and it then publishes at once): what they assert
does not depend on the machine's speed, and on a quiet machine they are the 5 % checks of old.

Each test has its own ROS_DOMAIN_ID and loopback-only discovery, in this process and in the
child, and its processes are started and ended (by process group, also when a test fails) by
conftest.py's launcher.
"""

from __future__ import annotations

import contextlib
import io
import itertools
import math
import signal
import statistics
import sys
import threading
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import pytest

rclpy = pytest.importorskip("rclpy")

from rclpy.context import Context  # noqa: E402
from rclpy.executors import SingleThreadedExecutor  # noqa: E402
from rclpy.node import Node  # noqa: E402
from rclpy.qos import QoSProfile, ReliabilityPolicy  # noqa: E402
from rclpy.serialization import deserialize_message  # noqa: E402
from rosgraph_msgs.msg import Clock  # noqa: E402
from sensor_msgs.msg import JointState  # noqa: E402
from std_msgs.msg import Float64  # noqa: E402

from conftest import Launcher, RosProcess, wait_until  # noqa: E402
import ros_helpers  # noqa: E402
from finger_sim.log import (  # noqa: E402
    LogArgumentError,
    LogFileError,
    McapRecorder,
    MissingTopicsError,
    read_log,
)
from finger_sim.ros import replay  # noqa: E402
from finger_sim.ros.replay import ClockSource, plan_replay, raw_messages  # noqa: E402

pytestmark = pytest.mark.timeout(60)

T0_NS = 100 * 10**9  # sim time of the first message: not 0, so an offset mix-up shows
JOINT_PERIOD_NS = 5_000_000  # 200 Hz
JOINT_COUNT = 200
FORCE_PERIOD_NS = 20_000_000  # 50 Hz
FORCE_PHASE_NS = 2_500_000  # between two joint messages: no ties in log time
FORCE_COUNT = 50
JOINT_NAMES = ["mcp", "pip", "dip", "input"]
TOPIC_TYPES = {"/joint_states": JointState, "/tip_force": Float64, "/clock": Clock}
REMAPPED_FORCE = "/tip_force_replayed"  # where --ros-args -r sends /tip_force

REPLAY = Path(sys.executable).with_name("finger_replay")  # the console script next to this Python
DEADLINE_S = 20.0  # for any one condition; the file runs in ~25 s
TIMING_TOLERANCE = 0.05  # at --rate 1: recorded vs received span and median period
FAST_RATE_TOLERANCE = 0.20  # at --rate 10


# -- the log ---------------------------------------------------------------------------------


def joint_time(k: int) -> int:
    return T0_NS + k * JOINT_PERIOD_NS


def force_time(j: int) -> int:
    return T0_NS + FORCE_PHASE_NS + j * FORCE_PERIOD_NS


def joint_values(k: int) -> tuple[list[float], list[float], list[float]]:
    """Positions, velocities, efforts of message k: distinct, not round in binary."""
    position = [0.01 * k, -0.02 * k, math.sin(0.1 * k), 1.0 / (k + 3)]
    velocity = [0.3 * math.cos(0.1 * k), 0.0, -1.5, 2.0**-k]
    effort = [1e-3 * k, 1e3, -0.25, math.pi]
    return position, velocity, effort


def force_value(j: int) -> float:
    return 0.5 * j - 3.1


def stamp(ns: int) -> tuple[int, int]:
    return divmod(ns, 10**9)


def write_log(path: Path, *, with_clock: bool = True) -> Path:
    """The test log: joints and clock at 200 Hz, force at 50 Hz, written in log-time order."""
    events: list[tuple[int, int, str]] = [(joint_time(k), 0, f"j{k}") for k in range(JOINT_COUNT)]
    events += [(force_time(j), 1, f"f{j}") for j in range(FORCE_COUNT)]
    if with_clock:
        events += [(joint_time(k), 2, f"c{k}") for k in range(JOINT_COUNT)]
    with McapRecorder(path, chunk_interval_s=0.25) as rec:  # several chunks
        for topic, msg_type in TOPIC_TYPES.items():
            if topic != "/clock" or with_clock:
                rec.register_channel(topic, msg_type)
        for t, _, key in sorted(events):
            index = int(key[1:])
            if key[0] == "j":
                msg = JointState()
                msg.header.stamp.sec, msg.header.stamp.nanosec = stamp(t)
                msg.header.frame_id = "palm"
                msg.name = JOINT_NAMES
                msg.position, msg.velocity, msg.effort = joint_values(index)
                rec.write("/joint_states", msg, t)
            elif key[0] == "f":
                rec.write("/tip_force", Float64(data=force_value(index)), t)
            else:
                clock = Clock()
                clock.clock.sec, clock.clock.nanosec = stamp(t)
                rec.write("/clock", clock, t)
    return path


@pytest.fixture(scope="module")
def log_path(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return write_log(tmp_path_factory.mktemp("replay") / "run.mcap")


def assert_joint_state(msg: JointState, k: int) -> None:
    position, velocity, effort = joint_values(k)
    assert (msg.header.stamp.sec, msg.header.stamp.nanosec) == stamp(joint_time(k))
    assert msg.header.frame_id == "palm"
    assert list(msg.name) == JOINT_NAMES
    assert list(msg.position) == position  # bit for bit: the recorded bytes are republished
    assert list(msg.velocity) == velocity
    assert list(msg.effort) == effort


# -- the listener and the replay process (isolation and processes: conftest.py) -----------------


class Listener:
    """Subscribes to the test topics in its own context and spins in its own thread, so that
    every arrival is recorded as it happens: (DDS reception ns, message) per topic."""

    def __init__(self, domain: int) -> None:
        self.context = Context()
        rclpy.init(context=self.context, domain_id=domain)
        self.node = Node("replay_listener", context=self.context)
        subscriptions = {**TOPIC_TYPES, REMAPPED_FORCE: Float64}
        self.received: dict[str, list[tuple[int, object]]] = {topic: [] for topic in subscriptions}
        self._lock = threading.Lock()
        for topic, msg_type in subscriptions.items():
            reliability = ReliabilityPolicy.BEST_EFFORT if topic == "/clock" else ReliabilityPolicy.RELIABLE
            qos = QoSProfile(depth=1000, reliability=reliability)
            self.node.create_subscription(msg_type, topic, self._callback(topic), qos)
        self.executor = SingleThreadedExecutor(context=self.context)
        self.executor.add_node(self.node)
        self._running = True
        self._thread = threading.Thread(target=self._spin, daemon=True)
        self._thread.start()

    def _callback(self, topic: str) -> Callable[[object, dict], None]:
        def on_message(msg: object, info: dict) -> None:
            with self._lock:
                self.received[topic].append((info["source_timestamp"], msg))

        return on_message

    def _spin(self) -> None:
        while self._running and self.context.ok():
            self.executor.spin_once(timeout_sec=0.05)

    def count(self, topic: str) -> int:
        with self._lock:
            return len(self.received[topic])

    def counts(self, *topics: str) -> tuple[int, ...]:
        with self._lock:
            return tuple(len(self.received[topic]) for topic in topics)

    def messages(self, topic: str) -> list[object]:
        with self._lock:
            return [msg for _, msg in self.received[topic]]

    def times_s(self, topic: str) -> list[float]:
        """When the replayer published each message of `topic` (its DDS source timestamp), s."""
        with self._lock:
            return [ns / 1e9 for ns, _ in self.received[topic]]

    def close(self) -> None:
        self._running = False
        self._thread.join(5)
        self.executor.shutdown()
        self.node.destroy_node()
        rclpy.try_shutdown(context=self.context)


@pytest.fixture
def listener(ros_domain: int) -> Iterator[Listener]:
    listening = Listener(ros_domain)
    try:
        yield listening
    finally:
        listening.close()


@pytest.fixture
def start_replay(launcher: Launcher) -> Callable[..., RosProcess]:
    """Starts finger_replay in this test's domain, stdout and stderr apart; the launcher ends it."""

    def start(*args: object) -> RosProcess:
        command = [str(REPLAY)] if REPLAY.exists() else [sys.executable, "-m", "finger_sim.ros.replay"]
        return launcher.start([*command, *map(str, args)], f"replay{len(launcher.processes)}", separate_stderr=True)

    return start


@pytest.fixture
def run_replay(start_replay: Callable[..., RosProcess]) -> Callable[..., tuple[int, str, str]]:
    """A replay run to its end: (status, stdout, stderr)."""
    return lambda *args: start_replay(*args).finish(DEADLINE_S)


def replay_here(*args: object) -> tuple[int, str, str]:
    """finger_replay's main() in this process, for the refusals made before any ROS call (a process
    start-up less each; run_replay keeps one of each kind in its own process): (status, stdout, stderr)."""
    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        try:
            status = replay.main([str(a) for a in args])
        except SystemExit as exc:  # argparse's usage errors
            status = exc.code
    return status, out.getvalue(), err.getvalue()


def wait_for(condition: Callable[[], Any], what: str) -> None:
    wait_until(condition, DEADLINE_S, what)


def assert_one_line_error(result: tuple[int, str, str], status: int, *fragments: str) -> None:
    code, _, err = result
    assert code == status, err
    assert "Traceback" not in err
    lines = err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("finger_replay: error: "), err
    for fragment in fragments:
        assert fragment in lines[0]


def relative_error(measured: float, expected: float) -> float:
    return abs(measured - expected) / expected


def reported_lateness_s(out: str) -> float:
    """The replayer's own max lateness from its summary line ("lateness ... max X ms"), s."""
    return float(out.split("lateness mean ")[1].split(" max ")[1].split(" ms")[0]) / 1e3


def assert_span(published: list[float], recorded_span: float, tolerance: float, late: float) -> None:
    """The span from first to last publication is the recorded one within `tolerance` (relative),
    widened by `late` (the replayer's reported max lateness, s): a message due at t is published at
    t or up to `late` later, never earlier, so no speed of the machine makes this fail."""
    span = published[-1] - published[0]
    assert recorded_span * (1 - tolerance) - late <= span <= recorded_span * (1 + tolerance) + late, (span, late)


# -- without DDS: planning and reading ---------------------------------------------------------


def test_raw_messages_are_the_recorded_bytes_in_log_time_order(log_path: Path) -> None:
    reader = read_log(log_path)
    records = list(raw_messages(reader, TOPIC_TYPES, reader.start_ns))
    assert len(records) == 2 * JOINT_COUNT + FORCE_COUNT
    times = [message.log_time for _, _, message in records]
    assert times == sorted(times)
    joints = [deserialize_message(m.data, JointState) for _, c, m in records if c.topic == "/joint_states"]
    for k, msg in enumerate(joints):
        assert_joint_state(msg, k)
    forces = [deserialize_message(m.data, Float64).data for _, c, m in records if c.topic == "/tip_force"]
    assert forces == [force_value(j) for j in range(FORCE_COUNT)]
    assert all(s is not None and s.name == "sensor_msgs/msg/JointState"
               for s, c, _ in records if c.topic == "/joint_states")


def test_raw_messages_filter_by_topic_and_start(log_path: Path) -> None:
    reader = read_log(log_path)
    start = joint_time(120)
    records = list(raw_messages(reader, ["/tip_force"], start))
    expected = [j for j in range(FORCE_COUNT) if force_time(j) >= start]
    values = [deserialize_message(m.data, Float64).data for _, _, m in records]
    assert values == [force_value(j) for j in expected]


def test_plan_chooses_one_clock_source(log_path: Path, tmp_path: Path) -> None:
    reader = read_log(log_path)
    plan = plan_replay(reader)
    assert plan.clock is ClockSource.RECORDED and plan.clock_hz is None
    assert set(plan.topics) == set(TOPIC_TYPES) and plan.origin_ns == T0_NS
    # --topics selects data topics; the recorded /clock still drives time
    plan = plan_replay(reader, topics=["/tip_force"])
    assert set(plan.topics) == {"/tip_force", "/clock"} and plan.clock is ClockSource.RECORDED
    # --clock HZ replaces the recorded /clock; --no-clock publishes none
    plan = plan_replay(reader, clock_hz=30.0)
    assert "/clock" not in plan.topics and (plan.clock, plan.clock_hz) == (ClockSource.GENERATED, 30.0)
    plan = plan_replay(reader, no_clock=True)
    assert "/clock" not in plan.topics and plan.clock is ClockSource.NONE
    # a log without /clock gets a generated one
    plan = plan_replay(read_log(write_log(tmp_path / "no_clock.mcap", with_clock=False)))
    assert (plan.clock, plan.clock_hz) == (ClockSource.GENERATED, replay.DEFAULT_CLOCK_HZ)
    plan = plan_replay(reader, start_offset_s=0.5)
    assert plan.origin_ns == T0_NS + 500_000_000


def test_plan_rejects_what_does_not_fit_the_log(log_path: Path) -> None:
    reader = read_log(log_path)
    with pytest.raises(MissingTopicsError, match="/nope"):
        plan_replay(reader, topics=["/nope"])
    with pytest.raises(LogArgumentError, match="--start-offset"):
        plan_replay(reader, start_offset_s=1.5)
    with pytest.raises(LogArgumentError, match="--topics"):
        plan_replay(reader, topics=["/clock"], no_clock=True)


def test_plan_refuses_a_log_without_messages(tmp_path: Path) -> None:
    path = tmp_path / "empty.mcap"
    with McapRecorder(path) as rec:
        rec.register_channel("/tip_force", Float64)
    with pytest.raises(LogFileError, match="no messages"):
        plan_replay(read_log(path))


# -- command line errors: one line, nonzero, before any ROS call --------------------------------


@pytest.mark.parametrize(
    ("args", "fragments"),
    [
        ("--rate 0", ["--rate", "> 0", "'0'"]),
        ("--rate fast", ["--rate", "'fast'"]),
        ("--start-offset -1", ["--start-offset", "'-1'"]),
        ("--clock nan", ["--clock", "'nan'"]),
        ("--clock 10 --no-clock", ["--no-clock", "--clock"]),
        ("--start-offset 2", ["--start-offset", "duration"]),
        ("--topics /nope", ["missing topics /nope", "/joint_states"]),
        ("--ros-args -r nonsense", ["ROS arguments", "nonsense"]),
    ],
)
def test_bad_arguments_exit_2_with_one_line(log_path: Path, args: str, fragments: list[str],
                                            run_replay: Callable[..., tuple[int, str, str]]) -> None:
    run = run_replay if args == "--rate 0" else replay_here  # one in its own process
    assert_one_line_error(run(log_path, *args.split()), replay.EXIT_USAGE, *fragments)


def test_bad_logs_exit_1_with_one_line(tmp_path: Path, run_replay: Callable[..., tuple[int, str, str]]) -> None:
    missing = tmp_path / "missing.mcap"
    assert_one_line_error(run_replay(missing), replay.EXIT_LOG, str(missing), "no such file")  # its own process
    text = tmp_path / "notes.mcap"
    text.write_text("not a log\n")
    assert_one_line_error(replay_here(text), replay.EXIT_LOG, str(text), "not an MCAP file")
    empty = tmp_path / "empty.mcap"
    empty.touch()
    assert_one_line_error(replay_here(empty), replay.EXIT_LOG, "not an MCAP file", "empty")
    assert_one_line_error(replay_here(tmp_path), replay.EXIT_LOG, "a directory")


def test_a_type_without_python_class_exits_1_with_one_line(tmp_path: Path) -> None:
    path = tmp_path / "foreign.mcap"
    with McapRecorder(path) as rec:
        rec.register_channel("/foreign", "foreign_msgs/msg/Gauge", definition="float64 value\n")
        rec.write("/foreign", {"value": 1.5}, T0_NS)
    assert_one_line_error(replay_here(path), replay.EXIT_LOG, "/foreign", "foreign_msgs/msg/Gauge",
                          "ros-jazzy-foreign-msgs")


# -- replay through DDS ------------------------------------------------------------------------


def test_replays_every_message_with_recorded_values_order_and_timing(
    log_path: Path, listener: Listener, start_replay: Callable[..., RosProcess]
) -> None:
    proc = start_replay(log_path, "--wait-for-subscribers", 10)
    data_counts = (JOINT_COUNT, FORCE_COUNT)
    wait_for(lambda: listener.counts("/joint_states", "/tip_force") == data_counts, "every data message")
    code, out, err = proc.finish(DEADLINE_S)
    assert code == 0, err
    assert f"published {2 * JOINT_COUNT + FORCE_COUNT} messages on 3 topics" in out

    # values and per-topic order
    for k, msg in enumerate(listener.messages("/joint_states")):
        assert_joint_state(msg, k)
    assert [m.data for m in listener.messages("/tip_force")] == [force_value(j) for j in range(FORCE_COUNT)]

    # /clock carries the log's times (best effort: allow a rare loss, never a foreign value)
    clocks = [ros_helpers.stamp(m) for m in listener.messages("/clock")]
    recorded = [joint_time(k) for k in range(JOINT_COUNT)]
    arrived = set(clocks)
    assert clocks == [t for t in recorded if t in arrived]
    assert len(clocks) >= 0.95 * JOINT_COUNT

    # timing: span and median period against the recording, by the publications' source timestamps
    late = reported_lateness_s(out)
    received = listener.times_s("/joint_states")
    assert_span(received, (joint_time(JOINT_COUNT - 1) - joint_time(0)) / 1e9, TIMING_TOLERANCE, late)
    forces = listener.times_s("/tip_force")
    assert_span(forces, (force_time(FORCE_COUNT - 1) - force_time(0)) / 1e9, TIMING_TOLERANCE, late)
    if late < JOINT_PERIOD_NS / 1e9 / 2:  # never late by half a period: no catch-up burst, so every gap is paced
        period = statistics.median(b - a for a, b in itertools.pairwise(received))
        assert relative_error(period, JOINT_PERIOD_NS / 1e9) < TIMING_TOLERANCE

    # interleaving across topics: in order of publication, log times never go back
    merged = sorted([(t, joint_time(k)) for k, t in enumerate(received)]
                    + [(t, force_time(j)) for j, t in enumerate(forces)])
    log_times = [log_time for _, log_time in merged]
    assert log_times == sorted(log_times)


def test_rate_10_plays_in_a_tenth_of_the_time(
    log_path: Path, listener: Listener, start_replay: Callable[..., RosProcess]
) -> None:
    proc = start_replay(log_path, "--rate", 10, "--wait-for-subscribers", 10)
    wait_for(lambda: listener.count("/joint_states") == JOINT_COUNT, "every joint state")
    code, out, err = proc.finish(DEADLINE_S)
    assert code == 0, err
    recorded_span = (joint_time(JOINT_COUNT - 1) - joint_time(0)) / 1e9
    assert_span(listener.times_s("/joint_states"), recorded_span / 10, FAST_RATE_TOLERANCE, reported_lateness_s(out))
    assert "(requested 10x)" in out
    for k, msg in enumerate(listener.messages("/joint_states")):
        assert_joint_state(msg, k)


def test_topics_filter_no_clock_and_ros_args_remap(
    log_path: Path, listener: Listener, start_replay: Callable[..., RosProcess]
) -> None:
    proc = start_replay(log_path, "--topics", "/tip_force", "--no-clock", "--rate", 5,
                        "--wait-for-subscribers", 10, "--wait-for-all-acked", 10,
                        "--ros-args", "-r", f"/tip_force:={REMAPPED_FORCE}")
    wait_for(lambda: listener.count(REMAPPED_FORCE) == FORCE_COUNT, "every force message")
    code, out, err = proc.finish(DEADLINE_S)  # it waited for our acknowledgements: nothing else is on its way
    assert code == 0, err
    assert err == ""  # no warning about missing subscribers or acknowledgements
    assert f"published {FORCE_COUNT} messages on 1 topics" in out
    forces = [m.data for m in listener.messages(REMAPPED_FORCE)]
    assert forces == [force_value(j) for j in range(FORCE_COUNT)]
    assert listener.count("/tip_force") == listener.count("/joint_states") == listener.count("/clock") == 0


def test_start_offset_skips_the_beginning(
    log_path: Path, listener: Listener, start_replay: Callable[..., RosProcess]
) -> None:
    offset_ns = 500_000_000
    joints = [k for k in range(JOINT_COUNT) if joint_time(k) >= T0_NS + offset_ns]
    forces = [j for j in range(FORCE_COUNT) if force_time(j) >= T0_NS + offset_ns]
    proc = start_replay(log_path, "--start-offset", offset_ns / 1e9, "--rate", 4,
                        "--wait-for-subscribers", 10)
    data_counts = (len(joints), len(forces))
    wait_for(lambda: listener.counts("/joint_states", "/tip_force") == data_counts,
             "the data messages after the offset")
    code, out, err = proc.finish(DEADLINE_S)
    assert code == 0, err
    for k, msg in zip(joints, listener.messages("/joint_states"), strict=True):
        assert_joint_state(msg, k)
    assert [m.data for m in listener.messages("/tip_force")] == [force_value(j) for j in forces]
    clocks = [ros_helpers.stamp(m) for m in listener.messages("/clock")]
    assert clocks and min(clocks) >= T0_NS + offset_ns


def test_generated_clock_replaces_the_recorded_one(
    log_path: Path, listener: Listener, start_replay: Callable[..., RosProcess]
) -> None:
    hz = 30
    proc = start_replay(log_path, "--clock", hz, "--wait-for-subscribers", 10)
    wait_for(lambda: listener.count("/joint_states") == JOINT_COUNT, "every joint state")
    code, out, err = proc.finish(DEADLINE_S)
    assert code == 0, err
    clocks = [ros_helpers.stamp(m) for m in listener.messages("/clock")]
    end = joint_time(JOINT_COUNT - 1)
    expected_ticks = (end - T0_NS) / 1e9 * hz + 2  # a tick at the start, one per period, one at the end
    # one source: the recorded /clock (200 messages) is not replayed besides the ticks
    assert 0.7 * expected_ticks <= len(clocks) <= expected_ticks + 1
    assert clocks == sorted(clocks) and clocks[0] >= T0_NS and clocks[-1] <= end
    assert clocks[-1] == end or len(clocks) < expected_ticks  # the last tick (best effort) is the end
    assert "/clock ticks generated" in out


def test_truncated_log_replays_its_intact_part_then_exits_1(
    log_path: Path, tmp_path: Path, listener: Listener, start_replay: Callable[..., RosProcess]
) -> None:
    data = log_path.read_bytes()
    cut = tmp_path / "cut.mcap"
    cut.write_bytes(data[: len(data) * 6 // 10])
    readable = read_log(cut)
    assert readable.truncated and 0 < readable.message_count < 2 * JOINT_COUNT + FORCE_COUNT
    proc = start_replay(cut, "--rate", 10, "--wait-for-subscribers", 10)
    code, out, err = proc.finish(DEADLINE_S)
    assert code == replay.EXIT_LOG
    assert "Traceback" not in err
    assert err.startswith("finger_replay: warning: ") and "truncated at byte" in err
    assert f"published {readable.message_count} messages" in out
    joints = listener.messages("/joint_states")
    assert joints
    for k, msg in enumerate(joints):
        assert_joint_state(msg, k)


def test_corrupt_chunk_stops_with_one_line(
    log_path: Path, tmp_path: Path, start_replay: Callable[..., RosProcess]
) -> None:
    data = bytearray(log_path.read_bytes())
    middle = len(data) // 2
    data[middle:middle + 64] = bytes(64)  # inside a compressed chunk: zstd or the CRC fails
    bad = tmp_path / "bad.mcap"
    bad.write_bytes(bytes(data))
    code, out, err = start_replay(bad, "--rate", 20).finish(DEADLINE_S)
    assert_one_line_error((code, out, err), replay.EXIT_LOG, str(bad), "corrupt")


@pytest.mark.parametrize("signum", [signal.SIGINT, signal.SIGTERM], ids=lambda signum: signum.name)
def test_signal_stops_a_loop_cleanly(
    signum: signal.Signals,
    log_path: Path,
    listener: Listener,
    start_replay: Callable[..., RosProcess],
) -> None:
    proc = start_replay(log_path, "--loop", "--rate", 5, "--topics", "/joint_states",
                        "--wait-for-subscribers", 10)
    wait_for(lambda: listener.count("/joint_states") > 1.5 * JOINT_COUNT, "a second pass")
    proc.send_signal(signum)
    code, out, err = proc.finish(5.0)
    assert code == 0, err
    assert "Traceback" not in err
    assert f"stopped by {signum.name}" in out and "passes" in out
    # the passes repeat the log: each message is the recorded one of its stamp, and the stamps rise within a
    # pass and start again. Not every message need be here: a burst the loaded listener could not take is
    # repaired by the reliable protocol's next heartbeat (Fast DDS: 3 s), which the stopped replayer did not wait for
    joints = listener.messages("/joint_states")
    ks = [((m.header.stamp.sec * 10**9 + m.header.stamp.nanosec) - T0_NS) // JOINT_PERIOD_NS for m in joints]
    for k, msg in zip(ks, joints):
        assert_joint_state(msg, k)
    assert any(b < a for a, b in itertools.pairwise(ks)), "no second pass"
