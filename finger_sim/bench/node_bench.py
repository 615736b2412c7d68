"""Speed of finger_node, measured from a separate client process; writes docs/node_performance.md.

    python -m finger_sim.bench.node_bench [--duration 60] [--fast-duration 10] [--out docs/node_performance.md]

Three runs of the node (paper_flexion, torque from the topic, 1 kHz physics, markers at their
default 30 Hz), each in its own process started by this script, which is the client:

1. realtime_factor 1, publishing every step, for --duration s (after WARMUP_S): the
   real-time factor from the joint_states stamps (sim time, as on /clock) against the
   client's wall clock on arrival; the node's late wake-ups (its own histogram, 10 µs bins,
   in /diagnostics); overruns and dropped steps; the torque-command-to-state latency: the
   client publishes a distinct torque on motor_torque at COMMAND_HZ and times, on its own
   clock, the arrival of the first joint_states whose mcp_joint effort is that torque; and the
   node's CPU time (/proc/<pid>/stat, all threads) over wall time, as a fraction of one core.
2. realtime_factor 0, publishing every step, for --fast-duration s: sim time per wall second.
3. The same, publishing every 10th step, for comparison.

Then the per-step costs (physics, messages, publishing) measured in this process, to say
where the time goes.

Targets: real-time factor 1.00 ± 0.01 over 60 s, p99 late wake-up < 1 ms,
command-to-state latency p99 < 3 ms, under half of one core; as fast as possible ≥ 20×.
Both processes run with ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST on their own domain id.

    python -m finger_sim.bench.node_bench --targets --old /work/main [--target-duration 10] [--rounds 2]

measures the four cost targets of the ROS layer instead, each run of the new code (this
checkout) followed by the same run of the old (`--old`: a checkout put first on PYTHONPATH),
A B A B, medians over the rounds, and writes them between the TARGETS markers of --out: CPU
(node and its log writer process) at 1 kHz with recording off and on; as fast as possible with
every-step publishing and recording, and every joint state in the log; 5 kHz physics publishing
at 1 kHz in real time; a 10-finger finger_hand at 1 kHz. No subscriber but the benchmark's
/diagnostics client; the figures come from the node's own 1 s diagnostics windows and /proc.

    python -m finger_sim.bench.node_bench --recording [--old <checkout>] [--target-duration 10] [--rounds 3] [--no-hand]

measures the two recording goals in one command: finger_node at 1 kHz with recording off and on
(the CPU recording adds, goal ≤ 20 %) and the 10-finger hand with recording off and on (goal
≤ 0.35 cores with it on), the four runs in turn each round (and each followed by the same run
of `--old` if given), with the log writer process's share; writes them between the RECORDING
markers of --out and prints them, with each configuration's spread over the rounds and the
rounds' paired differences (recording on minus the off run next to it). `--no-hand` runs
finger_node's pair only.

    python -m finger_sim.bench.node_bench --recording-cpu [--at-once] [--pin NODE_CPU WRITER_CPU] [--old <checkout>]
        [--target-duration 10] [--rounds 6]

decides the CPU recording adds at 1 kHz (a paired bootstrap interval over the rounds) and counts
recording's own CPU where it runs (the node's /diagnostics `log_cpu_*`) and every thread of the node,
recording off and on, and writes it between the RECORDING_CPU markers of --out
(finger_sim.bench.recording_cpu); --at-once runs a round's two nodes at the same time (in --domain-id
and the next), --pin puts the nodes' threads and their log writers on given CPUs; with --old (a checkout
whose node reports `log_cpu_*` too), each run is followed by the same run of the old code and recording's
parts are compared side by side.
"""

from __future__ import annotations

import argparse
import functools
import os
import re
import statistics
import sys
import tempfile
import time
from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field
from datetime import datetime, timezone
from pathlib import Path

import numpy as np

from finger_sim.bench import recording_cpu
from finger_sim.bench.processes import (ROOT, START_TIMEOUT_S, cpu_seconds, isolate_dds, machine, pin, ros_env, start_node,
                                        stop, tree_cpu_seconds)
from finger_sim.log.cpu_clocks import threads_cpu_ns

DEFAULT_DOMAIN_ID = 31
WARMUP_S = 3.0
COMMAND_HZ = 100.0
COMMAND_TORQUE = 2e-4  # N·m: small alternating torques keep the finger near extension
TARGETS = dict(rtf=(0.99, 1.01), late_p99_ms=1.0, latency_p99_ms=3.0, cpu_cores=0.5, fast_rtf=20.0)
#: The ROS layer's cost targets: CPU added by recording at 1 kHz (fraction), sim s per wall s as
#: fast as possible with every-step publishing and recording, a 5 kHz run's real-time factor,
#: a 10-finger hand's cores at 1 kHz.
COST_TARGETS = dict(record_cpu=0.20, fast_rtf=30.0, rtf_5k=0.99, hand_cores=0.35)
HAND_FINGERS = 10
TARGETS_BEGIN = "<!-- TARGETS begin: written by finger_sim/bench/node_bench.py --targets -->"
TARGETS_END = "<!-- TARGETS end -->"
RECORDING_BEGIN = "<!-- RECORDING begin: written by finger_sim/bench/node_bench.py --recording -->"
RECORDING_END = "<!-- RECORDING end -->"
#: Recording's own CPU in the node's /diagnostics (runtime.diagnostics): part → its running total's key.
RECORDER_PARTS = {"caller": "log_cpu_caller_s", "threads": "log_cpu_threads_s", "writer": "log_cpu_writer_s"}


@dataclass
class Run:
    """What the client saw of one node run."""

    realtime_factor: float
    wall_s: float = 0.0
    sim_s: float = 0.0
    cpu_cores: float = 0.0
    latencies_ms: list[float] = field(default_factory=list)
    commands_sent: int = 0
    states: int = 0
    diagnostics: list[dict[str, str]] = field(default_factory=list)

    @property
    def rtf(self) -> float:
        return self.sim_s / self.wall_s if self.wall_s else 0.0


