"""`Simulator.step`'s common step on a scene with events (stops, contact), in one compiled call.

On such a scene the Simulator steps with our DOP853 (`integrators.dop853.DormandPrince853`) and
checks every step's end for a gap crossing (`simulation.crossings`); nearly every step holds none.
`common_step` takes that step whole, on the same numbers: `DormandPrince853.step` under a torque
held over the step (its continuation and restart rules; `closed_loop._advance`'s internal steps,
i.e. the attempt, error control and step-size update; the θ error estimate; the projected dense
output) and the step-end gap check (`gap_screen.screen`). Where the step may hold a crossing, or
needs what only Python does (an earlier internal step's output, a failure, an error estimate it
does not hold), it puts the solution back as it was and answers
PYTHON: the Simulator takes that step in Python, as always (`simulation.event_step`).

Everything the call reads and keeps is one float64 array (one argument: numba's dispatch costs
about 0.1 µs per argument), which `simulation.event_step` moves to and from the integrator's
attributes when Python steps:

    [n_model, n_plan, n_gaps, the model (the integrator's), the gap plan (`gap_screen`), st, arr, work]
    st: the scalars T … X below, the stage torques (N_NODES), a copy of the scalars, then the torque
        profile the PROFILE flag steps under (`inputs.profile_array`, zero-padded to PROFILE_SIZE) and
        a held value's code (`inputs.HELD`);
    arr (ROWS × 6): y, f, y_old, dense (7 rows), the attempt's stages (16), y_new, out, then a
        copy of y, f, y_old and dense;
    work (4 × n_gaps): the gap screen's.
"""

from __future__ import annotations

from finger_sim.kernel import use_writable_cache

use_writable_cache()  # before numba reads NUMBA_CACHE_DIR
from numba import njit  # noqa: E402  (after the cache folder is set)

from finger_sim.integrators import dop853  # noqa: E402
from finger_sim.kernel.closed_loop import I_H, I_H_OLD, I_T, I_T_OLD, N_NODES, _advance  # noqa: E402
from finger_sim.kernel.gap_screen import screen  # noqa: E402
from finger_sim.kernel.integrators import _entry_point  # noqa: E402
from finger_sim.kernel import internal_steps  # noqa: E402  (its layout, read by `simulation.event_handover`)
from finger_sim.kernel.internal_steps import BRANCH, CONTINUED, COUNT, HISTORY_ROWS, HISTORY_SIZE, RESTARTED, record  # noqa: E402
from finger_sim.kernel.numerics import JIT, OK, _rhs, dop853_output, dop853_theta_error, torque_at  # noqa: E402

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
N_SCALARS = 33
TAUS = N_SCALARS
SAVED = TAUS + N_NODES
#: The profile's slot (code and up to three parameters), then the held value's code.
PROFILE_AT, PROFILE_SIZE = SAVED + N_SCALARS, 4
HELD_AT = PROFILE_AT + PROFILE_SIZE
ST_SIZE = HELD_AT + 1
#: The rows of arr.
Y, F, Y_OLD, DENSE, KK, Y_NEW, OUT = 0, 1, 2, 3, 10, 26, 27
KEPT = KK  # y, f, y_old and dense: what a step changes of the solution
ROWS = OUT + 1 + KEPT
#: The workspace's header: the lengths of the model, the gap plan and the number of gaps.
HEADER = 3
#: `common_step`'s flags: the solution is under this command's torque function; the step starts at
#: the last output (else at st[X:X + 6]); the torque is the profile in st (else the held command).
SAME, AT_LAST, PROFILE = 1, 2, 4
#: A rest on a stop is kept here only when the push into it (rad/s²) exceeds this share of the free
#: acceleration (at least 1 rad/s²) at both ends of the step: the compiled acceleration agrees with the
#: Python one the Simulator decides on (`JointStops.release_time`) to round-off, far inside this margin.
REST_MARGIN = 1e-9
#: A continuation matches the last output's time within this fraction of a step (`DormandPrince853.step`).
LAST_OUTPUT_SLACK = 1e-9
E53, E3_WEIGHT = dop853._E53, dop853.E3_WEIGHT
#: DOP853's first internal step (`DormandPrince853._restart`), its one plain function compiled.
initial_step = njit(**JIT)(dop853.initial_step)


