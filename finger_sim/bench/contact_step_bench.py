"""A contact step with and without its compiled parts, side by side in one process.

`python -m finger_sim.bench.contact_step_bench [--repeats N]`: `method: auto` at 1 kHz through
`Simulator.step` (the node's path) on each shipped contact scene in three variants: the whole
common step compiled (`simulation.event_step`, the default), the Python DOP853 step with the
compiled step-end gap check (`simulation.gap_screen`; the event step switched off), and the Python
check alone (both switched off; DOP853's watch of its internal steps stays compiled, `crossings.GapWatch`);
and the free paper_flexion. CPU per step (`time.process_time`), every variant timed in turn within each
repeat after one warm-up round; medians, and ratios to the free step.
"""

from __future__ import annotations

import argparse
import statistics
import time
from collections.abc import Sequence

from finger_sim.bench.plan import CONTACT_SCENES, config_dir
from finger_sim.scene import load_scene
from finger_sim.simulate import Simulator

#: The free-space scene a contact step is compared with.
FREE_SCENE = "paper_flexion"
#: Timing repeats (median).
REPEATS = 5
#: From this time on (s) the finger holds the object on grasp_cylinder and press_table (onset at ~0.2 s):
#: their steps after it are timed apart too, the common contact step without the onset's location.
HELD_FROM = 0.3


def measure(repeats: int) -> dict[tuple[str, str], float]:
    """Median µs per step of (scene, variant): variant "free", "dop853" (the free scene), "python check",
    "compiled check" or "compiled step"; and of (scene, variant + " held"): the steps from HELD_FROM on."""
    folder = config_dir()
    free = load_scene(folder / f"{FREE_SCENE}.yaml")
    # the free scene under auto (its lean compiled step), and under dop853: the contact path's floor, no gaps
    sims = {(FREE_SCENE, "free"): Simulator(free), (FREE_SCENE, "dop853"): Simulator(free.with_overrides(method="dop853"))}
    for name in CONTACT_SCENES:
        scene = load_scene(folder / f"{name}.yaml")
        off, check = Simulator(scene), Simulator(scene)
        off._gap_screen = off._event_step = None  # the Python check alone
        check._event_step = None  # the Python DOP853 step, the compiled check
        sims[name, "python check"], sims[name, "compiled check"] = off, check
        sims[name, "compiled step"] = Simulator(scene)
    samples: dict[tuple[str, str], list[float]] = {}
    for k in range(repeats + 1):  # the first round warms up
        for (name, variant), sim in sims.items():
            sim.reset()
            n, step = sim.scene.step_count, sim.step
            held = min(n, round(HELD_FROM / sim.dt))
            start = time.process_time()
            for _ in range(held):
                step()
            middle = time.process_time()
            for _ in range(n - held):
                step()
            end = time.process_time()
            if k:
                samples.setdefault((name, variant), []).append(1e6 * (end - start) / n)
                if n > held:
                    samples.setdefault((name, variant + " held"), []).append(1e6 * (end - middle) / (n - held))
    return {key: statistics.median(values) for key, values in samples.items()}


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m finger_sim.bench.contact_step_bench", description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=REPEATS)
    args = parser.parse_args(argv)
    medians = measure(args.repeats)
    free = medians[FREE_SCENE, "free"]
    floor = medians[FREE_SCENE, "dop853"]
    print(f"free {FREE_SCENE}: {free:.2f} µs/step under auto, {floor:.2f} µs/step ({floor / free:.2f}×) "
          f"under dop853 (median of {args.repeats})")
    print("| scene | Python check µs/step | compiled check µs/step | compiled step µs/step | × free: Python check "
          "| × free: compiled check | × free: compiled step | step / check |")
    print("|---|---:|---:|---:|---:|---:|---:|---:|")
    for name in CONTACT_SCENES:
        old, check, new = (medians[name, v] for v in ("python check", "compiled check", "compiled step"))
        print(f"| {name} | {old:.1f} | {check:.1f} | {new:.1f} | {old / free:.2f}× | {check / free:.2f}× "
              f"| {new / free:.2f}× | {new / check:.2f} |")
    for name in CONTACT_SCENES:
        if (name, "compiled step held") in medians:
            old, check, new = (medians[name, v + " held"] for v in ("python check", "compiled check", "compiled step"))
            print(f"| {name}, held (t ≥ {HELD_FROM} s) | {old:.1f} | {check:.1f} | {new:.1f} | {old / free:.2f}× "
                  f"| {check / free:.2f}× | {new / free:.2f}× | {new / check:.2f} |")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