def measure(realtime_factor: float, duration: float, domain_id: int, workdir: Path, *, commands: bool,
            publish_rate_hz: float = 1000.0, scene: str = "paper_flexion", command_hz: float = COMMAND_HZ) -> Run:
    import rclpy
    from diagnostic_msgs.msg import DiagnosticArray
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.qos import QoSProfile
    from sensor_msgs.msg import JointState
    from std_msgs.msg import Float64

    env = ros_env(domain_id)
    params = dict(scene=scene, torque_source="topic", physics_rate_hz=1000.0, publish_rate_hz=publish_rate_hz,
                  realtime_factor=realtime_factor, command_timeout=0.5)
    proc = start_node(params, workdir, env)
    context = rclpy.Context()
    rclpy.init(context=context, domain_id=domain_id)
    node = rclpy.create_node("node_bench_client", context=context)
    executor = SingleThreadedExecutor(context=context)
    executor.add_node(node)
    run = Run(realtime_factor)
    pending: dict[float, float] = {}  # torque → send time
    clock = {"first": None, "last": None}
    recording = [False]

    def on_state(msg: JointState) -> None:
        now = time.perf_counter()
        sent = pending.pop(msg.effort[0], None) if pending else None
        if recording[0]:
            run.states += 1
            if sent is not None:
                run.latencies_ms.append((now - sent) * 1e3)
            t = msg.header.stamp.sec + msg.header.stamp.nanosec * 1e-9  # sim time, as on /clock
            if clock["first"] is None:
                clock["first"] = (now, t)
            clock["last"] = (now, t)

    def on_diagnostics(msg: DiagnosticArray) -> None:
        for status in msg.status:
            if status.name.startswith("/finger_node"):
                run.diagnostics.append({kv.key: kv.value for kv in status.values} | {"_level": str(status.level)})

    node.create_subscription(JointState, "/joint_states", on_state, QoSProfile(depth=100))
    node.create_subscription(DiagnosticArray, "/diagnostics", on_diagnostics, QoSProfile(depth=100))
    pub = node.create_publisher(Float64, "/motor_torque", 10)
    counter = [0]

    def send() -> None:
        counter[0] += 1
        k = counter[0]
        value = (COMMAND_TORQUE if k % 2 else -COMMAND_TORQUE) * (1.0 + k * 1e-9)  # distinct every time
        pending[value] = time.perf_counter()
        pub.publish(Float64(data=value))
        run.commands_sent += recording[0]

    try:
        deadline = time.monotonic() + START_TIMEOUT_S
        while node.count_publishers("/joint_states") == 0 or pub.get_subscription_count() == 0:
            if time.monotonic() > deadline or proc.poll() is not None:
                raise RuntimeError(f"finger_node did not come up; see {workdir}")
            executor.spin_once(timeout_sec=0.05)
        if commands:
            node.create_timer(1.0 / command_hz, send)
        end_warmup = time.monotonic() + WARMUP_S
        while time.monotonic() < end_warmup:
            executor.spin_once(timeout_sec=0.05)
        recording[0] = True
        cpu0, wall0 = cpu_seconds(proc.pid), time.perf_counter()
        end = time.monotonic() + duration
        while time.monotonic() < end:
            executor.spin_once(timeout_sec=0.05)
        recording[0] = False
        cpu1, wall1 = cpu_seconds(proc.pid), time.perf_counter()
        run.cpu_cores = (cpu1 - cpu0) / (wall1 - wall0)
        # one more diagnostics period, so that the node's totals cover the whole window
        n_diag = len(run.diagnostics)
        deadline = time.monotonic() + 3.0
        while len(run.diagnostics) == n_diag and time.monotonic() < deadline:
            executor.spin_once(timeout_sec=0.05)
        (w0, t0), (w1, t1) = clock["first"], clock["last"]
        run.wall_s, run.sim_s = w1 - w0, t1 - t0
    finally:
        executor.shutdown()
        node.destroy_node()
        rclpy.try_shutdown(context=context)
        stop(proc)
    return run


def breakdown(domain_id: int, n: int = 5000) -> dict[str, float]:
    """µs per step of the node's per-step work, in this process: the scene's physics step, the
    three state messages refilled, and their three publishes with nobody subscribed."""
    import rclpy
    from geometry_msgs.msg import PoseStamped
    from rosgraph_msgs.msg import Clock
    from sensor_msgs.msg import JointState

    from finger_sim.ros import conversions
    from finger_sim.scene_paths import resolve_scene
    from finger_sim.scene import load_scene
    from finger_sim.simulate import Simulator

    sim = Simulator(load_scene(resolve_scene("paper_flexion")).with_overrides(dt=1e-3))
    frames = conversions.FingerFrames.from_system(sim.system)
    t = time.perf_counter()
    for _ in range(n):
        sim.step(1e-4)
    physics = (time.perf_counter() - t) / n * 1e6
    q, v = sim.q, sim.v
    js, pose, clk = conversions.joint_state(frames, q, v, 0.0, 0), conversions.fingertip_pose(frames, q, 0), conversions.clock(0)
    t = time.perf_counter()
    for i in range(n):
        conversions.joint_state(frames, q, v, 0.0, i, out=js)
        conversions.fingertip_pose(frames, q, i, out=pose)
        conversions.clock(i, out=clk)
    messages = (time.perf_counter() - t) / n * 1e6
    context = rclpy.Context()
    rclpy.init(context=context, domain_id=domain_id)
    node = rclpy.create_node("node_bench_breakdown", context=context)
    try:
        pubs = [(node.create_publisher(JointState, "/bench_js", 10), js), (node.create_publisher(PoseStamped, "/bench_pose", 10), pose),
                (node.create_publisher(Clock, "/bench_clock", 10), clk)]
        t = time.perf_counter()
        for _ in range(n):
            for pub, msg in pubs:
                pub.publish(msg)
        publish = (time.perf_counter() - t) / n * 1e6
    finally:
        node.destroy_node()
        rclpy.try_shutdown(context=context)
    return {"method": sim.method, "physics": physics, "messages": messages, "publish": publish}


