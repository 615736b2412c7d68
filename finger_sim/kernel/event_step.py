"""`Simulator.step`'s common step on a scene with events (stops, contact), in one compiled call.

On such a scene the Simulator steps with our DOP853 (`integrators.dop853.DormandPrince853`) and
checks every step's end for a gap crossing (`simulation.crossings`); nearly every step holds none.
`common_step` takes that step whole, on the same numbers: `DormandPrince853.step` under a torque
held over the step (its continuation and restart rules; `closed_loop._advance`'s internal steps,
i.e. the attempt, error control and step-size update; the θ error estimate; the projected dense
output) and the step-end gap check (`gap_screen.screen`). Where the step may hold a crossing, it
locates the contact onsets and releases in it and steps past them as `Simulator._advance` does
(`_settle`, `event_crossing.first_crossing`: SETTLED), or keeps the step for Python to locate (EVENT).
Where it needs what only Python does (an earlier internal step's output, a failure, an error estimate
it does not hold), it puts the solution back as it was and answers PYTHON: the Simulator takes that
step in Python, as always (`simulation.event_step`).

Everything the call reads and keeps is one float64 array (one argument: numba's dispatch costs
about 0.1 µs per argument), which `simulation.event_step` moves to and from the integrator's
attributes when Python steps:

    [n_model, n_plan, n_gaps, the model (the integrator's), the gap plan (`gap_screen`), st, arr, work,
     estimates, log]
    st: the scalars T … X below, the stage torques (N_NODES), a copy of the scalars, then the torque
        profile the PROFILE flag steps under (`inputs.profile_array`, zero-padded to PROFILE_SIZE), a
        held value's code (`inputs.HELD`), the count of steps `common_step` took (TAKEN) and of its
        estimate rows not yet read (ESTIMATE_COUNT);
    arr (ROWS × 6): y, f, y_old, dense (7 rows), the attempt's stages (16), y_new, then a copy of y, f,
        y_old and dense;
    work (4 × n_gaps): the gap screen's;
    estimates (ESTIMATE_ROWS × 4): q and the θ error estimate (rad) of each output `common_step` gave, oldest
        first, which `DormandPrince853.error_estimate` reads when asked (`simulation.event_step`);
    log: the last step's internal steps (`internal_steps.record`).
"""

from __future__ import annotations

from finger_sim.kernel import use_writable_cache

use_writable_cache()  # before numba reads NUMBA_CACHE_DIR
import numpy as np  # noqa: E402
from numba import njit  # noqa: E402  (after the cache folder is set)

from finger_sim.effects import stops  # noqa: E402
from finger_sim.integrators import dop853  # noqa: E402
from finger_sim.kernel.closed_loop import I_H, I_H_OLD, I_T, I_T_OLD, N_NODES, _advance  # noqa: E402
from finger_sim.kernel.gap_screen import crossed, gap_states, screen  # noqa: E402
from finger_sim.kernel.integrators import _entry_point  # noqa: E402
from finger_sim.kernel import internal_steps  # noqa: E402  (its layout, read by `simulation.event_handover`)
from finger_sim.kernel.internal_steps import (BRANCH, CONTINUED, COUNT, HISTORY_ROWS, HISTORY_SIZE,  # noqa: E402
                                              RESTARTED, ROW_DENSE, ROW_ERR, ROW_ERR_OLD, ROW_H, ROW_SIZE, ROW_T,
                                              ROW_Y_OLD, ROWS_AT, record)
from finger_sim.kernel import event_crossing  # noqa: E402
from finger_sim.kernel.event_checks import EVENT_TOLERANCE  # noqa: E402
from finger_sim.kernel.locate_event import _estimate  # noqa: E402
from finger_sim.kernel.numerics import (JIT, LAW, OK, _rhs, accelerations, dop853_output_rows,  # noqa: E402
                                        dop853_theta_error, torque_at)

