"""finger_node started under SCHED_FIFO (`chrt -f 20`, as a real-time simulation is deployed)
sets itself up as finger_sim.runtime.realtime says, read back from the kernel (/proc).

References: the scheduling policy and priority of each thread of the node and of its log's
writer process (/proc/<pid>/task/<tid>/stat), the locked memory (/proc/<pid>/status VmLck) and
the interpreter's switch interval (set in the node: seen as the node's log line only).
"""

from __future__ import annotations

import os
import shutil
import sys
import time
from pathlib import Path

import pytest

rclpy = pytest.importorskip("rclpy")

pytestmark = pytest.mark.skipif(os.geteuid() != 0 or shutil.which("chrt") is None, reason="needs root (as CI runs) and chrt")

BASE = 20
#: Wall s the node gets to start, set itself up and step.
START_TIMEOUT_S = 60.0


def sched(stat: Path) -> tuple[int, int]:
    """(policy, real-time priority) from a /proc stat file (fields 41 and 40)."""
    f = stat.read_text().rsplit(")", 1)[1].split()
    return int(f[38]), int(f[37])


def test_node_under_fifo_raises_its_stepping_thread_lowers_its_writer_and_locks_memory(launcher, tmp_path):
    node = launcher.start(["chrt", "-f", str(BASE), sys.executable, "-m", "finger_sim.ros.node", "--ros-args",
                           "-p", "realtime_factor:=1.0", "-p", f"record_dir:={tmp_path / 'bags'}"], "node")
    deadline = time.monotonic() + START_TIMEOUT_S
    while "the stepping thread runs at real-time priority" not in node.output():
        assert node.running() and time.monotonic() < deadline, node.output()
        time.sleep(0.1)
    threads = {int(t.name): sched(t / "stat") for t in Path(f"/proc/{node.pid}/task").iterdir()}
    children = [int(c) for t in Path(f"/proc/{node.pid}/task").glob("*/children") for c in t.read_text().split()]
    status = dict(line.split(":", 1) for line in Path(f"/proc/{node.pid}/status").read_text().splitlines())
    assert sorted(set(threads.values())) == [(os.SCHED_FIFO, BASE), (os.SCHED_FIFO, BASE + 1)]
    assert list(threads.values()).count((os.SCHED_FIFO, BASE + 1)) == 1  # the stepping thread alone
    assert len(children) == 1 and "writer_process" in Path(f"/proc/{children[0]}/cmdline").read_text()
    assert sched(Path(f"/proc/{children[0]}/stat")) == (os.SCHED_FIFO, BASE - 1)
    assert int(status["VmLck"].split()[0]) > int(status["VmRSS"].split()[0]) // 2 > 0
    assert (f"real-time policy at priority {BASE}: memory locked as touched (mlockall); GIL switch interval 0.5 ms; "
            f"child process {children[0]} at priority {BASE - 1}") in node.output()