@dataclass
class Window:
    """One measured node run: its CPU and its diagnostics windows (the first finger's)."""

    cores: float = 0.0
    cpu_per_sim_s: float = 0.0  # CPU s per sim s: the cores real time takes, whatever the load allowed
    writer_per_sim_s: float = 0.0  # of which the node's child processes (its log writer)
    rtf: list[float] = field(default_factory=list)  # sim s per wall s of each 1 s window
    dropped_steps: int = 0
    log_dropped: int = -1  # the log's status record; -1: not recording
    states_logged: int = 0  # joint_states in the log
    states_expected: int = 0  # steps + 1 by the last logged stamp (every-step publishing)
    # CPU s per sim s of each of the node process's threads, by OS name (cpu_clocks.threads_cpu_ns; numbered
    # names such as dds.shm.7000 summed as dds.shm.#), and of recording's own parts from the node's
    # /diagnostics (log_cpu_caller_s, …: caller, threads, writer; empty from a node that does not report them)
    threads: dict[str, float] = field(default_factory=dict)
    recorder: dict[str, float] = field(default_factory=dict)


def _hand_file(folder: Path) -> Path:
    """A hand of HAND_FINGERS copies of finger_default, side by side."""
    import yaml

    path = folder / "ten_fingers.yaml"
    fingers = [dict(name=f"f{i}", scene="finger_default", pose=[0.0, 0.02 * i, 0.0, 0.0, 0.0, 0.0]) for i in range(HAND_FINGERS)]
    path.write_text(yaml.safe_dump({"fingers": fingers}))
    return path


def alternate(files: dict[str, Path], params: dict, rounds: int, duration: float, domain_id: int, workdir: Path,
              label: str) -> dict[str, list]:
    """A B A B: the node of each scene file in `files` (name → path) measured by `measure_window` in turn,
    `rounds` times, under the same `params`; name → its windows, in round order. Progress on stderr."""
    env = ros_env(domain_id)
    rows: dict[str, list] = {}
    for r in range(rounds):
        for name, path in files.items():
            print(f"{label}: {name} round {r}", file=sys.stderr, flush=True)
            rows.setdefault(name, []).append(
                measure_window({"scene": str(path), **params}, duration, domain_id, workdir, env, f"{name}_{r}"))
    return rows



def side_by_side(doc: str, argv: list[str] | None, label: str, scenes: dict[str, dict], params: dict) -> dict[str, list]:
    """An A B A B benchmark of node runs from the command line (`--duration` measured s per run, `--rounds`,
    `--domain-id`): each scene mapping of `scenes` (name → mapping) written to `<label>_<name>.yaml` in a
    temporary folder and run by `alternate` under `params`; name → its windows. Prints the table's heading
    line (the time, rounds and duration) first."""
    import yaml

    parser = argparse.ArgumentParser(description=doc.splitlines()[0])
    parser.add_argument("--duration", type=float, default=20.0, help="measured s per node run")
    parser.add_argument("--rounds", type=int, default=2)
    parser.add_argument("--domain-id", type=int, default=80)
    args = parser.parse_args(argv)
    with tempfile.TemporaryDirectory(prefix=f"{label}_") as tmp:
        folder = Path(tmp)
        files = {}
        for name, data in scenes.items():
            files[name] = folder / f"{label}_{name}.yaml"
            files[name].write_text(yaml.safe_dump(data))
        rows = alternate(files, params, args.rounds, args.duration, args.domain_id, folder, label)
    when = datetime.now(timezone.utc).strftime("%Y-%m-%d %H:%M UTC")
    print(f"{when}; {args.rounds} rounds of {args.duration:g} s, medians\n")
    return rows


def window_medians(runs: list[Window]) -> tuple[float, float, float]:
    """(median real-time factor of the 1 s windows, lowest window, median CPU s per sim s) of some runs."""
    rtf = [x for w in runs for x in w.rtf]
    return statistics.median(rtf), min(rtf), statistics.median(w.cpu_per_sim_s for w in runs)

