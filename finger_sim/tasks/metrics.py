"""The scores of a grasp task, each computed from the run's own sampled outputs.

The run is sampled at every step: times t (s), the grip force F (N, `grip_force`, Σ F_n over
every contact), the setpoint F* in force at each sample (N). The script splits the run into
*segments*, one per setpoint change: segment i holds F*_i from its time t_i to the next change
(the last one to the run's end, inclusive). A *hold* segment has F*_i > 0, a *release* segment
F*_i = 0 (after t = 0).

Per hold segment (`segment_scores`):
- settle_time (s): from t_i to the first sample from which |F − F*_i| ≤ 5 % F*_i holds at every
  sample to the segment's end; inf if the last sample is outside that band.
- overshoot (%): how far F passes F*_i in the direction of the change, / F*_i · 100 over the
  segment: max(0, max F − F*_i) after a rise (from 0 or a lower setpoint), max(0, F*_i − min F)
  after a fall.
- hold_rms (N): √(mean (F − F*_i)²) over the holding window, the samples with
  t ≥ t_i + hold_after in the segment; nan when the window is empty.
- contact_lost: some sample of the holding window has F = 0 (no object is touched at all).

Per release segment: release_time (s), from t_i to the first sample from which F = 0 to the
segment's end; inf if the last sample still touches.

The task's scores (`task_scores`): the worst over its segments (the largest settle_time,
overshoot, hold_rms, release_time; contact_lost if any), plus peak_force (N, max F over the run),
crushed (an object's normal force exceeded its break_force: `finger_sim.grasp_objects`),
motor_work (J, the net work of the commanded torque on the MCP joint, Σ τ_k (θ1,k+1 − θ1,k):
exact for a torque held over each step; None when the command is not a torque), and
electrical_energy (J, ∫ u·i dt by the trapezoid rule, when the run has the `motor_voltage` and
`motor_current` outputs of a drive; None otherwise).
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np

from finger_sim.actuators.drive_outputs import MOTOR_CURRENT, MOTOR_VOLTAGE

#: The band around the setpoint that counts as reached, as a fraction of the setpoint.
SETTLE_BAND = 0.05
#: name → (unit, short definition): what a task's `limits` may name.
METRICS: dict[str, tuple[str, str]] = {
    "settle_time": ("s", "time to within 5 % of the setpoint, for good"),
    "overshoot": ("%", "largest excess over the setpoint"),
    "hold_rms": ("N", "RMS force error while holding"),
    "release_time": ("s", "time from a zero setpoint to no contact, for good"),
    "peak_force": ("N", "largest grip force"),
    "crushed": ("", "an object broke"),
    "contact_lost": ("", "no contact at some sample while holding"),
    "motor_work": ("J", "net work of the torque command, Σ τ Δθ1"),
    "electrical_energy": ("J", "∫ u·i dt (drive scenes)"),
}
BOOLEAN_METRICS = frozenset({"crushed", "contact_lost"})
#: The drive outputs electrical_energy integrates (a scene with a DC-motor drive reports them).
VOLTAGE, CURRENT = MOTOR_VOLTAGE.name, MOTOR_CURRENT.name

Scores = dict[str, "float | bool | None"]


@dataclass(frozen=True)
class Segment:
    """Samples [start, stop) of a run holding one setpoint `value` (N) from time `t0` (s)."""

    t0: float
    value: float
    start: int
    stop: int


def segments(t: np.ndarray, setpoints: Sequence[tuple[float, float]]) -> list[Segment]:
    """The run's segments: setpoint i covers the samples with t_i ≤ t < t_{i+1} (the last to the end)."""
    out = []
    for i, (t0, value) in enumerate(setpoints):
        start = int(np.searchsorted(t, t0, side="left"))
        stop = int(np.searchsorted(t, setpoints[i + 1][0], side="left")) if i + 1 < len(setpoints) else len(t)
        if stop > start:
            out.append(Segment(t0, value, start, stop))
    return out


def settle_time(t: np.ndarray, force: np.ndarray, seg: Segment) -> float:
    """s from seg.t0 to the first sample from which F stays within SETTLE_BAND of the setpoint."""
    f = force[seg.start:seg.stop]
    outside = np.abs(f - seg.value) > SETTLE_BAND * seg.value
    return _from_when(t[seg.start:seg.stop], outside, seg.t0)


def release_time(t: np.ndarray, force: np.ndarray, seg: Segment) -> float:
    """s from seg.t0 to the first sample from which F = 0 to the segment's end."""
    return _from_when(t[seg.start:seg.stop], force[seg.start:seg.stop] != 0.0, seg.t0)


