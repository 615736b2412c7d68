"""LogReader: index and messages checked against mcap's reader, and every kind of bad log."""

from __future__ import annotations

import json
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest
# The messages written and read here are rclpy's: without ROS this module is skipped, the rest of
# the log layer runs.
pytest.importorskip("rclpy")

from conftest import allocate_domain_id, ros_environment  # noqa: E402

from builtin_interfaces.msg import Time  # noqa: E402
from mcap.reader import SeekingReader, make_reader  # noqa: E402
from mcap.writer import IndexType, Writer  # noqa: E402
from mcap_ros2.decoder import DecoderFactory  # noqa: E402
from mcap_ros2.writer import Writer as Ros2Writer  # noqa: E402
from rclpy.serialization import serialize_message  # noqa: E402
from rosgraph_msgs.msg import Clock  # noqa: E402
from sensor_msgs.msg import JointState  # noqa: E402
from std_msgs.msg import Float64  # noqa: E402

from finger_sim.log import (  # noqa: E402
    CorruptLogError,
    LogDecodeError,
    LogError,
    LogNotFoundError,
    LogReader,
    McapRecorder,
    MissingMetadataError,
    MissingTopicsError,
    NotMcapError,
    message_definition,
    read_log,
)
from finger_sim.run_log import FINGER_SIM_METADATA  # noqa: E402

STEPS = 101  # 0 .. 2 s at 50 Hz
DT_NS = 20_000_000
TOPICS = {"/joint_states": "sensor_msgs/msg/JointState", "/motor_torque": "std_msgs/msg/Float64",
          "/clock": "rosgraph_msgs/msg/Clock"}
METADATA = {"scene": "name: paper_flexion\ndt: 0.001\nduration: 2.0\n", "integrator": "rk4", "version": "0.1.0"}
SUBPROCESS_TIMEOUT_S = 60.0
MCAP_HEADER_OFFSET = 8  # the header record follows the 8-byte magic


