"""Figures of stick–slip friction (spec §7) for docs/stick_slip.md (matplotlib, Agg).

- `stick_slip_hold.png`: the held grip (config/friction/hold_table.yaml) after the torque drops,
  under stick–slip with μ_s = 2 and μ_s = 1 and under the regularized law with μ = 1: θ1 and grip force.
- `stick_slip_sawtooth.png`: config/friction/sawtooth.yaml: θ1 (a staircase) and the friction torque
  on θ1 (a sawtooth) between ± the friction cones' capacity Σ μ_s F_n |j_k|.

    python -m finger_sim.bench.friction_figures --out docs
"""

from __future__ import annotations

import argparse
import dataclasses
from pathlib import Path

import numpy as np

from finger_sim import stick_slip
from finger_sim.effects.contact_outputs import FRICTION_MODE, GRIP_FORCE
from finger_sim.effects.friction_modes import FrictionLaw
from finger_sim.scene import Scene, load_scene
from finger_sim.simulate import Simulator, Trajectory, simulate

CONFIG = Path(__file__).resolve().parents[2] / "config" / "friction"
FIGSIZE = (11.0, 7.0)
DPI = 110


def _variant(scene: Scene, name: str, static: float | None, regularized: bool = False) -> Scene:
    if regularized:
        return dataclasses.replace(scene, name=name, friction_law=FrictionLaw())
    law = dataclasses.replace(scene.friction_law, static_friction=static)
    return dataclasses.replace(scene, name=name, friction_law=law)


def hold_figure(out: Path) -> Path:
    """θ1 (°) and grip force (N) of the held grip under the three laws: out/stick_slip_hold.png."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    base = load_scene(CONFIG / "hold_table.yaml")
    runs = {"stick–slip, μ_k = 1, μ_s = 2": simulate(_variant(base, "hold_ms2", 2.0)),
            "stick–slip, μ_k = μ_s = 1": simulate(_variant(base, "hold_ms1", None)),
            "regularized, μ = 1": simulate(_variant(base, "hold_reg", None, regularized=True))}
    fig, (ax_q, ax_f) = plt.subplots(2, 1, figsize=FIGSIZE, sharex=True)
    for label, traj in runs.items():
        ax_q.plot(traj.t, np.degrees(traj.q[:, 0]), label=label)
        ax_f.plot(traj.t, traj.outputs[GRIP_FORCE.name], label=label)
    ax_q.set_ylim(16.45, 16.70)
    ax_q.set_ylabel("θ1 (°)")
    ax_f.set_ylim(0.0, 1.0)
    ax_f.set_ylabel("grip force Σ F_n (N)")
    ax_f.set_xlabel("t (s)")
    ax_q.axvline(0.5, color="0.6", lw=0.8)
    ax_f.axvline(0.5, color="0.6", lw=0.8)
    ax_q.legend()
    ax_q.set_title("torque 0.05 → 0.02 N·m at 0.5 s, fingertip on a table (config/friction/hold_table.yaml)")
    path = out / "stick_slip_hold.png"
    fig.tight_layout()
    fig.savefig(path, dpi=DPI)
    plt.close(fig)
    return path


def capacity(scene: Scene, traj: Trajectory) -> np.ndarray:
    """Σ μ_s F_n |j_k| (N·m) at every row's pose."""
    element = stick_slip.element(Simulator(scene).system)
    return np.array([element.capacity(tuple(q)) for q in traj.q.tolist()])


def sawtooth_figure(out: Path) -> Path:
    """θ1 (°) and the friction torque (N·m) with ± capacity: out/stick_slip_sawtooth.png."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    scene = load_scene(CONFIG / "sawtooth.yaml")
    traj = simulate(scene)
    cap = capacity(scene, traj)
    fig, (ax_q, ax_f) = plt.subplots(2, 1, figsize=FIGSIZE, sharex=True)
    start = int(0.1 / scene.dt)  # after the approach to the table
    t = traj.t[start:]
    ax_q.plot(t, np.degrees(traj.q[start:, 0]), color="#1f77b4")
    ax_q.set_ylabel("θ1 (°)")
    locked = traj.outputs[FRICTION_MODE.name][start:] == 1.0
    ax_f.plot(t, traj.outputs["friction_torque"][start:], color="#d62728", label="friction torque on θ1")
    ax_f.plot(t, -cap[start:], color="0.4", lw=0.8, ls="--", label="− Σ μ_s F_n |j_k| (the cone's edge)")
    ax_f.fill_between(t, -cap[start:], 0.0, where=locked, color="#d62728", alpha=0.08, label="locked")
    ax_f.set_ylabel("N·m")
    ax_f.set_xlabel("t (s)")
    ax_f.legend(loc="lower left")
    ax_q.set_title("torque 0.02 + 0.1 t N·m, μ_k = 0.5, μ_s = 1 (config/friction/sawtooth.yaml)")
    path = out / "stick_slip_sawtooth.png"
    fig.tight_layout()
    fig.savefig(path, dpi=DPI)
    plt.close(fig)
    return path


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=Path("docs"), help="directory of the figures")
    args = parser.parse_args(argv)
    args.out.mkdir(parents=True, exist_ok=True)
    for path in (hold_figure(args.out), sawtooth_figure(args.out)):
        print(path)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