def workspace_size(n_model: int, n_plan: int, n_gaps: int) -> int:
    """The length of a workspace (module docstring)."""
    return HEADER + n_model + n_plan + ST_SIZE + ROWS * 6 + 4 * n_gaps + HISTORY_SIZE


@njit(**JIT)
def log_of(ws):
    """The workspace's log of the last step's internal steps (`internal_steps.record`): its last part."""
    return ws[ws.shape[0] - HISTORY_SIZE:]


def entry_point(ws):  # type: ignore[no-untyped-def]
    """`common_step`'s compiled entry for a workspace like ws and the Simulator's argument types (floats,
    an int), loaded (or compiled) now: it skips numba's type dispatch, as the lean path's `FastStepper.call`."""
    args = (ws.copy(), 0.0, 1e-3, 0.0, 0)
    common_step(*args)  # no last output: answers PYTHON at once
    return _entry_point(common_step, args)


@njit(**JIT)
def parts(ws):
    """The workspace's views: (model, gap plan, st, arr, work)."""
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
def common_step(ws, t, t1, command, flags):
    """The step from t to t1 (s) under the held `command` (N·m) or, with flag PROFILE, st's smooth profile,
    as `Simulator.step` takes a step with no gap crossing, on the workspace ws (module docstring); flags:
    SAME, AT_LAST, PROFILE (or'ed). Returns (status, q1, q1', the error estimate at q1 in rad, τ at t1
    in N·m): OK; or PYTHON with ws as it was."""
    m, plan, st, arr, work = parts(ws)
    st[SAVED:SAVED + N_SCALARS] = st[:N_SCALARS]
    arr[ROWS - KEPT:] = arr[:KEPT]
    o = LAST_Q if flags & AT_LAST else X
    q, v = (st[o], st[o + 1], st[o + 2]), (st[o + 3], st[o + 4], st[o + 5])
    prof = st[PROFILE_AT:PROFILE_AT + PROFILE_SIZE] if flags & PROFILE else st[HELD_AT:HELD_AT + 1]
    status, q1, v1, estimate = _step(m, plan, st, arr, work, t, t1, command, prof, (flags & SAME) != 0, q, v, log_of(ws))
    if status == PYTHON:
        restore(ws)
    return status, q1, v1, estimate, torque_at(prof, command, t1)


@njit(**JIT)
def restore(ws):
    """The solution in ws as it was before the last `common_step`."""
    _, _, st, arr, _ = parts(ws)
    st[:N_SCALARS] = st[SAVED:SAVED + N_SCALARS]
    arr[:KEPT] = arr[ROWS - KEPT:]


@njit(**JIT)
def _is(st, o, q, v):
    """Whether st[o:o + 6] holds (q, q') exactly."""
    return (st[o] == q[0] and st[o + 1] == q[1] and st[o + 2] == q[2] and st[o + 3] == v[0] and st[o + 4] == v[1]
            and st[o + 5] == v[2])


@njit(**JIT)
def _put(st, o, q, v):
    st[o], st[o + 1], st[o + 2], st[o + 3], st[o + 4], st[o + 5] = q[0], q[1], q[2], v[0], v[1], v[2]