def measure_window(params: dict, duration: float, domain_id: int, workdir: Path, env: dict[str, str], tag: str, *,
                   hand: bool = False, pin_cpus: tuple[int, int] | None = None) -> Window:
    """Start a stepping node, wait for its first /diagnostics, measure `duration` s after WARMUP_S,
    stop it (SIGINT: the log is closed) and count its log. pin_cpus: (the node's CPU, its log writer's),
    set at the first /diagnostics (processes.pin), or None: where the kernel puts them."""
    import rclpy
    from diagnostic_msgs.msg import DiagnosticArray
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.qos import QoSProfile

    from finger_sim.log import LogReader

    record_dir = workdir / tag
    params = dict(params, record_dir=str(record_dir))
    proc = start_node(params, workdir, env, module="finger_sim.ros.hand" if hand else "finger_sim.ros.node", tag=tag)
    context = rclpy.Context()
    rclpy.init(context=context, domain_id=domain_id)
    node = rclpy.create_node(f"node_bench_{tag}", context=context)  # a name of its own: runs may share this process
    executor = SingleThreadedExecutor(context=context)
    executor.add_node(node)
    windows: list[dict[str, str]] = []
    cpu_at: list[float] = []  # the node's CPU s (with its children) when each window arrived
    own_at: list[float] = []  # the node process's alone
    threads_at: list[dict[int, tuple[str, int]]] = []  # its threads' CPU ns

    def on_diagnostics(msg: DiagnosticArray) -> None:
        first = [s for s in msg.status if s.name.endswith("simulation")][:1]
        windows.extend({kv.key: kv.value for kv in s.values} for s in first)
        for _ in first:
            own_at.append(cpu_seconds(proc.pid))
            cpu_at.append(tree_cpu_seconds(proc.pid))
            threads_at.append(threads_cpu_ns(proc.pid))

    node.create_subscription(DiagnosticArray, "/diagnostics", on_diagnostics, QoSProfile(depth=100))
    out = Window()
    try:
        deadline = time.monotonic() + 2 * START_TIMEOUT_S
        while not windows:
            if time.monotonic() > deadline or proc.poll() is not None:
                raise RuntimeError(f"the node did not come up; see {workdir}/node_{tag}.log")
            executor.spin_once(timeout_sec=0.05)
        if pin_cpus is not None:
            pin(proc.pid, *pin_cpus)
        end_warmup = time.monotonic() + WARMUP_S
        while time.monotonic() < end_warmup:
            executor.spin_once(timeout_sec=0.05)
        first = len(windows)
        cpu0, wall0 = tree_cpu_seconds(proc.pid), time.perf_counter()
        end = time.monotonic() + duration
        while time.monotonic() < end:
            executor.spin_once(timeout_sec=0.05)
        out.cores = (tree_cpu_seconds(proc.pid) - cpu0) / (time.perf_counter() - wall0)
        measured = windows[first:]
        out.rtf = [float(w["realtime_factor"]) for w in measured]
        sim_s = float(windows[-1]["clock"]) - float(windows[first - 1]["clock"])
        out.cpu_per_sim_s = (cpu_at[-1] - cpu_at[first - 1]) / sim_s if sim_s > 0 else float("nan")
        children = (cpu_at[-1] - own_at[-1]) - (cpu_at[first - 1] - own_at[first - 1])
        out.writer_per_sim_s = children / sim_s if sim_s > 0 else float("nan")
        if sim_s > 0:
            out.threads = _per_thread_name(threads_at[first - 1], threads_at[-1], sim_s)
            out.recorder = {part: (float(windows[-1][key]) - float(windows[first - 1][key])) / sim_s
                            for part, key in RECORDER_PARTS.items() if key in windows[-1]}
        if measured:
            out.dropped_steps = int(measured[-1]["dropped_steps"]) - int(windows[first - 1]["dropped_steps"])
    finally:
        executor.shutdown()
        node.destroy_node()
        rclpy.try_shutdown(context=context)
        stop(proc)
    if params.get("record", True):
        (path,) = record_dir.glob("*.mcap")
        log = LogReader(path)
        topic = "/f0/joint_states" if hand else "/joint_states"
        stamps = [m.log_time for _, _, m in log.raw_messages([topic], log_time_order=False)]
        out.log_dropped, out.states_logged = log.dropped, len(stamps)
        out.states_expected = round((max(stamps) - min(stamps)) * params["physics_rate_hz"] / 1e9) + 1 if stamps else 0
    return out


def _per_thread_name(before: dict[int, tuple[str, int]], after: dict[int, tuple[str, int]], sim_s: float) -> dict[str, float]:
    """CPU s per sim s of the threads alive at both readings (tid → OS name, CPU ns), summed by name with a
    trailing number replaced by '#' (Fast DDS names its threads by port: dds.shm.7000)."""
    out: dict[str, float] = {}
    for tid, (name, ns) in after.items():
        if tid in before:
            key = re.sub(r"\d+$", "#", name)
            out[key] = out.get(key, 0.0) + (ns - before[tid][1]) / 1e9 / sim_s
    return out


#: The configurations of `--targets`, and those of `--recording` (recording on and off side by side).
TARGET_CONFIGS = ("1k_off", "1k_rec", "fast_rec", "5k_rec", "hand10_rec")
RECORDING_CONFIGS = ("1k_off", "1k_rec", "hand10_off", "hand10_rec")


def configs(workdir: Path) -> dict[str, tuple[dict, bool]]:
    """Every configuration of `targets` by name: (the node's parameters, whether it is a finger_hand);
    the hand's file is written to `workdir`."""
    base = dict(scene="paper_flexion", torque_source="topic", physics_rate_hz=1000.0, publish_rate_hz=0.0,
                realtime_factor=1.0, command_timeout=0.5)
    hand = {k: v for k, v in base.items() if k != "scene"} | dict(hand=str(_hand_file(workdir)))
    every = {
        "1k_off": (dict(base, record=False), False),
        "1k_rec": (base, False),
        "fast_rec": (dict(base, realtime_factor=0.0), False),
        "5k_rec": (dict(base, physics_rate_hz=5000.0, publish_rate_hz=1000.0), False),
        "hand10_off": (dict(hand, record=False), True),
        "hand10_rec": (hand, True),
    }
    return every


def side_envs(old: Path | None, domain_id: int) -> dict[str, dict[str, str]]:
    """'new' (this checkout, ROOT) and 'old' (`old`) → a node's environment in `domain_id`: its checkout first on
    PYTHONPATH, and PYTHONSAFEPATH set, because `python -m` otherwise puts the working folder first on sys.path,
    so that a bench started inside a checkout ran that checkout's code on both sides."""
    def env(checkout: Path) -> dict[str, str]:
        path = os.pathsep.join([str(checkout), os.environ.get("PYTHONPATH", "")]).rstrip(os.pathsep)
        return dict(ros_env(domain_id), PYTHONPATH=path, PYTHONSAFEPATH="1")

    return {"new": env(ROOT)} | ({} if old is None else {"old": env(old)})


def targets(old: Path | None, duration: float, rounds: int, domain_id: int, workdir: Path,
            names: tuple[str, ...] = TARGET_CONFIGS, pin_cpus: tuple[int, int] | None = None
            ) -> dict[tuple[str, str], list[Window]]:
    """The runs of the configurations `names`, new then old (none without `old`), `rounds` times:
    (config, 'new' | 'old') → runs. pin_cpus: see measure_window."""
    every = configs(workdir)
    envs = side_envs(old, domain_id)
    runs: dict[tuple[str, str], list[Window]] = {}
    for r in range(rounds):
        for name in names:
            params, is_hand = every[name]
            for side in envs:
                tag = f"{name}_{side}_{r}"
                print(f"targets: {tag}", file=sys.stderr, flush=True)
                runs.setdefault((name, side), []).append(
                    measure_window(params, duration, domain_id, workdir, envs[side], tag, hand=is_hand, pin_cpus=pin_cpus))
    return runs


