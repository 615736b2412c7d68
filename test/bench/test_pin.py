"""processes.pin: a process's threads on one CPU, its child processes' threads on another, as the kernel reports."""

from __future__ import annotations

import os
import subprocess
import sys
import time
from pathlib import Path

import pytest

from finger_sim.bench.processes import child_pids, pin

# A parent with a second thread, which starts a child that reports it is up; both then wait on stdin.
PARENT = """
import subprocess, sys, threading
threading.Thread(target=sys.stdin.read, daemon=True).start()
child = subprocess.Popen([sys.executable, "-c", "import sys; print('up', flush=True); sys.stdin.read()"],
                         stdin=subprocess.PIPE, stdout=sys.stdout)
sys.stdin.read()
child.stdin.close(); child.wait()
"""


@pytest.mark.skipif(len(os.sched_getaffinity(0)) < 2, reason="needs two CPUs")
def test_pin_puts_a_process_and_its_children_on_their_cpus() -> None:
    first, second = sorted(os.sched_getaffinity(0))[:2]
    parent = subprocess.Popen([sys.executable, "-c", PARENT], stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True)
    try:
        assert parent.stdout.readline().strip() == "up"  # the child is running
        children = child_pids(parent.pid)
        while len(list(Path(f"/proc/{parent.pid}/task").iterdir())) < 2:  # the parent's second thread
            time.sleep(0.01)
        pin(parent.pid, first, second)
        for owner, cpu in [(parent.pid, first), *((child, second) for child in children)]:
            tids = [int(task.name) for task in Path(f"/proc/{owner}/task").iterdir()]
            assert {tid: os.sched_getaffinity(tid) for tid in tids} == {tid: {cpu} for tid in tids}
        assert len(children) == 1 and len(list(Path(f"/proc/{parent.pid}/task").iterdir())) >= 2
    finally:
        parent.stdin.close()
        parent.wait(10)


def test_pin_outside_this_machine_is_a_one_line_error(capsys: pytest.CaptureFixture[str]) -> None:
    from finger_sim.bench import node_bench

    cpus = sorted(os.sched_getaffinity(0))
    with pytest.raises(SystemExit) as exit_:
        node_bench.main(["--recording-cpu", "--pin", "0", str(max(cpus) + 1)])
    assert exit_.value.code == 2
    assert capsys.readouterr().err.splitlines()[-1] == f"node_bench: error: --pin: two of the CPUs {cpus}, got 0 {max(cpus) + 1}"