#: `common_step`'s answer when Python must take the step.
PYTHON = 1
#: Its answer when the step may hold a gap crossing: the solution is kept advanced to the step's end, its
#: internal steps in the workspace's log (`internal_steps.record`), for Python to locate the crossing from.
EVENT = 2
#: The scalars of st: the internal step's (closed_loop's first four: t, next h, t_old, h_old, s), then
#: the θ error estimate at t and t_old (rad, `DormandPrince853._err`, `_err_old`); the last output
#: (HAS_LAST 1/0, its time, q, q' and its error estimate); the solution's origin (HAS_ORIGIN 1/0, t,
#: q, q'); the gap screen's kept end gaps (KNOWN 1/0, their rows SIDE); DOP853's tolerances; the
#: step's start (q, q') when the caller writes it (not the last output).
T, H, T_OLD, H_OLD = I_T, I_H, I_T_OLD, I_H_OLD
ERR, ERR_OLD, HAS_LAST, LAST_T, LAST_Q, LAST_V, LAST_EST = 4, 5, 6, 7, 8, 11, 14
HAS_ORIGIN, ORIGIN_T, ORIGIN_Q, ORIGIN_V, KNOWN, SIDE, RTOL, ATOL, X = 15, 16, 17, 20, 23, 24, 25, 26, 27
#: The output of a step a crossing ended (ENDED; HAS_END 1/0, its q and error estimate), which is not the last
#: output: a restart from it at the next step reads its estimate (`DormandPrince853.error_estimate`).
HAS_END, END_Q, END_EST = 33, 34, 37
#: The stops' restitution e (set by `simulation.event_step`); the impacts the kernel applied (a counter the
#: Simulator reads and clears: `Simulator.impacts`); the position of the gap the last RESTED step rests on.
RESTITUTION, IMPACTS, REST_GAP = 38, 39, 40
#: The end (s) of the internal step a watched pass stopped at (`_advance_to`: past a gap's other side), else −inf.
HIT = 41
N_SCALARS = 42
TAUS = N_SCALARS
SAVED = TAUS + N_NODES
#: The profile's slot (code and up to three parameters), then the held value's code.
PROFILE_AT, PROFILE_SIZE = SAVED + N_SCALARS, 4
HELD_AT = PROFILE_AT + PROFILE_SIZE
#: Steps `common_step` took (its answers but PYTHON and EVENT), and its estimate rows not yet read.
TAKEN, ESTIMATE_COUNT = HELD_AT + 1, HELD_AT + 2
ST_SIZE = HELD_AT + 3
#: The estimate rows (q, estimate): as many outputs as `common_step` records before they are read. When they are
#: full it adds FULL to its status, and the caller reads them before the next call.
ESTIMATE_ROWS, ESTIMATE_WIDTH = 512, 4
ESTIMATES_SIZE = ESTIMATE_ROWS * ESTIMATE_WIDTH
FULL = 16
#: The rows of arr.
Y, F, Y_OLD, DENSE, KK, Y_NEW = 0, 1, 2, 3, 10, 26
KEPT = KK  # y, f, y_old and dense: what a step changes of the solution
ROWS = Y_NEW + 1 + KEPT
#: The workspace's header: the lengths of the model, the gap plan and the number of gaps.
HEADER = 3
#: Its answer when the step held gap crossings (contact onsets, releases) that it located and stepped past
#: itself (`_settle`): the state at t1, as OK.
SETTLED = 3
#: Its answer when a located crossing ends the step (`Simulator._advance`): its state is the output, and the
#: solution's last output is the location's last trial (the next step starts off it: not AT_LAST).
ENDED = 4
#: Its answer when a stop's impact starts the rest on it (`simulation.impact.impact`) and the rest holds to the
#: step's end (`stays_at_rest`): the state at the impact with q' = 0, its gap's position in st[REST_GAP], the
#: solution's last output set as after ENDED. The Simulator enters the rest mode.
RESTED = 5
#: `common_step`'s flags: the solution is under this command's torque function; the step starts at
#: the last output (else at st[X:X + 6]); the torque is the profile in st (else the held command); a
#: crossing may be located here (Python's step would integrate under the same function: `_settle`).
SAME, AT_LAST, PROFILE, LOCATE = 1, 2, 4, 8
#: Events allowed in one step (`driver.MAX_EVENTS_PER_STEP`): more, and Python takes the step (and raises).
MAX_EVENTS_PER_STEP = 64
#: A rest on a stop is kept here only when the push into it (rad/s²) exceeds this share of the free
#: acceleration (at least 1 rad/s²) at both ends of the step: the compiled acceleration agrees with the
#: Python one the Simulator decides on (`JointStops.release_time`) to round-off, far inside this margin.
REST_MARGIN = 1e-9
#: A continuation matches the last output's time within this fraction of a step (`DormandPrince853.step`).
LAST_OUTPUT_SLACK = 1e-9
E53, E3_WEIGHT = dop853._E53, dop853.E3_WEIGHT
#: DOP853's first internal step (`DormandPrince853._restart`), its one plain function compiled.
initial_step = njit(**JIT)(dop853.initial_step)
#: `_impact`'s verdicts: `stops.rest_verdict`'s, whose one plain function is compiled.
BOUNCES, RESTS, UNSURE = stops.BOUNCES, stops.RESTS, stops.UNSURE
rest_verdict = njit(**JIT)(stops.rest_verdict)
#: `_cut_at`'s answers.
CUT_NONE, CUT, CUT_FAILED = 0, 1, 2
#: Whether an internal step straddles a located kink (`DormandPrince853.cut_at`), its one plain function compiled.
straddles = njit(**JIT)(dop853.straddles)
#: The next internal step after a cut at a kink (`DormandPrince853.cut_at`), its one plain function compiled.
restart_step = njit(**JIT)(dop853.restart_step)


