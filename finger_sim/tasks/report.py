"""The suite's report: one Markdown table per task (controllers side by side), a figure per task
(grip force and setpoint, MCP angle, command) and a JSON of every metric for CI."""

from __future__ import annotations

import json
import math
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from finger_sim.actuators.drive_outputs import MOTOR_CURRENT
from finger_sim.effects.contact_outputs import GRIP_FORCE
from finger_sim.tasks.metrics import METRICS
from finger_sim.tasks.runner import TaskRun


def _cell(value: Any) -> str:
    if value is None:
        return "n/a"
    if isinstance(value, bool):
        return "yes" if value else "no"
    if math.isinf(value):
        return "never"
    return f"{value:.4g}"


def _json_value(value: Any) -> Any:
    """JSON has no inf or nan: they become the strings "inf" and "nan"."""
    if isinstance(value, float) and not math.isfinite(value):
        return "nan" if math.isnan(value) else "inf"
    return value


def markdown(runs: Sequence[TaskRun], descriptions: dict[str, str], figures: dict[str, str] | None = None) -> str:
    """One section per task: a table of every metric (rows) per controller (columns), the task's
    limit beside each judged metric, ✔/✘ per judged value, and its figure when one was drawn."""
    lines: list[str] = []
    for task in dict.fromkeys(r.task for r in runs):
        group = [r for r in runs if r.task == task]
        limits = group[0].limits
        lines += [f"### {task}", "", descriptions.get(task, ""), ""]
        lines.append("| metric | limit | " + " | ".join(f"`{r.controller}`" for r in group) + " |")
        lines.append("|---|---|" + "---|" * len(group))
        for name, (unit, _) in METRICS.items():
            if all(r.scores.get(name) is None for r in group) and name not in limits:
                continue
            limit = limits.get(name)
            limit_text = "" if limit is None else (("= " + _cell(limit)) if isinstance(limit, bool) else f"≤ {_cell(limit)}")
            cells = []
            for r in group:
                mark = "" if name not in r.passed else (" ✔" if r.passed[name] else " ✘")
                cells.append(_cell(r.scores.get(name)) + mark)
            lines.append(f"| {name}{f' ({unit})' if unit else ''} | {limit_text} | " + " | ".join(cells) + " |")
        lines.append("| **result** | | " + " | ".join("**pass**" if r.ok else "**FAIL**" for r in group) + " |")
        crushes = [f"`{r.controller}`: {c.log_line()}" for r in group for c in r.crushes]
        lines += [""] + [f"- {c}" for c in crushes] + ([""] if crushes else [])
        if figures and task in figures:
            lines += [f"![{task}]({figures[task]})", ""]
    return "\n".join(lines)


def to_json(runs: Sequence[TaskRun]) -> str:
    """Every run's metrics, pass/fail per limit and crushes, as JSON (inf and nan as strings)."""
    data = [{
        "task": r.task,
        "controller": r.controller,
        "passed": r.ok,
        "scores": {k: _json_value(v) for k, v in r.scores.items()},
        "limits": {k: _json_value(v) for k, v in r.limits.items()},
        "judged": r.passed,
        "crushes": [{"object": c.object, "t": c.t, "force": c.force, "break_force": c.break_force} for c in r.crushes],
    } for r in runs]
    return json.dumps(data, indent=1)


def figure(runs: Sequence[TaskRun], path: Path) -> None:
    """The runs of one task: grip force and setpoint (N), MCP angle θ1 (°), command (N·m) over t (s)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    driven = MOTOR_CURRENT.name in runs[0].samples  # a drive task: the command is a voltage; draw the current
    fig, axes = plt.subplots(4 if driven else 3, 1, sharex=True, figsize=(7.5, 8.0 if driven else 6.5))
    for i, r in enumerate(runs):
        s, z = r.samples, len(runs) - i  # the first controller drawn on top
        axes[0].plot(s["t"], s[GRIP_FORCE.name], label=r.controller, zorder=z)
        axes[1].plot(s["t"], [math.degrees(x) for x in s["theta1"]], label=r.controller, zorder=z)
        axes[2].plot(s["t"], s["command"], label=r.controller, zorder=z)
        if driven:
            axes[3].plot(s["t"], s[MOTOR_CURRENT.name], label=r.controller, zorder=z)
    axes[0].plot(runs[0].samples["t"], runs[0].samples["setpoint"], "k--", lw=1, label="setpoint", zorder=len(runs) + 1)
    axes[0].set_ylabel("grip force (N)")
    axes[1].set_ylabel("θ1 (°)")
    axes[2].set_ylabel("command (V)" if driven else "command (N·m)")
    if driven:
        axes[3].set_ylabel("motor current (A)")
    axes[-1].set_xlabel("t (s)")
    axes[0].legend(fontsize=8)
    axes[0].set_title(runs[0].task)
    for ax in axes:
        ax.grid(alpha=0.3)
    fig.tight_layout()
    fig.savefig(path, dpi=90)
    plt.close(fig)
