"""finger_node's CPU with a 1 kHz controller in the loop, on the events executor against the single one.

    python -m finger_sim.bench.executor_node_bench [--seconds 10] [--rounds 2] [--domain-id 62]

Each run starts finger_pd_controller and finger_node (finger_default, 1 kHz physics, joint_states
every step, recording on, `executor` events or single) in their own processes, waits for the node's
start line and WARMUP_S more, then reads both processes' CPU (utime + stime, all threads; the
node's with its log writer child) over --seconds of wall time. Runs alternate events, single,
events, single … (A B A B); the table gives each run and the medians, in cores (CPU s per wall s).
"""

from __future__ import annotations

import os
import statistics
import subprocess
import tempfile
import time
from pathlib import Path

from finger_sim.bench.processes import cpu_seconds, executor_command, start_node, stop, tree_cpu_seconds

KINDS = ("events", "single")
#: Wall s after the node's start line before measuring: the controller joins, caches warm up.
WARMUP_S = 8.0
#: Wall s for a node to print its start line (imports and numba's cache: a minute on a loaded machine).
START_TIMEOUT_S = 180.0


def wait_for_start(path: Path, proc: subprocess.Popen, what: str) -> None:
    """Wait until the node's start line ('realtime_factor 1; …') is in its log `path`."""
    deadline = time.monotonic() + START_TIMEOUT_S
    while not (path.exists() and "realtime_factor 1" in path.read_text(errors="replace")):
        if time.monotonic() > deadline or proc.poll() is not None:
            raise RuntimeError(f"{what} did not come up; see {path}")
        time.sleep(0.2)


def run(kind: str, seconds: float, env: dict[str, str], workdir: Path) -> tuple[float, float]:
    """One run: (node cores, controller cores)."""
    controller = start_node({"realtime_factor": 1.0}, workdir, env, module="finger_sim.ros.pd_controller", tag=f"ctrl_{kind}")
    node = start_node({"realtime_factor": 1.0, "publish_rate_hz": 0.0, "record": True, "record_dir": str(workdir / "bags"),
                       "executor": kind}, workdir, env, tag=kind)
    try:
        wait_for_start(workdir / f"node_{kind}.log", node, f"finger_node ({kind})")
        time.sleep(WARMUP_S)
        n0, c0, w0 = tree_cpu_seconds(node.pid), cpu_seconds(controller.pid), time.perf_counter()
        time.sleep(seconds)
        n1, c1, w1 = tree_cpu_seconds(node.pid), cpu_seconds(controller.pid), time.perf_counter()
    finally:
        stop(node)
        stop(controller)
    return (n1 - n0) / (w1 - w0), (c1 - c0) / (w1 - w0)


def main(argv: list[str] | None = None) -> int:
    args, env = executor_command("executor_node_bench", __doc__, argv, seconds=10.0, rounds=2, domain_id=62)
    cores: dict[str, list[tuple[float, float]]] = {k: [] for k in KINDS}
    with tempfile.TemporaryDirectory(prefix="executor_node_") as tmp:
        for r in range(args.rounds):
            for kind in KINDS:
                cores[kind].append(run(kind, args.seconds, env, Path(tmp)))
                print(f"round {r + 1} {kind}: node {cores[kind][-1][0]:.3f} cores, controller {cores[kind][-1][1]:.3f}", flush=True)
    print(f"load average at end: {os.getloadavg()}")
    print("| executor | node cores per run | node median | controller median |")
    print("|---|---|---:|---:|")
    for kind in KINDS:
        node = [n for n, _ in cores[kind]]
        print(f"| {kind} | {', '.join(f'{n:.3f}' for n in node)} | {statistics.median(node):.3f} | "
              f"{statistics.median(c for _, c in cores[kind]):.3f} |")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
