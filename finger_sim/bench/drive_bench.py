"""The drive's cost per step against the same scene torque-driven (spec §8; docs/drive_performance.md).

Four scenes at 1 kHz with `method: auto`, each stepped by `Simulator.step` (the node's path) on
one kernel: free motion (6 V against 0.1 N·m) and closing on the cup. The runs of a pair
alternate, REPEATS times; each step is timed, and the median step over all runs and the mean
step (which includes the rare steps with events, and the machine's pauses) are printed with their
ratios as a Markdown table.

    python -m finger_sim.bench.drive_bench [--kernel compiled|python] [--repeats N]
"""

from __future__ import annotations

import argparse
import platform
import statistics
import time
from datetime import datetime, timezone

from finger_sim.scene import Scene, scene_from_dict
from finger_sim.simulate import Simulator

CUP = {"name": "cup", "type": "circle", "center": [0.065, 0.040], "radius": 0.012}
#: The torque a torque-driven finger gets instead of the drive's 6 V: the drive's stall torque on θ1
#: is 0.24 N·m, its no-load speed 5 rad/s; 0.1 N·m moves the free finger over a similar range.
TORQUE = 0.1  # N·m
VOLTAGE = 6.0  # V
DURATION = 0.25  # s
REPEATS = 7


def scene(drive: bool, objects: list[dict]) -> Scene:
    data: dict = {"objects": objects, "duration": DURATION, "integrator": {"method": "auto", "dt": 0.001}}
    if drive:
        data["model"] = {"drive": {}}
        data["input"] = {"voltage": {"type": "constant", "value": VOLTAGE}}
    else:
        data["input"] = {"torque": {"type": "constant", "value": TORQUE}}
    return scene_from_dict(data)


def step_times(sc: Scene, kernel: str, lean: bool = True) -> tuple[list[float], str]:
    """µs of each step of one whole run (after the Simulator is built), and the method auto chose;
    lean=False: without the Simulator's one-call step of a smooth stretch (`Simulator._lean`)."""
    sim = Simulator(sc, kernel=kernel)
    if not lean:
        sim._lean = None  # noqa: SLF001
    out = []
    clock = time.perf_counter
    for _ in range(sc.step_count):
        start = clock()
        sim.step()
        out.append((clock() - start) * 1e6)
    return out, sim.method


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--kernel", default="compiled", choices=("compiled", "python"))
    parser.add_argument("--repeats", type=int, default=REPEATS)
    args = parser.parse_args(argv)
    print(f"{datetime.now(timezone.utc):%Y-%m-%d %H:%M} UTC, {platform.processor() or platform.machine()}, "
          f"kernel {args.kernel}, {args.repeats} alternating runs of {DURATION} s at 1 kHz\n")
    print("| scene | method | torque-driven µs/step, median / mean | drive µs/step, median / mean | ratio, median / mean |\n"
          "|---|---|---|---|---|")
    for label, objects in (("free motion", []), ("closing on the cup", [CUP])):
        times: dict[bool, list[float]] = {False: [], True: []}
        methods = {}
        for _ in range(args.repeats):
            for drive in (False, True):
                t, methods[drive] = step_times(scene(drive, objects), args.kernel)
                times[drive] += t
        (a, am), (b, bm) = ((statistics.median(times[d]), statistics.fmean(times[d])) for d in (False, True))
        print(f"| {label} | {methods[False]} / {methods[True]} | {a:.1f} / {am:.1f} | {b:.1f} / {bm:.1f} | "
              f"{b / a:.2f} / {bm / am:.2f} |")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
