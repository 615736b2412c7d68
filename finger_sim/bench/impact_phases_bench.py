"""Where a whole run of a scene with a stop spends its CPU: per phase, as `simulate` steps it.

`python -m finger_sim.bench.impact_phases_bench [--scene paper_to_stop] [--repeats 21]`: the scene's whole
run (`kernel.advance`, the work-precision report's "whole run", Simulator built outside the timing) split
into its phases: the stretches of steps in one kernel call (`kernel.run_stretch._stretch`; free ones and
resting ones apart) and the steps taken one `Simulator.step` at a time (the first step, an impact step, a
release), the impact steps apart. Each phase is timed in CPU time around the call (`time.process_time`:
the machine is shared, wall time measures the other users); medians over the repeats, after one warm-up run. The split's total is the
run's own total.
"""

from __future__ import annotations

import argparse
import statistics
import time
from collections import defaultdict
from collections.abc import Callable
from typing import Any

from finger_sim import stepper_slot
from finger_sim.bench.plan import config_dir
from finger_sim.kernel import run_stretch
from finger_sim.scene import load_scene
from finger_sim.simulate import Simulator

#: Timing repeats (median).
REPEATS = 21


def phases(scene: Any, repeats: int) -> tuple[dict[str, float], dict[str, int]]:
    """Median µs of each phase over `repeats` whole runs, and the steps each phase took in one run."""
    times: dict[str, list[float]] = defaultdict(list)
    steps: dict[str, int] = defaultdict(int)
    current: dict[str, float] = defaultdict(float)
    inner_stretch: Callable[..., int] = run_stretch._stretch  # noqa: SLF001

    def stretch(sim: Simulator, *args: Any) -> int:
        phase = "stretches resting" if sim._resting is not None else "stretches free"  # noqa: SLF001
        start = time.process_time()
        count = inner_stretch(sim, *args)
        current[phase] += time.process_time() - start
        steps[phase] += count
        return count

    run_stretch._stretch = stretch  # noqa: SLF001
    try:
        for k in range(repeats + 1):  # the first: warm-up
            current.clear()
            steps.clear()
            sim = Simulator(scene)
            inner_step = sim.step

            def step(torque: Any = None, sim: Simulator = sim, inner_step: Callable[..., Any] = inner_step) -> Any:
                impacts = sim.impacts
                start = time.process_time()
                state = inner_step(torque)
                phase = "steps one by one, impact" if sim.impacts > impacts else "steps one by one"
                current[phase] += time.process_time() - start
                steps[phase] += 1
                return state

            sim.step = step  # type: ignore[method-assign]
            start = time.process_time()
            stepper_slot.kernel().advance(sim, scene.step_count)
            current["whole run"] = time.process_time() - start
            if k:
                for phase, seconds in current.items():
                    times[phase].append(seconds)
    finally:
        run_stretch._stretch = inner_stretch  # noqa: SLF001
    return {phase: 1e6 * statistics.median(v) for phase, v in times.items()}, dict(steps)


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scene", default="paper_to_stop")
    parser.add_argument("--repeats", type=int, default=REPEATS, help="timed whole runs (median)")
    args = parser.parse_args(argv)
    scene = load_scene(config_dir() / f"{args.scene}.yaml")
    medians, steps = phases(scene, args.repeats)
    whole = medians.pop("whole run")
    print(f"{args.scene}: whole run {whole:.1f} µs (median of {args.repeats})")
    print("phase | steps | µs (median) | share of the whole run")
    for phase, us in sorted(medians.items(), key=lambda item: -item[1]):
        print(f"{phase} | {steps.get(phase, 0)} | {us:.1f} | {us / whole:.0%}")


if __name__ == "__main__":
    main()