def workspace_size(n_model: int, n_plan: int, n_gaps: int) -> int:
    """The length of a workspace (module docstring)."""
    return HEADER + n_model + n_plan + ST_SIZE + ROWS * 6 + 4 * n_gaps + ESTIMATES_SIZE + HISTORY_SIZE


@njit(**LAW)
def log_of(ws):
    """The workspace's log of the last step's internal steps (`internal_steps.record`): its last part."""
    return ws[ws.shape[0] - HISTORY_SIZE:]


def entry_point(ws):  # type: ignore[no-untyped-def]
    """`common_step`'s compiled entry for a workspace like ws and the Simulator's argument types (floats,
    an int), loaded (or compiled) now: it skips numba's type dispatch, as the lean path's `FastStepper.call`."""
    args = (ws.copy(), 0, 1e-3, 0.0, 0)
    common_step(*args)  # no last output: answers PYTHON at once
    return _entry_point(common_step, args)


@njit(**LAW)
def parts(ws):
    """The workspace's views: (model, gap plan, st, arr, work); sliced once per call of a caller that steps many
    times (`event_run.run`), passed whole to the step with row indices (a view made per step costs reference
    counting: numba's atomic increments and decrements)."""
    nm, npl, ng = int(ws[0]), int(ws[1]), int(ws[2])
    o = HEADER
    m = ws[o:o + nm]
    o += nm
    plan = ws[o:o + npl]
    o += npl
    st = ws[o:o + ST_SIZE]
    o += ST_SIZE
    arr = ws[o:o + ROWS * 6].reshape((ROWS, 6))
    o += ROWS * 6
    return m, plan, st, arr, ws[o:o + 4 * ng].reshape((4, ng))


@njit(**JIT)
def common_step(ws, k, dt, command, flags):
    """Step k, from t = k·dt to t1 = (k + 1)·dt (s), under the held `command` (N·m) or, with flag PROFILE, st's
    smooth profile, as `Simulator.step` takes a step with no gap crossing, on the workspace ws (module
    docstring); flags: SAME, AT_LAST, PROFILE, LOCATE (or'ed). Returns (status, q1, q1', τ at t1 in N·m): OK
    (SETTLED, ENDED, RESTED); or PYTHON with ws as it was, or EVENT. A step taken (not PYTHON, not EVENT) is counted in
    st[TAKEN] and its output's θ error estimate (rad) appended to the estimate rows with q1; the status has
    FULL added when that fills them (the caller reads them, `ESTIMATE_COUNT` back to 0, before the next call)."""
    m, plan, st, arr, work = parts(ws)
    status, q1, v1, estimate, end = step_on(m, plan, st, arr, work, log_of(ws), profile_of(st, flags), k * dt,
                                            (k + 1) * dt, command, flags)
    if status == PYTHON or status == EVENT:
        return status, q1, v1, end
    st[TAKEN] += 1.0
    n = int(st[ESTIMATE_COUNT])
    o = ws.shape[0] - HISTORY_SIZE - ESTIMATES_SIZE + ESTIMATE_WIDTH * n  # (indices: no view made per step)
    ws[o], ws[o + 1], ws[o + 2], ws[o + 3] = q1[0], q1[1], q1[2], estimate
    st[ESTIMATE_COUNT] = n + 1
    return (status + FULL if n + 1 == ESTIMATE_ROWS else status), q1, v1, end


@njit(**LAW)
def profile_of(st, flags):
    """The torque the step runs under, as `torque_at` reads it: st's profile with flag PROFILE, else the held
    value's code."""
    return st[PROFILE_AT:PROFILE_AT + PROFILE_SIZE] if flags & PROFILE else st[HELD_AT:HELD_AT + 1]


@njit(**JIT)
def step_on(m, plan, st, arr, work, log, prof, t, t1, command, flags):
    """`common_step` on the workspace's `parts`, `log_of` and `profile_of` (for flags' PROFILE), sliced once by a
    caller that steps many times (`event_run.run`)."""
    for i in range(N_SCALARS):  # (element by element: a slice is a view)
        st[SAVED + i] = st[i]
    for r in range(KEPT):
        for c in range(6):
            arr[ROWS - KEPT + r, c] = arr[r, c]
    o = LAST_Q if flags & AT_LAST else X
    q, v = (st[o], st[o + 1], st[o + 2]), (st[o + 3], st[o + 4], st[o + 5])
    status, q1, v1, estimate = _step(m, plan, st, arr, work, t, t1, command, prof, (flags & SAME) != 0,
                                     (flags & LOCATE) != 0, q, v, log)
    if status == PYTHON:
        restore_views(st, arr)
    return status, q1, v1, estimate, torque_at(prof, command, t1)


