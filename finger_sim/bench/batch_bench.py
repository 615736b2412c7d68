"""The batch's cost against N, and against a Python loop over Simulator, side by side.

    python -m finger_sim.bench.batch_bench [--repeats 5] [--largest 10000]

The scenes are the paper's run (config/paper_flexion.yaml, rk6 under auto) with the torque
slope and the spring varied over a grid (N runs: the first N of 100 slopes × 100 springs).
Prints medians of `repeats` runs in this one process: wall and CPU (every thread) per
finger-step of `run_batch` (set-up included), for N = 1 … largest; then, for N = 1000, the
batch against `Simulator.step` loops on the Python and on the compiled kernel (construction
included), interleaved so that machine load hits all alike, and the largest difference of the
batch's final angles from the Python loop's.
"""

from __future__ import annotations

import argparse
import statistics
import time
from pathlib import Path

import numpy as np

from finger_sim.batch import run_batch
from finger_sim.scene import Scene, load_scene, scene_from_dict
from finger_sim.simulate import Simulator

SIZES = (1, 10, 100, 1000, 10000)
GOAL_N = 1000
SLOPES = np.linspace(0.005, 0.03, 100)  # N·m/s
SPRINGS = np.linspace(0.0005, 0.002, 100)  # N·m/rad


def paper_scenes(n: int) -> list[Scene]:
    """n paper runs with varied torque slope and PIP spring."""
    base = load_scene(Path(__file__).resolve().parents[2] / "config" / "paper_flexion.yaml").to_dict()
    scenes = []
    for i in range(n):
        data = {**base, "model": {**base["model"], "spring_stiffness": float(SPRINGS[i // len(SLOPES)])},
                "input": {"torque": {**base["input"]["torque"], "slope": float(SLOPES[i % len(SLOPES)])}}}
        scenes.append(scene_from_dict(data))
    return scenes


def _timed(run) -> tuple[float, float, object]:  # type: ignore[no-untyped-def]
    wall, cpu = time.perf_counter(), time.process_time()
    out = run()
    return time.perf_counter() - wall, time.process_time() - cpu, out


def _loop(scenes: list[Scene], kernel: str) -> np.ndarray:
    """A Python loop over Simulator: construct, step to the end; the final angles."""
    out = np.empty((len(scenes), 3))
    for i, scene in enumerate(scenes):
        sim = Simulator(scene, kernel=kernel)
        for _ in range(scene.step_count):
            sim.step()
        out[i] = sim.q
    return out


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--largest", type=int, default=SIZES[-1])
    args = parser.parse_args(argv)
    run_batch(paper_scenes(2))  # load the compiled loop (numba's cache) before timing
    print(f"paper runs (rk6, 300 steps each); medians of {args.repeats}; µs per finger-step, set-up included")
    print("      N   wall µs   CPU µs   wall s")
    for n in (s for s in SIZES if s <= args.largest):
        scenes = paper_scenes(n)
        steps = sum(s.step_count for s in scenes)
        walls, cpus = [], []
        for _ in range(args.repeats if n < 10000 else max(1, args.repeats // 2)):
            wall, cpu, _ = _timed(lambda: run_batch(scenes))
            walls.append(wall)
            cpus.append(cpu)
        w, c = statistics.median(walls), statistics.median(cpus)
        print(f"{n:7d} {w / steps * 1e6:9.3f} {c / steps * 1e6:8.3f} {w:8.3f}")
    scenes = paper_scenes(GOAL_N)
    steps = sum(s.step_count for s in scenes)
    rows: dict[str, list[tuple[float, float]]] = {"batch": [], "Simulator compiled": [], "Simulator python": []}
    finals: dict[str, np.ndarray] = {}
    for _ in range(args.repeats):
        for name, run in (("batch", lambda: run_batch(scenes).q), ("Simulator compiled", lambda: _loop(scenes, "compiled")),
                          ("Simulator python", lambda: _loop(scenes, "python"))):
            wall, cpu, finals[name] = _timed(run)
            rows[name].append((wall, cpu))
    print(f"\nN = {GOAL_N} paper runs, {steps:,} finger-steps; medians of {args.repeats}, interleaved")
    print("path                  wall µs/step  CPU µs/step   CPU ratio to batch   max |Δθ| vs python (rad)")
    batch_cpu = statistics.median(c for _, c in rows["batch"])
    for name, times in rows.items():
        w, c = statistics.median(t for t, _ in times), statistics.median(c for _, c in times)
        diff = float(np.abs(finals[name] - finals["Simulator python"]).max())
        print(f"{name:20s} {w / steps * 1e6:12.3f} {c / steps * 1e6:12.3f} {c / batch_cpu:18.1f}×   {diff:.1e}")
    validate = _timed(lambda: paper_scenes(GOAL_N))[1] / GOAL_N
    print(f"\nscene validation (scene_from_dict, what the sweep does per combination): {validate * 1e6:.0f} µs CPU per run")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
