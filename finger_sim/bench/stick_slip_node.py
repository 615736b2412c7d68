"""finger_node at 1 kHz, realtime_factor 1, on a stick–slip scene and on its regularized twin, side by side.

    python -m finger_sim.bench.stick_slip_node [--duration 20] [--rounds 2] [--domain-id 80]

The scene is hold_table (config/friction) under a periodic torque, so that the finger keeps sliding,
locking and breaking free for as long as the node runs: 0.03 ± 0.05 N·m at 1 Hz with μ_k = 0.3 and μ_s = 0.4
(the lock holds while the torque is near its mean and breaks at the extremes). Its twin is the same scene with the
regularized law (same μ_k). Each round runs stick–slip then regularized (A B A B), each node measured
`--duration` s after its warm-up by `node_bench.measure_window` (the node's own /diagnostics windows:
sim s per wall s; CPU s per sim s of the node process; dropped steps), recording off. Prints a
Markdown table of medians over the rounds.
"""

from __future__ import annotations

import statistics
import sys

import yaml

from finger_sim.bench.node_bench import side_by_side, window_medians
from finger_sim.bench.plan import config_dir

#: The periodic torque that keeps the held finger sliding and locking, N·m and Hz.
TORQUE = {"type": "sine", "offset": 0.03, "amplitude": 0.05, "frequency": 1.0}
#: μ_k and μ_s low enough that the lock breaks at the torque's extremes.
FRICTION = {"friction": 0.3, "static_friction": 0.4}
FRICTION_LAW_KEYS = ("friction_model", "static_friction", "stribeck_velocity")


def scenes() -> dict[str, dict]:
    """'stick_slip' and 'regularized' → the periodic hold_table scene (a scene mapping)."""
    data = yaml.safe_load((config_dir() / "friction" / "hold_table.yaml").read_text())
    data["input"] = {"torque": TORQUE}
    data["model"]["contact"].update(FRICTION)
    data["duration"] = 3600.0
    regularized = {**data, "model": {**data["model"], "contact": {
        k: v for k, v in data["model"]["contact"].items() if k not in FRICTION_LAW_KEYS}}}
    return {"stick_slip": data, "regularized": regularized}


def main(argv: list[str] | None = None) -> int:
    params = dict(torque_source="scene", physics_rate_hz=1000.0, publish_rate_hz=0.0, realtime_factor=1.0, record=False)
    rows = side_by_side(__doc__, argv, "stick_slip_node", scenes(), params)
    print("| law | real-time factor: median of 1 s windows | lowest window | CPU s per sim s | dropped steps |")
    print("|---|---|---|---|---|")
    base = statistics.median(w.cpu_per_sim_s for w in rows["regularized"])
    for name, runs in rows.items():
        rtf, lowest, cpu = window_medians(runs)
        print(f"| {name} | {rtf:.4f} | {lowest:.4f} | {cpu:.3f} ({cpu / base:.2f}×) | "
              f"{sum(w.dropped_steps for w in runs)} |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
