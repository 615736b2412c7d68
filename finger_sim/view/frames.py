"""The honest thinning of a run for display, and what each animation frame draws.

- Animation: frames at a fixed rate of sim time (one per sample, at most MAX_FRAMES per run). Each frame is the last
  recorded state at or before its time, never an interpolation, so what is drawn is a state
  of the run; a run sampled more coarsely keeps every sample.
- Plots: the min and the max of every pixel column (PLOT_BUCKETS time bins over the run), in
  time order, so that no peak disappears; a signal with few samples is kept whole. A mode
  (text) is kept at its changes.

Every position comes from the core's kinematics (spec §1: `kinematics.points`) and the contact
points and forces from the scene's contact element (spec §7), evaluated in Python here.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from finger_sim import kinematics
from finger_sim.effects.contact import build_contact
from finger_sim.effects.contact_geometry import Circle
from finger_sim.joints import joint_positions
from finger_sim.view.source import FingerRun, Signal

#: Most animation frames of a run: a 60 s run at 1 kHz is shown at 100 frames per second of sim time.
MAX_FRAMES = 6000
#: Frame rate of a run with a single sample time, Hz.
FRAME_RATE_HZ = 100.0
#: Time bins of a plot: about the pixel columns of a wide plot.
PLOT_BUCKETS = 1500
#: Two times closer than this are the same instant, s (the logs' stamps are whole ns).
SAME_TIME_S = 5e-10
#: Significant digits of a plotted (thinned) value: below a pixel.
PLOT_DIGITS = 7
#: Positions are written to 1e-9 m (far below what a screen shows, and what the tests compare).
POSITION_DECIMALS = 9
#: The drawing's margin around everything it shows, m.
VIEW_MARGIN = 0.01
#: Half-length of a plane drawn as a polygon, m: far outside any view (the SVG clips it).
PLANE_EXTENT = 1.0
POINTS = ("A", "B", "C", "D", "tip")


def frame_times(t0: float, t1: float, sample_dt: float) -> np.ndarray:
    """The frame grid t0 + k/rate (s), with the end appended. One rate for the whole file: one
    frame per sample (1/sample_dt), but no more than MAX_FRAMES over the run."""
    duration = max(t1 - t0, 0.0)
    rate = 1.0 / sample_dt if sample_dt > 0.0 else FRAME_RATE_HZ
    if duration > 0.0:
        rate = min(rate, MAX_FRAMES / duration)
    grid = t0 + np.arange(int(math.floor(duration * rate + 1e-9)) + 1) / rate
    return grid if t1 - grid[-1] <= SAME_TIME_S else np.append(grid, t1)


def frame_indices(t: np.ndarray, times: np.ndarray) -> np.ndarray:
    """Sample index of each frame: the last sample at or before its time (the first before the first)."""
    return np.clip(np.searchsorted(t, times + SAME_TIME_S, side="right") - 1, 0, len(t) - 1)


def envelope(t: np.ndarray, y: np.ndarray, t0: float, t1: float, buckets: int = PLOT_BUCKETS) -> tuple[np.ndarray, np.ndarray]:
    """(t, y) thinned to each bin's min and max sample in time order (both kept); unchanged when short."""
    if len(t) <= 2 * buckets:
        return t, y
    edges = np.searchsorted(t, np.linspace(t0, t1, buckets + 1)[1:-1])
    keep = []
    for chunk, start in zip(np.split(np.arange(len(t)), edges), np.concatenate(([0], edges))):
        if len(chunk) == 0:
            continue
        values = y[chunk]
        if np.all(np.isnan(values)):
            keep.append(start)
            continue
        keep += sorted({start + int(np.nanargmin(values)), start + int(np.nanargmax(values))})
    idx = np.array(keep)
    return t[idx], y[idx]


def mode_changes(signal: Signal) -> tuple[np.ndarray, np.ndarray]:
    """A mode's samples where it changes (and the first and last): exact, drawn as steps."""
    v = signal.values
    keep = np.flatnonzero(np.concatenate(([True], v[1:] != v[:-1])))
    keep = np.unique(np.append(keep, len(v) - 1))
    return signal.t[keep], v[keep]


def value_at(signal: Signal, times: np.ndarray) -> list[Any]:
    """The signal's last sample at or before each time (None before its first)."""
    idx = np.searchsorted(signal.t, times + SAME_TIME_S, side="right") - 1
    return [None if i < 0 else _json_value(signal.values[i]) for i in idx.tolist()]


