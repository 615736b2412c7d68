"""The shipped drive scenes' part of the work-precision report, run alone: `auto` against scipy's best at equal error.

    python -m finger_sim.bench.drive_wp [--scenes drive_grasp ...] [--repeats 3] [--rtols 1e-4 1e-6 ...] [--quick]

The measurements `finger-sim bench` makes of these scenes for its goal at auto's own error, and nothing else: the
reference (`reference.build_reference`: DOP853 at rtol 1e-13 through the mesh's modes, checked by Radau), scipy's
DOP853, RK45, LSODA and Radau over `--rtols` (`runners.run_scipy`, `reference.solve_drive`), and `auto` at 1 ms,
its whole run and step by step (`runners.run_method`); the goal row is the report's (`analysis.compare_auto`,
`markdown.render_auto_goal`). Besides, `simulate(scene)` timed whole (what a user's call costs: the drive's
outputs on every step and the columns after the run included), against the same scipy cost.
"""

from __future__ import annotations

import argparse
import statistics
import time

from finger_sim.bench.analysis import compare_auto
from finger_sim.bench.markdown import render_auto_goal
from finger_sim.bench.plan import AUTO_DT, DRIVE_SCENES, REPEATS, SCIPY_METHODS, SPACING, scene_file
from finger_sim.bench.reference import build_reference
from finger_sim.bench.runners import AUTO, Run, run_method, run_scipy
from finger_sim.scene import load_scene
from finger_sim.simulate import simulate

#: scipy's rtol grid here (the full bench's is 1e-3 … 1e-12; these bracket auto's error on the drive scenes).
RTOLS = (1e-4, 1e-6, 1e-8, 1e-10)


def simulate_cpu(name: str, repeats: int) -> float:
    """Median process time (s) of `simulate` of the scene, whole, after one untimed run (the numba cache loaded)."""
    scene = load_scene(scene_file(name))
    simulate(scene)
    cpus = []
    for _ in range(repeats):
        start = time.process_time()
        simulate(scene)
        cpus.append(time.process_time() - start)
    return statistics.median(cpus)


def measure(name: str, *, repeats: int, rtols: tuple[float, ...], quick: bool) -> tuple[float, list[Run]]:
    """(reference floor rad, the runs) of one drive scene: scipy's methods over `rtols`, auto whole and stepped."""
    scene = load_scene(scene_file(name))
    ref = build_reference(scene, quick=quick, spacing=SPACING)
    kw = {"spacing": SPACING, "repeats": repeats}
    runs = [run_scipy(scene, method, rtol, ref, **kw) for method in SCIPY_METHODS for rtol in rtols]
    runs += [run_method(scene, AUTO, AUTO_DT, ref, **kw), run_method(scene, AUTO, AUTO_DT, ref, whole_run=True, **kw)]
    return ref.floor, runs


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scenes", nargs="+", choices=DRIVE_SCENES, default=list(DRIVE_SCENES))
    parser.add_argument("--repeats", type=int, default=REPEATS, help="whole runs per row (median)")
    parser.add_argument("--rtols", type=float, nargs="+", default=list(RTOLS), help="scipy's rtol grid")
    parser.add_argument("--quick", action="store_true", help="the reference checked at the bench's quick rtol")
    args = parser.parse_args(argv)
    goal = []
    for name in args.scenes:
        floor, runs = measure(name, repeats=args.repeats, rtols=tuple(args.rtols), quick=args.quick)
        print(f"## {name} (reference floor {floor:.1e} rad)\n\n| run | knob | CPU ms, median | error rad | note |\n"
              "|---|---|---|---|---|")
        for r in runs:
            print(f"| {r.method} | {r.knob} {r.value:g} | {r.cpu * 1e3:.2f} | {r.error:.2e} | {r.status} {r.note} |")
        row = compare_auto(runs, name, floor)
        whole = simulate_cpu(name, args.repeats)
        if row is not None:
            goal.append(row)
            print(f"\nsimulate({name}) whole: {whole * 1e3:.2f} ms, {row.scipy / whole:.1f}× cheaper than scipy's best "
                  f"({row.scipy_method}, {row.scipy * 1e3:.2f} ms) at auto's error\n", flush=True)
    print("\n".join(render_auto_goal(goal)))


if __name__ == "__main__":
    main()