@njit(**JIT)
def restore(ws):
    """The solution in ws as it was before the last `common_step`."""
    _, _, st, arr, _ = parts(ws)
    restore_views(st, arr)


@njit(**JIT)
def restore_views(st, arr):
    """`restore` on the workspace's st and arr (`parts`)."""
    for i in range(N_SCALARS):
        st[i] = st[SAVED + i]
    for r in range(KEPT):
        for c in range(6):
            arr[r, c] = arr[ROWS - KEPT + r, c]


@njit(**JIT)
def _is(st, o, q, v):
    """Whether st[o:o + 6] holds (q, q') exactly."""
    return (st[o] == q[0] and st[o + 1] == q[1] and st[o + 2] == q[2] and st[o + 3] == v[0] and st[o + 4] == v[1]
            and st[o + 5] == v[2])


@njit(**JIT)
def _put(st, o, q, v):
    st[o], st[o + 1], st[o + 2], st[o + 3], st[o + 4], st[o + 5] = q[0], q[1], q[2], v[0], v[1], v[2]


@njit(**JIT)
def _step(m, plan, st, arr, work, t, t1, command, prof, same, locate, q, v, log):
    """`common_step` without the restore; its internal steps recorded in log; with `locate`, the crossings
    the step may hold are located here (`_settle`)."""
    h = t1 - t
    target = t + h
    log[COUNT], log[BRANCH] = 0.0, 0.0
    st[HIT] = -np.inf
    ended = st[HAS_END] == 1.0 and st[END_Q] == q[0] and st[END_Q + 1] == q[1] and st[END_Q + 2] == q[2]
    st[HAS_END] = 0.0
    if same and st[HAS_ORIGIN] == 1.0 and st[ORIGIN_T] == t and _is(st, ORIGIN_Q, q, v) and target >= t:
        pass  # a step from the solution's start: answered from it
    elif same and st[HAS_LAST] == 1.0 and _is(st, LAST_Q, q, v) and abs(st[LAST_T] - t) <= LAST_OUTPUT_SLACK * h \
            and target >= st[T_OLD]:
        st[HAS_ORIGIN], st[ORIGIN_T] = 1.0, t  # continuing the last output
        _put(st, ORIGIN_Q, q, v)
        log[BRANCH] = CONTINUED
    else:  # `DormandPrince853._restart`, from the last output's q (whose error estimate is kept)
        if ended:  # the output of a step a crossing ended (its estimate the newest at q)
            st[ERR] = st[ERR_OLD] = st[END_EST]
        elif st[HAS_LAST] == 1.0 and st[LAST_Q] == q[0] and st[LAST_Q + 1] == q[1] and st[LAST_Q + 2] == q[2]:
            st[ERR] = st[ERR_OLD] = st[LAST_EST]
        elif st[HAS_LAST] == 0.0 and st[HAS_ORIGIN] == 0.0 and st[H] <= 0.0:
            st[ERR] = st[ERR_OLD] = 0.0  # a new solution's first step (`simulation.event_step`: no estimates yet)
        else:
            return PYTHON, q, v, 0.0
        _restart(m, st, arr, t, q, v, torque_at(prof, command, t), h)
        st[HAS_ORIGIN], st[ORIGIN_T] = 1.0, t
        _put(st, ORIGIN_Q, q, v)
        log[BRANCH] = RESTARTED
    for c in range(N_NODES):
        st[TAUS + c] = command  # a held command's (a profile's are set by each attempt)
    side = int(st[SIDE])
    if st[KNOWN] != 1.0:  # the start's gaps: the watch's sides (`crossings.step_to_crossing`) and the screen's start
        gap_states(plan, (q[0], q[1], q[2], v[0], v[1], v[2]), work, side)
    # (most common steps take no internal step: the call, whose array arguments cost reference counts, is skipped)
    if st[T] < target and not _advance_to(m, st, arr, log, prof, target, plan, work, side):
        return PYTHON, q, v, 0.0
    stopped = st[HIT] > -np.inf  # past an internal step's end that showed a gap on its other side
    out_t, end = (st[HIT], st[HIT]) if stopped else (target, t1)
    t_old, h_old = st[T_OLD], st[H_OLD]
    if out_t < t_old:  # an earlier internal step's output: the history is Python's
        return PYTHON, q, v, 0.0
    status, q1, v1 = dop853_output_rows(m, t_old, h_old, arr, Y_OLD, DENSE, out_t)
    if status != OK:
        return PYTHON, q, v, 0.0
    status = OK
    if screen(plan, work, side, True, end - t if stopped else h, q, v, q1, v1):
        # a crossing may lie inside: kept for Python when the log holds the step's whole history
        if log[BRANCH] == 0.0 or log[COUNT] > HISTORY_ROWS:
            return PYTHON, q, v, 0.0
        if not locate:
            return EVENT, q, v, 0.0
        status, q1, v1, target, estimate = _settle(m, plan, st, arr, work, side, t, t1, end, out_t, command, prof, q,
                                                   v, q1, v1, log)
        if status == ENDED or status == RESTED:
            return status, q1, v1, estimate
        if status != SETTLED and status != OK:
            return status, q, v, 0.0
    elif stopped:  # a side the screen does not confirm: Python steps on from the stop
        return PYTHON, q, v, 0.0
    else:
        st[KNOWN], st[SIDE] = 1.0, 2 - side
    # `DormandPrince853._remember`: the estimate interpolated over the internal step that covers the output
    estimate = _estimate(target, st[T_OLD], st[H_OLD], st[ERR_OLD], st[ERR])
    st[HAS_LAST], st[LAST_T], st[LAST_EST] = 1.0, target, estimate
    _put(st, LAST_Q, q1, v1)
    return status, q1, v1, estimate


