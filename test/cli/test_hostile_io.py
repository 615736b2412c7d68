"""Issue 20: nothing a command writes destroys data, nothing it reads is trusted blindly.

Every hostile input is built here: logs are written (and altered) through mcap_ros2's own
writer from a run of the Simulator, so resim's exact answer is known; a full disk is a writer
that raises ENOSPC half way; a FIFO, an alias bomb, a chunk that claims 3 GiB are made on the
spot. Exit statuses: 2 refused, 5 a log's states refused, 6 data of a damaged log lost.
"""

from __future__ import annotations

import errno
import math
import os
import struct
import time
from pathlib import Path

import numpy as np
import pytest
from mcap.reader import make_reader
from mcap.writer import Writer as McapWriter
from mcap_ros2.writer import Writer as Ros2Writer

from finger_sim import kinematics
from finger_sim.cli import EXIT_DATA_LOST, EXIT_ERROR, EXIT_INVALID_LOG, main
from finger_sim.errors import ConfigError, shown
from finger_sim.joints import JOINT_NAMES, joint_positions, joint_velocities
from finger_sim.log import message_definition
from finger_sim.run_log import FINGER_SIM_METADATA, CommandEvent, RunLogError, run_metadata
from finger_sim.runtime.commands import MAX_REQUESTED_SHOWN
from finger_sim.scene import load_scene
from finger_sim.simulate import Simulator
from helpers import blocked_recorder

ROOT = Path(__file__).resolve().parents[2]
PAPER = ROOT / "config" / "paper_flexion.yaml"
STEPS = 40  # states 0..STEPS of the paper scene at its 1 ms step
CHUNK_BYTES = 2048  # small chunks: the log has several, to damage one of them
#: A refusal is read by a person: a line, not a dump of the input.
MAX_LINE = 1000
#: Wall time within which a hostile input must be refused (the unbounded cases took minutes).
PROMPT_S = 20.0
#: That wall-time bound: in make test's half at normal priority (at nice 19 under load a sweep of 8 runs took 26 s).
pytestmark = pytest.mark.timing


def states() -> list[tuple[int, list[float], list[float]]]:
    """(stamp ns, joint positions, joint velocities) of the paper scene's first STEPS steps."""
    scene = load_scene(PAPER)
    sim = Simulator(scene, kernel="python")
    q_ext, alpha = kinematics.extended_pose(scene.params), kinematics.distal_offset(scene.params)
    out = []
    for n in range(STEPS + 1):
        out.append((round(n * scene.dt * 1e9), list(joint_positions(sim.q, q_ext, alpha)), list(joint_velocities(sim.v))))
        sim.step(None)
    return out