def joint_angles(run: FingerRun) -> np.ndarray:
    """(N, 3) spec §6 joint positions (mcp, coupler, pip), rad, of every state."""
    p = run.scene.params
    q_ext, alpha = kinematics.extended_pose(p), kinematics.distal_offset(p)
    return np.array([joint_positions(tuple(q), q_ext, alpha) for q in run.q.tolist()]).reshape(-1, 3)


def finger_frames(run: FingerRun, times: np.ndarray) -> dict[str, Any]:
    """The animation of one finger as columns: per frame its time, the points A, B, C, D, tip
    (m, model plane), the active contacts [x, y, Fx, Fy] (m, N) and every signal's value."""
    p = run.scene.params
    alpha = kinematics.distal_offset(p)
    contact = build_contact(run.scene)
    idx = frame_indices(run.t, times)
    times = run.t[idx]
    points: dict[str, list[list[float]]] = {name: [] for name in POINTS}
    contacts = []
    for i in idx.tolist():
        q, v = tuple(run.q[i]), tuple(run.v[i])
        for name, (x, y) in kinematics.points(p, q, alpha).items():
            points[name].append([round(x, POSITION_DECIMALS), round(y, POSITION_DECIMALS)])
        found = contact.contacts(float(run.t[i]), q, v) if contact is not None else ()
        contacts.append([[round(c.point[0], POSITION_DECIMALS), round(c.point[1], POSITION_DECIMALS),
                          _json_value(c.force[0]), _json_value(c.force[1])] for c in found])
    angles = joint_angles(run)[idx]
    values = {s.name: value_at(s, times) for s in run.signals}
    values.update({f"{joint}_angle": [_json_value(math.degrees(a)) for a in angles[:, j].tolist()]
                   for j, joint in enumerate(("mcp", "coupler", "pip"))})
    return {"t": times.tolist(), "points": points, "contacts": contacts, "values": values}


def view_box(run: FingerRun, frames: dict[str, Any]) -> list[float]:
    """[x, y, width, height] (m) holding every frame's linkage with its capsules, and the circles."""
    xy = np.array([pt for name in POINTS for pt in frames["points"][name]])
    radius = max(run.scene.phalanx_radius)
    lo, hi = xy.min(axis=0) - radius, xy.max(axis=0) + radius
    for obj in run.scene.objects:
        if isinstance(obj, Circle):
            c = np.array(obj.center)
            lo, hi = np.minimum(lo, c - obj.radius), np.maximum(hi, c + obj.radius)
    lo, hi = lo - VIEW_MARGIN, hi + VIEW_MARGIN
    return [float(lo[0]), float(lo[1]), float(hi[0] - lo[0]), float(hi[1] - lo[1])]


def scene_objects(run: FingerRun) -> list[dict[str, Any]]:
    """The scene's objects as drawable shapes: a circle (centre, radius, m) or a plane as a
    polygon reaching PLANE_EXTENT beyond its point on the object's side (−normal)."""
    shapes = []
    for obj in run.scene.objects:
        if isinstance(obj, Circle):
            shapes.append({"name": obj.name, "type": "circle", "center": list(obj.center), "radius": obj.radius})
            continue
        (ox, oy), (nx, ny) = obj.point, obj.normal
        tx, ty = -ny, nx
        e = PLANE_EXTENT
        polygon = [[ox - e * tx, oy - e * ty], [ox + e * tx, oy + e * ty],
                   [ox + e * tx - e * nx, oy + e * ty - e * ny], [ox - e * tx - e * nx, oy - e * ty - e * ny]]
        shapes.append({"name": obj.name, "type": "plane", "polygon": polygon, "point": list(obj.point)})
    return shapes


def plot_signal(signal: Signal, t0: float, t1: float) -> tuple[list[float], list[Any]]:
    """A signal thinned for its plot (`envelope`, or `mode_changes` for a mode), as JSON lists."""
    if signal.is_mode:
        t, v = mode_changes(signal)
        return t.tolist(), [str(x) for x in v.tolist()]
    t, y = envelope(signal.t, signal.values, t0, t1)
    return t.tolist(), [None if not math.isfinite(x) else float(f"{x:.{PLOT_DIGITS}g}") for x in y.tolist()]


def _json_value(x: Any) -> Any:
    """A float as JSON can hold it (NaN and ±inf → None); text as is."""
    if isinstance(x, str):
        return x
    x = float(x)
    return x if math.isfinite(x) else None
