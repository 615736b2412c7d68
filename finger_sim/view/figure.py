"""The plots under the drawing: one plotly figure, one row per kind of signal, a shared time axis.

Rows are chosen by the signals' names, so new columns or topics find a row without a change
here: joint angles first, then torque, voltage, force, current, modes and rates; any other
numeric signal gets a row of its own. A hand's fingers share the rows (traces named by finger).
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass
from typing import Any

import plotly.graph_objects as go
from plotly.subplots import make_subplots

from finger_sim.view.frames import envelope, joint_angles, plot_signal
from finger_sim.view.source import FingerRun, Signal

#: Height of one plot row, px.
ROW_HEIGHT_PX = 170
#: Rows' vertical gap, px.
ROW_GAP_PX = 42
JOINTS = ("mcp", "coupler", "pip")
#: Margin of a plot's y range, a fraction of the data's span.
RANGE_PAD = 0.06


@dataclass(frozen=True)
class Row:
    """A plot row: its title, unit and which signal names it takes (None: modes)."""

    title: str
    unit: str
    pattern: re.Pattern[str] | None


ROWS = (
    Row("torque", "N·m", re.compile(r"torque|effort")),
    Row("voltage", "V", re.compile(r"voltage")),
    Row("force", "N", re.compile(r"force")),
    Row("current", "A", re.compile(r"current")),
    Row("mode", "", None),
    Row("joint rates", "rad/s", re.compile(r"_dot$|_velocity$")),
)
ANGLES = Row("joint angles", "°", re.compile(r"_angle$"))


def row_of(signal: Signal) -> Row:
    """The row a signal is plotted in: the first that matches its name, or its own."""
    for row in ROWS:
        if (row.pattern is None and signal.is_mode) or (row.pattern is not None and not signal.is_mode
                                                       and row.pattern.search(signal.name)):
            return row
    return Row(signal.name, "", re.compile(re.escape(signal.name)))


def units(runs: list[FingerRun]) -> dict[str, str]:
    """Each readout value's unit, by name (the joint angles' and every signal's)."""
    out = {f"{j}_angle": ANGLES.unit for j in JOINTS}
    out.update({s.name: row_of(s).unit for run in runs for s in run.signals})
    return out


def build_figure(runs: list[FingerRun], t0: float, t1: float) -> go.Figure:
    """The figure: a row per kind of signal present, thinned traces, a cursor line (shapes[0])."""
    rows: dict[str, tuple[Row, list[tuple[str, list[float], list[Any], bool]]]] = {ANGLES.title: (ANGLES, [])}
    several = len(runs) > 1
    for run in runs:
        prefix = f"{run.name} " if several else ""
        angles = joint_angles(run)
        for j, joint in enumerate(JOINTS):
            t, y = envelope(run.t, angles[:, j] * (180.0 / math.pi), t0, t1)
            rows[ANGLES.title][1].append((prefix + joint, t.tolist(), [float(f"{v:.7g}") for v in y.tolist()], False))
        for signal in run.signals:
            row = row_of(signal)
            t_list, y_list = plot_signal(signal, t0, t1)
            rows.setdefault(row.title, (row, []))[1].append((prefix + signal.name, t_list, y_list, signal.is_mode))
    order = [ANGLES.title] + [r.title for r in ROWS if r.title in rows] + [k for k in rows if k not in
                                                                           {ANGLES.title, *(r.title for r in ROWS)}]
    n = len(order)
    height = n * ROW_HEIGHT_PX + (n - 1) * ROW_GAP_PX + 90
    fig = make_subplots(rows=n, cols=1, shared_xaxes=True, vertical_spacing=ROW_GAP_PX / height,
                        subplot_titles=[f"{title} ({rows[title][0].unit})" if rows[title][0].unit else title
                                        for title in order])
    for i, title in enumerate(order, start=1):
        for name, t, y, is_mode in rows[title][1]:
            fig.add_trace(go.Scatter(x=t, y=y, name=name, mode="lines", line_shape="hv" if is_mode else "linear",
                                     legendgroup=title, hovertemplate=f"{name}: %{{y}}<extra></extra>"), row=i, col=1)
        numbers = [v for _, _, y, is_mode in rows[title][1] if not is_mode for v in y if v is not None]
        if numbers:
            fig.update_yaxes(range=_padded(min(numbers), max(numbers)), row=i, col=1)
    fig.update_xaxes(title_text="t (s)", row=n, col=1)
    fig.update_xaxes(range=[t0, t1], showspikes=True, spikemode="across", spikethickness=1)
    fig.update_layout(height=height, margin=dict(l=70, r=20, t=40, b=50), hovermode="x", template="plotly_white",
                      legend=dict(orientation="v", groupclick="toggleitem"),
                      shapes=[dict(type="line", xref="x", yref="paper", x0=t0, x1=t0, y0=0, y1=1,
                                   line=dict(color="#d62728", width=1.5))])
    return fig


def _padded(low: float, high: float) -> list[float]:
    """A y range around [low, high] with RANGE_PAD of its span on each side; a constant (plotly
    would put it at ±1) gets ±RANGE_PAD of its own size."""
    span = high - low
    pad = RANGE_PAD * span if span > 0.0 else RANGE_PAD * abs(high) or 1.0
    return [low - pad, high + pad]
