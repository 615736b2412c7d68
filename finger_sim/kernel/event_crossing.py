"""The first gap crossing of a step, found and located in the kernel: `crossings.first_crossing` compiled.

After the kernel's common step (`kernel.event_step`) its screen may show a possible crossing. Python's
`crossings.first_crossing` then takes, for every gap in the Simulator's order, the skip test, `bracket`'s
side test, and the location of a gap whose ends lie on opposite sides (`locate_gap`, whose Illinois loop is
compiled in `kernel.locate_event`). `first_crossing` here takes the same tests on the same numbers: the
gaps and rates at both ends are the screen's (`gap_screen.gap_states`), every trial of the location is
answered from the internal steps the kernel took (as `DormandPrince853.step` answers them from its
history). Where Python would need more, it declines (DECLINE) before anything is changed: `bracket`'s
trial steps (a crossing predicted between two ends on the same side), a depth gap crossing first (the
depth error), a trial the internal steps do not answer, or a crossing at the step's start. Python then
locates it as always. A stop's impact gap crossing first is located and answered IMPACT: the caller applies
the impact and its rest test (`event_step._impact`).

Besides the crossing, Python's trials leave the integrator's last output (the last trial) and the error
estimate of every trial state: the caller reads them in `out` (the OUT_* slots), to continue or restart
the internal solution from the crossing as `DormandPrince853.step` does.
"""

from __future__ import annotations

import math

import numpy as np

from finger_sim.kernel.jit import JIT, njit  # first: it keys numba's cache

from finger_sim.kernel import locate_event
from finger_sim.kernel.event_checks import EVENT_TOLERANCE, predicted_crossing
from finger_sim.kernel.locate_event import LOG_SIZE, META_COUNT, META_END, META_FAILED, META_FROM, META_GAP, \
    META_ROWS, META_SIZE, META_TO
from finger_sim.simulation.crossings import MAX_LOCATE_ITERATIONS

#: `first_crossing`'s answers: no crossing in the step; one located (in out); Python must look.
NONE, FOUND, DECLINE = 0, 1, 2
#: `first_crossing`'s answer when the earliest crossing is a stop's impact gap (located, out filled): the
#: caller applies the impact law and the rest test (`event_step._impact`).
IMPACT = 3
#: out's slots: the crossing (s, q, q', the error estimate at q in rad), then the last trial (HAS_LAST 1/0,
#: its time, q, q', its estimate).
OUT_S, OUT_Q, OUT_V, OUT_EST = 0, 1, 4, 7
OUT_HAS_LAST, OUT_LAST_T, OUT_LAST_Q, OUT_LAST_V, OUT_LAST_EST = 8, 9, 10, 13, 16
OUT_SIZE = 17


@njit(**JIT)
def depth_from(plan):
    """The position in the Simulator's gap order of the first depth gap (`depth_guard`): they come last."""
    n, groups = int(plan[0]), int(plan[1])
    o = 2
    for _ in range(groups):
        o += 2 + int(plan[o + 1])
    return n - int(plan[o])


@njit(**JIT)
def first_crossing(m, plan, work, a, t, q, v, t1, q1, v1, est1, segs, y_olds, denses, end, out):
    """The earliest crossing of the step (t, q, q') → (t1, q1, q1') (s, rad, rad/s), as
    `crossings.first_crossing` finds and locates it. work: the screen's rows (a, a + 1: the start's gaps and
    rates; 2 − a, 3 − a: the end's); est1: the error estimate at q1 (rad); segs, y_olds, denses: the internal
    steps that answer trials (`locate_event`'s layout, the current one last); end: the internal solution's
    time (s). Returns (NONE, FOUND, IMPACT or DECLINE, the crossing gap's position); FOUND and IMPACT fill out (OUT_*)."""
    n, b, h = int(plan[0]), 2 - a, t1 - t
    flags, deep = plan.shape[0] - n, depth_from(plan)
    meta, x = np.empty(META_SIZE), np.empty(6)
    lwork, trials = np.empty((2, n)), np.empty((MAX_LOCATE_ITERATIONS, LOG_SIZE))
    first = -1
    out[OUT_HAS_LAST] = 0.0
    for i in range(n):
        g0, r0, g1, r1 = work[a, i], work[a + 1, i], work[b, i], work[b + 1, i]
        impact = plan[flags + i] != 0.0
        if impact:
            g0 = max(g0, 0.0)  # an impact gap: the step starts on the open side
        if min(g0, g1) > h * (abs(r0) + abs(r1)):
            continue
        closed = g0 < -EVENT_TOLERANCE
        if (g1 < -EVENT_TOLERANCE) == closed:  # `bracket`: a crossing inside needs its trial steps
            if predicted_crossing(g0, r0, g1, r1, h, closed) is not None:
                return DECLINE, i
            continue
        meta[META_ROWS], meta[META_GAP], meta[META_FAILED], meta[META_COUNT] = segs.shape[0] - 1, i, 0.0, 0.0
        meta[META_FROM], meta[META_TO], meta[META_END] = -math.inf, math.inf, end
        s, qs, vs = locate_event.locate(m, plan, segs, y_olds, denses, meta, lwork, x, trials, t, q, v,
                                        t, g0, t1, g1, q1, v1, not impact)
        count = int(meta[META_COUNT])
        if meta[META_FAILED] != 0.0 or count > trials.shape[0]:
            return DECLINE, i
        if count:
            row = trials[count - 1]
            out[OUT_HAS_LAST], out[OUT_LAST_T] = 1.0, row[0]
            out[OUT_LAST_Q:OUT_LAST_Q + 3], out[OUT_LAST_V:OUT_LAST_V + 3] = row[1:4], row[4:7]
            out[OUT_LAST_EST] = row[7]
        if first >= 0 and not s < out[OUT_S]:
            continue
        # the estimate `error_estimate(q)` reads at the crossing: the newest trial at q, else the step's end
        estimate = math.nan
        for j in range(count - 1, -1, -1):
            if trials[j, 1] == qs[0] and trials[j, 2] == qs[1] and trials[j, 3] == qs[2]:
                estimate = trials[j, 7]
                break
        if math.isnan(estimate):
            if not (qs[0] == q1[0] and qs[1] == q1[1] and qs[2] == q1[2]):
                return DECLINE, i  # at the step's start: Python's estimate there
            estimate = est1
        first = i
        out[OUT_S], out[OUT_EST] = s, estimate
        out[OUT_Q], out[OUT_Q + 1], out[OUT_Q + 2] = qs[0], qs[1], qs[2]
        out[OUT_V], out[OUT_V + 1], out[OUT_V + 2] = vs[0], vs[1], vs[2]
    if first < 0:
        return NONE, first
    if first >= deep:
        return DECLINE, first  # a phalanx axis in the object (an error): Python's
    return (IMPACT if plan[flags + first] != 0.0 else FOUND), first
