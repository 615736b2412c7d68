"""The first gap crossing of a step, found and located in the kernel: `crossings.first_crossing` compiled.

After the kernel's common step (`kernel.event_step`) its screen may show a possible crossing. Python's
`crossings.first_crossing` then runs the guard loop (`locate.guard_loop`) over every gap in the Simulator's
order: `locate.gap_guard`'s skip test and side test, and the location of a gap whose ends lie on opposite
sides (`locate_gap`, whose Illinois loop is compiled in `kernel.locate_event`). `first_crossing` here runs
the same two functions, compiled from their source with this module's per-gap work bound under the names
they call: the gaps and rates at both ends are the screen's (`gap_screen.gap_states`), every trial of the location is
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

from finger_sim.kernel.jit import JIT, LAW, compiled, njit  # first: it keys numba's cache

from finger_sim.kernel import locate_event
from finger_sim.kernel.event_checks import predicted_crossing
from finger_sim.kernel.locate_event import LOG_SIZE, META_COUNT, META_END, META_FAILED, META_FROM, META_GAP, \
    META_ROWS, META_SIZE, META_TO
from finger_sim.simulation import locate as plain
from finger_sim.simulation.crossings import MAX_LOCATE_ITERATIONS
from finger_sim.simulation.locate import DECLINE, FOUND, NONE, ON_GAP

#: `first_crossing`'s answers: `locate.guard_loop`'s NONE (no crossing in the step), FOUND (one located, in
#: out) and DECLINE (Python must look); IMPACT: the earliest crossing is a stop's impact gap (located, out
#: filled), the caller applies the impact law and the rest test (`event_step._impact`).
IMPACT = 3
#: out's slots: the crossing (s, q, q', the error estimate at q in rad), then the last trial (HAS_LAST 1/0,
#: its time, q, q', its estimate).
OUT_S, OUT_Q, OUT_V, OUT_EST = 0, 1, 4, 7
OUT_HAS_LAST, OUT_LAST_T, OUT_LAST_Q, OUT_LAST_V, OUT_LAST_EST = 8, 9, 10, 13, 16
OUT_SIZE = 17
#: Where `first_crossing`'s meta (`locate_event`'s META_* slots first) holds the crossing `_onto_gap` located last
#: (q, q'), which `_keep` reads.
CROSSING = META_SIZE


@njit(**JIT)
def depth_from(plan):
    """The position in the Simulator's gap order of the first depth gap (`depth_guard`): they come last."""
    n, groups = int(plan[0]), int(plan[1])
    o = 2
    for _ in range(groups):
        o += 2 + int(plan[o + 1])
    return n - int(plan[o])


@njit(**LAW)
def _gap_kind(ctx, k):
    """Every guard of the compiled event step is a gap."""
    return ON_GAP


@njit(**LAW)
def _no_mode_guard(ctx, k, kind, a, b):
    """The compiled event step declares no mode guard: were one asked, Python would look."""
    return DECLINE, 0.0


@njit(**LAW)
def _gap_ends(ctx, k):
    """Gap k's (gap, rate) at the step's start and end, from the screen's rows, and whether it is an impact gap."""
    m, plan, work, a, t, q, v, t1, q1, v1, est1, segs, y_olds, denses, end, out, meta, x, lwork, trials = ctx
    b, n = 2 - a, int(plan[0])
    return work[a, k], work[a + 1, k], work[b, k], work[b + 1, k], plan[plan.shape[0] - n + k] != 0.0


@njit(**LAW)
def _inside_step(ctx, k, g0, r0, g1, r1, x):
    """A crossing predicted between ends on the same side: Python's `bracket` needs trial steps."""
    return DECLINE, 0.0


