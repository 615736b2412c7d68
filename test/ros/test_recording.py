"""finger_node's MCAP log, end to end: the node in its own process, the file read back by readers
someone else wrote.

References: the `rosbags` package (AnyReader, types built from the file's own definitions) and
`mcap` + `mcap_ros2` (indexed, and non-seeking up to a cut); the installed `.msg` files and
rosidl's type-description JSON for the schemas; what this test's own subscriber received and
published; the scene file; and the recorded joint states themselves for resim (bit for bit).
Each test has its own ROS_DOMAIN_ID and loopback discovery (conftest.py), waits for conditions
with deadlines, and stops what it started even when it fails.
"""

from __future__ import annotations

import dataclasses
import importlib.metadata
import itertools
import json
import math
import os
import re
import signal
import sys
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import yaml

rclpy = pytest.importorskip("rclpy")

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus  # noqa: E402
from geometry_msgs.msg import PoseStamped  # noqa: E402
from mcap.exceptions import EndOfFile  # noqa: E402
from mcap.reader import NonSeekingReader, make_reader  # noqa: E402
from mcap.records import Message  # noqa: E402
from mcap.stream_reader import StreamReader  # noqa: E402
from mcap.writer import MCAP0_MAGIC  # noqa: E402
from mcap_ros2.decoder import DecoderFactory  # noqa: E402
from rclpy.qos import QoSProfile, ReliabilityPolicy  # noqa: E402
from rosbags.highlevel import AnyReader  # noqa: E402
from rosgraph_msgs.msg import Clock  # noqa: E402
from sensor_msgs.msg import JointState  # noqa: E402
from std_msgs.msg import Float64  # noqa: E402
from std_srvs.srv import Trigger  # noqa: E402

import finger_sim  # noqa: E402
from finger_sim.log import McapRecorder, read_log  # noqa: E402
from finger_sim.run_log import FINGER_SIM_METADATA, load_run, resimulate  # noqa: E402
from finger_sim.scene import load_scene, scene_from_dict  # noqa: E402
from finger_sim.simulate import Simulator  # noqa: E402
from helpers import NODE, child_pids, run_cli, run_cli_here, wait_until_gone  # noqa: E402
from ros_helpers import resume, stamp, start_when_heard, values  # noqa: E402

CONTROLLER = "finger_sim.ros.pd_controller"
ROOT = Path(__file__).resolve().parents[2]
PAPER = ROOT / "config" / "paper_flexion.yaml"
NODE_DEFAULTS = ROOT / "config" / "finger_node.yaml"
RATE = 1000.0
DT_NS = 1_000_000
MAX_TORQUE = 0.05  # N·m, the node's default saturation
TYPES = {
    "/clock": "rosgraph_msgs/msg/Clock",
    "/joint_states": "sensor_msgs/msg/JointState",
    "/fingertip_pose": "geometry_msgs/msg/PoseStamped",
    "/finger_markers": "visualization_msgs/msg/MarkerArray",
    "/diagnostics": "diagnostic_msgs/msg/DiagnosticArray",
    "/finger_node/command_log": "diagnostic_msgs/msg/DiagnosticStatus",
    "/motor_torque": "std_msgs/msg/Float64",
    "/effort_commands": "std_msgs/msg/Float64MultiArray",
    "/joint_command": "sensor_msgs/msg/JointState",
    "/robot_description": "std_msgs/msg/String",
    "/parameter_events": "rcl_interfaces/msg/ParameterEvent",
}
SEPARATOR = "\n" + "=" * 80 + "\n"  # rosbag2's ros2msg separator between definitions
BEST_EFFORT = QoSProfile(depth=10_000, reliability=ReliabilityPolicy.BEST_EFFORT)
REPUBLISH_S = 0.5  # a command not answered on ~/command_log within this is sent again
QUIET_S = 0.5  # after a kill: spin until nothing more arrives for this long
SUBPROCESS_TIMEOUT_S = 60.0
CHUNK_S = 0.1  # record_chunk_interval of the kill -9 run
WRITTEN = re.compile(r"log (\S+\.mcap): (\d+) messages written, (\d+) dropped")
WHERE = re.compile(r"clock=(\S+) time=(\S+) step=(\d+) episode=(\d+)")


