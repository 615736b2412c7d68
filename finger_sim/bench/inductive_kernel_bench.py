"""The inductive drive's step (L > 0, spec §8) on the Python path and on the compiled kernel (docs/drive_performance.md).

The default drive at 6 V with L = 1 mH (auto: 32 substeps per 1 ms step), free and closing on the cup,
stepped by `Simulator.step` (the node's path) four ways, one run each per round, the rounds repeated
(A B C D, A B C D, ...): A the Python path; B the compiled substeps with the events in Python, every step
through the event loop (the lean call switched off: what ran before it); C the compiled kernel as it
runs now (a rolling step without gaps is one call, `kernel.drive.inductive_fast_step`); D the same scene
with L = 0, compiled. Median and mean step over all runs of each, and the medians' ratios to C.

    python -m finger_sim.bench.inductive_kernel_bench [--repeats N] [--inductance H]
"""

from __future__ import annotations

import argparse
import os
import platform
import statistics
from datetime import datetime, timezone

from finger_sim.bench.drive_bench import CUP, DURATION, REPEATS, step_times
from finger_sim.bench.inductance_bench import INDUCTANCE, scene
from finger_sim.simulate import Simulator

#: The four ways a scene is stepped: (label, inductance on or off, kernel, lean call kept).
WAYS = (("A python", True, "python", True), ("B compiled, events loop", True, "compiled", False),
        ("C compiled, lean", True, "compiled", True), ("D L = 0 compiled", False, "compiled", True))


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=REPEATS)
    parser.add_argument("--inductance", type=float, default=INDUCTANCE)
    args = parser.parse_args(argv)
    print(f"{datetime.now(timezone.utc):%Y-%m-%d %H:%M} UTC, {platform.processor() or platform.machine()}, load "
          f"{os.getloadavg()[0]:.1f}, {args.repeats} rounds of {DURATION} s at 1 kHz, L = {args.inductance:g} H\n")
    print("| scene | way | method (substeps) | µs/step median / mean | median ÷ C |\n|---|---|---|---|---|")
    for label, objects in (("free motion", []), ("closing on the cup", [CUP])):
        scenes = {True: scene(args.inductance, objects), False: scene(0.0, objects)}
        times: dict[str, list[float]] = {way[0]: [] for way in WAYS}
        for _ in range(args.repeats):
            for name, inductive, kernel, lean in WAYS:
                times[name] += step_times(scenes[inductive], kernel, lean)[0]
        medians = {name: statistics.median(t) for name, t in times.items()}
        for name, inductive, kernel, _ in WAYS:
            sim = Simulator(scenes[inductive], kernel=kernel)
            method = f"{sim.method} ({getattr(sim.integrator, 'substeps', 1)})"
            print(f"| {label} | {name} | {method} | {medians[name]:.1f} / {statistics.fmean(times[name]):.1f} | "
                  f"{medians[name] / medians[WAYS[2][0]]:.2f} |")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
