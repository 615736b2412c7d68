"""finger_node at 1 kHz, realtime_factor 1, with the default drive and with its torque-driven twin, side by side.

    python -m finger_sim.bench.drive_node [--duration 20] [--rounds 2] [--domain-id 80]

The drive scene is drive_grasp's (config/): the default drive (self-locking worm train) on the cup under a
square voltage of ±6 V at 1 Hz, so that the node keeps grasping, holding stuck and being back-driven open
for as long as it runs (the mesh changes mode at every half period). Its twin is the same finger and cup
without the drive, under a square torque of ±TWIN_TORQUE at 1 Hz. Each round runs drive then torque
(A B A B), each node measured `--duration` s after its warm-up by `node_bench.measure_window` (the node's own
1 s /diagnostics windows; CPU s of the node process per sim s; dropped steps; the log's states against the
steps run), recording on. Prints a Markdown table of medians over the rounds.
"""

from __future__ import annotations

import statistics
import sys

import yaml

from finger_sim.bench.node_bench import side_by_side, window_medians
from finger_sim.bench.plan import config_dir

#: The drive's voltage: ±6 V (the default drive's rated voltage) switching every 0.5 s.
VOLTAGE = {"type": "square", "amplitude": 6.0, "frequency": 1.0}
#: The twin's torque on θ1, N·m: a square wave of the same period that also closes on the cup and opens.
TWIN_TORQUE = {"type": "square", "amplitude": 0.1, "frequency": 1.0}
#: Long enough that no node reaches its scene's end while measured, s.
RUN_S = 3600.0


def scenes() -> dict[str, dict]:
    """'drive' and 'torque' → the cup scene under its periodic input (a scene mapping)."""
    data = yaml.safe_load((config_dir() / "drive_grasp.yaml").read_text())
    data["duration"] = RUN_S
    drive = {**data, "input": {"voltage": VOLTAGE}}
    torque = {**data, "model": {k: v for k, v in data["model"].items() if k != "drive"}, "input": {"torque": TWIN_TORQUE}}
    return {"drive": drive, "torque": torque}


def main(argv: list[str] | None = None) -> int:
    params = dict(torque_source="scene", physics_rate_hz=1000.0, realtime_factor=1.0)
    rows = side_by_side(__doc__, argv, "drive_node", scenes(), params)
    print("| input | real-time factor: median of 1 s windows | lowest window | CPU s per sim s | dropped steps "
          "| log: states logged / expected, dropped |")
    print("|---|---|---|---|---|---|")
    base = statistics.median(w.cpu_per_sim_s for w in rows["torque"])
    for name, runs in rows.items():
        rtf, lowest, cpu = window_medians(runs)
        logged = ", ".join(f"{w.states_logged} / {w.states_expected}, {w.log_dropped}" for w in runs)
        print(f"| {name} | {rtf:.4f} | {lowest:.4f} | {cpu:.3f} ({cpu / base:.2f}×) | "
              f"{sum(w.dropped_steps for w in runs)} | {logged} |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