# -- reading the file with other people's readers ------------------------------------------------
def plain(msg: Any) -> Any:
    """A message from rclpy, rosbags or mcap_ros2 as nested dicts and lists; floats as their hex
    (bitwise equal, NaN equal to NaN), so that messages from different libraries compare."""
    cls = type(msg)
    if hasattr(cls, "get_fields_and_field_types"):  # rclpy
        return {k: plain(getattr(msg, k)) for k in msg.get_fields_and_field_types()}
    if dataclasses.is_dataclass(msg):  # rosbags: constants are upper-case fields, __msgtype__ a tag
        return {f.name: plain(getattr(msg, f.name)) for f in dataclasses.fields(msg)
                if not f.name.isupper() and not f.name.startswith("__")}
    if hasattr(cls, "_type") and hasattr(cls, "__slots__"):  # mcap_ros2's decoder
        return {k: plain(getattr(msg, k)) for k in cls.__slots__}
    if isinstance(msg, bytes) and len(msg) == 1:  # rclpy's `byte` scalar (e.g. DiagnosticStatus.level)
        return msg[0]
    if isinstance(msg, (bytes, bytearray)):
        return list(msg)
    if isinstance(msg, (list, tuple, np.ndarray)) or type(msg).__name__ == "array":
        return [plain(v) for v in msg]
    if isinstance(msg, float):
        return float(msg).hex()
    if isinstance(msg, np.integer):
        return int(msg)
    return msg


def stamp_ns(topic: str, fields: dict) -> int | None:
    """The sim time a message carries (header stamp, /clock), None for unstamped types."""
    def ns(t: dict) -> int:
        return t["sec"] * 1_000_000_000 + t["nanosec"]

    if topic == "/clock":
        return ns(fields["clock"])
    if topic == "/finger_markers":
        stamps = {ns(m["header"]["stamp"]) for m in fields["markers"]}
        assert len(stamps) == 1, stamps
        return stamps.pop()
    if "header" in fields:
        return ns(fields["header"]["stamp"])
    return None


@dataclasses.dataclass
class McapView:
    """What mcap + mcap_ros2 read from a file: (topic, schema name, Message record, fields) in file order."""

    profile: str
    summary: Any
    channels: dict[str, Any]  # topic → channel
    schemas: dict[str, Any]  # topic → schema
    messages: list[tuple[str, str, Message, dict]]
    metadata: dict[str, dict[str, str]]

    def of(self, topic: str) -> list[tuple[int, dict]]:
        return [(m.log_time, f) for t, _, m, f in self.messages if t == topic]


def read_with_mcap(path: Path) -> McapView:
    with path.open("rb") as file:
        reader = make_reader(file, decoder_factories=[DecoderFactory()])
        header, summary = reader.get_header(), reader.get_summary()
        assert summary is not None, f"{path} has no summary"
        channels = {c.topic: c for c in summary.channels.values()}
        schemas = {c.topic: summary.schemas[c.schema_id] for c in summary.channels.values()}
        messages = [(c.topic, s.name, m, plain(d)) for s, c, m, d in reader.iter_decoded_messages(log_time_order=False)]
        metadata = {r.name: dict(r.metadata) for r in reader.iter_metadata()}
    return McapView(header.profile, summary, channels, schemas, messages, metadata)


def read_with_rosbags(path: Path) -> tuple[dict[str, Any], list[tuple[str, int, dict]]]:
    """(topic → connection, [(topic, log time, fields)]) by rosbags, types from the file's definitions."""
    with AnyReader([path]) as reader:
        connections = {c.topic: c for c in reader.connections}
        messages = [(c.topic, t, plain(reader.deserialize(raw, c.msgtype))) for c, t, raw in reader.messages()]
    return connections, messages


def check_definition(type_name: str, text: str) -> None:
    """A ros2msg schema as rosbag2 writes it: the type's .msg text, then for every type it depends
    on (rosidl's own list, from the type-description JSON) a separator line, `MSG: pkg/Type` and
    that type's .msg text."""
    share = Path(sys.prefix) / "share"

    def msg_text(name: str) -> str:
        pkg, _, typ = name.replace("/msg/", "/").partition("/")
        return (share / pkg / "msg" / f"{typ}.msg").read_bytes().decode()

    first, *rest = text.split(SEPARATOR)
    assert first == msg_text(type_name), type_name
    dependencies = []
    for block in rest:
        head, _, body = block.partition("\n")
        assert head.startswith("MSG: "), head
        dependencies.append(head.removeprefix("MSG: "))
        assert body == msg_text(dependencies[-1]), dependencies[-1]
    pkg, _, typ = type_name.replace("/msg/", "/").partition("/")
    described = json.loads((share / pkg / "msg" / f"{typ}.json").read_text())["type_description_msg"]
    expected = {r["type_name"].replace("/msg/", "/") for r in described["referenced_type_descriptions"]}
    assert len(dependencies) == len(set(dependencies)), dependencies
    assert set(dependencies) == expected, type_name