def write_log(path: Path, rows: list[tuple[int, list[float], list[float]]], *, record: dict[str, str] | None = None,
              chunk_size: int = CHUNK_BYTES) -> Path:
    """A finger_node-like log: the 'finger_sim' record and /joint_states, through mcap_ros2's writer."""
    scene = load_scene(PAPER)
    meta = run_metadata(scene, method=scene.method, method_reason="", torque_source="scene", parameters={})
    if not rows:  # the channel declared, no message on it: mcap's plain writer (mcap_ros2's declares on write)
        with path.open("wb") as file:
            plain = McapWriter(file)
            plain.start(profile="ros2", library="test")
            plain.add_metadata(FINGER_SIM_METADATA, {**meta, **(record or {})})
            schema_id = plain.register_schema("sensor_msgs/msg/JointState", "ros2msg",
                                              message_definition("sensor_msgs/msg/JointState").encode())
            plain.register_channel("/joint_states", "cdr", schema_id)
            plain.finish()
        return path
    with path.open("wb") as file, Ros2Writer(file, chunk_size=chunk_size) as writer:
        writer.add_metadata(FINGER_SIM_METADATA, {**meta, **(record or {})})
        schema = writer.register_msgdef("sensor_msgs/msg/JointState", message_definition("sensor_msgs/msg/JointState"))
        for stamp, q, v in rows:
            msg = {"header": {"stamp": {"sec": stamp // 10**9, "nanosec": stamp % 10**9}, "frame_id": ""},
                   "name": list(JOINT_NAMES), "position": q, "velocity": v, "effort": [0.0] * 3}
            writer.write_message("/joint_states", schema, msg, log_time=stamp, publish_time=stamp)
    return path


def run(capsys: pytest.CaptureFixture[str], *argv: str | Path) -> tuple[int, str, str]:
    start = time.monotonic()
    code = main([str(a) for a in argv])
    assert time.monotonic() - start < PROMPT_S
    out, err = capsys.readouterr()
    assert "Traceback" not in err
    assert all(len(line) <= MAX_LINE for line in err.splitlines()), err[:300]
    return code, out, err


def error_line(err: str) -> str:
    errors = [line for line in err.splitlines() if ": error: " in line]
    assert len(errors) == 1, err
    return errors[0]


@pytest.fixture(scope="module")
def good_rows() -> list[tuple[int, list[float], list[float]]]:
    return states()


@pytest.fixture
def good_log(tmp_path: Path, good_rows) -> Path:
    return write_log(tmp_path / "run.mcap", good_rows)


def test_the_built_log_is_reproduced(capsys, good_log: Path) -> None:
    """The reference for what follows: resim of the untouched log is exact, export has every state."""
    code, out, _ = run(capsys, "resim", good_log)
    assert code == 0 and f"{STEPS + 1} recorded states reproduced bit for bit" in out


# -- (1) an output that is an input or another output ---------------------------------------------
def test_export_refuses_to_write_over_its_log(capsys, good_log: Path, tmp_path: Path) -> None:
    before = good_log.read_bytes()
    link = tmp_path / "link.csv"
    link.symlink_to(good_log)
    for target in (good_log, tmp_path / "." / "run.mcap", link):
        code, _, err = run(capsys, "export", good_log, "--csv", target)
        assert code == EXIT_ERROR
        assert "--csv: expected a file other than LOG (it would be overwritten)" in error_line(err)
    assert good_log.read_bytes() == before


def test_one_output_twice_and_the_scene_as_output_are_refused(capsys, tmp_path: Path) -> None:
    scene = tmp_path / "s.yaml"
    scene.write_bytes(PAPER.read_bytes())
    code, _, err = run(capsys, "simulate", scene, "--csv", scene)
    assert code == EXIT_ERROR and "--csv: expected a file other than SCENE" in error_line(err)
    assert scene.read_bytes() == PAPER.read_bytes()
    code, _, err = run(capsys, "simulate", scene, "--csv", tmp_path / "x.png", "--plot", tmp_path / "x.png")
    assert code == EXIT_ERROR and "--plot: expected a file other than --csv" in error_line(err)
    code, _, err = run(capsys, "sweep", scene, "--vary", "model.damping=0.001", "--out", scene)
    assert code == EXIT_ERROR and "--out: expected a file other than SCENE" in error_line(err)
    code, _, err = run(capsys, "urdf", scene, "-o", scene)
    assert code == EXIT_ERROR and "-o/--out: expected a file other than SCENE" in error_line(err)
    assert scene.read_bytes() == PAPER.read_bytes()


# -- (2) a full disk leaves the old file and no partial one -----------------------------------------
def test_a_full_disk_keeps_the_old_output(capsys, monkeypatch, tmp_path: Path) -> None:
    """A CSV writer that writes half a row and then raises ENOSPC, as a full disk does."""
    import finger_sim.streaming

    real = finger_sim.streaming.stream_csv

    def full_disk(scene, path, **kwargs):  # noqa: ANN001, ANN003
        with open(path, "w") as f:
            f.write("t,theta1\n0.0,0.1")
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))

    keep = tmp_path / "keep.csv"
    keep.write_text("the previous run\n")
    monkeypatch.setattr(finger_sim.streaming, "stream_csv", full_disk)
    code, _, err = run(capsys, "simulate", PAPER, "--csv", keep)
    assert code == EXIT_ERROR and "No space left on device" in error_line(err)
    assert keep.read_text() == "the previous run\n"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["keep.csv"]  # no partial file beside it
    monkeypatch.setattr(finger_sim.streaming, "stream_csv", real)
    code, _, _ = run(capsys, "simulate", PAPER, "--csv", keep)
    assert code == 0 and keep.read_text().startswith("t,theta1")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["keep.csv"]