@njit(**JIT)
def _restart(m, st, arr, t, q, v, tau, span):
    """`DormandPrince853._restart`'s solution at (t, q, q') under τ (N·m) at t: y, f = y'(t), the internal
    time; the first internal step (`initial_step` over `span`, s) where none is proposed yet."""
    y, f = arr[Y], arr[F]
    st[T] = st[T_OLD] = t
    y[0], y[1], y[2], y[3], y[4], y[5] = q[0], q[1], q[2], v[0], v[1], v[2]
    _rhs(m, t, y, tau, f)
    if st[H] <= 0.0:
        st[H] = initial_step(y, f, st[RTOL], st[ATOL], span)


@njit(**JIT)
def _advance_to(m, st, arr, log, prof, target, plan, work, side):
    """`DormandPrince853.step`'s internal steps until st[T] ≥ target (s) (`closed_loop._advance`), each with its
    θ error estimate and recorded in log, watched as `crossings.step_to_crossing` watches them: they stop one step
    past the first one ending before target with a gap on the other side than in work's start rows `side`
    (`gap_screen.crossed`), its end time in st[HIT], where that one ends before target too. False where one fails.
    The rows are sliced only when a step is due."""
    if not st[T] < target:
        return True
    y, f, y_old, dense, kk, y_new = arr[Y], arr[F], arr[Y_OLD], arr[DENSE:KK], arr[KK:Y_NEW], arr[Y_NEW]
    taus = st[TAUS:SAVED]
    seen = False
    while st[T] < target:
        if not _advance(m, st[RTOL], st[ATOL], st, y, f, y_old, dense, kk, y_new, taus, prof):
            return False
        st[ERR_OLD] = st[ERR]
        st[ERR] += dop853_theta_error(E53, kk, st[H_OLD], E3_WEIGHT)
        record(log, st, y_old, dense)
        if st[T] < target and (seen or crossed(plan, work, side, y)):
            if seen:
                st[HIT] = st[T]
                return True
            seen = True
    return True