def at_once(old: Path | None, duration: float, domain_id: int, workdir: Path, names: tuple[str, ...],
            pin_cpus: tuple[int, int] | None = None) -> dict[tuple[str, str], list[Window]]:
    """One round of the configurations `names` run at the same time, the i-th in domain `domain_id` + i
    and started in that order (new, then old the same way): (config, side) → [its run]. A drift of the
    machine's load then falls on all of them alike. pin_cpus: see measure_window."""
    every = configs(workdir)
    runs: dict[tuple[str, str], list[Window]] = {}
    for side in side_envs(old, domain_id):
        with ThreadPoolExecutor(len(names)) as pool:
            futures = {}
            for i, name in enumerate(names):
                params, is_hand = every[name]
                env = side_envs(old, domain_id + i)[side]
                print(f"at once: {name}_{side} (domain {domain_id + i})", file=sys.stderr, flush=True)
                futures[(name, side)] = pool.submit(measure_window, params, duration, domain_id + i, workdir, env,
                                                    f"{name}_{side}", hand=is_hand, pin_cpus=pin_cpus)
            runs |= {key: [future.result()] for key, future in futures.items()}
    return runs


def targets_report(runs: dict[tuple[str, str], list[Window]], command: str, old: Path, duration: float, rounds: int,
                   load: tuple[tuple, tuple]) -> str:
    import statistics
    from datetime import datetime, timezone

    def med(name: str, side: str, value: Callable[[Window], float]) -> float:
        return statistics.median(value(w) for w in runs[(name, side)])

    def per_sim(name: str, side: str) -> float:
        return med(name, side, lambda w: w.cpu_per_sim_s)

    def added(side: str) -> float:
        return per_sim("1k_rec", side) / per_sim("1k_off", side) - 1.0

    def rtf(name: str, side: str) -> float:
        return med(name, side, lambda w: statistics.median(w.rtf) if w.rtf else float("nan"))

    def worst(name: str, side: str) -> float:
        return min(min(w.rtf, default=float("nan")) for w in runs[(name, side)])

    def logged(side: str) -> str:
        return "; ".join(f"{w.states_logged}/{w.states_expected} (dropped {w.log_dropped})" for w in runs[("fast_rec", side)])

    def complete(side: str) -> bool:
        return all(w.states_logged == w.states_expected and w.log_dropped == 0 for w in runs[("fast_rec", side)])

    def ok(flag: bool) -> str:
        return "yes" if flag else "**no**"

    t = COST_TARGETS
    both = ("new", "old")
    rows = [
        ("1 kHz, recording off: CPU s per sim s (cores at real time)", *(f"{per_sim('1k_off', x):.3f}" for x in both), "", ""),
        ("1 kHz, recording on: CPU s per sim s", *(f"{per_sim('1k_rec', x):.3f}" for x in both), "", ""),
        # Off and on run one after the other, a few rounds: the stepping thread alone scatters more than recording
        # adds, so this row reports and `--recording-cpu` (paired rounds run at once, counted by thread) decides.
        ("CPU added by recording at 1 kHz", *(f"{100 * added(x):+.0f} %" for x in both),
         f"≤ {100 * t['record_cpu']:.0f} %", "not decided here: `--recording-cpu`"),
        ("  real-time factor off / on (median window)", *(f"{rtf('1k_off', x):.3f} / {rtf('1k_rec', x):.3f}" for x in both), "", ""),
        ("as fast as possible, publishing and recording every step: sim s per wall s (median window)",
         *(f"{rtf('fast_rec', x):.1f}×" for x in both), f"≥ {t['fast_rtf']:g}×", ok(rtf("fast_rec", "new") >= t["fast_rtf"])),
        ("  the same, from its CPU s per sim s (sim s per CPU s: one free core)", *(f"{1 / per_sim('fast_rec', x):.1f}×" for x in both),
         "", ""),
        ("  joint_states in the log / steps (each run)", logged("new"), logged("old"), "all", ok(complete("new"))),
        ("5 kHz physics, 1 kHz publishing, recording: real-time factor (median window)",
         *(f"{rtf('5k_rec', x):.3f}" for x in both), f"≥ {t['rtf_5k']:g}", ok(rtf("5k_rec", "new") >= t["rtf_5k"])),
        ("  worst window; dropped steps; CPU s per sim s", *(f"{worst('5k_rec', x):.3f}; {sum(w.dropped_steps for w in runs[('5k_rec', x)])}; "
                                                           f"{per_sim('5k_rec', x):.3f}" for x in both), "", ""),
        (f"{HAND_FINGERS}-finger finger_hand at 1 kHz, recording: CPU s per sim s (cores at real time)",
         *(f"{per_sim('hand10_rec', x):.3f}" for x in both), f"≤ {t['hand_cores']:g}",
         ok(per_sim("hand10_rec", "new") <= t["hand_cores"])),
        (f"  {HAND_FINGERS}-finger hand: real-time factor (median window); cores over wall time",
         *(f"{rtf('hand10_rec', x):.3f}; {med('hand10_rec', x, lambda w: w.cores):.3f}" for x in both), "", ""),
    ]
    return "\n".join([
        TARGETS_BEGIN,
        "## The ROS layer's cost targets, old and new",
        "",
        f"Command: `{command}` ({datetime.now(timezone.utc):%Y-%m-%d %H:%M} UTC). New = this checkout, old = `{old}` "
        f"first on PYTHONPATH (the same venv). Each configuration ran new then old, {rounds} rounds (A B A B), "
        f"{duration:g} s measured after {WARMUP_S:g} s of warm-up; medians over the rounds. Node: paper_flexion, torque "
        "from `motor_torque` (nobody sends: the finger rests), publishing every step unless said, markers at 30 Hz, "
        "nobody subscribed but the benchmark's /diagnostics client. CPU: utime + stime of the node process and its "
        "child processes (the new log writer), read when each /diagnostics window arrives, divided by the sim time "
        "the node advanced meanwhile (the /diagnostics `clock`): the cores the run takes at real time, a figure "
        "that a loaded machine distorts less than cores over wall time when the node cannot keep real time. "
        f"Real-time factor: the node's own 1 s /diagnostics windows. Load average at start {load[0][0]:.1f}, at end {load[1][0]:.1f} on 2 cores: a busy, "
        "shared machine, so the side-by-side ratios say more than the absolute figures.",
        "",
        "| measure | new | old | target | new meets it |",
        "|---|---|---|---|---|",
        *(f"| {a} | {b} | {c} | {d} | {e} |" for a, b, c, d, e in rows),
        TARGETS_END,
    ])