# -- (4)-(6) states: none, non-finite, out of order, duplicated -----------------------------------
@pytest.mark.parametrize("command", ["export", "resim"])
@pytest.mark.parametrize(("alter", "problem"), [
    (lambda rows: [], "no joint states on /joint_states"),
    (lambda rows: rows[:5] + [(rows[5][0], [math.nan, *rows[5][1][1:]], rows[5][2])] + rows[6:],
     "/joint_states message 5 (stamp 0.005000000 s) holds a non-finite value (nan)"),
    (lambda rows: rows[:3] + [rows[4], rows[3]] + rows[5:], "/joint_states message 4 is stamped 0.003000000 s, before"),
    (lambda rows: rows[:3] + [rows[3], rows[3]] + rows[4:], "/joint_states message 4 repeats the stamp 0.003000000 s"),
])
def test_untrustworthy_states_are_refused(capsys, tmp_path: Path, good_rows, command: str, alter, problem: str) -> None:
    path = write_log(tmp_path / "bad.mcap", alter(list(good_rows)))
    csv = tmp_path / "out.csv"
    code, out, err = run(capsys, command, path, *(["--csv", csv] if command == "export" else []))
    assert code == EXIT_INVALID_LOG, out + err
    assert problem in error_line(err)
    assert "bit for bit" not in out and not csv.exists()


def test_a_nan_state_is_a_deviation_in_resim(good_rows) -> None:
    """Below the CLI's refusal: resimulate itself counts a NaN as a deviation, not as 'no larger'."""
    from finger_sim.log import read_log
    from finger_sim.run_log import load_run, resimulate

    import tempfile

    with tempfile.TemporaryDirectory() as folder:
        rows = list(good_rows)
        rows[7] = (rows[7][0], [math.nan, *rows[7][1][1:]], rows[7][2])
        result = resimulate(load_run(read_log(write_log(Path(folder) / "nan.mcap", rows))))
    assert not result.exact and result.max_deviation == math.inf and result.first_stamp_ns == rows[7][0]


# -- (7)-(9) bounded resources -------------------------------------------------------------------
BOMB = "a: &a [x, x, x, x, x, x, x, x, x, x]\n" + "".join(
    f"{c}: &{c} [{', '.join(['*' + p] * 10)}]\n" for p, c in zip("abcdefgh", "bcdefghi"))


@pytest.mark.parametrize("key", ["scene", "parameters"])
def test_an_alias_bomb_in_the_metadata_is_refused_at_once(capsys, tmp_path: Path, good_rows, key: str) -> None:
    path = write_log(tmp_path / "bomb.mcap", good_rows[:3], record={key: BOMB})
    code, _, err = run(capsys, "resim", path)
    assert code == EXIT_ERROR
    assert f"key '{key}'" in error_line(err) and "anchors and aliases are not allowed" in error_line(err)


def test_a_chunk_claiming_gigabytes_is_not_decompressed(capsys, tmp_path: Path, good_log: Path) -> None:
    """The zstd bomb: a small chunk whose uncompressed size says 3 GiB (in its record and its index)."""
    data = bytearray(good_log.read_bytes())
    with good_log.open("rb") as f:
        chunks = make_reader(f).get_summary().chunk_indexes
    claim = struct.pack("<Q", 3 << 30)
    first = chunks[0].chunk_start_offset
    data[first + 9 + 16:first + 9 + 24] = claim
    path = tmp_path / "bomb.mcap"
    path.write_bytes(bytes(data))
    claimed = f"corrupt record at byte {first}: chunk claims {3 << 30} bytes uncompressed"
    for command in ("export", "resim"):
        code, _, err = run(capsys, command, path)
        assert code == EXIT_ERROR, command
        assert claimed in error_line(err)
    code, out, err = run(capsys, "info", path)  # info reads on and reports the chunk as damaged
    assert code == EXIT_DATA_LOST and claimed in err and "1 DAMAGED" in out
    code, out, _ = run(capsys, "repair", path, "-o", tmp_path / "fixed.mcap")
    assert code == EXIT_DATA_LOST and "DROPPED 1 damaged part(s)" in out