@njit(**JIT)
def _step(m, plan, st, arr, work, t, t1, command, prof, same, q, v, log):
    """`common_step` without the restore; its internal steps recorded in log."""
    h = t1 - t
    target = t + h
    y, f, y_old, dense, kk, y_new, out = arr[Y], arr[F], arr[Y_OLD], arr[DENSE:KK], arr[KK:Y_NEW], arr[Y_NEW], arr[OUT]
    taus = st[TAUS:SAVED]
    log[COUNT], log[BRANCH] = 0.0, 0.0
    if same and st[HAS_ORIGIN] == 1.0 and st[ORIGIN_T] == t and _is(st, ORIGIN_Q, q, v) and target >= t:
        pass  # a step from the solution's start: answered from it
    elif same and st[HAS_LAST] == 1.0 and _is(st, LAST_Q, q, v) and abs(st[LAST_T] - t) <= LAST_OUTPUT_SLACK * h \
            and target >= st[T_OLD]:
        st[HAS_ORIGIN], st[ORIGIN_T] = 1.0, t  # continuing the last output
        _put(st, ORIGIN_Q, q, v)
        log[BRANCH] = CONTINUED
    else:  # `DormandPrince853._restart`, from the last output's q (whose error estimate is kept)
        if st[HAS_LAST] == 1.0 and st[LAST_Q] == q[0] and st[LAST_Q + 1] == q[1] and st[LAST_Q + 2] == q[2]:
            st[ERR] = st[ERR_OLD] = st[LAST_EST]
        elif st[HAS_LAST] == 0.0 and st[HAS_ORIGIN] == 0.0 and st[H] <= 0.0:
            st[ERR] = st[ERR_OLD] = 0.0  # a new solution's first step (`simulation.event_step`: no estimates yet)
        else:
            return PYTHON, q, v, 0.0
        st[T] = st[T_OLD] = t
        y[0], y[1], y[2], y[3], y[4], y[5] = q[0], q[1], q[2], v[0], v[1], v[2]
        _rhs(m, t, y, torque_at(prof, command, t), f)
        if st[H] <= 0.0:  # the first internal step
            st[H] = initial_step(y, f, st[RTOL], st[ATOL], h)
        st[HAS_ORIGIN], st[ORIGIN_T] = 1.0, t
        _put(st, ORIGIN_Q, q, v)
        log[BRANCH] = RESTARTED
    for c in range(N_NODES):
        taus[c] = command  # a held command's (a profile's are set by each attempt)
    while st[T] < target:
        if not _advance(m, st[RTOL], st[ATOL], st, y, f, y_old, dense, kk, y_new, taus, prof):
            return PYTHON, q, v, 0.0
        st[ERR_OLD] = st[ERR]
        st[ERR] += dop853_theta_error(E53, kk, st[H_OLD], E3_WEIGHT)
        record(log, st, y_old, dense)
    t_old, h_old = st[T_OLD], st[H_OLD]
    if target < t_old:  # an earlier internal step's output: the history is Python's
        return PYTHON, q, v, 0.0
    status, q1, v1 = dop853_output(m, t_old, h_old, y_old, dense, target, out)
    if status != OK:
        return PYTHON, q, v, 0.0
    side = int(st[SIDE])
    if screen(plan, work, side, st[KNOWN] == 1.0, h, q, v, q1, v1):
        # a crossing may lie inside: kept for Python when the log holds the step's whole history
        return (EVENT if log[BRANCH] != 0.0 and log[COUNT] <= HISTORY_ROWS else PYTHON), q, v, 0.0
    st[KNOWN], st[SIDE] = 1.0, 2 - side
    # `DormandPrince853._remember`: the estimate interpolated over the internal step that covers the output
    x = (target - t_old) / h_old if h_old > 0.0 else 1.0
    estimate = st[ERR_OLD] + min(1.0, max(0.0, x)) * (st[ERR] - st[ERR_OLD])
    st[HAS_LAST], st[LAST_T], st[LAST_EST] = 1.0, target, estimate
    _put(st, LAST_Q, q1, v1)
    return OK, q1, v1, estimate


@njit(**JIT)
def stays_at_rest(ws, t, t1, command, flags, sign, q0, q1, q2):
    """Whether the finger resting on a stop at q (q' = 0) stays there over [t, t1] (s) under the held
    `command` (N·m) or, with flag PROFILE, st's profile, as `JointStops.release_time` decides it (the push
    −sign·θ1'' into the gap > 0 at t and at t1; sign: the gap gradient's θ1 component), with REST_MARGIN to
    spare (else False: the Simulator decides). Returns (stays, τ at t1 in N·m)."""
    if not pushes_at(ws, t, command, flags, sign, q0, q1, q2)[0]:
        return False, 0.0
    stays, tau = pushes_at(ws, t1, command, flags, sign, q0, q1, q2)
    return (True, tau) if stays else (False, 0.0)


@njit(**JIT)
def pushes_at(ws, s, command, flags, sign, q0, q1, q2):
    """`stays_at_rest`'s test at one time s (s): (whether the push into the stop at rest at q exceeds
    REST_MARGIN, τ at s in N·m)."""
    m, _, st, arr, _ = parts(ws)
    prof = st[PROFILE_AT:PROFILE_AT + PROFILE_SIZE] if flags & PROFILE else st[HELD_AT:HELD_AT + 1]
    y, f = arr[OUT], arr[Y_NEW]  # scratch rows: neither is read across steps
    y[0], y[1], y[2], y[3], y[4], y[5] = q0, q1, q2, 0.0, 0.0, 0.0
    tau = torque_at(prof, command, s)
    _rhs(m, s, y, tau, f)
    push = -sign * f[3]
    return push > REST_MARGIN * max(1.0, abs(f[3])), tau
