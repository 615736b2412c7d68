"""The stepping thread's CPU per step of a real finger_node or finger_hand, in this process.

    python -m finger_sim.bench.step_loop_bench [--hand FILE | --scene NAME] [--steps 10000] [--profile]

Builds the node (paper_flexion or --scene, or the fingers of a hand file; torque from the topics, nobody
sends; realtime_factor 0, publishing every step, markers at 30 Hz, recording on unless
--no-record), publishes the first state, runs 500 steps of warm-up, then calls the stepping
loop's `_advance()` --steps times back to back: the work of one step (physics, CDR packing,
publishing, handing the log over) without the pacing. Prints wall and CPU µs per step of this
process (every thread: the recorder's sender thread included, the log writer process not), or
with --profile cProfile's table. Old against new: run it with PYTHONPATH set to the old checkout.
"""

from __future__ import annotations

import argparse
import cProfile
import gc
import pstats
import sys
import tempfile
import time

WARMUP_STEPS = 500
PROFILE_ROWS = 35


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="step_loop_bench", description=__doc__.split("\n\n")[0])
    parser.add_argument("--hand", help="a hand file: finger_hand instead of finger_node")
    parser.add_argument("--scene", default="paper_flexion", help="finger_node's scene (default paper_flexion)")
    parser.add_argument("--steps", type=int, default=10_000)
    parser.add_argument("--no-record", action="store_true")
    parser.add_argument("--profile", action="store_true", help="cProfile's table instead of the timing")
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


if __name__ == "__main__":
    sys.exit(main())