def test_resim_applies_the_step_budget(capsys, tmp_path: Path, good_rows) -> None:
    """dt = 1e-12 s in the log's scene: its 40 ms of states are 4e10 steps, refused before the first."""
    scene = load_scene(PAPER).with_overrides(dt=1e-12, duration=0.05)
    path = write_log(tmp_path / "tiny_dt.mcap", good_rows, record={"scene": scene.to_yaml()})
    code, _, err = run(capsys, "resim", path)
    assert code == EXIT_ERROR
    assert "re-simulating the log takes 40,000,000,001 steps" in error_line(err) and "--max-steps" in error_line(err)


def test_error_messages_never_hold_a_huge_value() -> None:
    huge = list(range(10**6))
    assert len(str(ConfigError("key", "a number", huge))) < 200
    assert len(shown("x" * 10**7)) < 400
    with pytest.raises(RunLogError) as info:
        CommandEvent.from_values({"event": "accepted", "torque": "1" * 10**6, "step": "0"})
    assert len(str(info.value)) < 500


def test_a_refused_command_is_summarised() -> None:
    """A 10⁶-element command: the refusal names the count, the log keeps 8 values."""
    from finger_sim.runtime.commands import TorqueCommands
    from finger_sim.runtime.timeline import Timeline

    commands = TorqueCommands(Timeline(1e-3), max_torque=1.0, command_timeout=0.0, accepting=True)
    event = commands.take("effort_commands", [0.5] * 10**6, 0)
    assert event is not None and event.reason == "expected exactly 1 element, got 1000000"
    assert event.requested == ", ".join(["0.5"] * MAX_REQUESTED_SHOWN) + ", … (1000000 elements)"


# -- (3) damaged chunks: repair goes on, info checks CRCs, --salvage ----------------------------------
def _flip_in_chunk(log: Path, out: Path, index: int) -> tuple[int, int]:
    """One bit flipped in the middle of chunk `index`; (the chunk's offset, its message count)."""
    data = bytearray(log.read_bytes())
    with log.open("rb") as f:
        reader = make_reader(f)
        chunk = sorted(reader.get_summary().chunk_indexes, key=lambda c: c.chunk_start_offset)[index]
        inside = [m for _, _, m in reader.iter_messages(log_time_order=False)
                  if chunk.message_start_time <= m.log_time <= chunk.message_end_time]
    middle = chunk.chunk_start_offset + chunk.chunk_length // 2
    data[middle] ^= 0x10
    out.write_bytes(bytes(data))
    return chunk.chunk_start_offset, len(inside)


def test_repair_info_and_salvage_go_past_a_damaged_chunk(capsys, tmp_path: Path, good_log: Path) -> None:
    damaged = tmp_path / "damaged.mcap"
    offset, lost = _flip_in_chunk(good_log, damaged, 1)
    assert 0 < lost < STEPS
    code, out, _ = run(capsys, "info", damaged)
    assert code == EXIT_DATA_LOST and "Status:   complete" in out
    assert f"1 DAMAGED, holding {lost} messages" in out
    code, out, _ = run(capsys, "info", good_log)
    assert code == 0 and "pass their CRC" in out and "DAMAGED" not in out

    fixed = tmp_path / "fixed.mcap"
    code, out, _ = run(capsys, "repair", damaged, "-o", fixed)
    assert code == EXIT_DATA_LOST
    assert f"DROPPED 1 damaged part(s) holding at least {lost} messages; first at byte {offset}" in out
    with fixed.open("rb") as f:  # mcap's own reader: every message outside the damaged chunk is there
        kept = [m.log_time for _, _, m in make_reader(f).iter_messages(log_time_order=False)]
    assert len(kept) == STEPS + 1 - lost and max(kept) == STEPS * 1_000_000

    code, _, err = run(capsys, "resim", damaged)
    assert code == EXIT_ERROR and "fails its CRC" in error_line(err)
    code, out, err = run(capsys, "resim", damaged, "--salvage")
    assert code == EXIT_DATA_LOST and f"{STEPS + 1 - lost} recorded states reproduced bit for bit" in out
    assert f"warning: skipped {damaged}: corrupt record at byte {offset}" in err
    csv = tmp_path / "salvaged.csv"
    code, _, _ = run(capsys, "export", damaged, "--salvage", "--csv", csv)
    assert code == EXIT_DATA_LOST
    assert len(np.loadtxt(csv, delimiter=",", skiprows=1, ndmin=2)) == STEPS + 1 - lost


