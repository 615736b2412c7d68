"""CPU per step of the node's path under `auto` and under a named fixed-step method, side by side.

    python -m finger_sim.bench.node_path_bench SCENE... [--versus rk4] [--command-every 1] [--repeats 3]

The node's path: one `Simulator.step(τ)` per step with a held torque τ, the scene's profile sampled
at the step's start and held for --command-every steps (1: a controller at the physics rate, so each
step's command is new and an error-controlled method restarts at each; the node with
`torque_source: scene` passes the profile instead, which needs no restart). CPU time per step (the
machine may be shared): the median over the run (at most MAX_STEPS steps), the median of --repeats
runs. Prints one JSON object: scene → {method: µs per step}. It measures whatever `finger_sim` it
imports, so the same command measures another checkout through PYTHONPATH.
"""

from __future__ import annotations

import argparse
import json
import statistics
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
#: Steps measured per run at most (finger_default runs for an hour).
MAX_STEPS = 2000


def scene_file(name: str) -> Path:
    path = ROOT / "config" / f"{name}.yaml"
    return path if path.exists() else ROOT / "config" / "hard" / f"{name}.yaml"


def per_step_us(scene, every: int, repeats: int) -> tuple[str, float]:
    """(method, median CPU µs per step) of the node's path on `scene`."""
    from finger_sim.simulate import Simulator

    n = min(scene.step_count, MAX_STEPS)
    Simulator(scene).step(0.0)  # loads the compiled code
    runs = []
    for _ in range(repeats):
        sim = Simulator(scene)
        times = []
        for k in range(n):
            tau = scene.torque((k - k % every) * scene.dt)
            start = time.process_time()
            sim.step(tau)
            times.append(time.process_time() - start)
        runs.append(1e6 * statistics.median(times))
    return sim.method, statistics.median(runs)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="node_path_bench", description=__doc__.split("\n\n")[0])
    parser.add_argument("scenes", nargs="+")
    parser.add_argument("--versus", default="rk4", help="the fixed-step method beside auto")
    parser.add_argument("--command-every", type=int, default=1, help="steps each command is held")
    parser.add_argument("--repeats", type=int, default=3)
    args = parser.parse_args(argv)
    import numba  # noqa: F401  (loaded first: the compiled kernel)

    from finger_sim.errors import StabilityError
    from finger_sim.scene import load_scene

    out = {}
    for name in args.scenes:
        scene = load_scene(scene_file(name))
        row = dict([per_step_us(scene, args.command_every, args.repeats)])
        try:
            row.update([per_step_us(scene.with_overrides(method=args.versus), args.command_every, args.repeats)])
        except StabilityError:  # a named explicit method on a contact it does not resolve at dt
            row[args.versus] = None
        out[name] = row
    print(json.dumps(out))
    return 0


if __name__ == "__main__":
    sys.exit(main())
