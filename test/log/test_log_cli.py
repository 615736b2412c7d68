"""`finger-sim info | export | resim` on a real node log and on every kind of bad log.

References: the node log read by mcap + mcap_ros2 (not finger_sim's reader); spec §6 for the
paper coordinates of the logged joint states (θ1 = mcp + θ1_ext, θ2 = coupler + θ2_ext,
θ3 = pip + θ1 − α, rates likewise); spec §5 for θ(0.3 s) = (34.34°, 54.39°, −53.02°); and
`finger-sim simulate` of the same scene. Each command runs at least once as the installed console
script in a subprocess, as a user runs it (run_cli: simulate, info, export, resim, repair, and a bad
log to each of info, export and resim); the other cases call the same main() in this process
(run_cli_here). The node runs once per module, on a domain of its own.
"""

from __future__ import annotations

import csv
import io
import math
import subprocess
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pytest
from mcap.reader import make_reader
from mcap_ros2.decoder import DecoderFactory
from mcap_ros2.writer import Writer as Ros2Writer

from conftest import Launcher, allocate_domain_id, ros_environment
from finger_sim import kinematics
from finger_sim.log import message_definition
from finger_sim.scene import load_scene
from helpers import NODE, run_cli, run_cli_here

ROOT = Path(__file__).resolve().parents[2]
PAPER = ROOT / "config" / "paper_flexion.yaml"
CSV_HEADER = "t,theta1,theta2,theta3,theta1_dot,theta2_dot,theta3_dot,energy,constraint_residual"
JOINTS = ["mcp_joint", "coupler_joint", "pip_joint"]
PAPER_DEG = (34.34, 54.39, -53.02)  # spec §5: θ at t = 0.3 s, to the digits shown
CHUNK_S = 0.05  # record_chunk_interval of the node run: six chunks in 0.3 s, to cut and corrupt
NODE_TIMEOUT_S = 60.0
TOL = 1e-12  # rad, rad/s, J: against `finger-sim simulate`
EXIT_ERROR, EXIT_TRUNCATED = 2, 3


@dataclass(frozen=True)
class NodeLog:
    path: Path
    stamps: list[int]  # ns, of the joint states, in file order
    positions: np.ndarray  # (n, 3), JOINTS order
    velocities: np.ndarray
    chunks: list  # mcap ChunkIndex records, by offset
    counts: dict[str, int]  # topic → messages, from the summary
    types: dict[str, str]  # topic → schema name


def read_csv(path: Path) -> tuple[str, np.ndarray]:
    text = path.read_text()
    header, _, body = text.partition("\n")
    rows = [[float(x) for x in row] for row in csv.reader(io.StringIO(body)) if row]
    return header, np.array(rows).reshape(-1, 9)


