"""The paths `auto` has at a scene's own output rate, as whole runs: error against cost, side by side.

    python -m finger_sim.bench.output_rate_bench [--scene toggle_passage] [--repeats 7] [--rtols 1e-8 1e-9 1e-10]

Each of the project's fixed-step methods at the scene's dt (their output is their steps) and the
error-controlled DOP853 at each rtol = atol (its output by its dense interpolant at the same dt, internal steps
of its own size: `DormandPrince853.run_grid`), every run timed whole as `simulate` steps it
(`kernel.advance`, after one untimed run), rounds interleaved (A B C A B C …), median CPU. The error: max
|θ − θ_ref| on the output grid against the bench's reference. Answers whether another path reaches `auto`'s
error for less (issue 17: auto never picks a path dearer than another at the same or better accuracy).
"""

from __future__ import annotations

import argparse
import os
import statistics
import time
from datetime import datetime, timezone

import numpy as np

from finger_sim import auto, stepper_slot
from finger_sim.bench.plan import SPACING, scene_file
from finger_sim.bench.reference import build_reference
from finger_sim.integrators.dop853 import DormandPrince853
from finger_sim.scene import load_scene
from finger_sim.simulate import Simulator

#: The fixed-step methods compared (auto's table picks among them on a smooth scene).
FIXED = ("rk4", "rk6", "dop8")


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scene", default="toggle_passage")
    parser.add_argument("--repeats", type=int, default=7, help="interleaved rounds (median)")
    parser.add_argument("--rtols", type=float, nargs="+", default=[1e-8, 1e-9, 1e-10], help="DOP853's rtol = atol")
    args = parser.parse_args(argv)
    scene = load_scene(scene_file(args.scene))
    ref = build_reference(scene, quick=False, spacing=SPACING)
    n, kernel = scene.step_count, stepper_slot.kernel()
    grid = np.arange(1, n + 1) * scene.dt
    paths = [(m, None) for m in FIXED] + [(DormandPrince853.name, rtol) for rtol in args.rtols]

    def build(method: str, rtol: float | None) -> Simulator:
        sim = Simulator(scene.with_overrides(method=method))
        if rtol is not None:
            sim.integrator.rtol = sim.integrator.atol = rtol
        return sim

    errors = {p: float(np.max(np.abs(kernel.advance(build(*p), n)[:, :3] - ref.theta(grid)))) for p in paths}
    cpus: dict[tuple, list[float]] = {p: [] for p in paths}
    for _ in range(args.repeats):
        for p in paths:
            sim = build(*p)
            start = time.process_time()
            kernel.advance(sim, n)
            cpus[p].append(time.process_time() - start)
    print(f"# {datetime.now(timezone.utc):%Y-%m-%d %H:%M} UTC, load {os.getloadavg()[0]:.1f}; {args.scene} at dt = "
          f"{scene.dt:g} s, whole runs, CPU median of {args.repeats} interleaved rounds; auto picks "
          f"{auto.choose_method(scene)[0]}")
    print("path | error (rad) | CPU (ms) | CPU / rk6's")
    base = statistics.median(cpus[("rk6", None)])
    for (method, rtol), cpu in cpus.items():
        label = method if rtol is None else f"{method} rtol {rtol:g}"
        print(f"{label} | {errors[method, rtol]:.2e} | {1e3 * statistics.median(cpu):.3f} | "
              f"{statistics.median(cpu) / base:.2f}")


if __name__ == "__main__":
    main()
