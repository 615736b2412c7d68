"""A located gap crossing in one compiled call: the Illinois loop on the step's logged dense output.

`crossings.locate_gap` locates a crossing by trial steps from the step's start; after the kernel's step
(or Python's) every trial is answered from the internal steps already taken (`DormandPrince853.step`'s
first branch: the dense output of the internal step that covers the trial time, projected). `locate`
runs the same loop (`locate.regula_falsi_gap`, compiled from its one definition, with
`locate.illinois_update`) on those internal steps, passed as arrays, with the gaps of the trial states
from the compiled gap plan (`gap_screen.gap_states`, `Contact._hits`' arithmetic) and each trial's error
estimate (`dop853.interpolated_estimate`). Its trials are logged, so that `simulation.event_locate` leaves
the integrator as Python's trials would have (its last output and the estimates of the trial states).

Arguments, all float64 arrays but the scalars:

    segs (r × SEG_SIZE): the internal steps a trial may fall in, in time order, the integrator's current
        one last: t_old, h_old (s), err_old, err (rad);
    y_olds (r × 6), denses (r × 7 × 6): their start states and dense outputs;
    meta: the META_* slots below;
    work (2 × n_gaps), x (6): scratch; log (n × LOG_SIZE): the trials (s, q, q', estimate).
"""

from __future__ import annotations

import math

import numpy as np

from finger_sim.kernel.jit import JIT, LAW, compiled, njit  # first: it keys numba's cache

from finger_sim.integrators import dop853
from finger_sim.kernel.gap_screen import gap_states
from finger_sim.kernel.numerics import OK, dop853_output
from finger_sim.simulation import locate as plain
from finger_sim.simulation.crossings import MAX_LOCATE_ITERATIONS

#: meta: the history rows among segs (0: no history, the current step answers every trial); the gap's
#: position in the gap plan; set to 1 when a trial fails or falls outside the rows given; the number of
#: trials taken; the times the history rows answer, [from, to) (s); the end of the internal solution (s).
META_ROWS, META_GAP, META_FAILED, META_COUNT, META_FROM, META_TO, META_END = 0, 1, 2, 3, 4, 5, 6
META_SIZE = 7
#: A segs row: t_old, h_old, err_old, err.
SEG_T, SEG_H, SEG_ERR_OLD, SEG_ERR = 0, 1, 2, 3
#: A log row: s (s), q (rad), q' (rad/s), the error estimate at q (rad).
LOG_SIZE = 8

_estimate = njit(**LAW)(dop853.interpolated_estimate)


@njit(**JIT)
def _gap_at(ctx, q, v):
    """The located gap at the state (q, q') (its rate is not used), from the compiled gap plan."""
    m, plan, segs, y_olds, denses, meta, work, x, log = ctx
    gap_states(plan, (q[0], q[1], q[2], v[0], v[1], v[2]), work, 0)
    return work[0, int(meta[META_GAP])]


@njit(**JIT)
def _trial(ctx, s):
    """(g(s), q(s), q'(s)): the trial step to s answered as `DormandPrince853.step` answers it from its
    history (`_segment`, then `dop853_output`), logged with its estimate (`_remember`)."""
    m, plan, segs, y_olds, denses, meta, work, x, log = ctx
    cur, n = segs.shape[0] - 1, int(meta[META_ROWS])
    i = cur
    if not (s >= segs[cur, SEG_T] or n == 0):  # an earlier internal step: `bisect_right` over their starts
        if not (meta[META_FROM] <= s < meta[META_TO]):
            meta[META_FAILED] = 1.0  # outside the rows given: Python takes the location
            return math.nan, (s, s, s), (s, s, s)
        i = max(0, np.searchsorted(segs[:n, SEG_T], s, side="right") - 1)
    if s > meta[META_END]:
        meta[META_FAILED] = 1.0  # past the internal solution: Python's trial would integrate further
        return math.nan, (s, s, s), (s, s, s)
    row = segs[i]
    status, q1, v1 = dop853_output(m, row[SEG_T], row[SEG_H], y_olds[i], denses[i], s, x)
    if status != OK:
        meta[META_FAILED] = 1.0  # Python's trial raises its error
        return math.nan, q1, v1
    k = int(meta[META_COUNT])
    if k < log.shape[0]:
        out = log[k]
        out[0], out[1], out[2], out[3], out[4], out[5], out[6] = s, q1[0], q1[1], q1[2], v1[0], v1[1], v1[2]
        out[7] = _estimate(s, row[SEG_T], row[SEG_H], row[SEG_ERR_OLD], row[SEG_ERR])
    meta[META_COUNT] = k + 1.0
    return _gap_at(ctx, q1, v1), q1, v1


@njit(**JIT)
def _gap_value(ctx, s, q):
    """g at the state q (time s unused: a fixed object's gaps depend on q alone)."""
    return _gap_at(ctx, q, (0.0, 0.0, 0.0))


_regula_falsi = compiled(plain.regula_falsi_gap, illinois_update=njit(**LAW)(plain.illinois_update),
                         trial=_trial, gap_value=_gap_value)


@njit(**JIT)
def locate(m, plan, segs, y_olds, denses, meta, work, x, log, t, q, v, a, ga, b, gb, qb, vb, kink):
    """Where in (a, b] (s) the gap meta[META_GAP] crosses inside the step from (t, q, q'):
    `crossings.locate_gap`'s (s, q(s), q'(s)), on the internal steps in segs, y_olds and denses (module docstring).
    Valid only where meta[META_FAILED] stays 0; the trials are in log[:meta[META_COUNT]]."""
    ctx = (m, plan, segs, y_olds, denses, meta, work, x, log)
    return _regula_falsi(ctx, t, q, v, a, ga, b, gb, qb, vb, kink, MAX_LOCATE_ITERATIONS)