@njit(**JIT)
def _settle(m, plan, st, arr, work, side, t, t1, end, out_t, command, prof, q, v, q1, v1, log):
    """`Simulator._advance`'s event loop for a step whose screen (start rows `side`) shows a possible
    crossing, the solution advanced to t1 with its internal steps in log: each crossing located
    (`event_crossing.first_crossing`; a kink's straddling internal step retaken to end there, `_cut_at`), the
    internal solution continued or restarted from it as
    `DormandPrince853.step` does (its internal steps logged for the next location), the rest of the step
    checked again. Returns (SETTLED, q1, q1', …) with the solution and its last output's origin set (OK: no
    crossing found; ENDED: the crossing ends the step, its state and estimate returned, the last output set);
    EVENT (nothing changed: Python locates from the log) or PYTHON (the solution
    moved: Python takes the step again) where Python must act (`first_crossing`'s DECLINE, a step that fails).
    The last two: the output's time (`DormandPrince853.step`'s target s + (t1 − s) from the last crossing s),
    and with ENDED the error estimate at the output (rad). A watched pass that stopped before t1 (`_advance_to`)
    is searched up to its stop: end (s), the segment's end `first_crossing` brackets to (t1 or the stop), and
    out_t, the output's time (the target or the stop)."""
    found = np.empty(event_crossing.OUT_SIZE)
    st[SAVED + KNOWN] = 0.0  # the screen's rows change here: a restored step computes its start's gaps again
    s, target = t, t + (t1 - t)
    for event in range(MAX_EVENTS_PER_STEP + 1):
        est1 = _estimate(out_t, st[T_OLD], st[H_OLD], st[ERR_OLD], st[ERR])
        segs, y_olds, denses = _history(st, arr, log)
        code, gap = event_crossing.first_crossing(m, plan, work, side, s, q, v, end, q1, v1, est1, segs, y_olds,
                                                denses, st[T], found)
        if code == event_crossing.NONE:
            if out_t < target:  # stopped where the screen saw a crossing that is none: Python steps on
                return PYTHON, q1, v1, target, 0.0
            st[KNOWN] = 0.0
            return (OK if event == 0 else SETTLED), q1, v1, target, 0.0
        if code == event_crossing.DECLINE or event == MAX_EVENTS_PER_STEP:  # Python acts
            return (EVENT if event == 0 else PYTHON), q1, v1, target, 0.0
        s = found[event_crossing.OUT_S]
        q = (found[event_crossing.OUT_Q], found[event_crossing.OUT_Q + 1], found[event_crossing.OUT_Q + 2])
        v = (found[event_crossing.OUT_V], found[event_crossing.OUT_V + 1], found[event_crossing.OUT_V + 2])
        lq = found[event_crossing.OUT_LAST_Q:event_crossing.OUT_LAST_V]
        lv = found[event_crossing.OUT_LAST_V:event_crossing.OUT_LAST_V + 3]
        rests = False
        if code == event_crossing.IMPACT:  # no cut (`crossings.first_crossing`: the impact restarts the solution)
            sign = plan[plan.shape[0] - int(plan[0]) + gap]
            verdict, v = _impact(m, st, s, t1, command, prof, sign, q, v)
            if verdict == UNSURE:  # near the rest test's edge: Python decides on its own acceleration
                return (EVENT if event == 0 else PYTHON), q1, v1, target, 0.0
            st[IMPACTS] += 1.0
            rests = verdict == RESTS
            if rests:
                st[REST_GAP] = gap
        else:
            onset = not work[side, gap] < -EVENT_TOLERANCE  # open at the start: the contact closes
            cut = _cut_at(m, st, arr, log, s, command, prof, found, onset)
            if cut == CUT_FAILED:
                return PYTHON, q1, v1, target, 0.0
            q = (found[event_crossing.OUT_Q], found[event_crossing.OUT_Q + 1], found[event_crossing.OUT_Q + 2])
            v = (found[event_crossing.OUT_V], found[event_crossing.OUT_V + 1], found[event_crossing.OUT_V + 2])
        if s >= t1 or rests:  # the crossing ends the step: its state the output, the last trial (else the end) the last output
            if found[event_crossing.OUT_HAS_LAST] == 1.0:
                st[LAST_T], st[LAST_EST] = found[event_crossing.OUT_LAST_T], found[event_crossing.OUT_LAST_EST]
                _put(st, LAST_Q, (lq[0], lq[1], lq[2]), (lv[0], lv[1], lv[2]))
            else:
                st[LAST_T], st[LAST_EST] = out_t, est1
                _put(st, LAST_Q, q1, v1)
            st[HAS_LAST], st[KNOWN] = 1.0, 0.0
            st[HAS_END], st[END_EST] = 1.0, found[event_crossing.OUT_EST]
            st[END_Q], st[END_Q + 1], st[END_Q + 2] = q[0], q[1], q[2]
            return (RESTED if rests else ENDED), q, v, target, found[event_crossing.OUT_EST]
        st[HAS_ORIGIN], st[ORIGIN_T] = 1.0, s
        _put(st, ORIGIN_Q, q, v)
        target = s + (t1 - s)  # `DormandPrince853.step`'s from the crossing
        gap_states(plan, (q[0], q[1], q[2], v[0], v[1], v[2]), work, side)  # the watch's start: the crossing's
        if not (found[event_crossing.OUT_HAS_LAST] == 1.0 and lq[0] == q[0] and lq[1] == q[1] and lq[2] == q[2]
                and lv[0] == v[0] and lv[1] == v[1] and lv[2] == v[2]
                and abs(found[event_crossing.OUT_LAST_T] - s) <= LAST_OUTPUT_SLACK * (t1 - s) and target >= st[T_OLD]):
            # `DormandPrince853._restart` from the crossing (the next step size kept), its steps logged anew
            st[ERR] = st[ERR_OLD] = found[event_crossing.OUT_EST]
            _restart(m, st, arr, s, q, v, torque_at(prof, command, s), t1 - s)
            log[COUNT], log[BRANCH] = 0.0, RESTARTED
        st[HIT] = -np.inf
        if not _advance_to(m, st, arr, log, prof, target, plan, work, side):  # (continued or restarted)
            return PYTHON, q1, v1, target, 0.0
        if log[COUNT] > HISTORY_ROWS:
            return PYTHON, q1, v1, target, 0.0
        stopped = st[HIT] > -np.inf
        out_t, end = (st[HIT], st[HIT]) if stopped else (target, t1)
        if out_t < st[T_OLD]:  # an earlier internal step's output: the history is Python's
            return PYTHON, q1, v1, target, 0.0
        status, q1, v1 = dop853_output_rows(m, st[T_OLD], st[H_OLD], arr, Y_OLD, DENSE, out_t)
        if status != OK:
            return PYTHON, q1, v1, target, 0.0
        if not screen(plan, work, side, True, end - s, q, v, q1, v1):
            if stopped:  # a side the screen does not confirm: Python steps on from the stop
                return PYTHON, q1, v1, target, 0.0
            st[KNOWN], st[SIDE] = 1.0, 2 - side
            return SETTLED, q1, v1, target, 0.0
    return PYTHON, q1, v1, target, 0.0  # (not reached: the last round returns)