def write_log(path: Path, *, metadata: bool = True) -> Path:
    with McapRecorder(path, chunk_interval_s=0.25) as recorder:
        recorder.register_channel("/joint_states", JointState)
        recorder.register_channel("/motor_torque", Float64)
        recorder.register_channel("/clock", Clock)
        if metadata:
            recorder.add_metadata(FINGER_SIM_METADATA, METADATA)
            recorder.add_metadata("operator_notes", {"note": "bench run"})
        for k in range(STEPS):
            t = k * DT_NS
            recorder.write("/joint_states", JointState(name=["mcp_joint"], position=[0.01 * k]), t)
            recorder.write("/motor_torque", Float64(data=-0.5 * k), t)
            recorder.write("/clock", Clock(clock=Time(sec=t // 10**9, nanosec=t % 10**9)), t)
    return path


@pytest.fixture(scope="module")
def complete_log(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return write_log(tmp_path_factory.mktemp("log") / "run.mcap")


def fields(msg: object) -> object:
    """A message decoded by mcap_ros2 as nested dicts (its classes differ per decoder instance)."""
    if hasattr(type(msg), "_type"):
        return {name: fields(getattr(msg, name)) for name in type(msg).__slots__}
    return [fields(v) for v in msg] if isinstance(msg, list) else msg


def mcap_messages(path: Path) -> list[tuple[str, int, object]]:
    """(topic, log time, fields) in file order, by mcap + mcap_ros2: the reference reader."""
    with path.open("rb") as file:
        reader = make_reader(file, decoder_factories=[DecoderFactory()])
        return [(c.topic, m.log_time, fields(d)) for _, c, m, d in reader.iter_decoded_messages(log_time_order=False)]


def chunk_indexes(path: Path) -> list:
    with path.open("rb") as file:
        summary = SeekingReader(file).get_summary()
    assert summary is not None
    return sorted(summary.chunk_indexes, key=lambda c: c.chunk_start_offset)


def copy_with(source: Path, target: Path, *, cut: int | None = None, patch: tuple[int, bytes] | None = None) -> Path:
    data = bytearray(source.read_bytes())
    if patch is not None:
        offset, replacement = patch
        data[offset:offset + len(replacement)] = replacement
    target.write_bytes(bytes(data[:cut]))
    return target


def test_index_agrees_with_mcap_summary(complete_log: Path) -> None:
    log = read_log(complete_log, expected_topics=TOPICS)
    with complete_log.open("rb") as file:
        reader = SeekingReader(file)
        summary, header = reader.get_summary(), reader.get_header()
    assert summary is not None and summary.statistics is not None
    stats = summary.statistics
    assert (log.profile, log.library) == (header.profile, header.library) == ("ros2", log.library)
    assert {t: (i.type, i.encoding, i.count) for t, i in log.topics.items()} == {
        t: (type_name, "cdr", STEPS) for t, type_name in TOPICS.items()
    }
    assert list(log.topics) == sorted(TOPICS)
    assert (log.message_count, log.chunk_count) == (stats.message_count, stats.chunk_count)
    assert log.message_count == 3 * STEPS and log.chunk_count >= 2.0 / 0.25
    assert (log.start_ns, log.end_ns) == (stats.message_start_time, stats.message_end_time) == (0, 2 * 10**9)
    assert log.duration_s == 2.0
    assert log.size == complete_log.stat().st_size
    assert not log.truncated and log.truncation is None
    assert log.metadata_record(FINGER_SIM_METADATA) == METADATA
    assert log.metadata == {FINGER_SIM_METADATA: METADATA, "operator_notes": {"note": "bench run"}}


def test_messages_decode_in_file_order_with_a_topic_filter(complete_log: Path) -> None:
    log = LogReader(complete_log)
    everything = list(log.messages())
    assert [(m.topic, m.log_time_ns, fields(m.msg)) for m in everything] == mcap_messages(complete_log)
    torque = list(log.messages("/motor_torque"))
    assert [(m.log_time_ns, m.msg.data) for m in torque] == [(k * DT_NS, -0.5 * k) for k in range(STEPS)]
    two = list(log.messages(["/clock", "/joint_states"]))
    assert [(m.topic, fields(m.msg)) for m in everything if m.topic != "/motor_torque"] == [
        (m.topic, fields(m.msg)) for m in two
    ]
    assert two[-1].msg.clock.sec == 2 and two[-2].msg.position == [0.01 * (STEPS - 1)]
    with pytest.raises(MissingTopicsError, match=r"missing topics /tip \(topics present: /clock, /joint_states,"):
        log.messages(["/tip", "/clock"])


def test_info_reads_like_ros2_bag_info(complete_log: Path) -> None:
    log = LogReader(complete_log)
    lines = log.info(FINGER_SIM_METADATA).splitlines()  # labels padded to the longest, "Metadata:", plus one space
    assert lines[0] == f"File:     {complete_log}"
    assert lines[1] == f"Size:     {complete_log.stat().st_size / 1024:.1f} KiB"
    assert lines[2:8] == [
        "Status:   complete",
        f"Profile:  ros2 (written by {log.library})",
        "Duration: 2.000000000 s",
        "Start:    0.000000000 s",
        "End:      2.000000000 s",
        f"Messages: {3 * STEPS} in {log.chunk_count} chunks",
    ]
    assert lines[8:] == [
        "Topics:   /clock | rosgraph_msgs/msg/Clock | 101 msgs | cdr",
        "          /joint_states | sensor_msgs/msg/JointState | 101 msgs | cdr",
        "          /motor_torque | std_msgs/msg/Float64 | 101 msgs | cdr",
        "Metadata: finger_sim, operator_notes",
        "            integrator: rk4",
        f"            scene: <3 lines, {len(METADATA['scene'])} chars>",
        "            version: 0.1.0",
    ]


def test_missing_file(tmp_path: Path) -> None:
    path = tmp_path / "absent.mcap"
    with pytest.raises(LogNotFoundError) as err:
        read_log(path)
    assert str(err.value) == f"{path}: no such file"


@pytest.mark.parametrize(
    ("content", "looks_like"),
    [
        (b"", "the file is empty"),
        (b"SQLite format 3\x00" + bytes(100), "an SQLite database, e.g. a rosbag2 .db3 file"),
        (b"#ROSBAG V2.0\n" + bytes(100), "a ROS 1 bag"),
        (bytes(range(7, 107)), r"it starts with b'\x07\x08\t\n\x0b\x0c\r\x0e\x0f\x10\x11\x12\x13\x14\x15\x16'"),
    ],
    ids=["empty", "sqlite", "ros1", "random"],
)
def test_not_an_mcap_file(tmp_path: Path, content: bytes, looks_like: str) -> None:
    path = tmp_path / "other.mcap"
    path.write_bytes(content)
    with pytest.raises(NotMcapError) as err:
        read_log(path)
    assert str(err.value) == f"{path}: not an MCAP file ({looks_like})"


def test_a_directory_is_not_a_log(tmp_path: Path) -> None:
    with pytest.raises(NotMcapError, match="not an MCAP file \\(a directory; for a rosbag2 bag pass the .mcap"):
        read_log(tmp_path)


@pytest.mark.parametrize("where", ["inside_chunk", "at_chunk_start", "inside_message_index", "inside_header"])
def test_truncated_log_keeps_its_intact_prefix(complete_log: Path, tmp_path: Path, where: str) -> None:
    chunks, k = chunk_indexes(complete_log), 4
    reference = mcap_messages(complete_log)
    previous = chunks[k - 1]
    cut, offset, readable = {
        "inside_chunk": (chunks[k].chunk_start_offset + chunks[k].chunk_length // 2, chunks[k].chunk_start_offset,
                         [m for m in reference if m[1] <= previous.message_end_time]),
        "at_chunk_start": (chunks[k].chunk_start_offset, chunks[k].chunk_start_offset,
                           [m for m in reference if m[1] <= previous.message_end_time]),
        "inside_message_index": (previous.chunk_start_offset + previous.chunk_length + 5,
                                 previous.chunk_start_offset + previous.chunk_length,
                                 [m for m in reference if m[1] <= previous.message_end_time]),
        "inside_header": (MCAP_HEADER_OFFSET + 4, MCAP_HEADER_OFFSET, []),
    }[where]
    path = copy_with(complete_log, tmp_path / "cut.mcap", cut=cut)
    log = read_log(path)
    assert log.truncation is not None
    assert (log.truncation.offset, log.truncation.size, log.truncation.readable) == (offset, cut, len(readable))
    assert str(log.truncation) == (
        f"{path}: truncated at byte {offset} of {cut}: no summary, the last record is cut off or missing "
        f"(the recorder was killed, or its disk was full); the {len(readable)} messages before byte {offset} are readable"
    )
    assert [(m.topic, m.log_time_ns, fields(m.msg)) for m in log.messages()] == readable
    assert log.message_count == len(readable)
    assert f"Status:   TRUNCATED, truncated at byte {offset} of {cut}" in log.info(FINGER_SIM_METADATA)
    if readable:
        assert log.metadata_record(FINGER_SIM_METADATA) == METADATA  # written before the first chunk
        assert {t: i.count for t, i in log.topics.items()} == {t: len(readable) // 3 for t in TOPICS}


def test_corrupt_chunk_in_a_complete_log(complete_log: Path, tmp_path: Path) -> None:
    chunks, k = chunk_indexes(complete_log), 3
    bad = chunks[k]
    middle = bad.chunk_start_offset + bad.chunk_length // 2
    path = copy_with(complete_log, tmp_path / "corrupt.mcap", patch=(middle, b"\xff" * 16))
    log = read_log(path)  # the summary is intact: the damage shows when the chunk is read
    read = []
    with pytest.raises(CorruptLogError) as err:
        read.extend(log.messages())
    assert err.value.offset == bad.chunk_start_offset
    assert str(err.value).startswith(
        f"{path}: corrupt record at byte {bad.chunk_start_offset}: chunk does not decompress or fails its CRC"
    )
    assert len(read) == len([m for m in mcap_messages(complete_log) if m[1] <= chunks[k - 1].message_end_time])


def test_corrupt_chunk_in_a_truncated_log_fails_at_open(complete_log: Path, tmp_path: Path) -> None:
    chunks = chunk_indexes(complete_log)
    bad = chunks[2]
    path = copy_with(complete_log, tmp_path / "both.mcap", cut=chunks[5].chunk_start_offset + 7,
                     patch=(bad.chunk_start_offset + bad.chunk_length // 2, b"\x00" * 16))
    with pytest.raises(CorruptLogError, match=f"corrupt record at byte {bad.chunk_start_offset}: chunk"):
        read_log(path)


def test_bad_record_length_in_a_complete_log_is_corruption_not_truncation(complete_log: Path, tmp_path: Path) -> None:
    bad = chunk_indexes(complete_log)[3]
    length_field = bad.chunk_start_offset + 1  # after the opcode byte
    path = copy_with(complete_log, tmp_path / "length.mcap", patch=(length_field, (1 << 40).to_bytes(8, "little")))
    log = read_log(path)
    with pytest.raises(CorruptLogError, match=f"corrupt record at byte {bad.chunk_start_offset}: malformed record"):
        list(log.messages())


def test_missing_metadata_record(tmp_path: Path) -> None:
    path = write_log(tmp_path / "bare.mcap", metadata=False)
    with pytest.raises(MissingMetadataError) as err:
        read_log(path).metadata_record(FINGER_SIM_METADATA)
    assert str(err.value) == f"{path}: no metadata record 'finger_sim' (records present: none)"
    assert "Metadata: none" in read_log(path).info(FINGER_SIM_METADATA).splitlines()


def test_missing_expected_topics(complete_log: Path) -> None:
    with pytest.raises(MissingTopicsError) as err:
        read_log(complete_log, expected_topics=["/joint_states", "/fingertip_pose", "/diagnostics"])
    assert str(err.value) == (
        f"{complete_log}: missing topics /diagnostics, /fingertip_pose "
        "(topics present: /clock, /joint_states, /motor_torque)"
    )


def test_mcap_from_another_program_indexes_but_does_not_decode(tmp_path: Path) -> None:
    path = tmp_path / "json.mcap"
    with path.open("wb") as file:
        writer = Writer(file)
        writer.start(profile="", library="someone else")
        schema = writer.register_schema(name="Point", encoding="jsonschema", data=b'{"type": "object"}')
        channel = writer.register_channel(topic="/points", message_encoding="json", schema_id=schema)
        writer.add_message(channel, log_time=5, data=json.dumps({"x": 1}).encode(), publish_time=5)
        writer.finish()
    log = read_log(path)
    assert {t: (i.type, i.encoding, i.count) for t, i in log.topics.items()} == {"/points": ("Point", "json", 1)}
    with pytest.raises(LogDecodeError) as err:
        list(log.messages())
    assert str(err.value) == (f"{path}: cannot decode messages on /points: message encoding 'json' with schema "
                              "encoding 'jsonschema' is not ROS 2 CDR")


def test_complete_log_without_summary_is_scanned(tmp_path: Path) -> None:
    path = tmp_path / "no_summary.mcap"
    with path.open("wb") as file:
        writer = Writer(file, index_types=IndexType.NONE, repeat_channels=False, repeat_schemas=False,
                        use_statistics=False, use_summary_offsets=False)
        writer.start(profile="ros2", library="minimal")
        definition = message_definition("std_msgs/msg/Float64").encode()
        schema = writer.register_schema(name="std_msgs/msg/Float64", encoding="ros2msg", data=definition)
        channel = writer.register_channel(topic="/motor_torque", message_encoding="cdr", schema_id=schema)
        for k in range(3):
            writer.add_message(channel, log_time=k, data=serialize_message(Float64(data=k / 2)), publish_time=k)
        writer.finish()
    log = read_log(path)
    assert not log.truncated
    assert (log.message_count, log.chunk_count, log.start_ns, log.end_ns) == (3, 1, 0, 2)
    assert [m.msg.data for m in log.messages()] == [0.0, 0.5, 1.0]


def test_reads_a_file_from_mcap_ros2s_writer(tmp_path: Path) -> None:
    path = tmp_path / "other_writer.mcap"
    with path.open("wb") as file, Ros2Writer(file) as writer:
        definition = message_definition("sensor_msgs/msg/JointState")
        schema = writer.register_msgdef("sensor_msgs/msg/JointState", definition)
        for k in range(3):
            writer.write_message("/joint_states", schema, {"name": ["pip_joint"], "position": [k / 4]}, log_time=k)
    assert [(m.log_time_ns, m.msg.name, m.msg.position) for m in read_log(path).messages()] == [
        (k, ["pip_joint"], [k / 4]) for k in range(3)
    ]


def test_every_error_is_a_log_error() -> None:
    for error in (LogNotFoundError, NotMcapError, CorruptLogError, MissingMetadataError, MissingTopicsError,
                  LogDecodeError):
        assert issubclass(error, LogError)


READ_WITHOUT_ROS = textwrap.dedent("""
    import sys
    for name in ("rclpy", "sensor_msgs", "std_msgs", "rosgraph_msgs", "builtin_interfaces"):
        sys.modules[name] = None  # any import of these now fails
    from finger_sim.log import read_log
    log = read_log(sys.argv[1])
    print(sum(1 for _ in log.messages()))
    print(log.info().splitlines()[2])
""")


def test_reading_needs_no_ros(complete_log: Path) -> None:
    done = subprocess.run([sys.executable, "-c", READ_WITHOUT_ROS, str(complete_log)], capture_output=True,
                          text=True, timeout=SUBPROCESS_TIMEOUT_S, env=ros_environment(allocate_domain_id()), check=False)
    assert done.returncode == 0, done.stderr
    assert done.stdout.splitlines() == [str(3 * STEPS), "Status:   complete"]
