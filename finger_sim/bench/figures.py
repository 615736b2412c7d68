"""The bench's work-precision figures (matplotlib, Agg): `wp_<scene>.png`, one per scene."""

from __future__ import annotations

import math

from collections.abc import Sequence
from pathlib import Path

from finger_sim.bench import analysis as an
from finger_sim.bench.plan import project_methods
from finger_sim.bench.reference import Reference
from finger_sim.bench.runners import FAMILY_PROJECT, FAMILY_SCIPY, WHOLE_RUN_SUFFIX, Run
from finger_sim.bench.tables import row_order

#: Errors are floored here on log axes (an exact match would otherwise vanish).
PLOT_FLOOR = 1e-16
#: Figure size (in) and resolution (dpi).
FIGSIZE = (13.5, 5.8)
DPI = 110
#: Colours: the project's methods in strong colours, scipy's in a muted set, MuJoCo's by integrator.
PROJECT_COLORS = ("#d62728", "#1f77b4", "#2ca02c", "#000000", "#9467bd", "#ff7f0e", "#8c564b", "#e377c2")
SCIPY_COLORS = {"RK45": "#7f7f7f", "DOP853": "#17becf", "Radau": "#393b79", "LSODA": "#6baed6"}
MUJOCO_COLORS = {"Euler": "#8c6d31", "RK4": "#e6550d", "implicitfast": "#bcbd22"}


def write_figure(name: str, runs: Sequence[Run], ref: Reference, out: Path) -> str:
    """Error and loop violation against CPU time, log-log, every method and peer: out/wp_<name>.png; its file name."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, (ax_err, ax_phi) = plt.subplots(1, 2, figsize=FIGSIZE, sharex=True)
    labels = sorted({r.method for r in runs}, key=lambda m: row_order(next(r for r in runs if r.method == m)))
    handles = []
    for label in labels:
        rs = sorted((r for r in runs if r.method == label and r.ok), key=lambda r: r.cpu)
        if not rs:
            continue
        kw = line_style(label, rs[0].family)
        cpu = [r.cpu for r in rs]
        (line,) = ax_err.plot(cpu, [max(r.error, PLOT_FLOOR) for r in rs], label=label, **kw)
        ax_phi.plot(cpu, [max(r.max_phi, PLOT_FLOOR) for r in rs], **kw)
        handles.append(line)
    for target in an.TARGETS:
        ax_err.axhline(target, color="grey", lw=0.7, alpha=0.6)
    if math.isfinite(ref.floor):  # none is claimed where the check cannot follow the scene
        handles.append(ax_err.axhspan(PLOT_FLOOR, max(ref.floor, PLOT_FLOOR), color="grey", alpha=0.15,
                                      label="reference floor"))
    ax_err.set_ylabel("max |θ − θ_ref| (rad)")
    ax_phi.set_ylabel("max |Φ| (m): loop violation")
    for ax in (ax_err, ax_phi):
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.set_xlabel("CPU time of the run (s)")
        ax.grid(True, which="both", alpha=0.25)
    ax_err.set_title(f"{name}: error against CPU time (targets 1e-6, 1e-9 rad)")
    ax_phi.set_title(f"{name}: loop closure")
    fig.tight_layout(rect=(0.0, 0.0, 0.85, 1.0))
    fig.legend(handles=handles, loc="center left", bbox_to_anchor=(0.85, 0.5), fontsize=7.5, frameon=False)
    path = out / f"wp_{name}.png"
    fig.savefig(path, dpi=DPI)
    plt.close(fig)
    return path.name


def line_style(label: str, family: str) -> dict:
    """matplotlib line keywords of one row label: solid for the project, dashed for scipy, dash-dot for MuJoCo."""
    if family == FAMILY_PROJECT:  # a whole run in its method's colour, thinner, diamonds
        methods, method = project_methods(), label.removesuffix(WHOLE_RUN_SUFFIX)
        color = PROJECT_COLORS[methods.index(method) % len(PROJECT_COLORS)] if method in methods else "k"
        if method != label:
            return {"color": color, "linestyle": (0, (5, 1, 1, 1)), "marker": "D", "ms": 3.5, "lw": 1.1}
        return {"color": color, "linestyle": "-", "marker": "o", "ms": 4, "lw": 1.6}
    if family == FAMILY_SCIPY:
        key = label.split()[1]
        numpy = "numpy" in label
        return {"color": SCIPY_COLORS.get(key, "grey"), "linestyle": ":" if numpy else "--", "marker": "s", "ms": 3.5, "lw": 1.2}
    _, integrator, setting = label.split()
    tight = setting == "tight"
    return {"color": MUJOCO_COLORS.get(integrator, "grey"), "linestyle": ":" if tight else "-.", "marker": "^" if tight else "v", "ms": 4, "lw": 1.2}
