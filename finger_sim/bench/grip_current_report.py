"""grip_current on the device (spec §8): the figure and numbers of docs/drive_grip_current.md.

Runs config/tasks/hold_voltage_off.yaml (the default self-locking drive on the cup, 1 kHz, the
controller one step late) at each setpoint against `finger_sim.tasks.current_grip.grip_current`,
prints a Markdown table (the current loop, the moment the voltage goes off, the grip held after it)
and draws grip force, current and voltage over time for the first setpoint.

    python -m finger_sim.bench.grip_current_report [--setpoints 1.2 1.5 2.0] [--figure docs/drive_grip_current.png]
"""

from __future__ import annotations

import argparse
import dataclasses
from datetime import datetime, timezone
from pathlib import Path

import numpy as np

from finger_sim.actuators.drive_outputs import MOTOR_CURRENT
from finger_sim.effects.contact_outputs import GRIP_FORCE
from finger_sim.tasks.current_grip import GRIP_CURRENT, current_setpoint, grip_current
from finger_sim.tasks.metrics import SETTLE_BAND
from finger_sim.tasks.runner import TaskRun, run_task
from finger_sim.tasks.schema import load_task

TASK = Path(__file__).resolve().parents[2] / "config" / "tasks" / "hold_voltage_off.yaml"


def run(setpoint: float) -> TaskRun:
    base = load_task(TASK)
    return run_task(dataclasses.replace(base, setpoints=((0.0, setpoint),)), grip_current)


def row(setpoint: float, result: TaskRun) -> str:
    s = result.samples
    target = current_setpoint(setpoint, GRIP_CURRENT)
    off = int(np.flatnonzero(s["command"] != 0.0)[-1]) + 1
    held = s[GRIP_FORCE.name][-1]
    return (f"| {setpoint:.2f} | {target:.4f} | {s['t'][off]:.3f} | {s[MOTOR_CURRENT.name][off]:.4f} "
            f"({(s[MOTOR_CURRENT.name][off] - target) / target * 100:+.2f} %) | {held:.4f} "
            f"({(held - setpoint) / setpoint * 100:+.2f} %) | {int(np.all(s[MOTOR_CURRENT.name][off + 2:] == 0.0))} | "
            f"{result.scores['settle_time']:.3f} | {result.scores['overshoot']:.2f} | "
            f"{result.scores['electrical_energy']:.4f} | {'pass' if result.ok else 'fail'} |")


def figure(setpoint: float, result: TaskRun, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    s = result.samples
    target = current_setpoint(setpoint, GRIP_CURRENT)
    fig, axes = plt.subplots(3, 1, sharex=True, figsize=(7.0, 6.5))
    axes[0].plot(s["t"], s[GRIP_FORCE.name], label="grip force (truth)")
    axes[0].axhline(setpoint, color="k", lw=0.8, ls="--", label="setpoint")
    axes[0].axhspan(setpoint * (1 - SETTLE_BAND), setpoint * (1 + SETTLE_BAND), color="0.85")
    axes[0].set_ylabel("N")
    axes[1].plot(s["t"], s[MOTOR_CURRENT.name], label="motor current (what the loop reads)")
    axes[1].axhline(target, color="k", lw=0.8, ls="--", label="current setpoint i*")
    axes[1].set_ylabel("A")
    axes[2].plot(s["t"], s["command"], label="voltage command")
    axes[2].set_ylabel("V")
    axes[2].set_xlabel("t (s)")
    for ax in axes:
        ax.legend(loc="lower right", fontsize=8)
        ax.grid(alpha=0.3)
    axes[0].set_title(f"grip_current, self-locking drive, {setpoint:g} N: approach, current loop, 0 V hold", fontsize=10)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--setpoints", type=float, nargs="+", default=[1.5, 1.2, 2.0])
    parser.add_argument("--figure", type=Path, default=None)
    args = parser.parse_args(argv)
    print(f"{datetime.now(timezone.utc):%Y-%m-%d %H:%M} UTC\n")
    print("| F* (N) | i* (A) | voltage off at (s) | current then (A) | grip held (N) | current 0 after | settle_time (s) "
          "| overshoot (%) | ∫u·i dt (J) | task |\n|---|---|---|---|---|---|---|---|---|---|")
    for k, setpoint in enumerate(args.setpoints):
        result = run(setpoint)
        print(row(setpoint, result))
        if k == 0 and args.figure is not None:
            figure(setpoint, result, args.figure)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
