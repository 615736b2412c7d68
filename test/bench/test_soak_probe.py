"""finger_sim.bench.soak_probe: the CPU time it records for a thread against the thread's own
count (time.thread_time in the sampled process), and its policy and priority against chrt's."""

from __future__ import annotations

import csv
import os
import shutil
import subprocess
import sys

import pytest

from finger_sim.bench import soak_probe

pytestmark = pytest.mark.skipif(not sys.platform.startswith("linux"), reason="reads /proc")

#: CPU s the sampled process spins for, then sleeps while the probe takes its last samples.
SPIN_S = 0.3
CHILD = f"""
import time
print("up", flush=True)
t0 = time.thread_time()
while time.thread_time() - t0 < {SPIN_S}:
    pass
print(time.thread_time_ns(), flush=True)
time.sleep(0.5)
"""


def test_probe_records_a_threads_cpu_time_and_policy(tmp_path):
    wrap = ["chrt", "-f", "5"] if os.geteuid() == 0 and shutil.which("chrt") else []
    child = subprocess.Popen([*wrap, sys.executable, "-c", CHILD], stdout=subprocess.PIPE, text=True)
    assert child.stdout.readline() == "up\n"  # chrt has set the policy and exec'd Python: sampled earlier, it reads SCHED_OTHER
    out = tmp_path / "probe.csv"
    assert soak_probe.main(["--pid", str(child.pid), "--out", str(out), "--period", "0.02"]) == 0  # returns when it exits
    own_ns = int(child.stdout.read().split()[0])
    child.wait()
    rows = [r for r in csv.DictReader(out.open()) if int(r["tid"]) == child.pid]
    assert len(rows) >= 10
    assert abs(max(int(r["run_ns"]) for r in rows) - own_ns) < 0.02e9  # the last sample is taken during the sleep
    assert {(r["policy"], r["rtprio"]) for r in rows} == ({("1", "5")} if wrap else {("0", "0")})
    assert all(int(r["majflt"]) >= 0 and float(r["steal_s"]) >= 0 for r in rows)
