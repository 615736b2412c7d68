"""The stepping thread's CPU per step of a real finger_node or finger_hand, in this process.

    python -m finger_sim.bench.step_loop_bench [--hand FILE | --scene NAME] [--steps 10000] [--profile | --paced]

Builds the node (paper_flexion or --scene, or the fingers of a hand file; torque from the topics, nobody
sends; realtime_factor 0, publishing every step, markers at 30 Hz, recording on unless
--no-record), publishes the first state, runs 500 steps of warm-up, then calls the stepping
loop's `_advance()` --steps times back to back: the work of one step (physics, CDR packing,
publishing, handing the log over) without the pacing. Prints wall and CPU µs per step of this
process (every thread: the recorder's sender thread included, the log writer process not), or
with --profile cProfile's table. With --paced, each step starts at the next 1 ms deadline (a sleep
in between, as the node's real-time loop: caches cold) and the figure is this thread's CPU per
`_advance()` (median and mean µs; the thread CPU clock, so neither the sleep nor other threads).
Old against new: run this file by path with PYTHONPATH set to the old checkout (its finger_sim is
the one imported).
"""

from __future__ import annotations

import argparse
import cProfile
import gc
import pstats
import statistics
import sys
import tempfile
import time

WARMUP_STEPS = 500
PACED_DT_S = 1e-3  # --paced: wall s between step deadlines
PROFILE_ROWS = 35


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="step_loop_bench", description=__doc__.split("\n\n")[0])
    parser.add_argument("--hand", help="a hand file: finger_hand instead of finger_node")
    parser.add_argument("--scene", default="paper_flexion", help="finger_node's scene (default paper_flexion)")
    parser.add_argument("--steps", type=int, default=10_000)
    parser.add_argument("--no-record", action="store_true")
    parser.add_argument("--profile", action="store_true", help="cProfile's table instead of the timing")
    parser.add_argument("--paced", action="store_true", help="steps at 1 ms deadlines; this thread's CPU per step")
    args = parser.parse_args(argv)

    import rclpy
    from rclpy.parameter import Parameter

    rclpy.init()
    with tempfile.TemporaryDirectory(prefix="step_loop_") as folder:
        params = dict(torque_source="topic", physics_rate_hz=1000.0, publish_rate_hz=0.0, realtime_factor=0.0,
                      command_timeout=0.5, record=not args.no_record, record_dir=folder)
        if args.hand:
            from finger_sim.ros.hand import FingerHand as node_type
            params["hand"] = args.hand
        else:
            from finger_sim.ros.node import FingerNode as node_type  # type: ignore[assignment]
            params["scene"] = args.scene
        node = node_type(parameter_overrides=[Parameter(k, value=v) for k, v in params.items()])
        try:
            node._publish_state(force=True)
            for _ in range(WARMUP_STEPS):
                node._advance()
            gc.freeze()
            if args.paced:
                print(paced(node, args.steps))
                return 0
            profile = cProfile.Profile() if args.profile else None
            wall, cpu = time.perf_counter(), time.process_time()
            if profile is not None:
                profile.enable()
            for _ in range(args.steps):
                node._advance()
            if profile is not None:
                profile.disable()
            wall, cpu = time.perf_counter() - wall, time.process_time() - cpu
            print(f"wall {1e6 * wall / args.steps:.1f} us/step, process cpu {1e6 * cpu / args.steps:.1f} us/step")
            if profile is not None:
                pstats.Stats(profile, stream=sys.stdout).sort_stats("tottime").print_stats(PROFILE_ROWS)
        finally:
            node.close_log()
            node.destroy_node()
            rclpy.try_shutdown()
    return 0


def paced(node: object, steps: int) -> str:
    """`steps` calls of node._advance(), each at the next 1 ms deadline; this thread's CPU per call."""
    thread_ns, costs = time.thread_time_ns, []
    start = time.perf_counter()
    for k in range(steps):
        before = thread_ns()
        node._advance()  # type: ignore[attr-defined]
        costs.append(thread_ns() - before)
        wait = start + (k + 1) * PACED_DT_S - time.perf_counter()
        if wait > 0:
            time.sleep(wait)
    return (f"paced: thread cpu median {statistics.median(costs) / 1e3:.1f} us/step, "
            f"mean {statistics.fmean(costs) / 1e3:.1f} us/step")


if __name__ == "__main__":
    sys.exit(main())