def recording_report(runs: dict[tuple[str, str], list[Window]], command: str, old: Path | None, duration: float,
                     rounds: int, load: tuple[tuple, tuple]) -> str:
    """The two recording goals (CPU added by recording at 1 kHz, the 10-finger hand's cores), each
    run's figures and the medians, new (and old) side by side."""
    import statistics
    from datetime import datetime, timezone

    sides = sorted({side for _, side in runs}, key=("new", "old").index)
    t = COST_TARGETS

    def med(name: str, side: str, value: Callable[[Window], float] = lambda w: w.cpu_per_sim_s) -> float:
        return statistics.median(value(w) for w in runs[(name, side)])

    def each(name: str, side: str, value: Callable[[Window], float] = lambda w: w.cpu_per_sim_s) -> str:
        return ", ".join(f"{value(w):.3f}" for w in runs[(name, side)])

    def added(rec: str, off: str, side: str) -> float:
        return med(rec, side) / med(off, side) - 1.0

    def ok(flag: bool) -> str:
        return "yes" if flag else "**no**"

    def spread(name: str, side: str, value: Callable[[Window], float] = lambda w: w.cpu_per_sim_s) -> str:
        values = [value(w) for w in runs[(name, side)]]
        return f"{min(values):.3f}–{max(values):.3f}"

    def paired(rec: str, off: str, side: str) -> list[float]:
        """Each round's recording-on run minus the recording-off run next to it, CPU s per sim s."""
        return [a.cpu_per_sim_s - b.cpu_per_sim_s for a, b in zip(runs[(rec, side)], runs[(off, side)])]

    writer = lambda w: w.writer_per_sim_s  # noqa: E731
    hand = ("hand10_off", "new") in runs
    rows = []
    for side in sides:
        diffs = paired("1k_rec", "1k_off", side)
        rows += [
            (side, "finger_node 1 kHz, recording off", each("1k_off", side), f"{med('1k_off', side):.3f}",
             spread("1k_off", side), "", ""),
            (side, "finger_node 1 kHz, recording on", each("1k_rec", side), f"{med('1k_rec', side):.3f}",
             spread("1k_rec", side), "", ""),
            (side, "  of which its log writer process", each("1k_rec", side, writer), f"{med('1k_rec', side, writer):.3f}",
             spread("1k_rec", side, writer), "", ""),
            (side, "  on − off, round by round", ", ".join(f"{d:+.3f}" for d in diffs),
             f"{statistics.median(diffs):+.3f}", f"{min(diffs):+.3f} to {max(diffs):+.3f}", "", ""),
            (side, "**CPU added by recording at 1 kHz** (ratio of medians; median of the rounds' differences)", "",
             f"{100 * added('1k_rec', '1k_off', side):+.0f} %; "
             f"{100 * statistics.median(diffs) / med('1k_off', side):+.0f} %", "",
             f"≤ {100 * t['record_cpu']:.0f} %", ok(added("1k_rec", "1k_off", side) <= t["record_cpu"])),
        ]
        if not hand:
            continue
        rows += [
            (side, f"{HAND_FINGERS}-finger finger_hand 1 kHz, recording off", each("hand10_off", side),
             f"{med('hand10_off', side):.3f}", spread("hand10_off", side), "", ""),
            (side, f"**{HAND_FINGERS}-finger finger_hand 1 kHz, recording on**", each("hand10_rec", side),
             f"{med('hand10_rec', side):.3f}", spread("hand10_rec", side), f"≤ {t['hand_cores']:g}",
             ok(med("hand10_rec", side) <= t["hand_cores"])),
            (side, "  of which its log writer process", each("hand10_rec", side, writer),
             f"{med('hand10_rec', side, writer):.3f}", spread("hand10_rec", side, writer), "", ""),
            (side, "  CPU added by recording, hand", "", f"{100 * added('hand10_rec', 'hand10_off', side):+.0f} %", "",
             "", ""),
        ]
    names = sorted({name for name, _ in runs}, key=RECORDING_CONFIGS.index)
    for side in sides:
        rows.append((side, f"  real-time factor, median window ({', '.join(names)})", "",
                     " / ".join(f"{med(n, side, lambda w: statistics.median(w.rtf) if w.rtf else float('nan')):.3f}"
                                for n in names), "", "", ""))
    old_text = f", old = `{old}` first on PYTHONPATH (the same venv)" if old is not None else ""
    hand_text = f"; a {HAND_FINGERS}-finger finger_hand of finger_default, off, on" if hand else ""
    return "\n".join([
        RECORDING_BEGIN,
        "## Recording's cost and the 10-finger hand, recording on and off side by side",
        "",
        f"Command: `{command}` ({datetime.now(timezone.utc):%Y-%m-%d %H:%M} UTC). New = this checkout{old_text}. "
        f"The runs (finger_node paper_flexion, recording off, on{hand_text}; torque from the topic, nobody sending; "
        "publishing every step) in turn, "
        f"{rounds} rounds (A B A B), {duration:g} s measured after {WARMUP_S:g} s of warm-up each; the node's "
        "default executor. Figures: CPU s (utime + stime of the node process and its log writer process) per "
        "sim s, from the node's 1 s /diagnostics windows: the cores the run takes at real time. "
        f"Load average at start {load[0][0]:.1f}, at end {load[1][0]:.1f} on 2 cores.",
        "",
        "| side | run | CPU s per sim s, each round | median | min–max | goal | met |",
        "|---|---|---|---|---|---|---|",
        *(f"| {' | '.join(row)} |" for row in rows),
        RECORDING_END,
    ])


def write_section(path: Path, section: str, begin: str, end: str) -> None:
    """Replace the section between `begin` and `end` in `path` (or append it)."""
    text = path.read_text() if path.exists() else ""
    if begin in text and end in text:
        head, rest = text.split(begin, 1)
        text = head + section + rest.split(end, 1)[1]
    else:
        text = text.rstrip("\n") + "\n\n" + section + "\n"
    path.write_text(text)