@njit(**LAW)
def _onto_gap(ctx, k, g0, g1, impact):
    """Gap k's crossing between ends on opposite sides, located by `locate_event.locate` on the internal
    steps (its q, q' into meta[CROSSING:]); Python's last trial goes to out (OUT_HAS_LAST…). DECLINE where a
    trial is not answered from them."""
    m, plan, work, a, t, q, v, t1, q1, v1, est1, segs, y_olds, denses, end, out, meta, x, lwork, trials = ctx
    meta[META_ROWS], meta[META_GAP], meta[META_FAILED], meta[META_COUNT] = segs.shape[0] - 1, k, 0.0, 0.0
    meta[META_FROM], meta[META_TO], meta[META_END] = -math.inf, math.inf, end
    s, qs, vs = locate_event.locate(m, plan, segs, y_olds, denses, meta, lwork, x, trials, t, q, v,
                                    t, g0, t1, g1, q1, v1, not impact)
    count = int(meta[META_COUNT])
    if meta[META_FAILED] != 0.0 or count > trials.shape[0]:
        return DECLINE, 0.0
    if count:
        row = trials[count - 1]
        out[OUT_HAS_LAST], out[OUT_LAST_T] = 1.0, row[0]
        out[OUT_LAST_Q:OUT_LAST_Q + 3], out[OUT_LAST_V:OUT_LAST_V + 3] = row[1:4], row[4:7]
        out[OUT_LAST_EST] = row[7]
    c = CROSSING
    meta[c], meta[c + 1], meta[c + 2], meta[c + 3], meta[c + 4], meta[c + 5] = qs[0], qs[1], qs[2], vs[0], vs[1], vs[2]
    return FOUND, s


@njit(**LAW)
def _keep(ctx, k, s):
    """Gap k's crossing at s (s), the earliest so far, into out with the estimate `error_estimate(q)` reads
    there: the newest trial at q, else the step's end; DECLINE at the step's start (Python's estimate there)."""
    m, plan, work, a, t, q, v, t1, q1, v1, est1, segs, y_olds, denses, end, out, meta, x, lwork, trials = ctx
    c, estimate = CROSSING, math.nan
    for j in range(int(meta[META_COUNT]) - 1, -1, -1):
        if trials[j, 1] == meta[c] and trials[j, 2] == meta[c + 1] and trials[j, 3] == meta[c + 2]:
            estimate = trials[j, 7]
            break
    if math.isnan(estimate):
        if not (meta[c] == q1[0] and meta[c + 1] == q1[1] and meta[c + 2] == q1[2]):
            return DECLINE
        estimate = est1
    out[OUT_S], out[OUT_EST] = s, estimate
    out[OUT_Q], out[OUT_Q + 1], out[OUT_Q + 2] = meta[c], meta[c + 1], meta[c + 2]
    out[OUT_V], out[OUT_V + 1], out[OUT_V + 2] = meta[c + 3], meta[c + 4], meta[c + 5]
    return FOUND


#: `locate.gap_guard` and `locate.guard_loop`, compiled from their source with the per-gap work above.
_gap_guard = compiled(plain.gap_guard, gap_ends=_gap_ends, onto_gap=_onto_gap, inside_step=_inside_step,
                      predicted_crossing=predicted_crossing)
_guard_loop = compiled(plain.guard_loop, guard_kind=_gap_kind, gap_guard=_gap_guard, mode_guard=_no_mode_guard,
                       keep=_keep)


@njit(**JIT)
def first_crossing(m, plan, work, a, t, q, v, t1, q1, v1, est1, segs, y_olds, denses, end, out):
    """The earliest crossing of the step (t, q, q') → (t1, q1, q1') (s, rad, rad/s), as
    `crossings.first_crossing` finds and locates it: `locate.guard_loop` and `locate.gap_guard`, compiled with
    the hooks above. work: the screen's rows (a, a + 1: the start's gaps and rates; 2 − a, 3 − a: the end's);
    est1: the error estimate at q1 (rad); segs, y_olds, denses: the internal steps that answer trials
    (`locate_event`'s layout, the current one last); end: the internal solution's time (s). Returns (NONE,
    FOUND, IMPACT or DECLINE, the crossing gap's position); FOUND and IMPACT fill out (OUT_*)."""
    n = int(plan[0])
    meta, x = np.empty(META_SIZE + 6), np.empty(6)
    lwork, trials = np.empty((2, n)), np.empty((MAX_LOCATE_ITERATIONS, LOG_SIZE))
    out[OUT_HAS_LAST] = 0.0
    ctx = (m, plan, work, a, t, q, v, t1, q1, v1, est1, segs, y_olds, denses, end, out, meta, x, lwork, trials)
    status, first = _guard_loop(ctx, n, t, t1)
    if status != FOUND:
        return status, first
    if first >= depth_from(plan):
        return DECLINE, first  # a phalanx axis in the object (an error): Python's
    return (IMPACT if plan[plan.shape[0] - n + first] != 0.0 else FOUND), first
