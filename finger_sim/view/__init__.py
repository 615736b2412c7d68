"""`finger-sim view`: one self-contained HTML file that shows a run (a node's MCAP log, a
finger or a hand, or a `simulate` CSV): the linkage to scale with its objects, contacts and
forces over a time slider, and plotly plots of every signal under a shared time cursor.

source.py reads the run, frames.py thins it for display and evaluates the core's kinematics
per frame, figure.py builds the plots, page.py writes the page (template.html, viewer.css,
viewer.js are its inline parts).
"""

from __future__ import annotations

from pathlib import Path

from finger_sim.view.page import write_page
from finger_sim.view.source import read_run


def write_view(run: Path, out: Path, *, scene: Path | None = None) -> str:
    """Write the viewer of `run` to `out`; a one-line summary of what it shows.

    scene: the scene file of a CSV (its geometry, objects and scripted torque).
    """
    from finger_sim.scene import load_scene

    fingers = read_run(run, load_scene(scene) if scene is not None else None)
    size = write_page(fingers, f"finger_sim: {run.name}", out)
    names = ", ".join(f.name or f.scene.name for f in fingers)
    states = sum(len(f.t) for f in fingers)
    return f"wrote {out} ({size / 1e6:.1f} MB): {len(fingers)} finger(s) ({names}), {states} states"


__all__ = ["write_view"]