def the_log(folder: Path) -> Path:
    logs = sorted(folder.glob("*.mcap"))
    assert len(logs) == 1, logs
    assert logs[0].name.startswith("paper_flexion_")
    return logs[0]


def written(output: str) -> tuple[Path, int, int]:
    """(path, messages written, dropped) from the node's last log line."""
    found = WRITTEN.findall(output)
    assert found, output
    path, n, dropped = found[-1]
    return Path(path), int(n), int(dropped)


def output(proc) -> str:
    """A child's output, also after stop() (which closes its log file)."""
    return proc.log_path.read_text(errors="replace")


# -- talking to the node ---------------------------------------------------------------------


def where(message: str) -> tuple[int, int, int]:
    """(clock ns, step, episode) from a service answer."""
    m = WHERE.search(message)
    assert m, message
    return round(float(m.group(1)) * 1e9), int(m.group(3)), int(m.group(4))


def publish_until(client, publisher, value: float, sent: list, log: list, match, what: str,
                  timeout: float = 20.0) -> dict[str, str]:
    """Publish `value` (again every REPUBLISH_S: commands are best effort) until a ~/command_log
    event satisfying `match` arrives; every publication is appended to `sent`."""
    seen = len(log)

    def arrived():
        return next((values(e) for e in log[seen:] if match(values(e))), None)

    for _ in range(int(timeout / REPUBLISH_S)):
        publisher.publish(Float64(data=value))
        sent.append(value)
        try:
            return client.wait_for(arrived, what, timeout=REPUBLISH_S)
        except AssertionError:
            continue
    raise AssertionError(f"timed out after {timeout:g} s waiting for {what}; log: {[values(e) for e in log]}")


def drain(client, received: list) -> None:
    """Spin until nothing has arrived for QUIET_S: take in what was in flight when a node died."""
    last = [len(received), time.monotonic()]

    def quiet() -> bool:
        if len(received) != last[0]:
            last[:] = [len(received), time.monotonic()]
        return time.monotonic() - last[1] >= QUIET_S

    client.wait_for(quiet, "the client to go quiet")


def logged_by_step(logged: list[tuple[int, dict]], topic: str) -> list[dict]:
    """The logged messages of a state topic indexed by step; asserts they are every step from 0,
    each once, in order: what the node published, as it steps one dt at a time."""
    stamps = [stamp_ns(topic, f) for _, f in logged]
    assert stamps == [n * DT_NS for n in range(len(stamps))], topic
    return [f for _, f in logged]


def is_subsequence(short: list, long: list) -> bool:
    it = iter(long)
    return all(any(x == y for y in it) for x in short)


