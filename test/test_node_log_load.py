"""finger_node's log under stress: a kill -9 after a pause, a run as fast as possible, a slow recorder.

References: the node's own answers (the step at which ~/pause stopped it), the count of steps
it ran, and the logs read back by finger_sim.log.reader (a linear scan, so a killed node's
file is read up to its last whole chunk) and by rosbags (an independent reader).
"""

from __future__ import annotations

import signal
import time
from pathlib import Path

import pytest

rclpy = pytest.importorskip("rclpy")

from sensor_msgs.msg import JointState  # noqa: E402
from std_msgs.msg import Float64  # noqa: E402
from std_srvs.srv import SetBool  # noqa: E402

from finger_sim.log.reader import LogReader  # noqa: E402
from finger_sim.ros import conversions  # noqa: E402

NODE = "finger_sim.ros.node"
CONFIG = Path(__file__).resolve().parents[1] / "config"
PAPER = CONFIG / "paper_flexion.yaml"
DT_NS = 1_000_000
#: Wall time the test waits while paused before the kill: longer than the recorder's 1 s
#: wall-time bound on an open chunk.
PAUSED_WAIT_S = 2.5
#: Period of the commands sent while paused: they are logged on arrival, so the recorder never
#: sits idle long enough for its idle flush.
COMMAND_PERIOD_S = 0.1


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
    end = time.monotonic() + PAUSED_WAIT_S
    while time.monotonic() < end:  # a controller that goes on sending while the sim is paused
        torque.publish(Float64(data=0.001))
        ros_client.spin(COMMAND_PERIOD_S)
    node.send_signal(signal.SIGKILL)
    node.wait(10.0)

    log = LogReader(the_log(tmp_path / "bags"))
    assert log.truncated  # no summary: killed
    logged = [conversions.from_time(m.msg.header.stamp) for m in log.messages("/joint_states")]
    assert logged == [n * DT_NS for n in range(step + 1)]