@njit(**JIT)
def _impact(m, st, s, t1, command, prof, sign, q, v):
    """`simulation.impact.impact` at the located impact (s, q, q') on a stop gap whose gradient's θ1 component is
    `sign`, in the step to t1 (s): (verdict, q' after it). RESTS: the rebound −e q' rises no higher than
    `stops.REST_HEIGHT` against the free acceleration (`JointStops.rests`) and the rest holds to t1
    (`JointStops.release_time` finds none): q' = 0; BOUNCES: q' = −e q'; UNSURE: the compiled acceleration is
    within REST_MARGIN of either test's edge (the Simulator decides on its own)."""
    e = st[RESTITUTION]
    v_plus = (-e * v[0], -e * v[1], -e * v[2])
    a = accelerations(m, s, q[0], q[1], q[2], 0.0, 0.0, 0.0, torque_at(prof, command, s))[0]  # θ1'' at rest
    verdict = rest_verdict(sign * a, sign * v_plus[0], REST_MARGIN * max(1.0, abs(a)))
    if verdict == BOUNCES:  # either test fails beyond the round-off
        return BOUNCES, v_plus
    if verdict == UNSURE:
        return UNSURE, v
    if not pushes_at(m, prof, t1, command, sign, q[0], q[1], q[2])[0]:  # the push into the stop at t1 keeps the rest
        return UNSURE, v
    return RESTS, (0.0, 0.0, 0.0)


@njit(**JIT)
def _cut_at(m, st, arr, log, s, command, prof, found, onset):
    """`DormandPrince853.cut_at` for the kink `event_crossing.first_crossing` located at s (s) (an `onset`: the
    gap open at the step's start): the logged internal step that straddles it (`dop853.straddles`) and those
    after it dropped, the solution retaken from that step's start with internal steps ending exactly at s, its
    output there put in found as the crossing and the last trial (OUT_*), the next step the one
    `dop853.restart_step` chooses (the caller continues from there). Returns CUT_NONE (no step straddles s: nothing
    changed), CUT (done) or CUT_FAILED (an internal step failed: Python retakes). A straddling step that covered a
    continued step's start (taken for the output before) is retaken from its copy of before the step; the log then
    holds the whole history from its start (its branch RESTARTED: no such step before it, `_history`)."""
    n, pre = int(log[COUNT]), 1 if log[BRANCH] == CONTINUED else 0
    j = n - 1
    while j >= 0 and not log[ROWS_AT + j * ROW_SIZE + ROW_T] < s:
        j -= 1
    if j >= 0:
        o = ROWS_AT + j * ROW_SIZE
        t_old, h_old, err_old, start = log[o + ROW_T], log[o + ROW_H], log[o + ROW_ERR_OLD], log[o + ROW_Y_OLD:o + ROW_DENSE]
    elif pre and st[SAVED + T_OLD] < s:
        t_old, h_old, err_old, start = st[SAVED + T_OLD], st[SAVED + H_OLD], st[SAVED + ERR_OLD], arr[ROWS - KEPT + Y_OLD]
    else:
        return CUT_NONE
    if not straddles(s, t_old, h_old):
        return CUT_NONE
    y, f, y_old, dense, kk, y_new = arr[Y], arr[F], arr[Y_OLD], arr[DENSE:KK], arr[KK:Y_NEW], arr[Y_NEW]
    taus = st[TAUS:SAVED]
    past = log[ROWS_AT + (j + 1) * ROW_SIZE + ROW_H] if j + 1 < n else h_old
    proposed = st[H]
    st[T], st[H], st[ERR] = t_old, h_old, err_old
    y[:] = start
    if j >= 0:
        log[COUNT] = j
    else:
        log[COUNT], log[BRANCH] = 0.0, RESTARTED
    _rhs(m, t_old, y, torque_at(prof, command, t_old), f)
    while st[T] < s:
        if not internal_steps.bounded_step(m, st[RTOL], st[ATOL], st, y, f, y_old, dense, kk, y_new, taus, prof, s):
            return CUT_FAILED
        st[ERR_OLD] = st[ERR]
        st[ERR] += dop853_theta_error(E53, kk, st[H_OLD], E3_WEIGHT)
        record(log, st, y_old, dense)
    st[H] = restart_step(onset, past, st[H], proposed)
    status, q, v = dop853_output_rows(m, st[T_OLD], st[H_OLD], arr, Y_OLD, DENSE, s)
    if status != OK:
        return CUT_FAILED
    estimate = _estimate(s, st[T_OLD], st[H_OLD], st[ERR_OLD], st[ERR])
    found[event_crossing.OUT_Q:event_crossing.OUT_Q + 3], found[event_crossing.OUT_V:event_crossing.OUT_V + 3] = q, v
    found[event_crossing.OUT_LAST_Q:event_crossing.OUT_LAST_Q + 3] = q
    found[event_crossing.OUT_LAST_V:event_crossing.OUT_LAST_V + 3] = v
    found[event_crossing.OUT_EST] = found[event_crossing.OUT_LAST_EST] = estimate
    found[event_crossing.OUT_HAS_LAST], found[event_crossing.OUT_LAST_T] = 1.0, s
    return CUT


