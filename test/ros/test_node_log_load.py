"""finger_node's log under stress: a kill -9 after a pause, a run as fast as possible, a slow recorder.

References: the node's own answers (the step at which ~/pause stopped it), the count of steps
it ran, and the logs read back by finger_sim.log.reader (a linear scan, so a killed node's
file is read up to its last whole chunk) and by rosbags (an independent reader).
"""

from __future__ import annotations

import contextlib
import os
import signal
from pathlib import Path

import pytest

rclpy = pytest.importorskip("rclpy")

from sensor_msgs.msg import JointState  # noqa: E402
from std_msgs.msg import Float64  # noqa: E402
from std_srvs.srv import SetBool  # noqa: E402

from finger_sim.cli import EXIT_INCOMPLETE  # noqa: E402
from finger_sim.log import RECORDING_STATUS  # noqa: E402
from finger_sim.log import writer_process  # noqa: E402
from finger_sim.log.errors import LogFileError  # noqa: E402
from finger_sim.log.reader import LogReader  # noqa: E402
from finger_sim.ros import conversions  # noqa: E402
from conftest import WAIT_TIMEOUT, Launcher, allocate_domain_id, ros_client_on, ros_environment, wait_until  # noqa: E402
from helpers import NODE, child_pids, run_cli, run_cli_here, wait_until_gone  # noqa: E402
from ros_helpers import resume  # noqa: E402

CONFIG = Path(__file__).resolve().parents[2] / "config"
PAPER = CONFIG / "paper_flexion.yaml"
DT_NS = 1_000_000
#: Period of the commands sent while paused: they are logged on arrival, so the recorder never
#: sits idle long enough for its idle flush.
COMMAND_PERIOD_S = 0.1
#: A queue of 50 messages between the stepping thread and the log's writer (which takes the
#: queue every handover, 0.5 s by default): far less than one handover of a 1 kHz run's 4 messages a step.
SMALL_QUEUE = 50


def the_log(folder: Path) -> Path:
    (path,) = folder.glob("*.mcap")
    return path


def test_a_kill_after_a_pause_keeps_the_paused_second(launcher, ros_client, tmp_path):
    """Issue 19 item 8: chunks close on sim time (60 s here) and on wall time (1 s); the node is
    paused at about 1 s of sim time while a controller keeps sending, then killed with SIGKILL.
    Every state up to the pause is in the file."""
    node = launcher.node(NODE, dict(scene=str(PAPER), realtime_factor=1.0, record_chunk_interval=60.0,
                                    command_qos="reliable", command_timeout=0.0))
    states = ros_client.collect(JointState, "/joint_states")
    torque = ros_client.publisher(Float64, "/motor_torque")
    ros_client.wait_for(lambda: states and conversions.from_time(states[-1].header.stamp) >= 1000 * DT_NS,
                        "a second of sim time")
    paused = ros_client.call(SetBool, "/finger_node/pause", SetBool.Request(data=True))
    assert paused.success, paused.message
    step = int(paused.message.split("step=")[1].split()[0])
    expected = [n * DT_NS for n in range(step + 1)]

    def paused_second_on_disk() -> bool:
        """Whether the file holds every state up to the pause: only the 1 s wall-time bound closes that
        chunk (its sim-time interval is 60 s, and the commands keep the recorder from idling)."""
        torque.publish(Float64(data=0.001))  # a controller that goes on sending while the sim is paused
        try:
            log = LogReader(the_log(tmp_path / "bags"))
            return [conversions.from_time(m.msg.header.stamp) for m in log.messages("/joint_states")] == expected
        except (ValueError, LogFileError):  # no file yet, or a record still being written
            return False

    # the event, not a wall time (a fixed 2.5 s wait here failed under load: the chunk closed later)
    wait_until(paused_second_on_disk, WAIT_TIMEOUT, "the paused second on disk",
               spin=lambda _: ros_client.spin(COMMAND_PERIOD_S))
    writers = child_pids(node.pid)
    node.send_signal(signal.SIGKILL)
    node.wait(10.0)
    wait_until_gone(writers)

    log = LogReader(the_log(tmp_path / "bags"))
    assert log.truncated  # no summary: killed
    logged = [conversions.from_time(m.msg.header.stamp) for m in log.messages("/joint_states")]
    assert logged == expected


def writer_pid(node_pid: int) -> int | None:
    """The node's log writer process once it runs the writer's code, else None. A child caught
    between fork and exec still runs the node's command line: stopping that one would stop the
    writer before it starts (the loaded CI did, and no message was ever dropped)."""
    for pid in child_pids(node_pid):
        with contextlib.suppress(OSError):
            if writer_process.__name__.encode() in Path(f"/proc/{pid}/cmdline").read_bytes():
                return pid
    return None


def scene_file(tmp_path: Path, duration: float) -> Path:
    """finger_default driven by a constant scripted torque for `duration` s."""
    text = (CONFIG / "finger_default.yaml").read_text()
    text = text.replace("torque: {type: constant, value: 0.0}", "torque: {type: constant, value: 0.01}")
    text = text.replace("duration: 3600.0", f"duration: {duration}")
    path = tmp_path / "held.yaml"
    path.write_text(text)
    return path