def test_repair_of_a_one_chunk_log_with_damage_says_so(capsys, tmp_path: Path, good_rows) -> None:
    log = write_log(tmp_path / "one.mcap", good_rows[:3], chunk_size=1 << 20)
    damaged = tmp_path / "damaged.mcap"
    _flip_in_chunk(log, damaged, 0)
    code, out, _ = run(capsys, "repair", damaged, "-o", tmp_path / "fixed.mcap")
    assert code == EXIT_DATA_LOST and ": 0 messages on 0 channels" in out and "holding at least 3 messages" in out


# -- (12) non-regular files, small items ------------------------------------------------------------
@pytest.mark.parametrize("command", ["simulate", "urdf", "resim"])
def test_a_fifo_is_refused_not_waited_on(capsys, tmp_path: Path, command: str) -> None:
    fifo = tmp_path / "scene.yaml"
    os.mkfifo(fifo)
    code, _, err = run(capsys, command, fifo)
    assert code == EXIT_ERROR
    assert "regular file" in error_line(err)


def test_a_scene_that_is_not_yaml_is_named_not_shown(capsys, tmp_path: Path) -> None:
    secret = tmp_path / "passwd"
    secret.write_text("root:x:0:0:root:/root:/bin/bash\n")
    code, _, err = run(capsys, "simulate", secret)
    assert code == EXIT_ERROR and str(secret) in error_line(err) and "root:x" not in err


def test_an_unknown_torque_key_is_named(tmp_path: Path) -> None:
    path = tmp_path / "s.yaml"
    path.write_text("input:\n  torque: {type: step, before: 0, after: 0.01, at: 0.1, foo: .nan}\n")
    with pytest.raises(ConfigError) as info:
        load_scene(path)
    assert "unknown key" in str(info.value) and "got 'foo'" in str(info.value)


# -- (10) sweep: counted before anything is built -------------------------------------------------
def test_a_huge_sweep_is_refused_from_its_counts(capsys, tmp_path: Path) -> None:
    """10⁸ combinations (eight keys of ten values): refused at once, in little memory, with the exact count."""
    import tracemalloc

    values = ",".join(f"{0.001 * (1 + k / 10):.4f}" for k in range(10))
    vary = [f"model.damping={values}", f"input.torque.slope={values}", f"model.spring_stiffness={values}",
            f"initial.theta1_dot={values}", f"name={','.join(f'run{k}' for k in range(10))}",
            f"initial.theta1={','.join(f'{k * 0.01:.2f}' for k in range(10))}", f"input.torque.offset={values}",
            f"duration={','.join(f'{0.1 + k * 0.01:.2f}' for k in range(10))}"]
    tracemalloc.start()
    try:
        code, _, err = run(capsys, "sweep", PAPER, *[a for v in vary for a in ("--vary", v)], "--out", tmp_path / "s.csv")
        _, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    dt = load_scene(PAPER).dt
    steps = 10**7 * sum(math.ceil((0.1 + k * 0.01) / dt - 1e-9) for k in range(10))
    assert code == EXIT_ERROR and f"100,000,000 runs, {steps:,} steps" in error_line(err)
    assert peak < 50 << 20 and not (tmp_path / "s.csv").exists()


