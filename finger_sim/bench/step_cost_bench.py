"""The stepping thread's message cost per step, old path against new, side by side in one process.

    python -m finger_sim.bench.step_cost_bench [--steps 5000] [--rounds 7] [--out docs/node_performance.md]

Per step a node publishes joint_states, fingertip_pose and /clock and, when recording, logs the
same three. The old path (before the CDR writers) refilled three rclpy messages (finger_sim.ros.conversions),
serialized each with rclpy, published and logged the bytes. The new path packs the three as CDR
bytes with finger_sim.log.cdr_writer (no message objects), then publishes and logs those bytes.
Both run here against the same publishers (nobody subscribed) and the same kind of recorder (an
McapRecorder to a temporary file, zstd chunks, its writer thread running), rounds alternating
old and new; the figures are medians over the rounds. Also the garbage collector's generation-0
collections per 10 000 steps of each path (the allocations that feed it), and the physics step
for scale.

With `--old-recorder DIR` (a checkout, e.g. main's), the new path also runs against the old
McapRecorder (DIR/finger_sim/log/recorder.py: mcap written and compressed by a thread of this
process) and the new one (a writer process), alternating: wall µs per step, this process's CPU
µs per step (time.process_time: every thread, the old writer thread included) and the writer
process's CPU µs per step (/proc), so the recording's cost on the stepping process is told
apart from the work moved out of it.

The report replaces the section between the STEP_COST markers of --out (added at the end if
absent), so that node_bench's own figures in that file stay as they were.
"""

from __future__ import annotations

import argparse
import gc
import importlib.util
import os
import statistics
import sys
import tempfile
import time
from collections.abc import Callable
from datetime import datetime, timezone
from pathlib import Path

from finger_sim.bench.processes import ROOT, cpu_seconds, isolate_dds, machine

DEFAULT_DOMAIN_ID = 32
WRITER_START_S = 1.5  # wall s granted to a new recorder's writer process to start (imports) before timing
SPLIT_HANDOVER_S = 1000.0  # a handover period longer than any loop: the writer stays idle until close
BEGIN = "<!-- STEP_COST begin: written by finger_sim/bench/step_cost_bench.py -->"
END = "<!-- STEP_COST end -->"


def _old_recorder(checkout: Path) -> type:
    """The McapRecorder class of `checkout`, loaded beside this package's (its relative imports
    resolve to this package's finger_sim.log modules, which it shares)."""
    spec = importlib.util.spec_from_file_location("finger_sim.log._old_recorder", checkout / "finger_sim" / "log" / "recorder.py")
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module
    spec.loader.exec_module(module)
    return module.McapRecorder


