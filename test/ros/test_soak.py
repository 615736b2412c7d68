"""Soak (opt-in: FINGER_SIM_SOAK_S=<seconds>, e.g. 3600): finger_node at 1 kHz in real time with
recording on and the PD controller in a closed loop, answering every state.

Only the node runs under SCHED_FIFO (`chrt -f NODE_FIFO_PRIORITY`, as a real-time simulation is
deployed; FINGER_SIM_SOAK_FIFO=<priority>, 0 for a normal policy): the controller, this test and
anything beside it run at a normal policy. The controller is not part of the real-time budget: in
real time (not lockstep) the node never waits for it. The test checks both policies from /proc.

References: the node's resident memory with its child processes' (/proc/<pid>/status VmRSS), sampled every RSS_PERIOD_S,
must stay within RSS_BAND_MB of its value at the end of the warm-up; every /diagnostics window
after the warm-up must show a real-time factor of at least MIN_WINDOW_RTF. The samples are
written to soak.csv in the test's folder (and its path printed) for the report in docs/, the windows
(sim time, real-time factor, wall time received, latest wake-up, dropped steps) to soak_windows.csv.

    FINGER_SIM_SOAK_S=3600 FINGER_SIM_TEST_DOMAINS=65-69 .venv/bin/pytest -q -s -m soak test/ros/test_soak.py

(as root, at a normal policy: the test starts the node itself under SCHED_FIFO; docs/soak_realtime.md
has the probe to run beside it and the report.)
"""

from __future__ import annotations

import os
import shutil
import sys
import time
from pathlib import Path

import pytest

rclpy = pytest.importorskip("rclpy")

from diagnostic_msgs.msg import DiagnosticArray  # noqa: E402
import yaml  # noqa: E402
from rclpy.qos import QoSProfile  # noqa: E402

from conftest import Launcher, RosProcess  # noqa: E402
from finger_sim.ros import conversions  # noqa: E402

SOAK_S = float(os.environ.get("FINGER_SIM_SOAK_S", "0"))
pytestmark = [pytest.mark.soak,
              pytest.mark.skipif(SOAK_S <= 0, reason="opt-in: set FINGER_SIM_SOAK_S to the soak's duration in s"),
              pytest.mark.timeout(int(SOAK_S) + 600)]

#: Wall time after the first state before RSS and real-time factor are judged, s.
WARMUP_S = 60.0
RSS_PERIOD_S = 5.0
RSS_BAND_MB = 5.0
MIN_WINDOW_RTF = 0.99
#: SCHED_FIFO priority of the node (its stepping thread one above, its log writer one below:
#: finger_sim.runtime.realtime); 0 runs it at a normal policy.
NODE_FIFO_PRIORITY = int(os.environ.get("FINGER_SIM_SOAK_FIFO", "20"))


def policies(pid: int) -> set[tuple[int, int]]:
    """(policy, real-time priority) of every thread of `pid`, from /proc/<pid>/task/*/stat (fields 41 and 40)."""
    out = set()
    for stat in Path(f"/proc/{pid}/task").glob("*/stat"):
        fields = stat.read_text().rsplit(")", 1)[1].split()
        out.add((int(fields[38]), int(fields[37])))
    return out


def start_node(launcher: Launcher, params: dict) -> RosProcess:
    """finger_node with `params`, under `chrt -f NODE_FIFO_PRIORITY` unless that is 0."""
    path = launcher.tmp / "node.params.yaml"
    path.write_text(yaml.safe_dump({"/**": {"ros__parameters": params}}))
    chrt = ["chrt", "-f", str(NODE_FIFO_PRIORITY)] if NODE_FIFO_PRIORITY else []
    return launcher.start(chrt + [sys.executable, "-m", "finger_sim.ros.node", "--ros-args", "--params-file", str(path)], "node")


