"""`auto` on scenes with events against scipy at equal error: step by step, and as a whole run.

    python -m finger_sim.bench.event_run_bench [--scenes paper_to_stop ...] [--repeats 5] [--rtols 1e-6 ...]

The work-precision report's comparison at `auto`'s own error (`analysis.compare_auto`, the bench's
reference, scipy's rows with their event handling, `runners.run_scipy`) for `auto` at 1 ms timed two
ways in one process: one `Simulator.step` per step (the node's path) and the whole
run as `simulate` steps it (`runners.run_method(whole_run=True)`, the report's goal row: stretches of steps in one kernel call,
`kernel.run_stretch`), with the same states. Prints one row per scene: CPU per run (median of the
repeats) and scipy's best CPU at the same error over each. Load on the shared machine moves all
rows of one scene alike (they run within seconds of each other); quote the ratios.
"""

from __future__ import annotations

import argparse
import math
import os
from datetime import datetime, timezone

from finger_sim.bench import analysis as an
from finger_sim.bench.plan import FULL_RTOL, SCIPY_METHODS, SPACING, scene_file
from finger_sim.bench.reference import build_reference
from finger_sim.bench.runners import AUTO, run_method, run_scipy
from finger_sim.scene import load_scene

#: The shipped scenes whose `auto` steps through the compiled event step (stops or contact).
EVENT_SCENES = ("paper_to_stop", "grasp_cylinder", "press_table", "grasp_impact", "grasp_rigid")


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scenes", nargs="+", default=list(EVENT_SCENES))
    parser.add_argument("--repeats", type=int, default=5, help="timing repeats per run (median)")
    parser.add_argument("--rtols", type=float, nargs="+", default=list(FULL_RTOL), help="scipy's rtol grid")
    args = parser.parse_args(argv)
    print(f"# {datetime.now(timezone.utc):%Y-%m-%d %H:%M} UTC, load {os.getloadavg()[0]:.1f}; CPU ms per run (median of "
          f"{args.repeats}); scipy: its cheapest of {', '.join(SCIPY_METHODS)} over rtol {min(args.rtols):g}…"
          f"{max(args.rtols):g} at auto's error")
    print("scene | auto's error (rad) | step by step | whole run | scipy's best at that error | scipy/step | scipy/whole")
    for name in args.scenes:
        scene = load_scene(scene_file(name))
        ref = build_reference(scene, quick=False, spacing=SPACING)
        kw = {"spacing": SPACING, "repeats": args.repeats}
        stepped = run_method(scene, AUTO, an.AUTO_DT, ref, **kw)
        whole = run_method(scene, AUTO, an.AUTO_DT, ref, whole_run=True, **kw)
        runs = [stepped, whole] + [run_scipy(scene, m, rtol, ref, **kw) for m in SCIPY_METHODS for rtol in args.rtols]
        c = an.compare_auto(runs, name, ref.check_difference)
        if c is None or math.isnan(c.whole_cpu):
            print(f"{name} | no comparison (auto or every scipy run failed)")
            continue
        bound = "" if c.scipy_reaches else " (scipy short of it: a lower bound)"
        print(f"{name} | {c.error:.2e} / {whole.error:.2e} | {1e3 * c.auto_cpu:.3f} | {1e3 * c.whole_cpu:.3f} | "
              f"{1e3 * c.scipy:.3f} {c.scipy_method}{bound} | {c.step_ratio:.1f}× | {c.ratio:.1f}×", flush=True)


if __name__ == "__main__":
    main()
