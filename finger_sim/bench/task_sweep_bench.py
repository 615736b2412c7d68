"""A gain sweep of the grip PI over the task suite: the per-row loop against the compiled sweep, side by side.

    python -m finger_sim.bench.task_sweep_bench [--kp 0.0025,0.005,0.01] [--ki 2,4,8] [--repeats 5]
                                                [--grid 64] [--workloads kernel,grid,suite,rest]

Workloads, each timed both ways, interleaved (A B A B …) so that outside load hits both alike:

- **kernel tasks**: the torque tasks of the installed suite (`config/tasks/`) that the kernel
  steps (`batch.batch_reason`) against the product of the kp and ki values, as `finger-sim tasks
  --vary kp=… --vary ki=…` runs them: **loop**, one `run_task` per (task, gain pair), today's
  per-row path; **sweep**, `run_suite`, which steps each task's columns together
  (`finger_sim.tasks.batch`);
- **grid**: `hold_cup` against `grid` gain pairs (a square kp × ki grid);
- **suite**: every torque task without a drive that the kernel steps, against the grid's gain
  pairs: the suite-wide gain sweep;
- **rest**: the torque tasks without a drive that the kernel does not step (a moving object:
  Python stages), against the grid's gain pairs: both ways run them row by row.

The default workloads are kernel and grid.

Figures: process CPU (every thread) and wall time of each repetition, their medians, and the
ratio sweep / loop per repetition (median). Both ways must give the same scores (checked).
"""

from __future__ import annotations

import argparse
import statistics
import time
from collections.abc import Callable, Sequence

import numpy as np

from finger_sim.effects.contact_outputs import GRIP_FORCE
from finger_sim.tasks.batch import batch_reason
from finger_sim.tasks.controllers import grip_pi
from finger_sim.tasks.runner import TaskRun, run_task
from finger_sim.tasks.schema import Task, load_task
from finger_sim.tasks.suite import ControllerSpec, installed_tasks, run_suite

#: The grid workload's task.
GRID_TASK = "hold_cup"
#: The workloads `--workloads` may name (module docstring).
WORKLOADS = ("kernel", "grid", "suite", "rest")


def columns(kps: Sequence[float], kis: Sequence[float]) -> list[ControllerSpec]:
    """One grip_pi column per (kp, ki), labelled as `--vary` labels them."""
    return [ControllerSpec(f"grip_pi[kp={kp:g},ki={ki:g}]", grip_pi, {"kp": kp, "ki": ki}) for kp in kps for ki in kis]


def by_loop(tasks: Sequence[Task], specs: Sequence[ControllerSpec]) -> list[TaskRun]:
    return [run_task(t, grip_pi, label=c.label, params=c.params) for t in tasks for c in specs]


def by_sweep(tasks: Sequence[Task], specs: Sequence[ControllerSpec]) -> list[TaskRun]:
    return run_suite(tasks, specs)


def timed(run: Callable[[], list[TaskRun]]) -> tuple[float, float, list[TaskRun]]:
    """(process CPU s, wall s, the runs)."""
    cpu, wall = time.process_time(), time.perf_counter()
    runs = run()
    return time.process_time() - cpu, time.perf_counter() - wall, runs


def compare(name: str, tasks: Sequence[Task], specs: Sequence[ControllerSpec], repeats: int) -> None:
    """Time both ways `repeats` times interleaved; print each repetition, the medians and ratios."""
    steps = sum(t.scene.step_count for t in tasks) * len(specs)
    loop_runs, sweep_runs = by_loop(tasks, specs), by_sweep(tasks, specs)  # warm-up (numba's cache, set-ups)
    same = all(a.scores == b.scores and np.array_equal(a.samples[GRIP_FORCE.name], b.samples[GRIP_FORCE.name])
               for a, b in zip(loop_runs, sweep_runs, strict=True))
    print(f"\n{name}: {len(tasks)} task(s) × {len(specs)} gain pairs = {len(loop_runs)} runs, "
          f"{steps} finger-steps; sweep equals loop: {same}")
    print("| rep | loop CPU s | sweep CPU s | CPU ratio | loop wall s | sweep wall s | wall ratio |")
    print("|---|---|---|---|---|---|---|")
    rows = []
    for r in range(repeats):
        lc, lw, _ = timed(lambda: by_loop(tasks, specs))
        sc, sw, _ = timed(lambda: by_sweep(tasks, specs))
        rows.append((lc, sc, lw, sw))
        print(f"| {r + 1} | {lc:.3f} | {sc:.3f} | {sc / lc:.3f} | {lw:.3f} | {sw:.3f} | {sw / lw:.3f} |")
    med = [statistics.median(x) for x in zip(*rows)]
    ratio_cpu = statistics.median(sc / lc for lc, sc, _, _ in rows)
    ratio_wall = statistics.median(sw / lw for _, _, lw, sw in rows)
    print(f"| median | {med[0]:.3f} | {med[1]:.3f} | {ratio_cpu:.3f} | {med[2]:.3f} | {med[3]:.3f} | {ratio_wall:.3f} |")
    print(f"CPU per finger-step, medians: loop {1e6 * med[0] / steps:.2f} µs, sweep {1e6 * med[1] / steps:.2f} µs")


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--kp", default="0.0025,0.005,0.01", help="kp values, N·m per N")
    parser.add_argument("--ki", default="2,4,8", help="ki values, N·m per N·s")
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--grid", type=int, default=64, help="gain pairs of the grid workload (a square number)")
    parser.add_argument("--workloads", default="kernel,grid", help="of kernel, grid, suite, rest (module docstring)")
    args = parser.parse_args(argv)
    workloads = set(args.workloads.split(","))
    if not workloads <= set(WORKLOADS):
        parser.error(f"--workloads: only {', '.join(WORKLOADS)}, got {args.workloads}")
    kps = [float(v) for v in args.kp.split(",")]
    kis = [float(v) for v in args.ki.split(",")]
    tasks = [t for t in (load_task(p) for p in installed_tasks()) if t.input == "torque"]
    kernel = [t for t in tasks if batch_reason(t, grip_pi) is None]
    side = round(args.grid ** 0.5)
    grid = columns(np.linspace(0.0025, 0.01, side).tolist(), np.linspace(2.0, 8.0, side).tolist())
    if "kernel" in workloads:
        compare("kernel tasks", kernel, columns(kps, kis), args.repeats)
    if "grid" in workloads:
        compare("grid", [t for t in tasks if t.name == GRID_TASK], grid, args.repeats)
    if "suite" in workloads:
        compare("suite", [t for t in kernel if t.scene.drive is None], grid, args.repeats)
    if "rest" in workloads:
        compare("rest", [t for t in tasks if t.scene.drive is None and t not in kernel], grid, args.repeats)


if __name__ == "__main__":
    main()