def _paths(domain_id: int, folder: Path, steps: int, rounds: int, old_recorder: Path | None = None) -> dict[str, object]:
    import rclpy
    from geometry_msgs.msg import PoseStamped
    from rclpy.serialization import serialize_message
    from rosgraph_msgs.msg import Clock
    from sensor_msgs.msg import JointState

    from finger_sim.log import McapRecorder
    from finger_sim.log.cdr_writer import JointStateCdr, PoseStampedCdr, clock_cdr
    from finger_sim.ros import conversions
    from finger_sim.scene import load_scene
    from finger_sim.scene_paths import resolve_scene
    from finger_sim.simulate import Simulator

    sim = Simulator(load_scene(resolve_scene("paper_flexion")).with_overrides(dt=1e-3))
    frames = conversions.FingerFrames.from_system(sim.system)
    q, v = sim.q, sim.v
    context = rclpy.Context()
    rclpy.init(context=context, domain_id=domain_id)
    node = rclpy.create_node("step_cost_bench", context=context)
    js_pub = node.create_publisher(JointState, "/joint_states", 10)
    pose_pub = node.create_publisher(PoseStamped, "/fingertip_pose", 10)
    clock_pub = node.create_publisher(Clock, "/clock", 10)
    joints_cdr, pose_cdr = JointStateCdr(frames.base_frame, frames.joint_names), PoseStampedCdr(frames.base_frame)
    msgs: dict[str, object] = {}

    def old(i: int, rec: McapRecorder | None) -> None:
        msgs["js"] = conversions.joint_state(frames, q, v, 0.001, i, out=msgs.get("js"))
        msgs["pose"] = conversions.fingertip_pose(frames, q, i, out=msgs.get("pose"))
        msgs["clock"] = conversions.clock(i, out=msgs.get("clock"))
        for pub, topic, key in ((clock_pub, "/clock", "clock"), (js_pub, "/joint_states", "js"),
                                (pose_pub, "/fingertip_pose", "pose")):
            if rec is None:
                pub.publish(msgs[key])
            else:
                data = serialize_message(msgs[key])
                pub.publish(data)
                rec.write(topic, data, i)

    def new(i: int, rec: McapRecorder | None) -> None:
        for pub, topic, data in ((clock_pub, "/clock", clock_cdr(i)),
                                 (js_pub, "/joint_states", joints_cdr(i, *conversions.joint_values(frames, q, v, 0.001))),
                                 (pose_pub, "/fingertip_pose", pose_cdr(i, *conversions.fingertip_values(frames, q)))):
            pub.publish(data)
            if rec is not None:
                rec.write(topic, data, i)

    def timed(path: Callable[[int, McapRecorder | None], None], recording: bool, tag: str,
              recorder: type = McapRecorder) -> tuple[float, ...]:
        """µs per step, gen-0 collections, and CPU µs per step of this process and of the writer process."""
        rec = None
        if recording:
            rec = recorder(folder / f"{tag}.mcap", queue_size=10 * steps).open()
            for topic, kind in (("/clock", Clock), ("/joint_states", JointState), ("/fingertip_pose", PoseStamped)):
                rec.register_channel(topic, kind)
        process = getattr(rec, "_process", None)  # the new recorder's writer process
        if process is not None:
            time.sleep(WRITER_START_S)  # it has started up (imports) before the clock starts
        collections = gc.get_stats()[0]["collections"]
        child0 = cpu_seconds(process.pid) if process is not None else 0.0
        t, cpu = time.perf_counter(), time.process_time()
        for i in range(steps):
            path(i * 1_000_000, rec)
        us = (time.perf_counter() - t) / steps * 1e6  # what the stepping thread sees
        if rec is not None:
            rec.close()  # the rest of the writer's work: counted in the CPU columns
            assert rec.dropped == 0
        cpu_us = (time.process_time() - cpu) / steps * 1e6
        collected = gc.get_stats()[0]["collections"] - collections
        child_us = 0.0
        if process is not None:  # closed: its CPU went to this process's children times
            child_us = (os.times().children_user + os.times().children_system - child_base[0] - child0) / steps * 1e6
            child_base[0] = os.times().children_user + os.times().children_system
        return us, collected, cpu_us, child_us

    child_base = [os.times().children_user + os.times().children_system]

    def split(recorder: type, tag: str) -> tuple[float, float, float]:
        """CPU µs per step of the recording alone, split: the caller's write() (a loop while the
        writer is idle: handover far away), the writer's work in this process (at close), and
        the writer process's (the new recorder's)."""
        rec = recorder(folder / f"{tag}.mcap", queue_size=10 * steps, handover_s=SPLIT_HANDOVER_S).open()
        for topic, kind in (("/clock", Clock), ("/joint_states", JointState), ("/fingertip_pose", PoseStamped)):
            rec.register_channel(topic, kind)
        process = getattr(rec, "_process", None)
        if process is not None:
            time.sleep(WRITER_START_S)
        child0 = cpu_seconds(process.pid) if process is not None else 0.0
        items = [("/clock", clock_cdr(0)), ("/joint_states", joints_cdr(0, *conversions.joint_values(frames, q, v, 0.001))),
                 ("/fingertip_pose", pose_cdr(0, *conversions.fingertip_values(frames, q)))]
        c0 = time.process_time()
        for i in range(steps):
            for topic, data in items:
                rec.write(topic, data, i * 1_000_000)
        c1 = time.process_time()
        rec.close()
        assert rec.dropped == 0
        c2 = time.process_time()
        child = 0.0
        if process is not None:
            child = os.times().children_user + os.times().children_system - child_base[0] - child0
            child_base[0] = os.times().children_user + os.times().children_system
        return tuple(x / steps * 1e6 for x in (c1 - c0, c2 - c1, child))  # type: ignore[return-value]

    try:
        t = time.perf_counter()
        for _ in range(steps):
            sim.step(1e-4)
        physics = (time.perf_counter() - t) / steps * 1e6
        results: dict[tuple[str, bool], list[tuple[float, ...]]] = {}
        recorders = {"new recorder": McapRecorder, "old recorder": _old_recorder(old_recorder)} if old_recorder else {}
        for r in range(rounds):
            for recording in (False, True):
                for name, path in (("old", old), ("new", new)):
                    results.setdefault((name, recording), []).append(timed(path, recording, f"{name}{r}"))
            for name, recorder in recorders.items():
                results.setdefault((name, True), []).append(timed(new, True, f"{name[:3]}rec{r}", recorder))
                results.setdefault((name, "split"), []).append(split(recorder, f"{name[:3]}split{r}"))
    finally:
        node.destroy_node()
        rclpy.try_shutdown(context=context)
    return {"physics": physics, "method": sim.method, "results": results}


