"""A gain sweep of the drive controllers over the drive tasks: the per-row loop against the compiled sweep.

    python -m finger_sim.bench.drive_sweep_bench [--grid 16] [--repeats 3]

Workloads, each timed both ways, interleaved (A B A B …) so that outside load hits both alike:
`hold_current` against `grip_current` and `hold_voltage_off` against `grip_voltage`, each over a
square kp × ki grid of `grid` gain pairs around the controller's own gains (½× … 2×): **loop**,
one `run_task` per gain pair (the per-row path); **sweep**, `run_suite`, which steps the columns
together (`finger_sim.tasks.batch_drive`). Figures as `task_sweep_bench`: process CPU (every
thread) and wall time per repetition, medians, the ratio sweep / loop per repetition (median);
both ways must give the same samples and scores (checked, bit for bit).
"""

from __future__ import annotations

import argparse
import statistics
from collections.abc import Sequence

import numpy as np

from finger_sim.bench.task_sweep_bench import timed
from finger_sim.tasks.controllers import GRIP_VOLTAGE, Factory, grip_voltage
from finger_sim.tasks.current_grip import GRIP_CURRENT, grip_current
from finger_sim.tasks.runner import TaskRun, run_task
from finger_sim.tasks.schema import Task, load_task
from finger_sim.tasks.suite import ControllerSpec, installed_tasks, run_suite

#: The drive tasks and the shipped controller each is swept with (its defaults: the grid's centre).
WORKLOADS = (("hold_current", "gc", grip_current, GRIP_CURRENT), ("hold_voltage_off", "gv", grip_voltage, GRIP_VOLTAGE))
#: The grid spans this factor below and above the controller's own kp and ki.
SPAN = 2.0


def columns(label: str, factory: Factory, defaults: dict, count: int) -> list[ControllerSpec]:
    """A square kp × ki grid of `count` columns, labelled as `--vary` labels them."""
    side = round(count ** 0.5)
    kps = np.geomspace(defaults["kp"] / SPAN, defaults["kp"] * SPAN, side).tolist()
    kis = np.geomspace(defaults["ki"] / SPAN, defaults["ki"] * SPAN, side).tolist()
    return [ControllerSpec(f"{label}[kp={kp:g},ki={ki:g}]", factory, {"kp": kp, "ki": ki}) for kp in kps for ki in kis]


def by_loop(task: Task, specs: Sequence[ControllerSpec]) -> list[TaskRun]:
    return [run_task(task, c.factory, label=c.label, params=c.params) for c in specs]  # type: ignore[arg-type]


def same_runs(a: Sequence[TaskRun], b: Sequence[TaskRun]) -> bool:
    return all(x.scores == y.scores and x.passed == y.passed and x.samples.keys() == y.samples.keys()
               and all(np.array_equal(x.samples[c], y.samples[c]) for c in x.samples) for x, y in zip(a, b, strict=True))


def compare(task: Task, specs: Sequence[ControllerSpec], repeats: int) -> None:
    """Time both ways `repeats` times interleaved; print each repetition, the medians and ratios."""
    steps = task.scene.step_count * len(specs)
    loop_runs, sweep_runs = by_loop(task, specs), run_suite([task], specs)  # warm-up (numba's cache, set-ups)
    print(f"\n{task.name}: {len(specs)} gain pairs, {steps} finger-steps; sweep equals loop: "
          f"{same_runs(loop_runs, sweep_runs)}; passed {sum(r.ok for r in sweep_runs)} / {len(specs)}")
    print("| rep | loop CPU s | sweep CPU s | CPU ratio | loop wall s | sweep wall s | wall ratio |")
    print("|---|---|---|---|---|---|---|")
    rows = []
    for r in range(repeats):
        lc, lw, _ = timed(lambda: by_loop(task, specs))
        sc, sw, _ = timed(lambda: run_suite([task], specs))
        rows.append((lc, sc, lw, sw))
        print(f"| {r + 1} | {lc:.3f} | {sc:.3f} | {sc / lc:.3f} | {lw:.3f} | {sw:.3f} | {sw / lw:.3f} |", flush=True)
    med = [statistics.median(x) for x in zip(*rows)]
    ratio_cpu = statistics.median(sc / lc for lc, sc, _, _ in rows)
    ratio_wall = statistics.median(sw / lw for _, _, lw, sw in rows)
    print(f"| median | {med[0]:.3f} | {med[1]:.3f} | {ratio_cpu:.3f} | {med[2]:.3f} | {med[3]:.3f} | {ratio_wall:.3f} |")
    print(f"CPU per finger-step, medians: loop {1e6 * med[0] / steps:.2f} µs, sweep {1e6 * med[1] / steps:.2f} µs")


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--grid", type=int, default=16, help="gain pairs per task (a square number)")
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--tasks", default=",".join(w[0] for w in WORKLOADS), help="which drive tasks")
    args = parser.parse_args(argv)
    tasks = {t.name: t for t in (load_task(p) for p in installed_tasks())}
    for name, label, factory, defaults in WORKLOADS:
        if name in args.tasks.split(","):
            compare(tasks[name], columns(label, factory, defaults, args.grid), args.repeats)


if __name__ == "__main__":
    main()