@njit(**JIT)
def _history(st, arr, log):
    """The internal steps a trial from the solution's origin is answered from, in `locate_event`'s layout
    (segs, y_olds, denses): the one that covered the start of a continued step (its copy from before the
    step), the logged ones, then the current one (`event_handover.hand_over`'s history, and the integrator's
    current step)."""
    n = int(log[COUNT])
    pre = 1 if log[BRANCH] == CONTINUED else 0
    rows = pre + n + 1
    segs, y_olds, denses = np.empty((rows, 4)), np.empty((rows, 6)), np.empty((rows, 7, 6))
    if pre:
        o = SAVED
        segs[0, 0], segs[0, 1], segs[0, 2], segs[0, 3] = st[o + T_OLD], st[o + H_OLD], st[o + ERR_OLD], st[o + ERR]
        y_olds[0] = arr[ROWS - KEPT + Y_OLD]
        denses[0] = arr[ROWS - KEPT + DENSE:ROWS - KEPT + KK]
    for i in range(n):
        row = log[ROWS_AT + i * ROW_SIZE:ROWS_AT + (i + 1) * ROW_SIZE]
        j = pre + i
        segs[j, 0], segs[j, 1], segs[j, 2], segs[j, 3] = row[ROW_T], row[ROW_H], row[ROW_ERR_OLD], row[ROW_ERR]
        y_olds[j] = row[ROW_Y_OLD:ROW_DENSE]
        for k in range(7):
            denses[j, k] = row[ROW_DENSE + 6 * k:ROW_DENSE + 6 * k + 6]
    c = rows - 1
    segs[c, 0], segs[c, 1], segs[c, 2], segs[c, 3] = st[T_OLD], st[H_OLD], st[ERR_OLD], st[ERR]
    y_olds[c] = arr[Y_OLD]
    denses[c] = arr[DENSE:KK]
    return segs, y_olds, denses


@njit(**JIT)
def stays_at_rest(ws, t, t1, command, flags, sign, q0, q1, q2):
    """Whether the finger resting on a stop at q (q' = 0) stays there over [t, t1] (s) under the held
    `command` (N·m) or, with flag PROFILE, st's profile, as `JointStops.release_time` decides it (the push
    −sign·θ1'' into the gap > 0 at t and at t1; sign: the gap gradient's θ1 component), with REST_MARGIN to
    spare (else False: the Simulator decides). Returns (stays, τ at t1 in N·m)."""
    m, _, st, _, _ = parts(ws)
    prof = profile_of(st, flags)
    if not pushes_at(m, prof, t, command, sign, q0, q1, q2)[0]:
        return False, 0.0
    stays, tau = pushes_at(m, prof, t1, command, sign, q0, q1, q2)
    return (True, tau) if stays else (False, 0.0)


@njit(**JIT)
def pushes_at(m, prof, s, command, sign, q0, q1, q2):
    """`stays_at_rest`'s test at one time s (s) on the model m under the torque `profile_of` selects: (whether
    the push into the stop at rest at q exceeds REST_MARGIN, τ at s in N·m)."""
    tau = torque_at(prof, command, s)
    a = accelerations(m, s, q0, q1, q2, 0.0, 0.0, 0.0, tau)[0]  # θ1''
    return -sign * a > REST_MARGIN * max(1.0, abs(a)), tau
