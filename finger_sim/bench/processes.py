"""Process and machine helpers of the node benchmarks (`node_bench`, `recording_bench`).

Starting and stopping a node in its own process group, its CPU time from /proc (in total and
by thread), the DDS isolation every process of a benchmark runs with, and the description of
the machine a report names.
"""

from __future__ import annotations

import argparse
import contextlib
import os
import platform
import signal
import subprocess
import sys
import time
from pathlib import Path

import yaml

#: The source checkout (docs/ lives here).
ROOT = Path(__file__).resolve().parents[2]
#: Wall-clock deadlines, s: a process coming up (DDS discovery included), and stopping after SIGINT.
START_TIMEOUT_S = 30.0
STOP_TIMEOUT_S = 10.0
#: Field indices of utime and stime in /proc/<pid>/stat after the command name (proc(5), counted from 0).
_UTIME, _STIME = 11, 12


def isolate_dds(domain_id: int) -> None:
    """Keep this process's DDS traffic on loopback, in its own domain (children inherit it)."""
    os.environ["ROS_DOMAIN_ID"] = str(domain_id)
    os.environ["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"
    os.environ.pop("ROS_LOCALHOST_ONLY", None)


def ros_env(domain_id: int) -> dict[str, str]:
    """Environment of a child ROS process: `domain_id`, loopback discovery only, unbuffered output."""
    env = dict(os.environ, ROS_DOMAIN_ID=str(domain_id), ROS_AUTOMATIC_DISCOVERY_RANGE="LOCALHOST", PYTHONUNBUFFERED="1")
    env.pop("ROS_LOCALHOST_ONLY", None)
    return env


def executor_command(prog: str, doc: str, argv: list[str] | None, *, seconds: float, rounds: int,
                     domain_id: int) -> tuple[argparse.Namespace, dict[str, str]]:
    """The command line of the executor benchmarks (`--seconds` measured per run, `--rounds`, `--domain-id`,
    defaults as given) and the environment of their child processes in that domain (`ros_env`). Prints
    the load average at start."""
    parser = argparse.ArgumentParser(prog=prog, description=doc.split("\n\n")[0])
    parser.add_argument("--seconds", type=float, default=seconds)
    parser.add_argument("--rounds", type=int, default=rounds)
    parser.add_argument("--domain-id", type=int, default=domain_id)
    args = parser.parse_args(argv)
    print(f"load average at start: {os.getloadavg()}")
    return args, ros_env(args.domain_id)


def _stat_cpu(stat: str) -> float:
    """utime + stime (s) from the text of a /proc/.../stat file."""
    fields = stat.rsplit(")", 1)[1].split()
    return (int(fields[_UTIME]) + int(fields[_STIME])) / os.sysconf("SC_CLK_TCK")


def cpu_seconds(pid: int) -> float:
    """CPU s (user + system, all threads) used so far by process `pid`."""
    return _stat_cpu(Path(f"/proc/{pid}/stat").read_text())


def tree_cpu_seconds(pid: int) -> float:
    """CPU s used so far by process `pid` and its living child processes (a node's log writer)."""
    total = cpu_seconds(pid)
    for stat in Path("/proc").glob("[0-9]*/stat"):
        try:
            text = stat.read_text()
        except OSError:  # the process ended
            continue
        if int(text.rsplit(")", 1)[1].split()[1]) == pid:  # ppid, the field after the state
            total += _stat_cpu(text)
    return total


def child_pids(pid: int) -> list[int]:
    """Process ids of the living child processes of process `pid` (any of its threads'), from /proc."""
    pids: list[int] = []
    for children in Path(f"/proc/{pid}/task").glob("*/children"):
        try:
            pids += [int(child) for child in children.read_text().split()]
        except OSError:  # the thread ended
            continue
    return pids


def pin(pid: int, cpu: int, children_cpu: int) -> None:
    """Every thread of process `pid` on CPU `cpu` and every thread of its child processes (a node's log
    writer) on CPU `children_cpu` (sched_setaffinity by thread; a thread started later inherits its creator's)."""
    for owner, where in [(pid, cpu), *((child, children_cpu) for child in child_pids(pid))]:
        for task in Path(f"/proc/{owner}/task").iterdir():
            with contextlib.suppress(ProcessLookupError):  # the thread ended
                os.sched_setaffinity(int(task.name), {where})


def thread_cpu(pid: int) -> dict[int, tuple[str, float]]:
    """CPU seconds of every thread of `pid`: tid → (name, utime + stime)."""
    out = {}
    for task in Path(f"/proc/{pid}/task").iterdir():
        try:
            text = (task / "stat").read_text()
        except OSError:  # the thread ended
            continue
        out[int(task.name)] = (text[text.index("(") + 1:text.rindex(")")], _stat_cpu(text))
    return out


def start_node(params: dict, workdir: Path, env: dict[str, str], *, module: str = "finger_sim.ros.node",
               tag: str | None = None) -> subprocess.Popen:
    """finger_node (or another stepping node's `module`) with `params` in its own session; its
    output goes to workdir/node_<tag>.log (default tag rtf<r>_pub<p>)."""
    tag = tag or f"rtf{params['realtime_factor']:g}_pub{params['publish_rate_hz']:g}"
    path = workdir / f"node_{tag}.yaml"
    path.write_text(yaml.safe_dump({"/**": {"ros__parameters": params}}))
    log = open(workdir / f"node_{tag}.log", "wb")
    return subprocess.Popen([sys.executable, "-m", module, "--ros-args", "--params-file", str(path)],
                            env=env, stdout=log, stderr=subprocess.STDOUT, stdin=subprocess.DEVNULL, start_new_session=True)


def stop(proc: subprocess.Popen) -> None:
    """SIGINT to the process group, SIGKILL after STOP_TIMEOUT_S."""
    if proc.poll() is None:
        os.killpg(proc.pid, signal.SIGINT)
        try:
            proc.wait(STOP_TIMEOUT_S)
        except subprocess.TimeoutExpired:
            os.killpg(proc.pid, signal.SIGKILL)
            proc.wait()


def wait_for_line(path: Path, text: str, proc: subprocess.Popen, what: str) -> None:
    """Wait (up to START_TIMEOUT_S) until `text` appears in the log file `path` of `proc`, named `what` in the error."""
    deadline = time.monotonic() + START_TIMEOUT_S
    while not (path.exists() and text in path.read_text(errors="replace")):
        if time.monotonic() > deadline or proc.poll() is not None:
            raise RuntimeError(f"{what} did not come up; see {path}")
        time.sleep(0.1)


def cpu_model() -> str:
    """The CPU's model name (/proc/cpuinfo), else what `platform` knows, else '?'."""
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or "?"


def os_release() -> str:
    """The distribution's PRETTY_NAME (/etc/os-release), or '?'."""
    try:
        for line in Path("/etc/os-release").read_text().splitlines():
            if line.startswith("PRETTY_NAME="):
                return line.split("=", 1)[1].strip('"')
    except OSError:
        pass
    return "?"


def machine() -> dict[str, str]:
    """The machine a node benchmark ran on: CPU, cores, OS, Python, ROS middleware."""
    try:
        import rclpy

        rmw = rclpy.get_rmw_implementation_identifier()
    except Exception:  # noqa: BLE001 - informational only
        rmw = "?"
    return {
        "cpu": cpu_model(),
        "cores": str(os.cpu_count()),
        "os": f"{platform.system()} {platform.release()} ({os_release()})",
        "python": platform.python_version(),
        "rmw": rmw,
    }