def test_sweep_progress_is_a_few_lines_off_a_terminal(capsys, tmp_path: Path) -> None:
    code, _, err = run(capsys, "sweep", PAPER, "--vary", "model.damping=0.001,0.002,0.003,0.004,0.005,0.006,0.007,0.008",
                       "--vary", "duration=0.01", "--out", tmp_path / "s.csv")
    assert code == 0
    assert err.splitlines() == ["sweep: 8 of 8 runs (25 %)", "sweep: 8 of 8 runs (50 %)", "sweep: 8 of 8 runs (75 %)",
                                "sweep: 8 of 8 runs (100 %)"]


# -- the node: a FIFO scene, a namespace rmw refuses ---------------------------------------------
NODE_TIMEOUT_S = 60.0


@pytest.mark.parametrize("case", ["fifo", "namespace"])
def test_the_node_refuses_in_one_line(launcher, tmp_path: Path, case: str) -> None:
    pytest.importorskip("rclpy")
    params = {"record": False}
    ros_args: list[str] = []
    if case == "fifo":
        fifo = tmp_path / "scene.yaml"
        os.mkfifo(fifo)
        params["scene"] = str(fifo)
    else:
        ros_args = ["-r", "__ns:=/" + "a" * 250]
    node = launcher.node("finger_sim.ros.node", params, ros_args=ros_args)
    assert node.wait(NODE_TIMEOUT_S) == EXIT_ERROR, node.output()
    out = node.output()
    assert "Traceback" not in out
    errors = [line for line in out.splitlines() if "[ERROR]" in line]
    assert len(errors) == 1 and "cannot start: " in errors[0], out
    assert ("regular file" if case == "fifo" else "invalid node namespace") in errors[0]


def test_replay_names_a_topic_of_a_foreign_type(launcher, tmp_path: Path) -> None:
    """/joint_states recorded as std_msgs/msg/Float64: republished as recorded, with a warning naming both types."""
    pytest.importorskip("rclpy")
    import sys

    from finger_sim.log import McapRecorder

    path = tmp_path / "foreign_type.mcap"
    with McapRecorder(path) as rec:
        rec.register_channel("/joint_states", "std_msgs/msg/Float64", definition=message_definition("std_msgs/msg/Float64"))
        rec.write("/joint_states", {"data": 1.5}, 1_000_000)
    done = launcher.start([sys.executable, "-m", "finger_sim.ros.replay", str(path), "--no-clock"], "replay",
                          separate_stderr=True).finish(NODE_TIMEOUT_S)
    code, _, err = done
    assert code == 0, err
    warnings = [line for line in err.splitlines() if "warning" in line]
    assert warnings == ["finger_replay: warning: /joint_states: recorded as std_msgs/msg/Float64, not "
                        "sensor_msgs/msg/JointState as finger_node's topic of that name; republished as "
                        "std_msgs/msg/Float64, so subscribers expecting sensor_msgs/msg/JointState will not receive it"]


def test_the_recorder_queue_is_bounded_in_bytes(monkeypatch, tmp_path: Path) -> None:
    """Few but huge messages: dropped once the waiting bytes pass the bound, though the count is far below its own."""
    import finger_sim.log.recorder as recorder_module

    monkeypatch.setattr(recorder_module, "MAX_QUEUED_BYTES", 3000)
    with blocked_recorder(tmp_path) as (recorder, problems):
        recorder.register_channel("/blob", "std_msgs/msg/String", definition=message_definition("std_msgs/msg/String"))
        results = [recorder.write("/blob", b"\0" * 1000, i) for i in range(10)]
        assert results == [True] * 3 + [False] * 7  # 3000 bytes wait; a fourth 1000 would pass the bound
        assert recorder.dropped == 7
        assert len(problems) == 1 and "3 messages wait for the writer (3000 bytes; limits 10000 and 3000)" in problems[0]
