"""A stepping node under a real-time policy publishes through Fast DDS's asynchronous writer
thread unless the user chose a mode (finger_sim.ros.publication_mode): no priority inversion on
a subscriber's shared-memory lock. At a normal policy it keeps rmw's synchronous default.

Reference: Fast DDS's own threads in /proc/<pid>/task/*/comm. ASYNCHRONOUS publishers run a
flow-controller thread (dds.asyn.*) that synchronous ones do not: a node under `chrt -f` started
without the variable has as many as one started with the user's ASYNCHRONOUS, more than one with
SYNCHRONOUS (before the change it had SYNCHRONOUS's), and at a normal policy as many as SYNCHRONOUS.
"""

from __future__ import annotations

import os
import shutil
import sys
from pathlib import Path

import pytest

rclpy = pytest.importorskip("rclpy")

from sensor_msgs.msg import JointState  # noqa: E402

from finger_sim.ros.publication_mode import PREFERRED_MODE, PUBLICATION_MODE_VAR, prefer_async_publication  # noqa: E402

#: Prefix of the names of Fast DDS's asynchronous writer threads.
ASYNC_THREAD = "dds.asyn."
#: SCHED_FIFO priority of the node under test (low: it runs briefly beside everything else).
FIFO_PRIORITY = 1


def test_the_users_mode_wins_and_a_normal_policy_keeps_the_default():
    assert prefer_async_publication(env := {}, os.SCHED_FIFO) == PREFERRED_MODE == "ASYNCHRONOUS"
    assert env == {PUBLICATION_MODE_VAR: PREFERRED_MODE}
    assert prefer_async_publication(env := {PUBLICATION_MODE_VAR: "SYNCHRONOUS"}, os.SCHED_RR) == "SYNCHRONOUS"
    assert env == {PUBLICATION_MODE_VAR: "SYNCHRONOUS"}
    assert prefer_async_publication(env := {}, os.SCHED_OTHER) is None and env == {}


def async_threads(pid: int) -> int:
    return sum(p.read_text().startswith(ASYNC_THREAD) for p in Path(f"/proc/{pid}/task").glob("*/comm"))


@pytest.mark.skipif(os.geteuid() != 0 or not shutil.which("chrt"), reason="a node under SCHED_FIFO needs root and chrt")
def test_finger_node_under_fifo_publishes_asynchronously_unless_told_otherwise(launcher, ros_client):
    assert os.sched_getscheduler(0) == os.SCHED_OTHER
    states = ros_client.collect(JointState, "/joint_states")
    counts = {}
    runs = ((None, True), ("ASYNCHRONOUS", True), ("SYNCHRONOUS", True), (None, False))
    for i, (mode, fifo) in enumerate(runs):
        launcher.env.pop(PUBLICATION_MODE_VAR, None)
        if mode is not None:
            launcher.env[PUBLICATION_MODE_VAR] = mode
        prefix = f"run{i}_"  # this node's joint names: states still queued from the last node do not count
        path = launcher.tmp / f"{prefix}params.yaml"
        path.write_text(f"/**:\n  ros__parameters:\n    record: false\n    frame_prefix: {prefix}\n")
        chrt = ["chrt", "-f", str(FIFO_PRIORITY)] if fifo else []
        node = launcher.start(chrt + [sys.executable, "-m", "finger_sim.ros.node", "--ros-args", "--params-file", str(path)],
                              f"node{i}")
        ros_client.wait_for(lambda: sum(s.name[0].startswith(prefix) for s in states) > 10,
                            f"joint_states from the node ({mode or 'default'} mode, fifo {fifo})")
        counts[mode, fifo] = async_threads(node.pid)
        node.stop()
    assert counts[None, True] == counts["ASYNCHRONOUS", True] > counts["SYNCHRONOUS", True] == counts[None, False], counts
