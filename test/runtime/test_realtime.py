"""finger_sim.runtime.realtime under a real-time policy: the priorities and the locked memory the
kernel reports in /proc (the reference), with privileges, without them, and switched off.

A stepping thread calls realtime.prepare() in a child interpreter started by `chrt -f 20` with a
child process of its own (as a node's log writer); the interpreter prints its /proc readings.
"""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys

import pytest

pytestmark = pytest.mark.skipif(not sys.platform.startswith("linux") or os.geteuid() != 0 or shutil.which("chrt") is None,
                                reason="needs Linux, root (as CI runs) and chrt")

BASE = 20


def throttling_lines(lines: list[str]) -> tuple[list[str], list[str]]:
    """(the lines about the kernel's real-time throttling, the others); checks the former against /proc."""
    runtime, period = (int(open(f"/proc/sys/kernel/sched_rt_{k}_us").read()) for k in ("runtime", "period"))
    about = [line for line in lines if "sched_rt_runtime_us" in line]
    if 0 <= runtime < period:
        assert about == [f"WARN kernel.sched_rt_runtime_us is {runtime} of kernel.sched_rt_period_us {period}: once the "
                         f"real-time threads of a CPU have run {runtime / 1e3:g} ms in a period, the kernel stops them for up "
                         f"to {(period - runtime) / 1e3:g} ms (a step that late); a real-time run sets it to -1 (sysctl, root)"]
    else:
        assert about == []
    return about, [line for line in lines if line not in about]
PROBE = r"""
import json, subprocess, threading
from pathlib import Path
from finger_sim.runtime import realtime
lines = []
child = subprocess.Popen(["sleep", "30"])
ready, release = threading.Event(), threading.Event()
def stepping():  # alive while /proc is read
    realtime.prepare(lambda m: lines.append("INFO " + m), lambda m: lines.append("WARN " + m))
    out["stepping"] = threading.get_native_id()
    ready.set()
    release.wait()
out = {}
thread = threading.Thread(target=stepping)
thread.start()
ready.wait()
def sched(stat):  # (policy, rt priority) from /proc/<pid>/stat fields 41 and 40
    f = Path(stat).read_text().rsplit(")", 1)[1].split()
    return int(f[38]), int(f[37])
out["threads"] = {int(t.name): sched(t / "stat") for t in Path("/proc/self/task").iterdir()}
out["child"] = sched(f"/proc/{child.pid}/stat")
status = dict(l.split(":", 1) for l in Path("/proc/self/status").read_text().splitlines())
out["vmlck_kb"], out["vmrss_kb"] = (int(status[k].split()[0]) for k in ("VmLck", "VmRSS"))
out["lines"] = lines
release.set()
child.kill()
print(json.dumps(out))
"""


def run_probe(*wrap: str, env: dict[str, str] | None = None) -> dict:
    argv = [*wrap, sys.executable, "-c", PROBE]
    done = subprocess.run(argv, capture_output=True, text=True, timeout=60, env={**os.environ, **(env or {})})
    assert done.returncode == 0, done.stderr
    return json.loads(done.stdout.splitlines()[-1])


def test_realtime_policy_raises_the_stepping_thread_lowers_the_child_and_locks_memory():
    out = run_probe("chrt", "-f", str(BASE))
    stepping = out["threads"].pop(str(out["stepping"]))
    assert stepping == [os.SCHED_FIFO, BASE + 1]
    assert set(map(tuple, out["threads"].values())) == {(os.SCHED_FIFO, BASE)}  # the main thread stays
    assert out["child"] == [os.SCHED_FIFO, BASE - 1]
    assert out["vmlck_kb"] >= out["vmrss_kb"] > 0  # every resident page locked
    assert throttling_lines(out["lines"])[1] == [f"INFO real-time policy at priority {BASE}: memory locked as touched (mlockall); GIL switch interval 0.5 ms; child process "
                            f"{out['lines'][0].split('child process ')[1].split()[0]} at priority {BASE - 1}",
                            f"INFO the stepping thread runs at real-time priority {BASE + 1}"]


def test_without_privileges_each_refused_step_is_named_and_the_rest_done():
    drop = "-sys_nice,-ipc_lock"
    out = run_probe("chrt", "-f", str(BASE), "setpriv", f"--bounding-set={drop}", f"--inh-caps={drop}")
    assert set(map(tuple, out["threads"].values())) == {(os.SCHED_FIFO, BASE)}
    assert out["child"] == [os.SCHED_FIFO, BASE - 1]  # lowering needs no privilege
    assert out["vmlck_kb"] == 0
    warnings = [line for line in throttling_lines(out["lines"])[1] if line.startswith("WARN")]
    assert len(warnings) == 2
    assert "mlockall failed" in warnings[0] and "CAP_IPC_LOCK" in warnings[0]
    assert f"stays at real-time priority {BASE} (raising it to {BASE + 1}: Operation not permitted)" in warnings[1]


@pytest.mark.parametrize("wrap, env", [(("chrt", "-f", str(BASE)), {"FINGER_SIM_REALTIME_SETUP": "0"}),
                                       ((), {})], ids=["switched-off", "normal-policy"])
def test_switched_off_or_under_a_normal_policy_nothing_changes(wrap, env):
    out = run_probe(*wrap, env=env)
    policy = (os.SCHED_FIFO, BASE) if wrap else (os.SCHED_OTHER, 0)
    assert set(map(tuple, out["threads"].values())) == {policy}
    assert tuple(out["child"]) == policy
    assert out["vmlck_kb"] == 0
    assert out["lines"] == ([f"INFO real-time policy at priority {BASE}; FINGER_SIM_REALTIME_SETUP=0: "
                             "scheduling and memory left as inherited"] if wrap else [])
