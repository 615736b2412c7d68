"""McapRecorder: files read back by rosbags and by mcap + mcap_ros2, chunking, crash, I/O failure."""

from __future__ import annotations

import dataclasses
import select
import struct
import subprocess
import sys
import textwrap
import threading
import time
from collections.abc import Callable
from pathlib import Path

import pytest
# The messages written and read here are rclpy's: without ROS this module is skipped, the rest of
# the log layer runs.
pytest.importorskip("rclpy")

from conftest import allocate_domain_id, ros_environment  # noqa: E402

from builtin_interfaces.msg import Time  # noqa: E402
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue  # noqa: E402
from geometry_msgs.msg import PoseStamped  # noqa: E402
from mcap.exceptions import McapError  # noqa: E402
from mcap.reader import NonSeekingReader, SeekingReader, make_reader  # noqa: E402
from mcap_ros2.decoder import DecoderFactory  # noqa: E402
from rclpy.serialization import deserialize_message, serialize_message  # noqa: E402
from rosbags.highlevel import AnyReader  # noqa: E402
from rosbags.typesys import Stores, get_typestore  # noqa: E402
from rosgraph_msgs.msg import Clock  # noqa: E402
from sensor_msgs.msg import Imu, JointState  # noqa: E402
from std_msgs.msg import Char, Float64, Float64MultiArray, MultiArrayDimension, MultiArrayLayout, String  # noqa: E402

from finger_sim.log import (  # noqa: E402
    LogArgumentError,
    LogReader,
    McapRecorder,
    MessageDefinitionNotFoundError,
    RecorderStateError,
    message_definition,
    type_name_of,
)
from helpers import blocked_recorder, wait_until_gone  # noqa: E402

SHARE = Path(sys.prefix) / "share"  # where the ROS 2 wheels install their .msg files
DEADLINE_S = 20.0  # generous bound for conditions that normally hold within milliseconds
STEPS = 5
T0_NS = 1_500_000_000  # log times start away from zero so that "as given" is tested
DT_NS = 20_000_000
PUBLISH_LAG_NS = 1_000  # publish_time = log_time - lag, so the two are told apart
JOINTS = ["mcp_joint", "coupler_joint", "pip_joint"]


def log_time(k: int) -> int:
    return T0_NS + k * DT_NS