def read_rosbags(path: Path) -> dict[str, list]:
    """Messages by topic, by rosbags (an independent reader)."""
    from rosbags.highlevel import AnyReader

    out: dict[str, list] = {}
    with AnyReader([path]) as reader:
        for c, _, raw in reader.messages():
            out.setdefault(c.topic, []).append(reader.deserialize(raw, c.msgtype))
    return out


FAST_STEPS = 5000  # the run as fast as possible, 1 kHz steps
#: The real-time run that drops: long enough that, with its writer process stopped, its handovers
#: (about 460 B a step with markers) fill the recorder's 1 MB pipe (about 2300 steps), then the queue, with
#: a margin for a slow start.
DROP_STEPS = 8000


@pytest.fixture(scope="module")
def loaded_runs(tmp_path_factory) -> dict[str, tuple[int, str, Path]]:
    """The two runs of a small queue, started at once (each only runs its scene to the end):
    "fast" at realtime_factor 0, "drops" at 1, started paused and resumed once its writer process is
    stopped (until the node reports dropping). Kind → (exit status, output, log path)."""
    runs, launchers = {}, []
    try:
        for kind, steps, factor in (("fast", FAST_STEPS, 0.0), ("drops", DROP_STEPS, 1.0)):
            folder = tmp_path_factory.mktemp(kind)
            launchers.append(Launcher(ros_environment(allocate_domain_id()), folder))
            runs[kind] = (launchers[-1].node(NODE, dict(scene=str(scene_file(folder, steps / 1000)), torque_source="scene",
                                                        realtime_factor=factor, record_queue_size=SMALL_QUEUE,
                                                        start_paused=kind == "drops")), folder)
        node = runs["drops"][0]
        writer = wait_until(lambda: writer_pid(node.pid), 60.0, "the log's writer process")
        os.kill(writer, signal.SIGSTOP)  # a writer that cannot keep up: the pipe fills, then the queue
        try:
            # resumed only now: started running, a loaded machine could run the whole scene while the
            # writer started, leaving too few steps after the stop to fill the pipe (no drop in 60 s)
            with ros_client_on(int(launchers[-1].env["ROS_DOMAIN_ID"])) as client:
                resume(client, "/finger_node", timeout=60.0)
            wait_until(lambda: "dropping messages" in node.output(), 60.0, "the node's report of dropped messages")
        finally:
            os.kill(writer, signal.SIGCONT)
        return {kind: (node.wait(120.0), node.output(), folder / "bags") for kind, (node, folder) in runs.items()}
    finally:
        for launcher in launchers:
            launcher.stop_all()


def test_as_fast_as_possible_the_log_keeps_every_message(loaded_runs):
    """realtime_factor 0 with a queue far too small for the rate: the stepping waits for the
    writer (back-pressure), so every state, pose and clock tick of every step is in the log."""
    exit_status, output, bags = loaded_runs["fast"]
    assert exit_status == 0, output
    path = the_log(bags)
    log = read_rosbags(path)
    for topic in ("/joint_states", "/fingertip_pose"):
        assert [conversions.from_time(m.header.stamp) for m in log[topic]] == [n * DT_NS for n in range(FAST_STEPS + 1)]
    assert len(log["/clock"]) == FAST_STEPS + 1
    status = LogReader(path).metadata_record(RECORDING_STATUS)
    assert status["messages_dropped"] == "0"
    assert int(status["messages_recorded"]) == sum(len(v) for v in log.values())
    info = run_cli_here("info", path)  # `info` runs as a process on the dropping run's log
    assert info.returncode == 0 and "INCOMPLETE" not in info.stdout, info.stdout + info.stderr


def test_a_real_time_run_that_drops_says_so_in_its_log(loaded_runs, tmp_path):
    """realtime_factor 1 with the same small queue and a recorder slowed on purpose (its writer
    process stopped until the node reports dropping): messages are dropped, and the log says how
    many (its 'recording' record, written at close); `info` shows it; `export` and `resim` refuse
    the log (exit 7) unless --accept-incomplete."""
    exit_status, output, bags = loaded_runs["drops"]
    assert exit_status == 0, output
    path = the_log(bags)
    log = read_rosbags(path)
    status = LogReader(path).metadata_record(RECORDING_STATUS)
    dropped = int(status["messages_dropped"])
    by_topic = dict(item.split("=") for item in status["dropped_by_topic"].split(", "))
    assert dropped > 0 and sum(int(n) for n in by_topic.values()) == dropped
    assert int(status["messages_recorded"]) == sum(len(v) for v in log.values())  # all handed over reached the file
    states = len(log["/joint_states"])
    assert states + int(by_topic.get("/joint_states", 0)) == DROP_STEPS + 1  # every state: in the file or counted

    info = run_cli("info", path)
    assert info.returncode == 0 and f"INCOMPLETE: {dropped} messages dropped while recording" in info.stdout
    for command in (("resim", path), ("export", path, "--csv", tmp_path / "out.csv")):
        refused = run_cli_here(*command)
        assert refused.returncode == EXIT_INCOMPLETE, refused.stderr
        assert f"{dropped} messages were dropped while recording" in refused.stderr
        assert "--accept-incomplete" in refused.stderr
    accepted = run_cli_here("resim", path, "--accept-incomplete")
    assert accepted.returncode == 0, accepted.stdout + accepted.stderr  # the states that are there agree
    assert "warning" in accepted.stderr and "incomplete" in accepted.stderr
