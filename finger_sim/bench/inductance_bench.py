"""The cost of the winding's inductance per step (spec §8, L > 0; docs/drive_performance.md).

The default drive (6 V) at 1 kHz with `method: auto`, free and closing on the cup, with L = 0 and
with L > 0 (the current a state: auto's explicit method in substeps that resolve L/R), stepped by
`Simulator.step` (the node's path) on one kernel. The runs of a pair alternate, REPEATS times; the
median and mean step over all runs and their ratio, as a Markdown table.

    python -m finger_sim.bench.inductance_bench [--kernel compiled|python] [--repeats N] [--inductance H]
"""

from __future__ import annotations

import argparse
import platform
import statistics
from datetime import datetime, timezone

from finger_sim.bench.drive_bench import CUP, DURATION, REPEATS, VOLTAGE, step_times
from finger_sim.scene import Scene, scene_from_dict
from finger_sim.simulate import Simulator

#: The inductance benchmarked by default, H: L/R = 1.25e-4 s with the default 8 Ω, 32 substeps of 1 ms
#: by auto's rule (|s|·h ≤ 1/4).
INDUCTANCE = 1e-3


def scene(inductance: float, objects: list[dict]) -> Scene:
    return scene_from_dict({"model": {"drive": {"inductance": inductance}}, "objects": objects,
                            "input": {"voltage": {"type": "constant", "value": VOLTAGE}}, "duration": DURATION,
                            "integrator": {"method": "auto", "dt": 0.001}})


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--kernel", default="compiled", choices=("compiled", "python"))
    parser.add_argument("--repeats", type=int, default=REPEATS)
    parser.add_argument("--inductance", type=float, default=INDUCTANCE)
    args = parser.parse_args(argv)
    print(f"{datetime.now(timezone.utc):%Y-%m-%d %H:%M} UTC, {platform.processor() or platform.machine()}, "
          f"kernel {args.kernel}, {args.repeats} alternating runs of {DURATION} s at 1 kHz, L = {args.inductance:g} H\n")
    print("| scene | method (substeps) | L = 0 µs/step, median / mean | L > 0 µs/step, median / mean | ratio, median / mean |\n"
          "|---|---|---|---|---|")
    for label, objects in (("free motion", []), ("closing on the cup", [CUP])):
        times: dict[float, list[float]] = {0.0: [], args.inductance: []}
        methods = {}
        for _ in range(args.repeats):
            for inductance in times:
                t, methods[inductance] = step_times(scene(inductance, objects), args.kernel)
                times[inductance] += t
        substeps = Simulator(scene(args.inductance, objects), kernel=args.kernel).integrator.substeps  # type: ignore[attr-defined]
        (a, am), (b, bm) = ((statistics.median(times[x]), statistics.fmean(times[x])) for x in times)
        print(f"| {label} | {methods[0.0]} / {methods[args.inductance]} ({substeps}) | {a:.1f} / {am:.1f} | "
              f"{b:.1f} / {bm:.1f} | {b / a:.2f} / {bm / am:.2f} |")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