def stamp(k: int) -> Time:
    t = log_time(k)
    return Time(sec=t // 10**9, nanosec=t % 10**9)


# topic → (type, message k, its expected fields as plain data)
def joint_state(k: int) -> JointState:
    msg = JointState(name=JOINTS, position=[0.1 * k, 0.2 * k, -0.3 * k], velocity=[1.0, 2.0, 3.0 + k],
                     effort=[0.5 * k, 0.0, -0.25])
    msg.header.stamp, msg.header.frame_id = stamp(k), "finger_base"
    return msg


def pose(k: int) -> PoseStamped:
    msg = PoseStamped()
    msg.header.stamp, msg.header.frame_id = stamp(k), "finger_base"
    msg.pose.position.x, msg.pose.position.y, msg.pose.position.z = 0.01 * k, 0.0, -0.042
    msg.pose.orientation.y, msg.pose.orientation.w = 0.6, 0.8
    return msg


def diagnostics(k: int) -> DiagnosticArray:
    status = DiagnosticStatus(level=DiagnosticStatus.WARN, name="finger_sim: integrator", message=f"step {k}",
                              hardware_id="sim", values=[KeyValue(key="constraint_error", value=f"{k}e-12")])
    msg = DiagnosticArray(status=[status])
    msg.header.stamp = stamp(k)
    return msg


MESSAGES: dict[str, tuple[str, Callable[[int], object]]] = {
    "/joint_states": ("sensor_msgs/msg/JointState", joint_state),
    "/fingertip_pose": ("geometry_msgs/msg/PoseStamped", pose),
    "/motor_torque": ("std_msgs/msg/Float64", lambda k: Float64(data=0.125 * k - 1.0)),
    "/state": ("std_msgs/msg/Float64MultiArray", lambda k: Float64MultiArray(
        layout=MultiArrayLayout(dim=[MultiArrayDimension(label="q", size=3, stride=3)], data_offset=0),
        data=[float(k), k + 0.5, -k / 3])),
    "/clock": ("rosgraph_msgs/msg/Clock", lambda k: Clock(clock=stamp(k))),
    "/diagnostics": ("diagnostic_msgs/msg/DiagnosticArray", diagnostics),
}
BYTES_TOPICS = {"/motor_torque", "/clock"}  # handed over as CDR bytes instead of message objects
METADATA = {"scene": "name: paper_flexion\ndt: 0.001\n", "integrator": "rk4", "version": "0.1.0"}

# rosbag2's order of dependencies: depth first, each type once, sorted per message.
DEPENDENCIES = {
    "sensor_msgs/msg/JointState": ["std_msgs/Header", "builtin_interfaces/Time"],
    "geometry_msgs/msg/PoseStamped": ["geometry_msgs/Pose", "geometry_msgs/Point", "geometry_msgs/Quaternion",
                                      "std_msgs/Header", "builtin_interfaces/Time"],
    "std_msgs/msg/Float64": [],
    "std_msgs/msg/Float64MultiArray": ["std_msgs/MultiArrayLayout", "std_msgs/MultiArrayDimension"],
    "rosgraph_msgs/msg/Clock": ["builtin_interfaces/Time"],
    "diagnostic_msgs/msg/DiagnosticArray": ["diagnostic_msgs/DiagnosticStatus", "diagnostic_msgs/KeyValue",
                                            "std_msgs/Header", "builtin_interfaces/Time"],
}


def plain(value: object) -> object:
    """Field values of a message from any library as nested dicts, lists and scalars."""
    if hasattr(type(value), "get_fields_and_field_types"):  # rclpy
        return {name: plain(getattr(value, name)) for name in type(value).get_fields_and_field_types()}
    if hasattr(value, "__msgtype__"):  # rosbags: a dataclass; constants and __msgtype__ have defaults
        return {f.name: plain(getattr(value, f.name)) for f in dataclasses.fields(value)
                if f.default is dataclasses.MISSING}
    if hasattr(type(value), "__slots__") and hasattr(type(value), "_type"):  # mcap_ros2
        return {name: plain(getattr(value, name)) for name in type(value).__slots__}
    if isinstance(value, bytes) and len(value) == 1:  # rclpy's byte scalar; the others use int
        return value[0]
    if hasattr(value, "tolist"):
        return plain(value.tolist())
    if isinstance(value, (list, tuple)) or type(value).__name__ == "array":
        return [plain(v) for v in value]
    return value


def msg_text(type_name: str) -> str:
    package, _, name = type_name.replace("/msg/", "/").partition("/")
    return (SHARE / package / "msg" / f"{name}.msg").read_text()


@pytest.fixture(scope="module")
def recorded(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, McapRecorder]:
    path = tmp_path_factory.mktemp("log") / "run.mcap"
    with McapRecorder(path) as recorder:
        for topic, (type_name, _) in MESSAGES.items():
            recorder.register_channel(topic, type_name)
        recorder.add_metadata("finger_sim", METADATA)
        for k in range(STEPS):
            for topic, (_, make) in MESSAGES.items():
                msg = make(k)
                data = serialize_message(msg) if topic in BYTES_TOPICS else msg
                assert recorder.write(topic, data, log_time(k), publish_time_ns=log_time(k) - PUBLISH_LAG_NS)
    return path, recorder


def test_counters_after_close(recorded: tuple[Path, McapRecorder]) -> None:
    _, recorder = recorded
    assert (recorder.written, recorder.dropped) == (STEPS * len(MESSAGES), 0)


def test_rosbags_reads_every_field(recorded: tuple[Path, McapRecorder]) -> None:
    path, _ = recorded
    with AnyReader([path]) as reader:  # builds its types from the definitions in the file
        assert {c.topic: c.msgtype for c in reader.connections} == {t: m[0] for t, m in MESSAGES.items()}
        assert {t: info.msgcount for t, info in reader.topics.items()} == dict.fromkeys(MESSAGES, STEPS)
        seen = {topic: 0 for topic in MESSAGES}
        for connection, timestamp, raw in reader.messages():
            k = seen[connection.topic]
            assert timestamp == log_time(k)
            assert plain(reader.deserialize(raw, connection.msgtype)) == plain(MESSAGES[connection.topic][1](k))
            seen[connection.topic] += 1
    assert seen == dict.fromkeys(MESSAGES, STEPS)


def test_mcap_reads_records_as_rosbag2_writes_them(recorded: tuple[Path, McapRecorder]) -> None:
    path, _ = recorded
    with path.open("rb") as file:
        reader = make_reader(file, decoder_factories=[DecoderFactory()])
        assert reader.get_header().profile == "ros2"
        summary = reader.get_summary()
        assert summary is not None and summary.statistics is not None
        assert {c.topic: summary.schemas[c.schema_id].name for c in summary.channels.values()} == {
            t: m[0] for t, m in MESSAGES.items()
        }
        assert {s.encoding for s in summary.schemas.values()} == {"ros2msg"}
        assert {c.message_encoding for c in summary.channels.values()} == {"cdr"}
        assert all(c.metadata == {} for c in summary.channels.values())  # no offered_qos_profiles
        assert summary.statistics.message_count == STEPS * len(MESSAGES)
        assert (summary.statistics.message_start_time, summary.statistics.message_end_time) == (
            log_time(0), log_time(STEPS - 1))
        assert [(m.name, m.metadata) for m in reader.iter_metadata()] == [("finger_sim", METADATA)]
        seen = {topic: 0 for topic in MESSAGES}
        for _, channel, message, decoded in reader.iter_decoded_messages(log_time_order=False):
            k = seen[channel.topic]
            assert (message.sequence, message.log_time, message.publish_time) == (
                k + 1, log_time(k), log_time(k) - PUBLISH_LAG_NS)
            assert plain(decoded) == plain(MESSAGES[channel.topic][1](k))
            seen[channel.topic] += 1
    assert seen == dict.fromkeys(MESSAGES, STEPS)


@pytest.mark.parametrize("type_name", sorted(DEPENDENCIES))
def test_schema_is_the_concatenated_definition(recorded: tuple[Path, McapRecorder], type_name: str) -> None:
    path, _ = recorded
    with path.open("rb") as file:
        summary = SeekingReader(file).get_summary()
    assert summary is not None
    (data,) = [s.data.decode() for s in summary.schemas.values() if s.name == type_name]
    expected = msg_text(type_name) + "".join(
        f"\n{'=' * 80}\nMSG: {dep}\n{msg_text(dep)}" for dep in DEPENDENCIES[type_name]
    )
    assert data == expected
    assert data.count("\n" + "=" * 80 + "\nMSG: ") == len(DEPENDENCIES[type_name])


def test_rclpy_messages_are_written_as_exact_cdr(tmp_path: Path) -> None:
    """Encoded field by field, or via rclpy for numpy and byte values: rclpy's C typesupport reads
    the bytes back, and so does rosbags, which rejects trailing bytes."""
    imu = Imu(linear_acceleration_covariance=[float(i) for i in range(9)])  # numpy: via rclpy
    imu.orientation.w = 1.0
    samples = [MESSAGES[topic][1](3) for topic in MESSAGES] + [imu, Char(data=65), String(data="flexion")]
    with McapRecorder(tmp_path / "encodings.mcap") as recorder:
        for i, msg in enumerate(samples):
            recorder.register_channel(f"/t{i}", type(msg))
            recorder.write(f"/t{i}", msg, 0)
    with (tmp_path / "encodings.mcap").open("rb") as file:
        written = {c.topic: m.data for _, c, m in make_reader(file).iter_messages(log_time_order=False)}
    typestore = get_typestore(Stores.ROS2_JAZZY)
    for i, msg in enumerate(samples):
        data = written[f"/t{i}"]
        assert plain(deserialize_message(data, type(msg))) == plain(msg)
        assert plain(typestore.deserialize_cdr(data, type_name_of(msg))) == plain(msg)


def test_missing_definition_names_the_files_searched(tmp_path: Path) -> None:
    with pytest.raises(MessageDefinitionNotFoundError, match=r"no message definition for nosuch_msgs/msg/Thing: "
                       r"looked for .*share/nosuch_msgs/msg/Thing\.msg"):
        message_definition("nosuch_msgs/Thing", prefixes=[tmp_path])


def test_chunks_close_every_interval_of_log_time(tmp_path: Path) -> None:
    path = tmp_path / "chunks.mcap"
    interval_s, rate_hz, span_s = 0.5, 100, 3.0
    with McapRecorder(path, chunk_interval_s=interval_s) as recorder:
        recorder.register_channel("/motor_torque", Float64)
        for i in range(round(span_s * rate_hz) + 1):
            recorder.write("/motor_torque", Float64(data=float(i)), i * 10**9 // rate_hz)
    with path.open("rb") as file:
        summary = SeekingReader(file).get_summary()
    assert summary is not None
    chunks = summary.chunk_indexes
    assert len(chunks) >= span_s / interval_s
    assert all(c.message_end_time - c.message_start_time < interval_s * 1e9 for c in chunks)
    assert {c.compression for c in chunks} == {"zstd"}


def test_chunks_close_by_size_when_log_time_stands_still(tmp_path: Path) -> None:
    path, count, chunk_size = tmp_path / "size.mcap", 100, 4000
    with McapRecorder(path, chunk_size=chunk_size) as recorder:
        recorder.register_channel("/state", Float64MultiArray)
        for _ in range(count):
            recorder.write("/state", Float64MultiArray(data=[1.0] * 100), 0)  # one log time
    with path.open("rb") as file:
        reader = SeekingReader(file)
        summary = reader.get_summary()
        (size,) = {len(m.data) for _, _, m in reader.iter_messages()}
    assert summary is not None and summary.statistics is not None
    per_chunk = -(-chunk_size // size)  # messages until the payload reaches chunk_size
    assert summary.statistics.chunk_count == len(summary.chunk_indexes) == -(-count // per_chunk)


def test_idle_writer_closes_the_open_chunk(tmp_path: Path) -> None:
    path = tmp_path / "idle.mcap"
    with McapRecorder(path, idle_flush_s=0.05) as recorder:
        recorder.register_channel("/motor_torque", Float64)
        for i in range(3):
            recorder.write("/motor_torque", Float64(data=float(i)), i)
        deadline = time.monotonic() + DEADLINE_S
        while recorder.written < 3 and time.monotonic() < deadline:
            time.sleep(0.01)
        assert recorder.written == 3
        log = LogReader(path)  # while recording: no summary yet, the chunk is on disk
        assert log.truncated
        assert [m.msg.data for m in log.messages()] == [0.0, 1.0, 2.0]
    assert not LogReader(path).truncated


def test_a_chunk_closes_on_wall_time_while_log_time_stands_still(tmp_path: Path) -> None:
    """A paused node: log time stands still, yet messages keep coming (diagnostics, commands), so
    neither the log-time span nor the idle timer closes the chunk; the wall-time bound does."""
    path, wall_s = tmp_path / "paused.mcap", 0.2
    with McapRecorder(path, chunk_interval_s=60.0, idle_flush_s=60.0, chunk_wall_s=wall_s) as recorder:
        recorder.register_channel("/motor_torque", Float64)
        deadline = time.monotonic() + DEADLINE_S
        i = 0
        while recorder.written == 0 and time.monotonic() < deadline:
            recorder.write("/motor_torque", Float64(data=float(i)), 5_000_000)  # one log time
            i += 1
            time.sleep(0.01)
        assert recorder.written > 0
        log = LogReader(path)  # while recording: the closed chunk is on disk
        assert log.truncated
        on_disk = [m.msg.data for m in log.messages()]
    assert on_disk == [float(k) for k in range(len(on_disk))] and 0 < len(on_disk) <= i


CHILD = textwrap.dedent("""
    import sys, time
    from std_msgs.msg import Float64
    from finger_sim.log import McapRecorder

    path, ready_after, deadline_s = sys.argv[1], int(sys.argv[2]), float(sys.argv[3])
    recorder = McapRecorder(path, chunk_interval_s=0.1).open()
    recorder.register_channel("/value", Float64)
    i, start = 0, time.monotonic()
    while time.monotonic() - start < deadline_s:  # until killed; the bound only guards a lost parent
        recorder.write("/value", Float64(data=float(i)), i * 10_000_000)
        i += 1
        if i == ready_after:
            while recorder.written < ready_after // 2:
                time.sleep(0.001)
            print("written", recorder.written, recorder.writer_pid, flush=True)
        time.sleep(0.0002)
""")


def test_kill_9_leaves_a_readable_prefix(tmp_path: Path) -> None:
    path, ready_after = tmp_path / "killed.mcap", 200
    child = subprocess.Popen(
        [sys.executable, "-c", CHILD, str(path), str(ready_after), str(DEADLINE_S)],
        stdout=subprocess.PIPE, text=True, env=ros_environment(allocate_domain_id()),
    )
    try:
        ready, _, _ = select.select([child.stdout], [], [], DEADLINE_S)
        assert ready, "the child never reported progress"
        line = child.stdout.readline().split()
        assert line[0] == "written", line
        written, writer = int(line[1]), int(line[2])
        child.kill()  # SIGKILL: no finally, no atexit, no close()
        child.wait(DEADLINE_S)
        wait_until_gone([writer])  # it writes what it was handed, then leaves the file as a crash does
    finally:
        if child.poll() is None:
            child.kill()
            child.wait(DEADLINE_S)
    log = LogReader(path)
    assert log.truncated and log.truncation is not None
    values = [(m.log_time_ns, m.msg.data) for m in log.messages()]
    assert len(values) >= written  # everything in closed chunks survived
    assert values == [(i * 10_000_000, float(i)) for i in range(len(values))]  # a prefix of what was written
    # mcap's own linear reader agrees up to the cut, where it stops with an error.
    mcap_values = []
    with path.open("rb") as file:
        try:
            for _, _, message, decoded in NonSeekingReader(file, decoder_factories=[DecoderFactory()]) \
                    .iter_decoded_messages(log_time_order=False):
                mcap_values.append((message.log_time, decoded.data))
        except (McapError, struct.error):  # EndOfFile at the cut, or a cut inside a length field
            pass
    assert mcap_values == values


@pytest.mark.parametrize("where", ["under_a_file", "dev_full"])
def test_unwritable_path_or_full_disk_is_reported_once(tmp_path: Path, where: str) -> None:
    if where == "under_a_file":  # root ignores permissions, but not a file used as a directory
        (tmp_path / "file").write_text("")
        path, reason = tmp_path / "file" / "run.mcap", "Not a directory"
    else:
        path, reason = Path("/dev/full"), "No space left on device"
    problems: list[str] = []
    with McapRecorder(path, on_problem=problems.append) as recorder:
        recorder.register_channel("/motor_torque", Float64)
        recorder.add_metadata("finger_sim", METADATA)
        results = [recorder.write("/motor_torque", Float64(data=float(i)), i * DT_NS) for i in range(50)]
    recorder.close()  # idempotent
    assert all(results)  # accepted into the queue: the caller never learns of the disk
    assert (recorder.written, recorder.dropped) == (0, 50)
    assert len(problems) == 1
    assert str(path) in problems[0] and reason in problems[0]
    assert recorder.error is not None and str(path) in recorder.error and reason in recorder.error


def test_error_is_none_while_writing_works(tmp_path: Path) -> None:
    with McapRecorder(tmp_path / "ok.mcap") as recorder:
        recorder.register_channel("/motor_torque", Float64)
        recorder.write("/motor_torque", Float64(data=1.0), 0)
    assert recorder.error is None and (recorder.written, recorder.dropped) == (1, 0)
    assert [p.name for p in tmp_path.iterdir()] == ["ok.mcap"]  # no temporary file left behind


def test_metadata_is_bounded(tmp_path: Path) -> None:
    """A record over 64 kB (e.g. an expanded YAML alias bomb) is refused at the call, naming its size."""
    with McapRecorder(tmp_path / "meta.mcap") as recorder:
        recorder.add_metadata("small", {"k": "v" * 1000})
        with pytest.raises(LogArgumentError, match=r"metadata record 'big': expected at most 65536 bytes, "
                                                   r"got '70001 bytes'"):
            recorder.add_metadata("big", {"k": "v" * 70_000})
    assert set(LogReader(tmp_path / "meta.mcap").metadata) == {"small"}


def test_queue_overflow_drops_and_reports_once(tmp_path: Path) -> None:
    with blocked_recorder(tmp_path, queue_size=4) as (recorder, problems):
        recorder.register_channel("/motor_torque", Float64)
        results = [recorder.write("/motor_torque", Float64(data=float(i)), i) for i in range(10)]
        assert results == [True] * 4 + [False] * 6
        assert recorder.dropped == 6
        assert len(problems) == 1 and "4 messages wait for the writer" in problems[0]
    # A pipe cannot seek: writing the chunk fails, is reported once, and its messages are counted.
    assert (recorder.written, recorder.dropped) == (0, 10)
    assert len(problems) == 2 and "cannot write" in problems[1]


def test_misuse_raises_at_the_call(tmp_path: Path) -> None:
    problems: list[str] = []
    recorder = McapRecorder(tmp_path / "misuse.mcap", on_problem=problems.append)
    with pytest.raises(RecorderStateError, match="cannot write: the recorder is not open yet"):
        recorder.write("/motor_torque", b"", 0)
    with recorder:
        with pytest.raises(RecorderStateError, match="cannot open: the recorder is open"):
            recorder.open()
        with pytest.raises(LogArgumentError, match="topic: expected an absolute ROS 2 name"):
            recorder.register_channel("motor_torque", Float64)
        recorder.register_channel("/motor_torque", Float64)
        recorder.register_channel("/motor_torque", "std_msgs/Float64")  # same type again: fine
        with pytest.raises(LogArgumentError, match=r"msg_type: expected std_msgs/msg/Float64 \(as registered"):
            recorder.register_channel("/motor_torque", JointState)
        with pytest.raises(LogArgumentError, match=r"topic: expected a registered topic \(/motor_torque\)"):
            recorder.write("/nope", Float64(), 0)
        with pytest.raises(LogArgumentError, match="message: expected a std_msgs/msg/Float64 for /motor_torque, "
                                                   "got 'sensor_msgs/msg/JointState'"):
            recorder.write("/motor_torque", JointState(), 0)
        with pytest.raises(LogArgumentError, match="log_time_ns: expected 0 <= ns < 2\\*\\*64, got -1"):
            recorder.write("/motor_torque", Float64(), -1)
        with pytest.raises(LogArgumentError, match="data: expected a mapping of str to str"):
            recorder.add_metadata("finger_sim", {"dt": 0.001})  # type: ignore[dict-item]
        assert recorder.write("/motor_torque", {"data": 2.5}, 0)  # plain fields are encoded from the schema
    assert not problems
    assert not recorder.write("/motor_torque", Float64(), 1)
    assert not recorder.write("/motor_torque", Float64(), 2)
    assert (recorder.written, recorder.dropped, len(problems)) == (1, 2, 1)
    with pytest.raises(RecorderStateError, match="cannot register a channel: the recorder is closed"):
        recorder.register_channel("/clock", Clock)


def test_writes_from_many_threads_keep_per_channel_sequences(tmp_path: Path) -> None:
    path, per_thread, threads = tmp_path / "threads.mcap", 200, 4
    with McapRecorder(path) as recorder:
        recorder.register_channel("/motor_torque", Float64)
        workers = [threading.Thread(target=lambda: [recorder.write("/motor_torque", Float64(), 0)
                                                    for _ in range(per_thread)]) for _ in range(threads)]
        for w in workers:
            w.start()
        for w in workers:
            w.join(DEADLINE_S)
    with path.open("rb") as file:
        sequences = [m.sequence for _, _, m in make_reader(file).iter_messages(log_time_order=False)]
    assert sorted(sequences) == list(range(1, per_thread * threads + 1))
