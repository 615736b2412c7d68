"""A contact step against a free step in the batch's compiled loop, side by side in one process.

    python -m finger_sim.bench.batch_contact_bench [--runs 200] [--method rk4] [--duration 0.5] [--repeats 5]

`run_batch` of `runs` copies of config/grasp_cylinder.yaml (the finger closes onto the cup and
holds it from ~0.2 s on; 0.5 s: 500 steps) with a named explicit method, and of the same scene without the cup (free);
process CPU per finger-step of the whole call (set-up, the compiled loop, the onset step handed to
each finger's Simulator), medians of `repeats`, the two interleaved. A longer `duration` spreads
the per-run set-up over more steps, most of them in contact.
"""

from __future__ import annotations

import argparse
import statistics
import time
from pathlib import Path

from finger_sim.batch import run_batch
from finger_sim.scene import load_scene, scene_from_dict

SCENE = Path(__file__).resolve().parents[2] / "config" / "grasp_cylinder.yaml"


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--runs", type=int, default=200)
    ap.add_argument("--method", default="rk4")
    ap.add_argument("--duration", type=float, default=0.5, help="s")
    ap.add_argument("--repeats", type=int, default=5)
    args = ap.parse_args(argv)
    data = load_scene(SCENE).to_dict()
    data["integrator"]["method"] = args.method
    data["duration"] = args.duration
    contact = scene_from_dict(data)
    free = scene_from_dict({k: v for k, v in data.items() if k != "objects"})
    cases = {"contact (grasp_cylinder)": [contact] * args.runs, "free (no cup)": [free] * args.runs}
    for scenes in cases.values():
        run_batch(scenes[:2])  # numba's cache load
    cpu: dict[str, list[float]] = {name: [] for name in cases}
    handed: dict[str, int] = {}
    for _ in range(args.repeats):
        for name, scenes in cases.items():
            start = time.process_time()
            result = run_batch(scenes)
            cpu[name].append(time.process_time() - start)
            handed[name] = int(result.handed_over[0])
    steps = args.runs * contact.step_count
    med = {name: 1e6 * statistics.median(v) / steps for name, v in cpu.items()}
    print(f"# {time.strftime('%Y-%m-%d %H:%M UTC', time.gmtime())}; {args.runs} runs × {contact.step_count} steps, "
          f"{args.method}, medians of {args.repeats}")
    print("| scene | CPU µs / finger-step | steps handed to the Simulator per run |")
    print("|---|---:|---:|")
    for name in cases:
        print(f"| {name} | {med[name]:.3f} | {handed[name]} |")
    contact_cost, free_cost = med["contact (grasp_cylinder)"], med["free (no cup)"]
    print(f"\ncontact / free: {contact_cost / free_cost:.2f}×")


if __name__ == "__main__":
    main()