# -- tests -----------------------------------------------------------------------------------
def test_round_trip_read_by_rosbags_and_mcap(launcher, ros_client, tmp_path):
    """A short run with commands (one NaN, one saturated), stopped with SIGINT: the file holds
    what was published and received, as rosbag2 would have written it, and the resolved scene."""
    bags = tmp_path / "bags"
    params = dict(scene=str(PAPER), torque_source="topic", realtime_factor=1.0, record_dir=str(bags),
                  start_paused=True, command_timeout=0.0)
    node = launcher.node(NODE, params)
    states = ros_client.collect(JointState, "/joint_states")
    poses = ros_client.collect(PoseStamped, "/fingertip_pose")
    clocks = ros_client.collect(Clock, "/clock", BEST_EFFORT)
    events = ros_client.collect(DiagnosticStatus, "/finger_node/command_log")
    diagnostics = ros_client.collect(DiagnosticArray, "/diagnostics")
    torque_pub = ros_client.publisher(Float64, "/motor_torque")
    start_when_heard(ros_client, "/finger_node", states, poses, clocks)
    ros_client.wait_for(lambda: torque_pub.get_subscription_count(), "the motor_torque subscription")
    sent: list[float] = []
    publish_until(ros_client, torque_pub, math.nan, sent, events, lambda v: v["event"] == "refused", "NaN refused")
    resume(ros_client, "/finger_node")
    sat = publish_until(ros_client, torque_pub, 1e9, sent, events, lambda v: v["event"] == "accepted", "1e9 saturated")
    held = publish_until(ros_client, torque_pub, 0.003, sent, events,
                         lambda v: v["event"] == "accepted" and v["torque"] == "0.003", "0.003 accepted")
    end = int(held["stamp_ns"]) + 300 * DT_NS
    ros_client.wait_for(lambda: stamp(states[-1]) >= end, "300 steps after the last command")
    ros_client.wait_for(lambda: diagnostics, "diagnostics (about 1 Hz of wall time)")
    check_recording_cpu(ros_client, diagnostics, node.pid)
    assert node.stop() == 0, output(node)
    out = output(node)
    assert "Traceback" not in out, out
    assert "Failed to publish log message to rosout" not in out, out  # Ctrl-C is quiet (issue 19, item 11)
    path = the_log(bags)
    reported, n_written, n_dropped = written(out)
    assert (reported, n_dropped) == (path, 0)

    # -- mcap + mcap_ros2: header, schemas, channels, sequence numbers, times, counts ----------
    view = read_with_mcap(path)
    assert view.profile == "ros2"
    assert {t: s.name for t, s in view.schemas.items()} == TYPES
    for topic, schema in view.schemas.items():
        assert schema.encoding == "ros2msg"
        assert view.channels[topic].message_encoding == "cdr"
        check_definition(schema.name, schema.data.decode())
    stats = view.summary.statistics
    assert stats.message_count == len(view.messages) == n_written
    by_channel = {topic: view.of(topic) for topic in TYPES}
    assert {view.channels[t].id: len(m) for t, m in by_channel.items() if m} == \
        {k: v for k, v in stats.channel_message_counts.items() if v}
    for topic in TYPES:
        seqs = [m.sequence for t, _, m, _ in view.messages if t == topic]
        assert seqs == list(range(1, len(seqs) + 1)), topic  # from 1, no gaps, in file order
        times = [t for t, _ in by_channel[topic]]
        assert times == sorted(times), f"log time went back on {topic}"
        for log_time, fields in by_channel[topic]:
            stamped = stamp_ns(topic, fields)
            assert stamped is None or log_time == stamped, (topic, log_time, stamped)
    assert all(m.publish_time == m.log_time for _, _, m, _ in view.messages)
    for topic in ("/joint_states", "/fingertip_pose", "/clock", "/diagnostics", "/finger_markers",
                  "/finger_node/command_log", "/motor_torque"):
        assert by_channel[topic], f"nothing on {topic}"
    assert by_channel["/effort_commands"] == []

    # -- rosbags: the same topics, types and messages --------------------------------------
    connections, rb_messages = read_with_rosbags(path)
    assert {t: c.msgtype for t, c in connections.items()} == TYPES
    assert all(c.ext.serialization_format == "cdr" for c in connections.values())
    assert {t: c.msgcount for t, c in connections.items()} == {t: len(m) for t, m in by_channel.items()}
    for topic in TYPES:
        mine = sorted(((t, repr(f)) for t, f in by_channel[topic]))
        theirs = sorted(((t, repr(f)) for top, t, f in rb_messages if top == topic))
        assert mine == theirs, topic

    # -- what the subscriber received is in the log, field for field ------------------------
    for topic, got in (("/joint_states", states), ("/fingertip_pose", poses)):
        logged = logged_by_step(by_channel[topic], topic)  # also: every step from 0, none twice
        received = [plain(m) for m in got]
        assert len(received) >= 200  # most of them (keep-last writers may drop a few for a slow reader)
        assert [stamp_ns(topic, f) for f in received] == sorted({stamp_ns(topic, f) for f in received}), topic
        assert all(logged[stamp_ns(topic, f) // DT_NS] == f for f in received), topic
    assert is_subsequence([plain(c) for c in clocks], [f for _, f in by_channel["/clock"]])  # best effort: some
    logged_events = [f for _, f in by_channel["/finger_node/command_log"]]
    assert is_subsequence([plain(e) for e in events], logged_events)

    # -- commands as received; the command log refuses the NaN ------------------------------
    torques = [float.fromhex(f["data"]) for _, f in by_channel["/motor_torque"]]
    assert is_subsequence([x.hex() for x in torques], [x.hex() for x in sent])
    assert any(math.isnan(x) for x in torques) and 1e9 in torques and 0.003 in torques
    log = [{kv["key"]: kv["value"] for kv in e["values"]} for e in logged_events]
    refused = [e for e in log if e["event"] == "refused"]
    assert len(refused) == sum(math.isnan(x) for x in torques)  # every NaN received, refused
    assert all((e["requested"], e["source"], e["reason"]) == ("nan", "/motor_torque", "not a finite number")
               for e in refused)
    assert all(e["level"] == 1 for e in logged_events if values_of(e)["event"] == "refused")  # WARN
    accepted = [e for e in log if e["event"] == "accepted"]
    assert [(e["torque"], e["requested"], e["saturated"]) for e in accepted] == \
        [(str(MAX_TORQUE), "1000000000.0", "True"), ("0.003", "0.003", "False")]
    assert accepted[0]["step"] == sat["step"] and accepted[1]["step"] == held["step"]
    for log_time, fields in by_channel["/finger_node/command_log"]:
        assert log_time == int(values_of(fields)["stamp_ns"])  # no reset here: the event's own time
    s1, s2 = int(sat["step"]), int(held["step"])
    for _, js in by_channel["/joint_states"]:
        n = stamp_ns("/joint_states", js) // DT_NS  # state n follows step n − 1
        applied = 0.0 if n <= s1 else MAX_TORQUE if n <= s2 else 0.003
        assert float.fromhex(js["effort"][0]) == applied, n
    last_diag = values_of(by_channel["/diagnostics"][-1][1]["status"][0])
    assert (last_diag["log_file"], last_diag["log_messages_dropped"]) == (str(path), "0")

    # -- the run's record: resolved scene, parameters, version, method --------------------------
    meta = view.metadata[FINGER_SIM_METADATA]
    assert set(meta) == {"version", "scene", "method", "method_reason", "kernel", "torque_source", "dt", "parameters",
                         "record_time", "log_time_offset_ns"}
    assert (meta["record_time"], meta["log_time_offset_ns"]) == ("sim", "0")  # the default: log time = sim time
    expected_scene = load_scene(PAPER).with_overrides(dt=1.0 / RATE)
    assert scene_from_dict(yaml.safe_load(meta["scene"])) == expected_scene
    defaults = yaml.safe_load(NODE_DEFAULTS.read_text())["/**"]["ros__parameters"]
    assert yaml.safe_load(meta["parameters"]) == {**defaults, **params}
    sim = Simulator(expected_scene)
    assert (meta["method"], meta["method_reason"]) == (sim.method, sim.method_reason)
    assert meta["version"] == finger_sim.__version__ == importlib.metadata.version("finger_sim")
    assert (meta["torque_source"], meta["dt"]) == ("topic", "0.001")


def stat_cpu_s(pid: int) -> float:
    """utime + stime of process `pid` (all its threads), s, from /proc/<pid>/stat."""
    fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def check_recording_cpu(ros_client: Any, diagnostics: list, node_pid: int) -> None:
    """The recorder's CPU in /diagnostics (`log_cpu_*`, McapRecorder.cpu) against /proc, read after the report
    was published: each part > 0 while recording, the stepping thread's and the recorder's threads' within the
    node process's utime + stime, the writer's within its process's (two clock ticks of rounding each)."""
    def running_log() -> dict[str, str] | None:
        last = values(diagnostics[-1].status[0])
        return last if min(float(last[k]) for k in ("log_cpu_caller_s", "log_cpu_threads_s", "log_cpu_writer_s")) > 0 else None

    report = ros_client.wait_for(running_log, "a report counting every part of recording's CPU")
    (writer,) = child_pids(node_pid)
    tick = 1.0 / os.sysconf("SC_CLK_TCK")
    node_s, writer_s = stat_cpu_s(node_pid), stat_cpu_s(writer)
    caller, threads, writer_part = (float(report[k]) for k in ("log_cpu_caller_s", "log_cpu_threads_s", "log_cpu_writer_s"))
    assert caller + threads <= node_s + 2 * tick, (report, node_s)
    assert writer_part <= writer_s + 2 * tick, (report, writer_s)
    assert float(report["log_cpu_s"]) == pytest.approx(caller + threads + writer_part)
    assert float(report["log_cpu_per_sim_s"]) >= 0.0


def values_of(fields: dict) -> dict[str, str]:
    """Key-values of a DiagnosticStatus given as plain fields."""
    return {kv["key"]: kv["value"] for kv in fields["values"]}


def test_sigterm_closes_the_log(launcher, ros_client, tmp_path):
    """SIGTERM (what a supervisor sends) ends the node with the log's summary written."""
    bags = tmp_path / "bags"
    node = launcher.node(NODE, dict(scene=str(PAPER), realtime_factor=1.0, record_dir=str(bags)))
    states = ros_client.collect(JointState, "/joint_states")
    ros_client.wait_for(lambda: len(states) >= 200, "200 joint states")
    os.killpg(node.pid, signal.SIGTERM)
    assert node.wait(10.0) == 0, output(node)
    assert_closed_log(node, bags, len(states))


def assert_closed_log(node, bags: Path, n_states: int) -> None:
    """The exited node's log is closed and whole: the file the node reported, nothing dropped, the end
    magic, a summary counting every message written and at least the n_states joint states received."""
    path = the_log(bags)
    reported, n_written, n_dropped = written(output(node))
    assert (reported, n_dropped) == (path, 0)
    assert path.read_bytes().endswith(MCAP0_MAGIC)
    with path.open("rb") as file:
        summary = make_reader(file).get_summary()
    assert summary is not None and summary.statistics is not None
    assert summary.statistics.message_count == n_written
    assert summary.statistics.channel_message_counts[
        next(c.id for c in summary.channels.values() if c.topic == "/joint_states")] >= n_states
    assert not read_log(path).truncated


#: Wall seconds from a signal to the node's exit: stop the stepping, close the log, leave DDS.
SIGNAL_EXIT_S = 10.0
#: Wall seconds for the node to start and publish (imports and numba's cache load; a minute on a loaded machine).
NODE_START_S = 120.0


@pytest.mark.parametrize("executor", ["events", "single"])
def test_sigint_to_the_node_alone_ends_it_with_a_complete_log(launcher, ros_client, tmp_path, executor):
    """SIGINT to the node's own process (Ctrl-C in its terminal; not its group) ends it within
    SIGNAL_EXIT_S with status 0 and a complete log, on both executors. The EventsExecutor spun in
    the main thread never noticed a signal (its asio handler replaced rclpy's and never ended the
    spin): the node ran on until SIGKILL."""
    bags = tmp_path / "bags"
    node = launcher.node(NODE, dict(scene=str(PAPER), realtime_factor=1.0, record_dir=str(bags), executor=executor))
    states = ros_client.collect(JointState, "/joint_states")
    ros_client.wait_for(lambda: len(states) >= 200, "200 joint states", NODE_START_S)
    node.send_signal(signal.SIGINT)
    assert node.wait(SIGNAL_EXIT_S) == 0, output(node)
    assert_closed_log(node, bags, len(states))


def test_wall_start_log_time_and_publisher_qos(launcher, tmp_path):
    """record_time 'wall_start': every log time is the Unix time at the start plus the message's
    sim-time stamp, recorded in the metadata, and resim reads the log as it reads a sim-time
    one. Every published topic's channel carries its publisher's QoS as rosbag2 stores it
    (read back by rosbags): /clock best effort, state topics reliable and volatile."""
    from rosbags.interfaces import QosDurability, QosReliability
    from rosbags.rosbag2 import Reader

    bags = tmp_path / "bags"
    before = time.time_ns()
    node = launcher.node(NODE, dict(scene=str(PAPER), torque_source="scene", realtime_factor=0.0,
                                    record_dir=str(bags), record_time="wall_start"))
    assert node.wait(SUBPROCESS_TIMEOUT_S) == 0, output(node)
    after = time.time_ns()
    path = the_log(bags)
    reader = read_log(path)
    run = load_run(reader)
    offset = run.metadata.log_time_offset_ns
    assert run.metadata.record_time == "wall_start" and before <= offset <= after
    log_times = [m.log_time for _, _, m in reader.raw_messages(["/joint_states"])]
    assert log_times == [stamp + offset for stamp, _ in run.joint_states]
    assert reader.start_ns == offset  # the first state is stamped 0 on /clock
    assert resimulate(run).exact
    with Reader(path) as bag:
        qos = {c.topic: c.ext.offered_qos_profiles for c in bag.connections}
    assert qos["/clock"][0].reliability == QosReliability.BEST_EFFORT
    for topic in ("/joint_states", "/fingertip_pose", "/diagnostics", "/finger_node/command_log"):
        (profile,) = qos[topic]
        assert (profile.reliability, profile.durability) == (QosReliability.RELIABLE, QosDurability.VOLATILE), topic
    if "/robot_description" in qos:
        assert qos["/robot_description"][0].durability == QosDurability.TRANSIENT_LOCAL
    assert qos["/motor_torque"] == []  # received, not published: no offer to record


def log_written(diagnostics: list) -> int:
    """The most messages the node reported on /diagnostics as written to its log file (closed
    chunks, flushed to the operating system); 0 before its first report."""
    return max((int(values(s)["log_messages_written"]) for a in diagnostics for s in a.status), default=0)


def test_kill_9_leaves_a_readable_prefix(launcher, ros_client, tmp_path):
    """SIGKILL mid-run: every message the node reported as written before it survives, readable;
    the logged states are a prefix of what was published.

    How far the file gets before the kill is scheduling (the sender thread's handovers, the
    writer process's share of the CPU), so the bounds come from the node's own report on
    /diagnostics, taken before the kill, not from wall time."""
    bags = tmp_path / "bags"
    node = launcher.node(NODE, dict(scene=str(PAPER), realtime_factor=1.0, record_dir=str(bags), start_paused=True,
                                    record_chunk_interval=CHUNK_S))
    states = ros_client.collect(JointState, "/joint_states")
    diagnostics = ros_client.collect(DiagnosticArray, "/diagnostics")
    start_when_heard(ros_client, "/finger_node", states)
    resume(ros_client, "/finger_node")
    first = stamp(states[0])
    paused_written = log_written(diagnostics)
    ros_client.wait_for(lambda: stamp(states[-1]) >= first + 8 * CHUNK_S * 1e9
                        and log_written(diagnostics) > paused_written, "8 chunk intervals of states, a chunk reported written")
    writers = child_pids(node.pid)
    os.killpg(node.pid, signal.SIGKILL)
    assert node.wait(10.0) == -signal.SIGKILL
    wait_until_gone(writers)
    drain(ros_client, states)
    reported = log_written(diagnostics)  # every report was published before the node died
    path = the_log(bags)

    log = read_log(path)
    assert log.truncated and log.truncation is not None
    assert log.truncation.size == path.stat().st_size and log.truncation.readable == log.message_count
    assert log.message_count >= reported > paused_written  # what was reported written survived
    ours = [(m.log_time_ns, plain(m.msg)) for m in log.messages()]
    assert len(ours) == log.message_count

    # mcap's own non-seeking readers, up to the cut
    theirs = []
    with path.open("rb") as file, pytest.raises(EndOfFile):
        for _, channel, message, decoded in NonSeekingReader(file, decoder_factories=[DecoderFactory()]) \
                .iter_decoded_messages(log_time_order=False):
            theirs.append((message.log_time, plain(decoded)))
    assert theirs == ours
    records = []
    with path.open("rb") as file, pytest.raises(EndOfFile):
        records.extend(r for r in StreamReader(file).records if isinstance(r, Message))
    assert [m.log_time for m in records] == [t for t, _ in ours]

    # the logged joint states are a prefix of what was published (every step from 0), hold at
    # least the states in the reported chunks, and agree with what the subscriber saw of them.
    # Which of the two got further by the kill (the subscriber, or the writer process) is a race.
    logged = logged_by_step([(m.log_time_ns, plain(m.msg)) for m in log.messages("/joint_states")], "/joint_states")
    in_reported = sum(1 for m in itertools.islice(log.messages(), reported) if m.topic == "/joint_states")
    assert len(logged) >= in_reported > 0
    received = [plain(m) for m in states]
    seen = [f for f in received if stamp_ns("/joint_states", f) // DT_NS < len(logged)]
    first_step = first // DT_NS
    assert [stamp_ns("/joint_states", f) // DT_NS for f in seen][:in_reported - first_step] \
        == list(range(first_step, in_reported))  # reported written long before the kill: all delivered
    assert all(logged[stamp_ns("/joint_states", f) // DT_NS] == f for f in seen)

    done = run_cli("info", str(path))
    assert done.returncode == 3, done
    err = done.stderr.splitlines()
    assert len(err) == 1 and err[0].startswith(f"finger-sim: warning: {path}: truncated at byte "), done.stderr
    assert "Traceback" not in done.stderr + done.stdout
    assert "Status:   TRUNCATED" in done.stdout

    # repaired, the same messages are read by rosbags, from the summary
    assert_repairs(path, log.message_count)


def assert_repairs(path: Path, count: int, run: Callable[..., Any] = run_cli) -> None:
    """`finger-sim repair` of `path` is a complete log with `count` messages for rosbags and mcap;
    `run` is run_cli (the console script's own process) or run_cli_here (this process)."""
    done = run("repair", str(path))
    assert done.returncode == 0 and done.stderr == "", done
    out = path.with_name(path.stem + ".repaired.mcap")
    with AnyReader([out]) as bag:
        assert sum(1 for _ in bag.messages()) == count
    with out.open("rb") as file:
        assert sum(1 for _ in make_reader(file).iter_messages(log_time_order=False)) == count
    assert not read_log(out).truncated


@pytest.mark.parametrize("after_s", [0.0, 0.5, 1.0, 1.5])
def test_a_kill_at_any_moment_leaves_a_repairable_log(launcher, tmp_path, after_s):
    """SIGKILL from process start through node start-up and log creation: every .mcap left in
    record_dir is an MCAP prefix (never a partial header) that repair makes whole."""
    bags = tmp_path / "bags"
    node = launcher.node(NODE, dict(scene=str(PAPER), realtime_factor=1.0, record_dir=str(bags)))
    deadline = time.monotonic() + after_s
    while time.monotonic() < deadline and not list(bags.glob("*.mcap")):
        time.sleep(0.001)  # kill as soon as the log file appears, or at after_s
    writers = child_pids(node.pid)
    os.killpg(node.pid, signal.SIGKILL)
    assert node.wait(10.0) == -signal.SIGKILL
    wait_until_gone(writers)
    for path in sorted(bags.glob("*.mcap")):
        head = path.read_bytes()[:8]
        assert head in (b"", MCAP0_MAGIC), head  # empty (name reserved) or a whole header follows
        count = read_log(path).message_count if head else 0
        assert_repairs(path, count, run_cli_here)  # repair's own process: test_kill_9_leaves_a_readable_prefix


def test_resim_of_a_controller_run_is_bit_for_bit(launcher, ros_client, tmp_path):
    """finger_node driven by finger_pd_controller in another process, with a reset half way:
    the log alone reproduces every recorded state exactly; one tampered torque shows up at the
    first state it touches."""
    bags = tmp_path / "bags"
    node = launcher.node(NODE, dict(scene=str(PAPER), torque_source="topic", realtime_factor=1.0, record_dir=str(bags)))
    controller = launcher.node(CONTROLLER, dict(setpoint=0.8), name="pd")
    states = ros_client.collect(JointState, "/joint_states")
    ros_client.wait_for(lambda: states and states[-1].effort[0] > 0.0, "the controller's torque", timeout=30.0)
    t_on = stamp(states[-1])
    ros_client.wait_for(lambda: stamp(states[-1]) >= t_on + 700 * DT_NS, "0.7 s of closed loop")
    reset = ros_client.call(Trigger, "/finger_node/reset")
    assert reset.success, reset.message
    clock_r, step_r, episode = where(reset.message)
    assert (step_r, episode) == (0, 1)
    ros_client.wait_for(lambda: stamp(states[-1]) >= clock_r + 700 * DT_NS, "0.7 s of the second episode")
    assert node.stop() == 0, output(node)
    assert controller.stop() == 0, output(controller)
    path = the_log(bags)

    done = run_cli("resim", str(path))
    assert done.returncode == 0, done
    assert "reproduced bit for bit" in done.stdout and done.stderr == ""
    view = read_with_mcap(path)
    n_states = len(view.of("/joint_states"))
    run = load_run(read_log(path))
    result = resimulate(run)
    assert (result.max_deviation, result.first_stamp_ns) == (0.0, None)
    assert result.compared >= n_states >= 1400
    events = [e.to_values() for e in run.events]  # as logged: key → value
    assert [e["event"] for e in events].count("reset") == 1
    accepted = [e for e in events if e["event"] == "accepted"]
    assert {e["episode"] for e in accepted} == {"0", "1"} and len(accepted) > 100  # the PD changes it every step

    # tamper with one torque in the second episode: a copy written by the recorder
    second = [e for e in accepted if e["episode"] == "1"]
    target = second[len(second) // 2]
    bad_torque = float(target["torque"]) + 1e-3
    tampered = tmp_path / "tampered.mcap"
    copy_log(path, tampered, view, target, repr(bad_torque))
    first_off = int(target["stamp_ns"]) + DT_NS  # the state after the step it was applied to
    result = resimulate(load_run(read_log(tampered)))
    assert result.first_stamp_ns == first_off and result.max_deviation > 0.0
    assert result.compared == n_states
    done = run_cli_here("resim", str(tampered))  # resim's own process: the untampered log above
    assert done.returncode == 4, done
    assert done.stdout.strip() == (f"resim: max deviation {result.max_deviation:.3e} over {n_states} recorded states; "
                                   f"first at t = {first_off / 1e9:.6f} s on /clock")


def copy_log(source: Path, target: Path, view: McapView, event: dict[str, str], torque: str) -> None:
    """Every message of `source` rewritten by McapRecorder, with `event`'s torque replaced."""
    changed = 0
    log = read_log(source)
    with McapRecorder(target) as recorder:
        for topic, schema in view.schemas.items():
            recorder.register_channel(topic, schema.name, definition=schema.data.decode())
        recorder.add_metadata(FINGER_SIM_METADATA, log.metadata_record(FINGER_SIM_METADATA))
        for m in log.messages():
            if m.topic == "/finger_node/command_log":
                kv = {v.key: v for v in m.msg.values}
                if all(kv[k].value == event[k] for k in ("event", "episode", "step")):
                    kv["torque"].value = torque
                    changed += 1
            recorder.write(m.topic, m.msg, m.log_time_ns)
    assert changed == 1
