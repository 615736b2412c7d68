"""DOP853's internal steps up to an output time, in one compiled call: `DormandPrince853.step`'s loop.

`DormandPrince853.step` advances its internal solution (`while t < target: _advance()`) before it
answers from the dense output. Under a held torque that loop runs here: `closed_loop._advance` (the
kernel's `DormandPrince853._advance`: the attempt, error control and step-size update, the same
numbers) and the θ error estimate, each accepted step recorded as `DormandPrince853` keeps it in its
history (what an event's trial steps inside the step are answered from). Where a contact or an impact
shortens the internal step (tens of internal steps per 1 ms output around an onset), this is most of a
located event's cost in Python. A step of the Simulator's event loop (`crossings.step_to_crossing`) is
watched here too, on the gap plan (`gap_screen.crossed`): its internal steps stop one past the first whose
end shows a gap on its other side, as `DormandPrince853._watched`'s Python loop stops them.
"""

from __future__ import annotations

from math import inf

import numpy as np

from finger_sim.kernel import use_writable_cache

use_writable_cache()  # before numba reads NUMBA_CACHE_DIR
from numba import njit  # noqa: E402  (after the cache folder is set)

from finger_sim.integrators import dop853  # noqa: E402
from finger_sim.kernel.closed_loop import I_H, I_H_OLD, I_T, I_T_OLD, _advance  # noqa: E402
from finger_sim.kernel.gap_screen import crossed, gap_states  # noqa: E402
from finger_sim.kernel.numerics import JIT, dop853_theta_error  # noqa: E402

#: The scalars of `advance_to`'s st: closed_loop's t, next h, t_old, h_old (s), then the θ error
#: estimate at t and at t_old (rad: `DormandPrince853._err`, `_err_old`), then the watch's state (WATCH).
ERR, ERR_OLD, WATCH = 4, 5, 6
ST_SIZE = 7
#: The watch's states in st[WATCH] (`advance_to` with a gap plan): START, the step's start gaps not yet in work;
#: UNSEEN, no internal step has ended with a gap on its other side; SEEN, one has (the next one ends the pass);
#: STOPPED, the pass ended there, before its target.
START, UNSEEN, SEEN, STOPPED = 0.0, 1.0, 2.0, 3.0
#: `advance_to`'s gap plan and work when it does not watch (an empty plan).
NO_PLAN, NO_WORK = np.empty(0), np.empty((4, 0))
#: A history row: t_old, h_old (s), err_old, err (rad), y_old (6), then the dense output's 7 × 6.
ROW_T, ROW_H, ROW_ERR_OLD, ROW_ERR, ROW_Y_OLD, ROW_DENSE = 0, 1, 2, 3, 4, 10
ROW_SIZE = ROW_DENSE + 7 * 6
E53, E3_WEIGHT = dop853._E53, dop853.E3_WEIGHT


@njit(**JIT)
def bounded_step(m, rtol, atol, st, y, f, y_old, dense, kk, y_new, taus, prof, bound):
    """`closed_loop._advance` ending at `bound` (s) at the latest: `DormandPrince853._advance(torque, bound)`
    (scipy's t_bound, `DormandPrince853.cut_at`). False if it fails."""
    st[I_H] = min(st[I_H], bound - st[I_T])
    if not _advance(m, rtol, atol, st, y, f, y_old, dense, kk, y_new, taus, prof):
        return False
    if st[I_H_OLD] == bound - st[I_T_OLD]:
        st[I_T] = bound
    return True


@njit(**JIT)
def advance_to(m, rtol, atol, st, y, f, y_old, dense, kk, y_new, taus, prof, target, history, bounded, plan, work,
               start):
    """Accepted internal steps from st[T] until st[T] ≥ target (s), at most len(history) of them, under
    the held torque in taus (prof: `inputs.HELD_ARRAY`); m: the model; y, f, y_old, dense: the solution
    (in place); kk, y_new: the attempt's scratch. Row i of history gets the i-th step (ROW_* layout).
    `bounded`: the last step ends exactly at target (`bounded_step`).
    Watched where `plan` (a gap plan, `gap_screen`) is not empty, as `DormandPrince853._watched` watches: the
    steps stop one past the first that ends before target with a gap on the other side than at the step's
    `start` (q, q'; its gaps into work's rows 0 and 1 at START), where that one ends before target too (STOPPED);
    st[WATCH] carries the state from one call to the next.
    Returns the number of steps taken, or −(that number + 1) where the next one fails (st, y, f as
    after the steps taken: Python retries it and raises)."""
    watched = plan.shape[0] > 0
    if watched and st[WATCH] == START:
        gap_states(plan, (start[0], start[1], start[2], start[3], start[4], start[5]), work, 0)
        st[WATCH] = UNSEEN
    n = 0
    while st[I_T] < target and n < history.shape[0]:
        if not bounded_step(m, rtol, atol, st, y, f, y_old, dense, kk, y_new, taus, prof, target if bounded else inf):
            return -(n + 1)
        st[ERR_OLD] = st[ERR]
        st[ERR] += dop853_theta_error(E53, kk, st[I_H_OLD], E3_WEIGHT)
        row = history[n]
        row[ROW_T], row[ROW_H], row[ROW_ERR_OLD], row[ROW_ERR] = st[I_T_OLD], st[I_H_OLD], st[ERR_OLD], st[ERR]
        row[ROW_Y_OLD:ROW_DENSE] = y_old
        for i in range(7):
            row[ROW_DENSE + 6 * i:ROW_DENSE + 6 * i + 6] = dense[i]
        n += 1
        if watched and st[I_T] < target and (st[WATCH] == SEEN or crossed(plan, work, 0, y)):
            if st[WATCH] == SEEN:
                st[WATCH] = STOPPED
                return n
            st[WATCH] = SEEN
    return n


#: A step's record of its internal steps (`event_step.common_step`): the count, the branch the step took
#: (CONTINUED: the last output continued; RESTARTED; else none recorded), then HISTORY_ROWS rows (ROW_*).
COUNT, BRANCH, ROWS_AT = 0, 1, 2
CONTINUED, RESTARTED = 1.0, 2.0
HISTORY_ROWS = 64
HISTORY_SIZE = ROWS_AT + HISTORY_ROWS * ROW_SIZE


@njit(**JIT)
def record(log, st, y_old, dense):
    """Append the accepted internal step in st (T_OLD, H_OLD, ERR_OLD, ERR at `advance_to`'s indices)
    with y_old and dense to log (the layout above); a full log stops counting at HISTORY_ROWS + 1."""
    n = int(log[COUNT])
    if n < HISTORY_ROWS:
        o = ROWS_AT + n * ROW_SIZE
        log[o + ROW_T], log[o + ROW_H] = st[I_T_OLD], st[I_H_OLD]
        log[o + ROW_ERR_OLD], log[o + ROW_ERR] = st[ERR_OLD], st[ERR]
        log[o + ROW_Y_OLD:o + ROW_DENSE] = y_old
        for i in range(7):
            log[o + ROW_DENSE + 6 * i:o + ROW_DENSE + 6 * i + 6] = dense[i]
        log[COUNT] = n + 1
    else:
        log[COUNT] = HISTORY_ROWS + 1