def paper_coordinates(positions: np.ndarray, velocities: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Spec §6 inverted, written out here: (θ, θ') from (mcp, coupler, pip) and their rates."""
    p = load_scene(PAPER).params
    ext = kinematics.extended_pose(p)  # θ_ext: the assembly at θ1 = 0
    alpha = ext[0] - ext[2]  # α = θ1_ext − θ3_ext
    mcp, coupler, pip = positions.T
    t1 = mcp + ext[0]
    theta = np.column_stack([t1, coupler + ext[1], pip + t1 - alpha])
    w1, w2, wp = velocities.T
    return theta, np.column_stack([w1, w2, wp + w1])


def single_error_line(done: subprocess.CompletedProcess) -> str:
    assert "Traceback" not in done.stdout + done.stderr, done.stderr
    lines = done.stderr.splitlines()
    assert len(lines) == 1, done.stderr
    return lines[0]


@pytest.fixture(scope="module")
def node_log(tmp_path_factory: pytest.TempPathFactory) -> NodeLog:
    """The paper's run through finger_node (scene torque, as fast as possible), logged once."""
    pytest.importorskip("rclpy")
    tmp = tmp_path_factory.mktemp("node_log")
    launcher = Launcher(ros_environment(allocate_domain_id()), tmp)
    try:
        node = launcher.node(NODE, dict(scene=str(PAPER), torque_source="scene", realtime_factor=0.0,
                                        record_dir=str(tmp / "bags"), record_chunk_interval=CHUNK_S))
        assert node.wait(NODE_TIMEOUT_S) == 0, node.output()
    finally:
        launcher.stop_all()
    (path,) = sorted((tmp / "bags").glob("*.mcap"))
    stamps, positions, velocities = [], [], []
    with path.open("rb") as file:
        reader = make_reader(file, decoder_factories=[DecoderFactory()])
        summary = reader.get_summary()
        for _, _, message, js in reader.iter_decoded_messages(topics=["/joint_states"], log_time_order=False):
            order = [list(js.name).index(n) for n in JOINTS]
            stamps.append(js.header.stamp.sec * 1_000_000_000 + js.header.stamp.nanosec)
            assert stamps[-1] == message.log_time
            positions.append([js.position[i] for i in order])
            velocities.append([js.velocity[i] for i in order])
    assert summary is not None and summary.statistics is not None
    counts = {c.topic: summary.statistics.channel_message_counts.get(c.id, 0) for c in summary.channels.values()}
    types = {c.topic: summary.schemas[c.schema_id].name for c in summary.channels.values()}
    chunks = sorted(summary.chunk_indexes, key=lambda c: c.chunk_start_offset)
    assert len(stamps) == 301 and len(chunks) >= 4, (len(stamps), len(chunks))
    return NodeLog(path, stamps, np.array(positions), np.array(velocities), chunks, counts, types)


@pytest.fixture(scope="module")
def simulated(tmp_path_factory: pytest.TempPathFactory) -> np.ndarray:
    """`finger-sim simulate` of the same scene (its dt is the node's 1 kHz)."""
    csv_path = tmp_path_factory.mktemp("simulate") / "sim.csv"
    done = run_cli("simulate", PAPER, "--csv", csv_path)
    assert done.returncode == 0, done.stderr
    header, rows = read_csv(csv_path)
    assert header == CSV_HEADER
    return rows


# -- good logs ----------------------------------------------------------------------------------
def test_info_lists_what_mcap_reads(node_log: NodeLog) -> None:
    done = run_cli("info", node_log.path)
    assert (done.returncode, done.stderr) == (0, ""), done.stderr
    lines = done.stdout.splitlines()
    assert lines[0] == f"File:     {node_log.path}"
    assert "Status:   complete" in lines and "Duration: 0.300000000 s" in lines
    assert f"Messages: {sum(node_log.counts.values())} in {len(node_log.chunks)} chunks" in lines
    topic_lines = [line.removeprefix("Topics:").strip() for line in lines if " | " in line]
    assert topic_lines == [f"{topic} | {node_log.types[topic]} | {node_log.counts[topic]} msgs | cdr"
                           for topic in sorted(node_log.counts)]
    assert "Metadata: finger_sim, recording" in lines and "            torque_source: scene" in lines


def test_export_is_the_logged_states_in_paper_coordinates(node_log: NodeLog, simulated: np.ndarray,
                                                          tmp_path: Path) -> None:
    out = tmp_path / "export.csv"
    done = run_cli("export", node_log.path, "--csv", out)
    assert (done.returncode, done.stderr) == (0, ""), done.stderr
    assert done.stdout.splitlines()[0] == f"{node_log.path}: 301 joint states of scene 'paper_flexion' (scene torque)"
    header, rows = read_csv(out)
    assert header == CSV_HEADER
    theta, rates = paper_coordinates(node_log.positions, node_log.velocities)
    np.testing.assert_array_equal(rows[:, 0], np.array(node_log.stamps) / 1e9)
    np.testing.assert_array_equal(rows[:, 1:4], theta)
    np.testing.assert_array_equal(rows[:, 4:7], rates)
    # the whole table, energy and residual included, is the offline run's
    assert rows.shape == simulated.shape
    np.testing.assert_allclose(rows, simulated, rtol=0, atol=TOL)
    assert np.all(rows[:, 8] < 1e-12)  # |Φ| stays at round-off


def test_export_reaches_the_papers_angles(node_log: NodeLog, simulated: np.ndarray, tmp_path: Path) -> None:
    out = tmp_path / "export.csv"
    assert run_cli_here("export", node_log.path, "--csv", out).returncode == 0
    _, rows = read_csv(out)
    final = rows[-1]
    assert final[0] == pytest.approx(0.3, abs=1e-15)
    assert tuple(round(math.degrees(a), 2) for a in final[1:4]) == PAPER_DEG
    np.testing.assert_allclose(final[1:4], simulated[-1, 1:4], rtol=0, atol=TOL)
    assert simulated[-1, 0] == pytest.approx(0.3, abs=1e-15)


ROS_HEADER = ("t,mcp_position,coupler_position,pip_position,mcp_velocity,coupler_velocity,pip_velocity,"
              "mcp_effort,coupler_effort,pip_effort,torque,tip_x,tip_y,tip_z,tip_qx,tip_qy,tip_qz,tip_qw,tip_pitch")
ROS_UNITS = "# units: s, rad, rad, rad, rad/s, rad/s, rad/s, N·m, N·m, N·m, N·m, m, m, m, 1, 1, 1, 1, rad"


def read_ros_csv(path: Path) -> np.ndarray:
    comment, header, _ = path.read_text().split("\n", 2)
    assert (comment, header) == (ROS_UNITS, ROS_HEADER)
    return np.loadtxt(path, delimiter=",", comments="#", skiprows=2, ndmin=2)


def test_export_ros_columns_are_the_logged_messages(node_log: NodeLog, tmp_path: Path) -> None:
    """--columns ros against what the node published, read by mcap_ros2: joint_states' positions,
    velocities and efforts as logged, and fingertip_pose's position and orientation."""
    out = tmp_path / "ros.csv"
    done = run_cli_here("export", node_log.path, "--csv", out, "--columns", "ros")
    assert (done.returncode, done.stderr) == (0, ""), done.stderr  # no progress output off a terminal
    rows = read_ros_csv(out)
    efforts, poses = [], []
    with node_log.path.open("rb") as file:
        reader = make_reader(file, decoder_factories=[DecoderFactory()])
        for _, channel, _, msg in reader.iter_decoded_messages(topics=["/joint_states", "/fingertip_pose"],
                                                               log_time_order=False):
            if channel.topic == "/joint_states":
                efforts.append([msg.effort[list(msg.name).index(n)] for n in JOINTS])
            else:
                p, o = msg.pose.position, msg.pose.orientation
                poses.append([p.x, p.y, p.z, o.x, o.y, o.z, o.w])
    np.testing.assert_array_equal(rows[:, 0], np.array(node_log.stamps) / 1e9)
    np.testing.assert_allclose(rows[:, 1:4], node_log.positions, rtol=0, atol=TOL)  # through θ and back
    np.testing.assert_allclose(rows[:, 4:7], node_log.velocities, rtol=0, atol=TOL)
    np.testing.assert_allclose(rows[:, 7:10], np.array(efforts), rtol=0, atol=1e-15)
    np.testing.assert_array_equal(rows[:, 10], rows[:, 7])  # torque: the motor's, at mcp_joint
    np.testing.assert_allclose(rows[:, 11:18], np.array(poses), rtol=0, atol=TOL)
    np.testing.assert_allclose(2 * np.arctan2(rows[:, 15], rows[:, 17]), rows[:, 18], rtol=0, atol=TOL)


def test_every_thins_both_column_sets_and_simulate_agrees(node_log: NodeLog, simulated: np.ndarray,
                                                          tmp_path: Path) -> None:
    for columns in ("paper", "ros"):
        out = tmp_path / f"{columns}.csv"
        assert run_cli_here("export", node_log.path, "--csv", out, "--columns", columns, "--every", "7").returncode == 0
        rows = read_ros_csv(out) if columns == "ros" else read_csv(out)[1]
        assert len(rows) == math.ceil(301 / 7)
        np.testing.assert_array_equal(rows[:, 0], np.array(node_log.stamps[::7]) / 1e9)
    np.testing.assert_allclose(read_csv(tmp_path / "paper.csv")[1], simulated[::7], rtol=0, atol=TOL)
    # simulate --columns ros (streamed): the same scene offline, spec §6's efforts from its own torque
    sim_out = tmp_path / "sim_ros.csv"
    done = run_cli_here("simulate", PAPER, "--csv", sim_out, "--columns", "ros", "--every", "7")
    assert (done.returncode, done.stderr) == (0, ""), done.stderr
    sim_rows, logged = read_ros_csv(sim_out), read_ros_csv(tmp_path / "ros.csv")
    np.testing.assert_allclose(sim_rows[:, [0, 1, 2, 3, 4, 5, 6, 9, 11, 12, 13, 14, 15, 16, 17, 18]],
                               logged[:, [0, 1, 2, 3, 4, 5, 6, 9, 11, 12, 13, 14, 15, 16, 17, 18]], rtol=0, atol=TOL)
    scene = load_scene(PAPER)
    np.testing.assert_array_equal(sim_rows[:, 7], [scene.torque(t) for t in sim_rows[:, 0]])
    np.testing.assert_allclose(sim_rows[:, 9], -scene.spring_stiffness * sim_rows[:, 3], rtol=1e-15, atol=0)
    assert not sim_rows[:, 8].any()
    # and the same through the in-memory path (with --plot)
    both = tmp_path / "sim_plot.csv"
    assert run_cli_here("simulate", PAPER, "--csv", both, "--columns", "ros", "--every", "7",
                   "--plot", tmp_path / "p.png").returncode == 0
    np.testing.assert_array_equal(read_ros_csv(both), sim_rows)


def test_resim_reproduces_the_scene_run(node_log: NodeLog) -> None:
    done = run_cli("resim", node_log.path)
    assert (done.returncode, done.stderr) == (0, ""), done.stderr
    assert done.stdout.strip() == "resim: 301 recorded states reproduced bit for bit (max deviation 0)"


# -- bad logs -----------------------------------------------------------------------------------
RANDOM = bytes([0x8F]) + np.random.default_rng(7).bytes(4095)
TEXT = b"# finger_node log of Tuesday\nt,theta1\n0,0\n"


@pytest.mark.parametrize("command", ["info", "export", "resim"])
@pytest.mark.parametrize(
    ("content", "problem"),
    [
        (None, "no such file"),
        (b"", "not an MCAP file (the file is empty)"),
        (RANDOM, f"not an MCAP file (it starts with {RANDOM[:16]!r})"),
        (TEXT, "not an MCAP file (it starts with b'# finger_node lo')"),
    ],
    ids=["missing", "empty", "random", "text"],
)
def test_not_a_log(tmp_path: Path, command: str, content: bytes | None, problem: str) -> None:
    path = tmp_path / "run.mcap"
    if content is not None:
        path.write_bytes(content)
    done = (run_cli if content is TEXT else run_cli_here)(command, path)  # one process per command
    assert done.returncode == EXIT_ERROR
    assert single_error_line(done) == f"finger-sim {command}: error: {path}: {problem}"
    assert done.stdout == ""


@pytest.mark.parametrize("command", ["info", "export", "resim"])
def test_truncated_log_is_read_up_to_the_cut(node_log: NodeLog, tmp_path: Path, command: str) -> None:
    """Cut inside the fourth chunk (as a kill -9 leaves it): a warning, the intact part, exit 3."""
    k = 3
    chunk = node_log.chunks[k]
    cut = chunk.chunk_start_offset + chunk.chunk_length // 2
    path = tmp_path / "cut.mcap"
    path.write_bytes(node_log.path.read_bytes()[:cut])
    out = tmp_path / "cut.csv"
    done = run_cli_here(command, path, *(["--csv", out] if command == "export" else []))
    assert done.returncode == EXIT_TRUNCATED
    line = single_error_line(done)
    assert line.startswith(f"finger-sim: warning: {path}: truncated at byte {chunk.chunk_start_offset} of {cut}: "), line
    assert line.endswith(f"; reading the intact part (`finger-sim repair {path}` makes a complete copy)")
    intact = sum(t <= node_log.chunks[k - 1].message_end_time for t in node_log.stamps)
    assert 0 < intact < len(node_log.stamps)
    if command == "export":
        _, rows = read_csv(out)
        theta, _ = paper_coordinates(node_log.positions[:intact], node_log.velocities[:intact])
        np.testing.assert_array_equal(rows[:, 1:4], theta)  # the prefix, and only it
    elif command == "resim":
        assert done.stdout.strip() == f"resim: {intact} recorded states reproduced bit for bit (max deviation 0)"
    else:
        assert f"Status:   TRUNCATED, truncated at byte {chunk.chunk_start_offset} of {cut}" in done.stdout


@pytest.mark.parametrize("command", ["export", "resim"])
def test_corrupt_chunk(node_log: NodeLog, tmp_path: Path, command: str) -> None:
    """Bytes overwritten inside a chunk of a complete log (`info` and `--salvage`: test_hostile_io)."""
    chunk = node_log.chunks[2]
    data = bytearray(node_log.path.read_bytes())
    middle = chunk.chunk_start_offset + chunk.chunk_length // 2
    data[middle:middle + 16] = b"\xff" * 16
    path = tmp_path / "corrupt.mcap"
    path.write_bytes(bytes(data))
    done = run_cli_here(command, path)
    assert done.returncode == EXIT_ERROR
    line = single_error_line(done)
    assert line.startswith(f"finger-sim {command}: error: {path}: corrupt record at byte {chunk.chunk_start_offset}: "
                           "chunk does not decompress or fails its CRC"), line


@pytest.fixture
def foreign_log(tmp_path: Path) -> Path:
    """An MCAP from another program: mcap_ros2's own writer, joint states, no 'finger_sim' record."""
    path = tmp_path / "foreign.mcap"
    with path.open("wb") as file, Ros2Writer(file) as writer:
        schema = writer.register_msgdef("sensor_msgs/msg/JointState", message_definition("sensor_msgs/msg/JointState"))
        for k in range(3):
            writer.write_message("/joint_states", schema, {"name": JOINTS, "position": [k / 4, 0.0, 0.0],
                                                            "velocity": [0.0] * 3}, log_time=k * 1_000_000)
    return path


@pytest.mark.parametrize("command", ["export", "resim"])
def test_log_from_another_program(foreign_log: Path, command: str) -> None:
    done = run_cli_here(command, foreign_log)
    assert done.returncode == EXIT_ERROR
    assert single_error_line(done) == (f"finger-sim {command}: error: {foreign_log}: no metadata record 'finger_sim' "
                                       "(records present: none)")


def test_info_describes_a_log_from_another_program(foreign_log: Path) -> None:
    """A valid MCAP is not an error for `info` (as for `ros2 bag info`): it says what is there."""
    done = run_cli_here("info", foreign_log)
    assert (done.returncode, done.stderr) == (0, "")
    assert "Topics:   /joint_states | sensor_msgs/msg/JointState | 3 msgs | cdr" in done.stdout.splitlines()
    assert "Metadata: none" in done.stdout.splitlines()


# -- cut at the end, foreign schemas, garbled metadata ----------------------------------------------
@pytest.mark.parametrize("missing", [1, 8, 9])
def test_info_calls_a_log_without_its_end_truncated(node_log: NodeLog, tmp_path: Path, missing: int) -> None:
    """Missing only the closing magic's last byte, all of it, or one byte more: not 'complete'."""
    path = tmp_path / "end.mcap"
    path.write_bytes(node_log.path.read_bytes()[:-missing])
    done = run_cli_here("info", path)
    assert done.returncode == EXIT_TRUNCATED, done.stdout
    assert "Status:   complete" not in done.stdout
    assert f"Messages: {sum(node_log.counts.values())} in {len(node_log.chunks)} chunks" in done.stdout.splitlines()
    assert single_error_line(done).startswith(f"finger-sim: warning: {path}: truncated at byte ")


def _rewritten(node_log: NodeLog, path: Path, *, schema_name: str, definition: str,
               metadata: dict[str, str] | None = None) -> Path:
    """The node log's metadata and one joint state on /joint_states, under another schema."""
    from finger_sim.log import read_log
    from finger_sim.run_log import FINGER_SIM_METADATA

    record = read_log(node_log.path).metadata_record(FINGER_SIM_METADATA)
    with path.open("wb") as file, Ros2Writer(file) as writer:
        writer.add_metadata(FINGER_SIM_METADATA, {**record, **(metadata or {})})
        schema = writer.register_msgdef(schema_name, definition)
        writer.write_message("/joint_states", schema, {"data": 0.25, "name": JOINTS, "position": [0.0] * 3,
                                                        "velocity": [0.0] * 3}, log_time=0)
    return path


@pytest.mark.parametrize("command", ["export", "resim"])
@pytest.mark.parametrize(("schema_name", "definition", "problem"), [
    ("std_msgs/msg/Float64", "float64 data", "topic /joint_states: expected schema sensor_msgs/msg/JointState, "
                                             "got std_msgs/msg/Float64"),
    ("sensor_msgs/msg/JointState", "float64 data\nstring[] name", "topic /joint_states: the sensor_msgs/msg/JointState "
                                                                 "schema in the log lacks float64[] position, "
                                                                 "float64[] velocity: a foreign definition"),
])
def test_foreign_joint_state_schema_is_refused(node_log: NodeLog, tmp_path: Path, command: str, schema_name: str,
                                               definition: str, problem: str) -> None:
    path = _rewritten(node_log, tmp_path / "foreign_schema.mcap", schema_name=schema_name, definition=definition)
    done = run_cli_here(command, path)
    assert done.returncode == EXIT_ERROR
    assert single_error_line(done) == f"finger-sim {command}: error: {path}: {problem}"


@pytest.mark.parametrize("command", ["export", "resim"])
@pytest.mark.parametrize(("metadata", "problem"), [
    ({"scene": "model: [unclosed"}, "metadata record 'finger_sim', key 'scene' does not parse as a scene: "),
    ({"scene": "integrator: {method: [rk4]}"}, "metadata record 'finger_sim', key 'scene' does not parse as a scene: "),
    ({"torque_source": "joystick"}, "metadata record 'finger_sim', key 'torque_source': expected one of "
                                    "['topic', 'scene'], got 'joystick'"),
])
def test_metadata_that_does_not_parse_is_one_line(node_log: NodeLog, tmp_path: Path, command: str,
                                                  metadata: dict[str, str], problem: str) -> None:
    path = _rewritten(node_log, tmp_path / "bad_meta.mcap", schema_name="sensor_msgs/msg/JointState",
                      definition=message_definition("sensor_msgs/msg/JointState"), metadata=metadata)
    done = run_cli_here(command, path)
    assert done.returncode == EXIT_ERROR
    assert single_error_line(done).startswith(f"finger-sim {command}: error: {path}: {problem}")


# -- repair -----------------------------------------------------------------------------------------
def _independent_counts(path: Path) -> tuple[int, int]:
    """Messages of a log as rosbags and as mcap's seeking reader (from the summary) read them."""
    from rosbags.rosbag2 import Reader as RosbagsReader

    with RosbagsReader(path) as bag:
        by_rosbags = sum(1 for _ in bag.messages())
    with path.open("rb") as file:
        reader = make_reader(file)
        assert reader.get_summary() is not None
        by_mcap = sum(1 for _ in reader.iter_messages(log_time_order=False))
    return by_rosbags, by_mcap


def _cuts(node_log: NodeLog) -> dict[str, int]:
    data = node_log.path.read_bytes()
    size, header_end = len(data), 8 + 9 + int.from_bytes(data[9:17], "little")  # magic, opcode, length, body
    third = node_log.chunks[2]
    return {
        "inside the header": header_end - 5,  # not from the recorder (see test_log_recorder), but repairable
        "after the header": header_end,
        "mid-chunk": third.chunk_start_offset + third.chunk_length // 2,
        "at a chunk's start": third.chunk_start_offset,
        "after a chunk": third.chunk_start_offset + third.chunk_length,
        "in the summary": node_log.chunks[-1].chunk_start_offset + node_log.chunks[-1].chunk_length + 200,
        "at the end magic": size - 8,
        "one byte short": size - 1,
    }


@pytest.mark.parametrize("where", ["inside the header", "after the header", "mid-chunk", "at a chunk's start", "after a chunk",
                                   "in the summary", "at the end magic", "one byte short"])
def test_repair_makes_a_cut_log_whole(node_log: NodeLog, tmp_path: Path, where: str) -> None:
    """Every message up to the last intact chunk, read by rosbags and by mcap's own reader."""
    from rosbags.rosbag2 import Reader as RosbagsReader
    from rosbags.rosbag2 import ReaderError

    from finger_sim.log import read_log

    cut = _cuts(node_log)[where]
    path = tmp_path / "cut.mcap"
    path.write_bytes(node_log.path.read_bytes()[:cut])
    with pytest.raises(ReaderError):
        RosbagsReader(path).open()  # the problem repair solves
    ours = read_log(path)
    intact_chunks = [c for c in node_log.chunks if c.chunk_start_offset + c.chunk_length <= cut]
    last = max((c.message_end_time for c in intact_chunks), default=-1)
    with node_log.path.open("rb") as file:
        expected = sum(m.log_time <= last for _, _, m in make_reader(file).iter_messages(log_time_order=False))
    assert ours.message_count == expected

    done = run_cli_here("repair", path)
    assert (done.returncode, done.stderr) == (0, ""), done.stderr
    out = tmp_path / "cut.repaired.mcap"
    assert done.stdout.startswith(f"repaired {path} → {out}: {expected} messages")
    assert _independent_counts(out) == (expected, expected)
    repaired = read_log(out)
    assert not repaired.truncated and repaired.message_count == expected
    assert repaired.metadata == ours.metadata and repaired.profile == "ros2"
    assert [(t.topic, t.type, t.definition) for t in repaired.topics.values()] == \
           [(t.topic, t.type, t.definition) for t in ours.topics.values()]
    if expected:
        done = run_cli_here("resim", out)
        stamps = sum(s <= last for s in node_log.stamps)
        assert done.stdout.strip() == f"resim: {stamps} recorded states reproduced bit for bit (max deviation 0)"


def test_repair_keeps_every_message_of_a_complete_log(node_log: NodeLog, tmp_path: Path) -> None:
    out = tmp_path / "copy.mcap"
    done = run_cli("repair", node_log.path, "-o", out)
    assert done.returncode == 0, done.stderr
    total = sum(node_log.counts.values())
    assert _independent_counts(out) == (total, total)
    with node_log.path.open("rb") as a, out.open("rb") as b:
        original = [(m.channel_id, m.log_time, m.publish_time, m.sequence, m.data)
                    for _, _, m in make_reader(a).iter_messages(log_time_order=False)]
        copied = [(m.channel_id, m.log_time, m.publish_time, m.sequence, m.data)
                  for _, _, m in make_reader(b).iter_messages(log_time_order=False)]
    assert [m[1:] for m in copied] == [m[1:] for m in original]


def test_repair_refuses_to_overwrite_its_input(node_log: NodeLog, tmp_path: Path) -> None:
    path = tmp_path / "log.mcap"
    path.write_bytes(node_log.path.read_bytes()[:-100])
    before = path.read_bytes()
    done = run_cli_here("repair", path, "-o", tmp_path / "." / "log.mcap")
    assert done.returncode == EXIT_ERROR
    assert "-o/--out: expected a file other than LOG" in single_error_line(done)
    assert path.read_bytes() == before
