"""The cost of a Simulator step on stick–slip scenes against the regularized law, side by side in one process.

    python -m finger_sim.bench.stick_slip_bench [--rounds 5]

Per scene three paths, each a fresh Simulator stepped through the whole scene at its dt (the node's
`Simulator.step`, one call per 1 ms period): stick–slip with `method: auto` (our compiled DOP853 on the
compiled friction law), stick–slip on scipy's DOP853 in Python (`adaptive`, auto's path before the
compiled form), and the regularized law's twin with `auto`. Rounds alternate the paths; the figures are
medians over the rounds of each run's median wall time per step (µs), the median over the steps in which the
finger moves (sliding: the regularized law's finger always moves), the 99th percentile, the share of steps over
the 1 ms period, and the CPU per simulated second. Prints a markdown table.
"""

from __future__ import annotations

import argparse
import os
import statistics
import time
from datetime import datetime, timezone

import numpy as np

from finger_sim.bench.plan import config_dir
from finger_sim.scene import Scene, load_scene, scene_from_dict

#: The node's period at 1 kHz, s.
PERIOD = 1e-3
SCENES = ("hold_table", "sawtooth")


def paths(name: str) -> dict[str, Scene]:
    """The three paths of a friction scene (config/friction/<name>.yaml)."""
    stick = load_scene(config_dir() / "friction" / f"{name}.yaml")
    data = stick.to_dict()
    scipy_data = {**data, "integrator": {**data["integrator"], "method": "adaptive"}}
    contact = {k: v for k, v in data["model"]["contact"].items()
               if k not in ("friction_model", "static_friction", "stribeck_velocity")}
    regularized = {**data, "model": {**data["model"], "contact": contact}}
    return {"stick_slip auto": stick, "stick_slip scipy (before)": scene_from_dict(scipy_data),
            "regularized auto": scene_from_dict(regularized)}


def run(scene: Scene) -> tuple[np.ndarray, np.ndarray, float, str]:
    """(wall s of each step, whether the finger moved in it, CPU s per simulated s, method) of one fresh
    Simulator through the scene."""
    from finger_sim.simulate import Simulator

    sim = Simulator(scene)
    sim.step()  # loads what the first step loads (compiled code from numba's cache)
    n = scene.step_count - 1
    walls, moving = np.empty(n), np.empty(n, dtype=bool)
    cpu = time.process_time()
    for k in range(n):
        before = sim.v[0]
        start = time.perf_counter()
        sim.step()
        walls[k] = time.perf_counter() - start
        moving[k] = before != 0.0 or sim.v[0] != 0.0
    return walls, moving, (time.process_time() - cpu) / (n * scene.dt), sim.method


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rounds", type=int, default=5)
    args = parser.parse_args(argv)
    print(f"{datetime.now(timezone.utc):%Y-%m-%d %H:%M} UTC, load average {os.getloadavg()[0]:.2f} "
          f"{os.getloadavg()[1]:.2f} {os.getloadavg()[2]:.2f}, {args.rounds} rounds")
    print("| scene | path | method | median µs/step | moving steps: median µs | p99 µs | steps > 1 ms | "
          "CPU s per sim s | moving median / regularized |")
    print("|---|---|---|---|---|---|---|---|---|")
    for name in SCENES:
        scenes = paths(name)
        figures: dict[str, list[tuple[float, ...]]] = {label: [] for label in scenes}
        methods = {}
        for _ in range(args.rounds):
            for label, scene in scenes.items():
                walls, moving, cpu, methods[label] = run(scene)
                figures[label].append((np.median(walls) * 1e6, np.median(walls[moving]) * 1e6,
                                       np.percentile(walls, 99) * 1e6, float((walls > PERIOD).mean()), cpu))
        medians = {label: [statistics.median(f[i] for f in rows) for i in range(5)] for label, rows in figures.items()}
        base = medians["regularized auto"][1]
        for label, (median, moving_median, p99, late, cpu) in medians.items():
            print(f"| {name} | {label} | {methods[label]} | {median:.0f} | {moving_median:.0f} | {p99:.0f} | {late:.1%} | "
                  f"{cpu:.3f} | {moving_median / base:.2f} |")
    print(f"end: load average {os.getloadavg()[0]:.2f}")


if __name__ == "__main__":
    main()