def rss_mb(pid: int) -> float:
    """Resident memory of `pid` and its child processes (the node's log writer), MB."""
    total = 0.0
    for line in Path(f"/proc/{pid}/status").read_text().splitlines():
        if line.startswith("VmRSS:"):
            total = int(line.split()[1]) / 1024
            break
    else:
        raise AssertionError(f"no VmRSS for pid {pid}")
    children = " ".join(p.read_text() for p in Path(f"/proc/{pid}/task").glob("*/children")).split()
    return total + sum(rss_mb(int(child)) for child in children)


def test_closed_loop_soak_holds_memory_and_real_time(launcher, ros_client, tmp_path):
    assert os.sched_getscheduler(0) == os.SCHED_OTHER, \
        "run the soak at a normal policy (no chrt): it starts the node alone under SCHED_FIFO"
    if NODE_FIFO_PRIORITY:
        assert os.geteuid() == 0 and shutil.which("chrt"), "a node under SCHED_FIFO needs root and chrt"
    controller = launcher.node("finger_sim.ros.pd_controller", dict(setpoint=0.8))
    node = start_node(launcher, dict(realtime_factor=1.0, command_qos="reliable", command_timeout=0.0))
    diagnostics: list[tuple[float, DiagnosticArray]] = []  # (wall time received, time.time() s, message)
    ros_client.node.create_subscription(DiagnosticArray, "/diagnostics", lambda m: diagnostics.append((time.time(), m)),
                                        QoSProfile(depth=10_000))
    ros_client.wait_for(lambda: diagnostics, "the first /diagnostics", 60.0)
    assert policies(controller.pid) == {(os.SCHED_OTHER, 0)}
    node_policy = os.SCHED_FIFO if NODE_FIFO_PRIORITY else os.SCHED_OTHER
    assert {p for p, _ in policies(node.pid)} == {node_policy}, node.output()
    start = time.monotonic()
    samples: list[tuple[float, float]] = []  # (wall s since start, RSS MB)
    while (elapsed := time.monotonic() - start) < SOAK_S:
        samples.append((elapsed, rss_mb(node.pid)))
        deadline = time.monotonic() + RSS_PERIOD_S
        while time.monotonic() < deadline:
            ros_client.spin(0.1)
        assert node.running(), node.output()
    windows = []  # (sim s, the window's real-time factor, commands received, wall s received, latest wake-up ms, dropped steps)
    for wall, d in diagnostics:
        v = conversions.parse_values(d.status[0])
        windows.append((float(v["clock"]), float(v["realtime_factor"]), int(v["commands_received"]), wall,
                        float(v["late_wakeup_max_ms"]), int(v["dropped_steps"])))
    out = tmp_path / "soak.csv"
    out.write_text("t_s,rss_mb\n" + "".join(f"{t:.1f},{m:.2f}\n" for t, m in samples))
    (tmp_path / "soak_windows.csv").write_text("sim_t_s,window_rtf,wall_s,late_wakeup_max_ms,dropped_steps\n" + "".join(
        f"{c:.3f},{r:.4f},{w:.3f},{lm:.2f},{ds}\n" for c, r, _, w, lm, ds in windows))
    judged = [m for t, m in samples if t >= WARMUP_S]
    base = judged[0]
    late = [(c, r) for c, r, *_ in windows if c >= WARMUP_S]
    worst = min(late, key=lambda w: w[1])
    print(f"\nsoak {SOAK_S:g} s: RSS {samples[0][1]:.1f} MB at start, {base:.1f} MB after warm-up, "
          f"{min(judged):.1f}..{max(judged):.1f} MB after it, {samples[-1][1]:.1f} MB at the end; "
          f"worst window RTF {worst[1]:.4f} at sim t = {worst[0]:.0f} s; {len(late)} windows, "
          f"{sum(r < MIN_WINDOW_RTF for _, r in late)} below {MIN_WINDOW_RTF}; "
          f"commands received {windows[-1][2]}; dropped steps {windows[-1][5]}; samples in {out}")
    assert max(abs(m - base) for m in judged) <= RSS_BAND_MB
    assert worst[1] >= MIN_WINDOW_RTF
