"""PNG figures with matplotlib (Agg backend: no display needed)."""

from __future__ import annotations

import math
from collections.abc import Mapping
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from finger_sim import kinematics  # noqa: E402
from finger_sim.effects.contact_outputs import GRIP_FORCE  # noqa: E402
from finger_sim.model import FingerParams  # noqa: E402

#: Postures drawn by `finger-sim kinematics` (MCP angles, degrees), as in the paper's Fig. 5.
POSTURES_DEG = (0.0, 30.0, 60.0, 90.0)


def plot_angles(t: np.ndarray, q: np.ndarray, path: str | Path, title: str,
                outputs: Mapping[str, np.ndarray] | None = None) -> None:
    """θ1, θ2, θ3 (degrees) against time, like the paper's Figs. 7-9; with the force elements'
    outputs (name → values, N: a run's `Trajectory.outputs`, e.g. contact forces) a fourth panel."""
    forces = dict(outputs or {})
    fig, axes = plt.subplots(3 + bool(forces), 1, sharex=True, figsize=(7, 7 + 2 * bool(forces)))
    for i, ax in enumerate(axes[:3]):
        ax.plot(t, np.degrees(q[:, i]))
        ax.set_ylabel(f"θ{i + 1} (deg)")
        ax.grid(True, alpha=0.3)
    if forces:
        ax = axes[3]
        for name, values in forces.items():
            ax.plot(t, values, label=name, lw=2.0 if name == GRIP_FORCE.name else 1.0)
        ax.set_ylabel("force (N)")
        ax.legend(fontsize=7, ncol=2)
        ax.grid(True, alpha=0.3)
    axes[-1].set_xlabel("t (s)")
    axes[0].set_title(title)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def plot_kinematics(p: FingerParams, mcp_range: tuple[float, float], path: str | Path) -> None:
    """Fingertip trajectory over the MCP range (paper Fig. 4) and a few postures (Fig. 5), mm."""
    alpha = kinematics.distal_offset(p)
    tips = np.array([pose[:2] for pose in kinematics.fingertip_trajectory(p, mcp_range)]) * 1e3
    fig, ax = plt.subplots(figsize=(6.5, 6))
    # the paper draws Y downward: flexion curls the finger down the page
    ax.plot(tips[:, 0], tips[:, 1], "k--", label="fingertip trajectory")
    for deg in POSTURES_DEG:
        pts = kinematics.points(p, kinematics.assemble(p, math.radians(deg)), alpha)
        xy = {k: np.array(v) * 1e3 for k, v in pts.items()}
        chain = np.array([xy["D"], xy["C"], xy["B"], xy["A"], xy["D"]])
        ax.plot(chain[:, 0], chain[:, 1], "-o", ms=3, lw=1, label=f"θ1 = {deg:.0f}°")
        distal = np.array([xy["C"], xy["B"], xy["tip"]])
        ax.plot(distal[:, 0], distal[:, 1], "-", lw=2, color=ax.lines[-1].get_color())
    ax.set_aspect("equal")
    ax.invert_yaxis()
    ax.set_xlabel("X (mm)")
    ax.set_ylabel("Y (mm, downward as in the paper)")
    ax.legend(fontsize=8)
    ax.grid(True, alpha=0.3)
    ax.set_title("Fingertip trajectory and postures")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
