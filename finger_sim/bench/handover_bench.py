"""What recording costs a paced 1 kHz loop, without ROS: the node's hand-over path alone.

    python -m finger_sim.bench.handover_bench [--old <checkout>] [--messages 3 22] [--node] [--seconds 8] [--rounds 3]

Each run is a fresh process that steps a 1 kHz loop paced like the node (sleep to the next
1 ms deadline) and hands each step's state of N CDR messages (JointState-sized, 160 bytes,
one topic each) through finger_sim.ros.state_output.StateOutput, as the node's
_publish_state does, into a McapRecorder with the default handover; sending is a no-op. With
--node the states are instead finger_node's own (`node_states`: paper_flexion stepped at 1 kHz,
/clock, joint_states and fingertip_pose every step, markers at 30 Hz, diagnostics at 1 Hz, made
by the node's CDR writers and rclpy's serializer; no DDS). The
same loop with no recorder is the baseline. Figures: CPU s per sim s (cores at real time) of
the loop's process (every thread: the recorder's sender thread included) and of its log writer
process (McapRecorder.cpu, to the ns), over SECONDS after WARMUP_S (the writer process's
start-up excluded); the log's bytes per sim s; and the loop
thread's own CPU for one state's begin, adds and flush (median µs, thread CPU clock): what the
stepping thread pays per state, paced. With --old, every run of this checkout is followed by the same
run of the old one (first on PYTHONPATH): A B A B, medians over the rounds.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

WARMUP_S = 3.0  # wall s after open before measuring: the writer process imports mcap, numpy, zstd
RATE_HZ = 1000.0
PAYLOAD_BYTES = 160  # about a 3-joint JointState's CDR
NS = 1_000_000_000
MARKERS_EVERY, DIAGNOSTICS_EVERY = 33, 1000  # steps between the node's markers (30 Hz) and diagnostics (1 Hz)
NODE = 0  # `--messages` value standing for the node's own states (--node)


def node_states(steps: int) -> tuple[dict[str, str], list[tuple[list[str], list[bytes]]]]:
    """finger_node's logged topics (topic → type) and each step's (topics, CDR bytes): paper_flexion
    at 1 kHz under its scripted torque, as finger_sim.ros.finger and node publish it."""
    from rclpy.serialization import serialize_message

    from finger_sim.log.cdr_writer import JointStateCdr, MarkerArrayCdr, PoseStampedCdr, clock_cdr
    from finger_sim.ros import conversions
    from finger_sim.scene import load_scene
    from finger_sim.scene_paths import resolve_scene
    from finger_sim.simulate import Simulator

    sim = Simulator(load_scene(resolve_scene("paper_flexion")).with_overrides(dt=1e-3))
    frames = conversions.FingerFrames.from_system(sim.system)
    joints, pose = JointStateCdr(frames.base_frame, frames.joint_names), PoseStampedCdr(frames.base_frame)
    markers = MarkerArrayCdr(conversions.markers(frames, sim.q, 0))
    types = {"/clock": "rosgraph_msgs/msg/Clock", "/joint_states": "sensor_msgs/msg/JointState",
             "/fingertip_pose": "geometry_msgs/msg/PoseStamped", "/finger_markers": "visualization_msgs/msg/MarkerArray",
             "/diagnostics": "diagnostic_msgs/msg/DiagnosticArray"}
    states = []
    for k in range(steps):
        sim.step()
        stamp = k * round(NS / RATE_HZ)
        topics = ["/clock", "/joint_states", "/fingertip_pose"]
        datas = [clock_cdr(stamp), joints(stamp, *conversions.joint_values(frames, sim.q, sim.v, sim.torque)),
                 pose(stamp, *conversions.fingertip_values(frames, sim.q))]
        if k % MARKERS_EVERY == 0:
            topics.append("/finger_markers")
            datas.append(markers(stamp, conversions.marker_values(frames, sim.q)))
        if k % DIAGNOSTICS_EVERY == 0:  # about the node's: one status of ~25 values
            values = {f"key_{i}": 0.001 * (k + i) for i in range(25)}
            status = conversions.status("finger_node: simulation", "finger", b"\x00", "running", values)
            topics.append("/diagnostics")
            datas.append(serialize_message(conversions.diagnostic_array(stamp, [status])))
        states.append((topics, datas))
    return types, states


def run_loop(messages: int, seconds: float, record: bool) -> dict[str, float]:
    """One paced loop in this process: {'loop': cores, 'writer': cores, 'rtf': sim s per wall s}."""
    from finger_sim.log import McapRecorder
    from finger_sim.ros.interfaces import Endpoint
    from finger_sim.ros.state_output import StateOutput

    steps, dt_ns = round(seconds * RATE_HZ), round(NS / RATE_HZ)
    if messages == NODE:
        types, states = node_states(steps)
    else:
        types = {f"/f{i}/joint_states": "sensor_msgs/msg/JointState" for i in range(messages)}
        states = [(list(types), [(k * dt_ns).to_bytes(8, "little") * (PAYLOAD_BYTES // 8)] * messages) for k in range(steps)]
    folder = tempfile.mkdtemp(prefix="handover_bench_")
    recorder = McapRecorder(Path(folder) / "bench.mcap").open() if record else None
    endpoints = {}
    for topic, type_name in types.items():
        if recorder is not None:
            recorder.register_channel(topic, type_name)
        endpoints[topic] = Endpoint(None, topic, object, True, False, lambda data: None)
    output = StateOutput(recorder)
    time.sleep(WARMUP_S)
    w0, c0 = recorder.cpu().writer_s if recorder is not None else 0.0, time.process_time()
    thread_ns, states_ns = time.thread_time_ns, []
    start = time.perf_counter()
    for k in range(steps):
        stamp = k * dt_ns
        topics, datas = states[k]
        state_start = thread_ns()
        output.begin()
        for topic, data in zip(topics, datas):
            output.add(endpoints[topic], data, stamp)
        output.flush(stamp)
        states_ns.append(thread_ns() - state_start)
        wait = start + (k + 1) / RATE_HZ - time.perf_counter()
        if wait > 0:
            time.sleep(wait)
    wall = time.perf_counter() - start
    loop, writer = time.process_time() - c0, (recorder.cpu().writer_s - w0) if recorder is not None else 0.0
    log_bytes = 0
    if recorder is not None:
        recorder.close()
        expected = sum(len(datas) for _, datas in states)
        assert (recorder.written, recorder.dropped) == (expected, 0), "the log lost messages"
        log_bytes = recorder.path.stat().st_size
    sim = steps / RATE_HZ
    import finger_sim

    return {"loop": loop / sim, "writer": writer / sim, "rtf": sim / wall, "state_us": statistics.median(states_ns) / 1e3,
            "log_bytes": log_bytes / sim, "package": str(Path(finger_sim.__file__).parent)}


def _run(checkout: Path | None, messages: int, seconds: float, record: bool) -> dict[str, float]:
    env = dict(os.environ)
    if checkout is not None:
        env["PYTHONPATH"] = os.pathsep.join([str(checkout), env.get("PYTHONPATH", "")]).rstrip(os.pathsep)
    # this file run by path: the old checkout need not have it, and its finger_sim is the one imported
    argv = ["handover_bench", "--one", str(messages), str(seconds), "1" if record else "0"]
    code = f"import runpy, sys; sys.argv = {argv!r}; runpy.run_path({__file__!r}, run_name='__main__')"
    expected = Path(checkout if checkout is not None else Path(__file__).parents[2]).resolve()
    # run in the checkout: `-c` puts the working folder first on sys.path
    out = subprocess.run([sys.executable, "-c", code], env=env, check=True, capture_output=True, text=True, cwd=expected)
    result = json.loads(out.stdout.strip().splitlines()[-1])
    assert Path(result.pop("package")).resolve().parent == expected, f"{result}: not the checkout {expected}"
    return result


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--old", type=Path, default=None, help="a checkout of the old code, run after each new run")
    parser.add_argument("--messages", type=int, nargs="+", default=[3, 22], help="CDR messages per state")
    parser.add_argument("--node", action="store_true", help="finger_node's own states instead (node_states)")
    parser.add_argument("--seconds", type=float, default=8.0, help="measured sim (= wall) s per run")
    parser.add_argument("--rounds", type=int, default=3)
    parser.add_argument("--one", nargs=3, help=argparse.SUPPRESS)  # a single run in this process (JSON out)
    args = parser.parse_args(argv)
    if args.one:
        print(json.dumps(run_loop(int(args.one[0]), float(args.one[1]), args.one[2] == "1")))
        return 0
    sides = {"new": None} | ({"old": args.old} if args.old is not None else {})
    if args.node:
        args.messages = [NODE]
    runs: dict[tuple[str, int, bool], list[dict[str, float]]] = {}
    load0 = os.getloadavg()[0]
    for _ in range(args.rounds):
        for n in args.messages:
            for record in (False, True):
                for side, checkout in sides.items():
                    runs.setdefault((side, n, record), []).append(_run(checkout, n, args.seconds, record))
    print(f"load average {load0:.1f} → {os.getloadavg()[0]:.1f}; medians of {args.rounds} rounds, cores (CPU s per sim s)")
    print("| side | messages a state | loop, no log | loop, recording | its writer process (rounds) | added by recording | "
          "the same, µs a step | loop thread a state, µs (no log, recording) | real-time factor (lowest run) | log, kB per sim s |")
    print("|---|---|---|---|---|---|---|---|---|---|")
    for n in args.messages:
        for side in sides:
            off, on = runs[(side, n, False)], runs[(side, n, True)]
            base = statistics.median(r["loop"] for r in off)
            loop = statistics.median(r["loop"] for r in on)
            writer = statistics.median(r["writer"] for r in on)
            rtf = min(r["rtf"] for r in off + on)
            added = loop + writer - base
            state_us = [statistics.median(r["state_us"] for r in runs) for runs in (off, on)]
            writers = ", ".join(f"{r['writer']:.4f}" for r in on)
            print(f"| {side} | {'node' if n == NODE else n} | {base:.4f} | {loop:.4f} | {writer:.4f} ({writers}) | +{added:.4f} | "
                  f"{added * 1e6 / RATE_HZ:.1f} | {state_us[0]:.1f}, {state_us[1]:.1f} | {rtf:.3f} | "
                  f"{statistics.median(r['log_bytes'] for r in on) / 1e3:.1f} |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