def _p(values: list[float], q: float) -> float:
    return float(np.percentile(values, q)) if values else float("nan")


def report(rt: Run, fast: Run, fast_decimated: Run, parts: dict, info: dict[str, str], command: str,
           load: tuple[tuple, tuple]) -> str:
    last = rt.diagnostics[-1] if rt.diagnostics else {}
    window_p99 = [float(d["late_wakeup_p99_ms"]) for d in rt.diagnostics if float(d.get("realtime_factor", 0)) > 0]
    late_p99 = float(last.get("late_wakeup_p99_ms_total", "nan"))
    lat = rt.latencies_ms
    lo, hi = TARGETS["rtf"]

    def ok(flag: bool) -> str:
        return "yes" if flag else "**no**"

    rows = [
        ("real-time factor (client: state stamps / wall time)", f"{rt.rtf:.4f}", f"{lo:.2f} … {hi:.2f}", ok(lo <= rt.rtf <= hi)),
        ("real-time factor (node, since start)", f"{float(last.get('realtime_factor_mean', 'nan')):.4f}", "", ""),
        ("late wake-up p99 (node, whole run)", f"{late_p99:.3f} ms", f"< {TARGETS['late_p99_ms']:g} ms", ok(late_p99 < TARGETS["late_p99_ms"])),
        ("late wake-up p99, median of 1 s windows", f"{_p(window_p99, 50):.3f} ms", "", ""),
        ("late wake-up max (node, whole run)", f"{float(last.get('late_wakeup_max_ms_total', 'nan')):.3f} ms", "", ""),
        ("overruns / dropped steps", f"{last.get('overruns', '?')} / {last.get('dropped_steps', '?')}", "", ""),
        ("command → state latency p50 / p99 / max", f"{_p(lat, 50):.2f} / {_p(lat, 99):.2f} / {max(lat) if lat else float('nan'):.2f} ms",
         f"p99 < {TARGETS['latency_p99_ms']:g} ms", ok(_p(lat, 99) < TARGETS["latency_p99_ms"])),
        ("commands timed / sent", f"{len(lat)} / {rt.commands_sent}", "", ""),
        ("node CPU (all threads)", f"{rt.cpu_cores:.3f} cores", f"< {TARGETS['cpu_cores']:g}", ok(rt.cpu_cores < TARGETS["cpu_cores"])),
        ("joint_states received by the client", f"{rt.states} ({rt.states / rt.wall_s:.1f}/s)" if rt.wall_s else "?", "", ""),
    ]
    def fast_rows(run: Run, target: bool) -> list[tuple[str, str, str, str]]:
        windows = [float(d["realtime_factor"]) for d in run.diagnostics if float(d.get("realtime_factor", 0)) > 0]
        return [
            ("sim time per wall second (client: state stamps / wall time)", f"{run.rtf:.1f}×",
             f"≥ {TARGETS['fast_rtf']:g}×" if target else "", ok(run.rtf >= TARGETS["fast_rtf"]) if target else ""),
            ("median of the node's 1 s windows", f"{_p(windows, 50):.1f}×", "", ""),
            ("node CPU (all threads)", f"{run.cpu_cores:.3f} cores", "", ""),
            ("joint_states received by the client", f"{run.states / run.wall_s:.0f}/s" if run.wall_s else "?", "", ""),
        ]

    def table(title: str, body: list[tuple[str, str, str, str]]) -> str:
        lines = [f"### {title}", "", "| measure | value | target | met |", "|---|---|---|---|"]
        lines += [f"| {a} | {b} | {c} | {d} |" for a, b, c, d in body]
        return "\n".join(lines)

    return "\n".join([
        "# finger_node performance",
        "",
        f"Written by `finger_sim/bench/node_bench.py`. Command: `{command}`",
        "",
        "The node (scene paper_flexion, torque from `motor_torque`, physics 1 kHz, joint_states + "
        "fingertip_pose + /clock at 1 kHz, markers at 30 Hz) runs in its own process; the benchmark "
        "process is the client (subscribes joint_states and /diagnostics, publishes a distinct "
        f"torque at {COMMAND_HZ:g} Hz and times the first joint state carrying it). Loopback discovery, "
        "one DDS domain for the pair.",
        "",
        "## Machine",
        "",
        *(f"- {k}: {v}" for k, v in info.items()),
        f"- load average (1, 5, 15 min) at start {load[0][0]:.2f}, {load[0][1]:.2f}, {load[0][2]:.2f}; "
        f"at end {load[1][0]:.2f}, {load[1][1]:.2f}, {load[1][2]:.2f} (shared machine: other work was running)",
        "",
        "## Results",
        "",
        table(f"realtime_factor 1, {rt.wall_s:.1f} s measured after {WARMUP_S:g} s of warm-up", rows),
        "",
        table(f"realtime_factor 0 (as fast as possible), publishing every step (1 kHz of sim time), {fast.wall_s:.1f} s",
              fast_rows(fast, True)),
        "",
        table(f"realtime_factor 0, publishing at 100 Hz of sim time (for comparison), {fast_decimated.wall_s:.1f} s",
              fast_rows(fast_decimated, False)),
        "",
        "## Where the time goes at realtime_factor 0",
        "",
        f"Per step, measured in the benchmark process (µs): physics ({parts['method']}, chosen by the scene's "
        f"`auto`) {parts['physics']:.1f}; refilling joint_states, fingertip_pose and /clock {parts['messages']:.1f}; "
        f"publishing the three with nobody subscribed {parts['publish']:.1f}. Together "
        f"{parts['physics'] + parts['messages'] + parts['publish']:.0f} µs, i.e. at most "
        f"{1e3 / (parts['physics'] + parts['messages'] + parts['publish']):.0f}× real time at 1 kHz physics before "
        f"any subscriber; the measured run took {1e3 / fast.rtf if fast.rtf else float('nan'):.0f} µs per step with the "
        "client subscribed to joint_states (a reliable, synchronous Fast DDS write to a matched reader costs "
        "tens of µs in rclpy; a publishing thread does not help: tried, it overlapped little with the physics, "
        f"the GIL being held through most of the write). Publishing every 10th step gives {fast_decimated.rtf:.0f}×.",
        "",
        "Definitions. Late wake-up: wall time between when a step was due (anchor + n·dt/realtime_factor) "
        "and the wake-up of the stepping loop that stepped it, from the node's own histogram (10 µs bins) reported in "
        "/diagnostics. Overrun: a wake-up that found more than one step due (caught up at once). "
        "Dropped steps: backlog beyond 50 ms of wall time, abandoned (sim time slips). Latency: client "
        "wall clock from publishing a torque to receiving the first joint state whose mcp_joint effort "
        "is that torque (command transport + wait for the next due step + step + state transport + the "
        "client's executor). CPU: utime + stime of the node process over the measured wall time.",
        "",
    ])


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="node_bench", description=__doc__.split("\n\n")[0])
    parser.add_argument("--duration", type=float, default=60.0, help="measured real-time run, s")
    parser.add_argument("--fast-duration", type=float, default=10.0, help="measured as-fast-as-possible run, s")
    parser.add_argument("--domain-id", type=int, default=DEFAULT_DOMAIN_ID)
    parser.add_argument("--out", type=Path, default=ROOT / "docs" / "node_performance.md")
    parser.add_argument("--targets", action="store_true", help="measure the ROS layer's cost targets, new against --old")
    parser.add_argument("--recording", action="store_true",
                        help="measure recording's added CPU at 1 kHz and the 10-finger hand's cores, recording on and off")
    parser.add_argument("--recording-cpu", action="store_true",
                        help="recording's own CPU at 1 kHz, counted by thread, against the node's without recording")
    parser.add_argument("--old", type=Path, default=None, help="with --targets (required), --recording or --recording-cpu: the old checkout")
    parser.add_argument("--target-duration", type=float, default=10.0,
                        help="with --targets, --recording, --recording-cpu: measured s per run")
    parser.add_argument("--rounds", type=int, default=2, help="with --targets, --recording, --recording-cpu: A B rounds")
    parser.add_argument("--at-once", action="store_true",
                        help="with --recording-cpu: each round's off and on nodes at the same time, in --domain-id and the next")
    parser.add_argument("--pin", type=int, nargs=2, metavar=("NODE_CPU", "WRITER_CPU"), default=None,
                        help="with --recording-cpu: every node's threads on NODE_CPU, its log writer process on WRITER_CPU")
    parser.add_argument("--no-hand", action="store_true",
                        help="with --recording: finger_node's pair only (more rounds in the same time)")
    args = parser.parse_args(argv)
    if args.pin is not None and not set(args.pin) <= os.sched_getaffinity(0):
        parser.error(f"--pin: two of the CPUs {sorted(os.sched_getaffinity(0))}, got {' '.join(map(str, args.pin))}")
    isolate_dds(args.domain_id)
    command = "python -m finger_sim.bench.node_bench " + " ".join(argv if argv is not None else sys.argv[1:])
    load0 = os.getloadavg()
    if args.recording_cpu:
        runs: dict[tuple[str, str], list[Window]] = {}
        with tempfile.TemporaryDirectory(prefix="node_recording_cpu_") as tmp:
            for r in range(args.rounds):  # off, on, then on, off: a drift of the machine's load falls on both alike
                order = RECORDING_CONFIGS[:2] if r % 2 == 0 else RECORDING_CONFIGS[1::-1]
                folder = Path(tmp) / f"round{r}"
                folder.mkdir()
                run = at_once if args.at_once else functools.partial(targets, rounds=1)
                for key, windows in run(args.old, args.target_duration, domain_id=args.domain_id, workdir=folder,
                                        names=order, pin_cpus=tuple(args.pin) if args.pin else None).items():
                    runs.setdefault(key, []).extend(windows)
        old = (runs[("1k_off", "old")], runs[("1k_rec", "old")]) if args.old is not None else None
        section = recording_cpu.report(runs[("1k_off", "new")], runs[("1k_rec", "new")], command.strip(),
                                       args.target_duration, (load0, os.getloadavg()), old,
                                       how=recording_cpu.design(args.at_once, args.pin))
        write_section(args.out, section, recording_cpu.BEGIN, recording_cpu.END)
        print(section)
        return 0
    if args.recording:
        with tempfile.TemporaryDirectory(prefix="node_recording_") as tmp:
            names = RECORDING_CONFIGS[:2] if args.no_hand else RECORDING_CONFIGS
            runs = targets(args.old, args.target_duration, args.rounds, args.domain_id, Path(tmp), names)
        section = recording_report(runs, command.strip(), args.old, args.target_duration, args.rounds, (load0, os.getloadavg()))
        write_section(args.out, section, RECORDING_BEGIN, RECORDING_END)
        print(section)
        return 0
    if args.targets:
        if args.old is None:
            parser.error("--targets needs --old (the checkout to compare with)")
        with tempfile.TemporaryDirectory(prefix="node_targets_") as tmp:
            runs = targets(args.old, args.target_duration, args.rounds, args.domain_id, Path(tmp))
        section = targets_report(runs, command.strip(), args.old, args.target_duration, args.rounds, (load0, os.getloadavg()))
        write_section(args.out, section, TARGETS_BEGIN, TARGETS_END)
        print(section)
        return 0
    with tempfile.TemporaryDirectory(prefix="node_bench_") as tmp:
        rt = measure(1.0, args.duration, args.domain_id, Path(tmp), commands=True)
        fast = measure(0.0, args.fast_duration, args.domain_id, Path(tmp), commands=False)
        fast_decimated = measure(0.0, args.fast_duration, args.domain_id, Path(tmp), commands=False, publish_rate_hz=100.0)
    parts = breakdown(args.domain_id)
    text = report(rt, fast, fast_decimated, parts, machine(), command.strip(), (load0, os.getloadavg()))
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(text)
    print(text)
    return 0


if __name__ == "__main__":
    sys.exit(main())