def report(measured: dict, command: str, steps: int, rounds: int) -> str:
    results = measured["results"]

    def us(name: str, recording: bool) -> float:
        return statistics.median(r[0] for r in results[(name, recording)])

    def gc0(name: str, recording: bool) -> float:
        return statistics.median(r[1] for r in results[(name, recording)]) * 10_000 / steps

    rows = []
    for recording, label in ((False, "publish only"), (True, "publish and record")):
        o, n = us("old", recording), us("new", recording)
        rows.append(f"| {label} | {o:.1f} | {n:.1f} | {o / n:.2f}× | {gc0('old', recording):.0f} | {gc0('new', recording):.0f} |")
    recorder_rows = []
    if ("old recorder", True) in results:
        def col(name: str, k: int) -> float:
            return statistics.median(r[k] for r in results[(name, True)])
        base = us("new", False)
        base_cpu = statistics.median(r[2] for r in results[("new", False)])
        for name, what in (("old recorder", "a writer thread in this process"), ("new recorder", "a writer process")):
            recorder_rows.append(f"| {name} ({what}) | {col(name, 0):.1f} | {col(name, 0) - base:.1f} | {col(name, 2):.1f} | "
                                 f"{col(name, 2) - base_cpu:.1f} | {col(name, 3):.1f} |")
        recorder_rows = [
            "",
            "The recording's cost, old recorder against new, both on the new message path (rows alternating in each "
            f"round; publishing alone costs {base:.1f} µs of wall time and {base_cpu:.1f} µs of CPU per step here). Wall: the stepping loop alone, what the "
            "stepping thread sees. CPU: the loop and closing the log (the old writer thread's backlog, the new writer "
            "process's end); the stepping process's CPU counts all its threads.",
            "",
            "| publish and record, per step | wall µs | wall µs over publishing alone | stepping process CPU µs | "
            "its CPU µs over publishing alone | writer process CPU µs |",
            "|---|---|---|---|---|---|",
            *recorder_rows,
            "",
            "The same recording alone (no publishing), its CPU split: the caller's `write()` calls, timed while the "
            "writer is idle (its handover period set beyond the loop); the writer's work in the stepping process "
            "(timed at close: the old writer thread's whole share); the writer process's.",
            "",
            "| record only, CPU µs per step | caller's write() | writer in the stepping process | writer process |",
            "|---|---|---|---|",
            *(f"| {name} | " + " | ".join(f"{statistics.median(r[k] for r in results[(name, 'split')]):.1f}" for k in range(3)) + " |"
              for name in ("old recorder", "new recorder")),
        ]
    return "\n".join([
        BEGIN,
        "## The message path per step, old and new",
        "",
        f"Command: `{command}` ({datetime.now(timezone.utc):%Y-%m-%d %H:%M} UTC, {machine().get('cpu', '?')}, "
        f"{os.cpu_count()} cores shared with other work). {rounds} rounds of {steps} steps, old and new alternating; "
        "medians. Per step: joint_states, fingertip_pose and /clock published (nobody subscribed) and, when "
        "recording, written to an McapRecorder (this checkout's). Old: refill three rclpy "
        "messages, rclpy's serialize_message, publish and log the bytes. New: finger_sim.log.cdr_writer packs the "
        "CDR bytes from the state (no message objects), published and logged as they are.",
        "",
        "| per step | old µs | new µs | old/new | old gen-0 gc per 10k steps | new gen-0 gc per 10k steps |",
        "|---|---|---|---|---|---|",
        *rows,
        "",
        *recorder_rows,
        "",
        f"For scale: one physics step of paper_flexion ({measured['method']}) takes {measured['physics']:.1f} µs here.",
        END,
    ])


def write_section(path: Path, section: str) -> None:
    """Replace the STEP_COST section of `path` (or append it)."""
    text = path.read_text() if path.exists() else ""
    if BEGIN in text and END in text:
        head, rest = text.split(BEGIN, 1)
        text = head + section + rest.split(END, 1)[1]
    else:
        text = text.rstrip("\n") + "\n\n" + section + "\n"
    path.write_text(text)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="step_cost_bench", description=__doc__.split("\n\n")[0])
    parser.add_argument("--steps", type=int, default=5000)
    parser.add_argument("--rounds", type=int, default=7)
    parser.add_argument("--domain-id", type=int, default=DEFAULT_DOMAIN_ID)
    parser.add_argument("--out", type=Path, default=ROOT / "docs" / "node_performance.md")
    parser.add_argument("--old-recorder", type=Path, default=None, help="a checkout whose McapRecorder to compare with")
    args = parser.parse_args(argv)
    isolate_dds(args.domain_id)
    command = "python -m finger_sim.bench.step_cost_bench " + " ".join(argv if argv is not None else sys.argv[1:])
    with tempfile.TemporaryDirectory(prefix="step_cost_") as tmp:
        measured = _paths(args.domain_id, Path(tmp), args.steps, args.rounds, args.old_recorder)
    section = report(measured, command.strip(), args.steps, args.rounds)
    write_section(args.out, section)
    print(section)
    return 0


if __name__ == "__main__":
    sys.exit(main())
