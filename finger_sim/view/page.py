"""One self-contained HTML file: plotly.js, the styles, the data and the viewer's script inline.

The page makes no request to any address: the drawing is SVG built by `viewer.js` from the
data block, and the plots are plotly.js's official "basic" partial bundle (scatter, bar, pie;
npm plotly.js-basic-dist-min, the same version as the full bundle of the plotly package that
builds the figure, vendored in vendor/ with its MIT license). It is a quarter of the full
bundle's 4.8 MB and opens in about half the time (docs/viewer.md).
"""

from __future__ import annotations

import html
import json
import re
from importlib import resources
from pathlib import Path
from typing import Any

import numpy as np

from finger_sim.view.figure import build_figure, units
from finger_sim.view.frames import finger_frames, frame_times, scene_objects, view_box
from finger_sim.view.source import FingerRun

#: A slot of template.html: /*NAME*/.
PLACEHOLDER = re.compile(r"/\*(TITLE|STYLE|PLOTLY|VIEW_DATA|PLOT_DATA|SCRIPT)\*/")
#: plotly.js's basic partial bundle (npm plotly.js-basic-dist-min 4.1.1, = the plotly package's plotly.js).
PLOTLY_BUNDLE = "plotly-basic.min.js"
#: Length of the longest force arrow drawn, m.
ARROW_LENGTH = 0.025


def view_data(runs: list[FingerRun]) -> dict[str, Any]:
    """What viewer.js draws: the frame times and, per finger, its frames, objects and view box."""
    first = runs[0]
    t0 = min(float(r.t[0]) for r in runs)
    t1 = max(float(r.t[-1]) for r in runs)
    sample_dt = float(np.median(np.diff(first.t))) if len(first.t) > 1 else 0.0
    times = frame_times(t0, t1, sample_dt)
    fingers = []
    for run in runs:
        frames = finger_frames(run, times)
        forces = [abs(c[k]) for frame in frames["contacts"] for c in frame for k in (2, 3) if c[k] is not None]
        fingers.append({
            "label": run.name or run.scene.name,
            "scene": run.scene.name,
            "radii": list(run.scene.phalanx_radius),
            "viewBox": view_box(run, frames),
            "objects": scene_objects(run),
            "arrowScale": ARROW_LENGTH / max(forces) if forces and max(forces) > 0.0 else 0.0,  # m per N
            "frames": frames,
        })
    return {"times": times.tolist(), "t0": t0, "t1": t1, "units": units(runs), "fingers": fingers}


def build_page(runs: list[FingerRun], title: str) -> str:
    """The viewer of `runs` as one HTML document."""
    data = view_data(runs)
    figure = build_figure(runs, data["t0"], data["t1"])
    assets = resources.files("finger_sim.view")
    template = (assets / "template.html").read_text(encoding="utf-8")
    parts = {
        "TITLE": html.escape(title),
        "STYLE": (assets / "viewer.css").read_text(encoding="utf-8"),
        "PLOTLY": (assets / "vendor" / PLOTLY_BUNDLE).read_text(encoding="utf-8"),
        "VIEW_DATA": _script_json(json.dumps(data, allow_nan=False, separators=(",", ":"))),
        "PLOT_DATA": _script_json(figure.to_json()),
        "SCRIPT": (assets / "viewer.js").read_text(encoding="utf-8"),
    }
    # one pass, so that nothing inserted is searched for placeholders again
    return PLACEHOLDER.sub(lambda m: parts[m[1]], template)


def write_page(runs: list[FingerRun], title: str, out: Path) -> int:
    """Write the viewer to `out`; its size, bytes."""
    text = build_page(runs, title)
    out.write_text(text, encoding="utf-8")
    return out.stat().st_size


def _script_json(text: str) -> str:
    """JSON safe inside a <script> element: no `</` can close it."""
    return text.replace("</", "<\\/")