def overshoot(force: np.ndarray, seg: Segment, previous: float = 0.0) -> float:
    """%: how far F passes the setpoint F* in the direction of the change from the `previous`
    setpoint (N), / F* · 100 over the segment: max(0, max F − F*) after a rise, max(0, F* − min F)
    after a fall (F starts above F* there: that is not an overshoot)."""
    f = force[seg.start:seg.stop]
    excess = float(f.max()) - seg.value if seg.value >= previous else seg.value - float(f.min())
    return max(0.0, excess) / seg.value * 100.0


def hold_window(t: np.ndarray, seg: Segment, hold_after: float) -> slice:
    """The samples of the segment with t ≥ t0 + hold_after."""
    first = max(seg.start, int(np.searchsorted(t, seg.t0 + hold_after, side="left")))
    return slice(first, max(first, seg.stop))


def hold_rms(t: np.ndarray, force: np.ndarray, seg: Segment, hold_after: float) -> float:
    """N: RMS of F − F* over the holding window; nan if it is empty."""
    f = force[hold_window(t, seg, hold_after)]
    return float(np.sqrt(np.mean((f - seg.value) ** 2))) if f.size else math.nan


def contact_lost(t: np.ndarray, force: np.ndarray, seg: Segment, hold_after: float) -> bool:
    """Some sample of the holding window has F = 0."""
    return bool(np.any(force[hold_window(t, seg, hold_after)] == 0.0))


def electrical_energy(t: np.ndarray, outputs: Mapping[str, np.ndarray]) -> float | None:
    """J: ∫ u·i dt (trapezoid rule) over the run, or None without a drive's voltage and current."""
    if VOLTAGE not in outputs or CURRENT not in outputs:
        return None
    return float(np.trapezoid(outputs[VOLTAGE] * outputs[CURRENT], t))


def motor_work(torque: np.ndarray, theta1: np.ndarray) -> float:
    """J: Σ τ_k (θ1,k+1 − θ1,k), τ_k the torque held over step k (the last sample's is not applied)."""
    return float(np.dot(torque[:-1], np.diff(theta1)))


def task_scores(t: np.ndarray, force: np.ndarray, setpoints: Sequence[tuple[float, float]], hold_after: float,
                crushed: bool, outputs: Mapping[str, np.ndarray] | None = None,
                torque: tuple[np.ndarray, np.ndarray] | None = None) -> Scores:
    """Every metric of METRICS for a run (module docstring): the worst over its segments.
    torque: (τ per sample, N·m, held over the step that follows it; θ1 per sample, rad)."""
    segs = segments(t, setpoints)
    previous = {id(s): (segs[i - 1].value if i else 0.0) for i, s in enumerate(segs)}
    holds = [s for s in segs if s.value > 0.0]
    releases = [s for s in segs if s.value == 0.0 and s.t0 > 0.0]
    rms = [hold_rms(t, force, s, hold_after) for s in holds]
    rms = [x for x in rms if not math.isnan(x)]
    return {
        "settle_time": max((settle_time(t, force, s) for s in holds), default=None),
        "overshoot": max((overshoot(force, s, previous[id(s)]) for s in holds), default=None),
        "hold_rms": max(rms, default=None),
        "release_time": max((release_time(t, force, s) for s in releases), default=None),
        "peak_force": float(force.max()),
        "crushed": crushed,
        "contact_lost": any(contact_lost(t, force, s, hold_after) for s in holds),
        "motor_work": None if torque is None else motor_work(*torque),
        "electrical_energy": electrical_energy(t, outputs or {}),
    }


def judge(scores: Scores, limits: Mapping[str, float | bool]) -> dict[str, bool]:
    """Pass (True) or fail per limit: a number passes at or below its limit, a boolean when
    equal; a metric the run does not define (None, nan) fails."""
    out = {}
    for name, limit in limits.items():
        value = scores.get(name)
        if isinstance(limit, bool):
            out[name] = value is limit
        else:
            out[name] = isinstance(value, float) and not math.isnan(value) and value <= limit
    return out


def _from_when(t: np.ndarray, bad: np.ndarray, t0: float) -> float:
    """Time from t0 to the first sample after the last `bad` one (0 if none is bad; inf if the last is)."""
    if not bad.any():
        return max(0.0, float(t[0]) - t0)
    last = int(np.flatnonzero(bad)[-1])
    return math.inf if last == len(t) - 1 else float(t[last + 1]) - t0
