"""The rollout's compiled loops: many fingers, each stepped with the Simulator's own arithmetic.

`run` loops `numerics._profile_step`, the one function that `Simulator.step` (through
`FastStepper`) and `simulate` (through `numerics.fast_run`) call for a smooth scene, over the
fingers (numba `prange`: every thread) and their steps. A finger stops at a step whose status
is not OK (a torque switch inside the step, BREAKPOINT, which the Python side hands to the
finger's Simulator; or a failure, which it raises) and reports where.

`run_rows` is `run` for a batch of whole scenes (`finger_sim.batch.run_batch`): each row its own
step count, and each step checked for an event (a stop, a contact gap: `kernel.event_checks`);
a step that holds one, or a switch, or fails, is taken back and the row stops before it, EVENT,
for the row's Simulator to take.

`run_lockstep` is the same step in lock-step across a tile of fingers, structure of arrays
(one contiguous array per state component, the finger index innermost): every stage, force
law, the closed-form Schur solve and the projection's Newton iterations are loops over the
fingers of a tile, with the operations of `_profile_step` (`rk_step`, `accelerations`,
`generalized_force`, `project`) in their order, so a row's numbers are `run`'s bit for bit
(tested). It takes a group of rows that share the method, the force elements' layout and a
smooth input (ramp, sine, constant or held): no torque switch can fall inside a step.
"""

from __future__ import annotations

import math

import numpy as np

from finger_sim.kernel import use_writable_cache

use_writable_cache()  # before numba reads NUMBA_CACHE_DIR
from numba import njit, prange  # noqa: E402  (after the cache folder is set)

from finger_sim.inputs import CONSTANT, HELD, RAMP, SINE  # noqa: E402
from finger_sim.kernel.event_checks import RATE_STEP, kink, residual, stop_closed  # noqa: E402
from finger_sim.kernel.force_laws import element_forces  # noqa: E402
from finger_sim.kernel.layout import HEADER, NO_FORCE  # noqa: E402
from finger_sim.kernel.numerics import (NON_FINITE, NOT_CONVERGED, OK, STATE_NON_FINITE, _profile_step,  # noqa: E402
                                        plan_parts, torque_at)
from finger_sim.kernel.vector_trig import LANES, sincos_row  # noqa: E402
from finger_sim.projection import ACCEPTED_RESIDUAL_FACTOR, MAX_ITERATIONS, POSITION_TOLERANCE  # noqa: E402

#: A row's status after `run_rows`: reached its last step, or stopped before a step that its
#: Simulator must take (an event, a switch inside the step, or a kernel status other than OK).
DONE = 0
EVENT = 1
PARALLEL = {"cache": True, "nogil": True, "error_model": "numpy", "parallel": True}
SERIAL = {"cache": True, "nogil": True, "error_model": "numpy"}
#: Fingers stepped together by `run_lockstep`: a tile's state, stages and work arrays
#: (~40 arrays of TILE floats) stay in the core's L1/L2 cache; tiles run on every thread.
TILE = 64
#: The declared laws written out for a tile (`force_laws.tile_statements`), generated from each law's source.
tile_element_force = element_forces().tile_element_force
#: Force element codes `run_lockstep` evaluates (contact's branches per candidate stay in `run`).
LOCKSTEP_CODES = (NO_FORCE, *element_forces().TILE_CODES)
#: Input kinds with no switch inside a step: rows under them can step in lock-step.
SMOOTH_INPUTS = (HELD, CONSTANT, RAMP, SINE)
#: Rows of a tile's trig work array: sin, cos of θ1, θ2, θ3 and of u = θ1 − θ3 − α, then u.
S1, C1, S2, C2, S3, C3, SU, CU, U = range(9)
TRIG_ROWS = 9


def lockstep_layout(model: np.ndarray, tab: np.ndarray, prof: np.ndarray) -> tuple | None:
    """What rows stepped together by `run_lockstep` must share (the tableau, the force elements'
    codes and sizes, the input's length), or None when a row needs `run` (Euler, a contact or
    drive block, an input with switches inside steps). model, tab, prof: as `run_lockstep` reads them."""
    if tab.shape[1] == 0 or int(prof[0]) not in SMOOTH_INPUTS:
        return None
    layout, o = [], HEADER + 1
    for _ in range(int(model[HEADER])):
        code, size = int(model[o]), int(model[o + 1])
        if code not in LOCKSTEP_CODES:
            return None
        layout.append((code, size))
        o += 2 + size
    if o != len(model):  # a drive block follows the elements
        return None
    return tab.tobytes(), tuple(layout), len(prof)


@njit(**PARALLEL)
def run(plans, profiles, which, control, q, v, status, reached):
    """Advance finger i from q[i, 0], v[i, 0] through steps 0 … nstep − 1 into q[i, 1:], v[i, 1:].

    plans: one `CompiledRungeKutta.step_plan` per distinct scene, zero-padded rows; profiles:
    each scene's compiled input profile (`inputs.profile_array`, zero-padded; HELD when the input
    is `control`); which[i]: finger i's scene row; control: nbatch × nstep held input values, or
    nbatch × 0 for the scenes' own profiles. q, v: nbatch × (nstep + 1) × 3, rad and rad/s.
    status[i], reached[i]: the kernel status of the last step tried (OK: all done) and the steps done.
    """
    nbatch, nstep = q.shape[0], q.shape[1] - 1
    held_input = control.shape[1] > 0
    for i in prange(nbatch):
        dt, m, tab = plan_parts(plans[which[i]])
        prof = profiles[which[i]]
        s = tab.shape[1]
        work, taus = np.empty((max(s, 1), 6)), np.empty(max(s, 1))
        x = np.empty(6)
        x[0], x[1], x[2], x[3], x[4], x[5] = q[i, 0, 0], q[i, 0, 1], q[i, 0, 2], v[i, 0, 0], v[i, 0, 1], v[i, 0, 2]
        code = OK
        k = 0
        while k < nstep:
            held = control[i, k] if held_input else 0.0
            code, _ = _profile_step(m, tab, prof, held, k, dt, x, work, taus)
            if code != OK:
                break
            k += 1
            q[i, k, 0], q[i, k, 1], q[i, k, 2] = x[0], x[1], x[2]
            v[i, k, 0], v[i, k, 1], v[i, k, 2] = x[3], x[4], x[5]
        status[i], reached[i] = code, k


@njit(**PARALLEL)
def run_rows(plans, profiles, stops, limits, gaps, depths, states, steps, lasts, max_res, trajs, record):
    """Advance every row i from step steps[i] to lasts[i] under its own profile (in place: states
    (N × 6, q then q'), steps, max_res, the largest |Φ| so far; trajs[i, k] = q after step k when
    record). Returns each row's status, DONE or EVENT.

    plans, profiles: each row's step plan and compiled profile (zero-padded rows); stops[i],
    limits[i]: whether row i has MCP stops, and (lower, upper) rad; gaps[i]: its contact candidates;
    depths[i]: its thinner phalanx radius, m (`event_checks.kink`).
    """
    n = states.shape[0]
    status = np.empty(n, dtype=np.int64)
    for i in prange(n):
        status[i], steps[i], max_res[i] = _row(plans[i], profiles[i], stops[i], limits[i], gaps[i], depths[i],
                                               states[i], steps[i], lasts[i], max_res[i], trajs[i], record)
    return status


@njit(**SERIAL)
def _row(plan, prof, stop, limits, gaps, depth, x, step, last, max_res, traj, record):
    """One row of `run_rows`: (status, step reached, max |Φ|)."""
    dt, m, tab = plan_parts(plan)
    s = tab.shape[1]
    work, taus = np.empty((max(s, 1), 6)), np.empty(max(s, 1))
    start = np.empty(6)
    before, after, shifted = np.empty(gaps), np.empty(gaps), np.empty(gaps)
    rates, rates_after = np.empty(gaps), np.empty(gaps)
    known_eps = 0.0  # the rate step over which `before` and `rates` hold this step's start (0: not known)
    while step < last:
        start[:] = x
        code, _ = _profile_step(m, tab, prof, 0.0, step, dt, x, work, taus)
        h = (step + 1) * dt - step * dt
        if code != OK or (stop and stop_closed(x, limits)) or \
                (gaps > 0 and kink(m, start, x, h, before, after, shifted, rates, rates_after, depth, known_eps)):
            x[:] = start
            return EVENT, step, max_res
        if gaps > 0:  # this step's end is the next one's start
            before, after, rates, rates_after, known_eps = after, before, rates_after, rates, RATE_STEP * h
        step += 1
        r = residual(m, x)
        if r > max_res:
            max_res = r
        if record:
            traj[step, 0], traj[step, 1], traj[step, 2] = x[0], x[1], x[2]
    return DONE, step, max_res


@njit(**PARALLEL)
def run_lockstep(dt, tab, models, profiles, control, q, v, status, reached):
    """`run` for rows sharing one tableau and layout, in lock-step tiles of TILE fingers.

    dt: the step, s; tab: the method's tableau (`layout.tableau_array`, at least one stage);
    models: (model length, nbatch), each column finger i's flat model (`layout.model_array`,
    the same element codes and sizes in every column, no drive block); profiles: (profile
    length, nbatch), each column finger i's smooth compiled input (ignored under `control`);
    control, q, v, status, reached: as `run`.
    """
    nbatch = q.shape[0]
    for tile in prange((nbatch + TILE - 1) // TILE):
        lo = tile * TILE
        _tile(dt, tab, models, profiles, control, q, v, status, reached, lo, min(lo + TILE, nbatch))


@njit(**SERIAL)
def _tile(dt, tab, models, profiles, control, q, v, status, reached, lo, hi):
    """Fingers lo … hi − 1 of `run_lockstep` through every step."""
    n, nstep, s = hi - lo, q.shape[1] - 1, tab.shape[1]
    held_input = control.shape[1] > 0
    m = np.ascontiguousarray(models[:, lo:hi])
    prof = np.ascontiguousarray(profiles[:, lo:hi].T)  # a row per finger, as `torque_at` reads it
    width = max(n, LANES)  # `sincos_row` reads and writes a row of fewer than LANES fingers up to LANES
    x = np.zeros((6, width))
    y = np.zeros((6, width))
    kk = np.empty((s, 6, n))
    taus = np.empty((s, n))
    force = np.empty((3, n))
    grad = np.empty((6, n))
    resid = np.empty((2, n))
    trig = np.zeros((TRIG_ROWS, width))
    done = np.empty(n, dtype=np.bool_)
    alive = np.ones(n, dtype=np.bool_)
    code = np.full(n, OK)
    for f in range(n):
        for c in range(3):
            x[c, f], x[3 + c, f] = q[lo + f, 0, c], v[lo + f, 0, c]
        status[lo + f], reached[lo + f] = OK, nstep
    for k in range(nstep):
        t0, t1 = k * dt, (k + 1) * dt
        h = t1 - t0
        for i in range(s):  # τ at each stage's node, as `_profile_step` for a smooth profile
            node, c_i = int(tab[s + 2, i]), tab[s + 1, i]
            for f in range(n):
                held = control[lo + f, k] if held_input else 0.0
                taus[node, f] = torque_at(prof[f], held, t0 + c_i * h)
        for i in range(s):  # `rk_step`'s stages
            for c in range(6):
                for f in range(n):
                    y[c, f] = x[c, f]
            for j in range(i):
                a = tab[i, j]
                if a != 0.0:
                    ha = h * a
                    for c in range(6):
                        for f in range(n):
                            y[c, f] += ha * kk[j, c, f]
            for c in range(3):
                for f in range(n):
                    kk[i, c, f] = y[3 + c, f]
            _accelerations(m, y, taus[int(tab[s + 2, i])], force, kk[i], trig, n)
        for j in range(s):
            b = tab[s, j]
            if b != 0.0:
                hb = h * b
                for c in range(6):
                    for f in range(n):
                        x[c, f] += hb * kk[j, c, f]
        _project(m, x, grad, resid, trig, done, code, n)
        for f in range(n):
            if code[f] == OK and not math.isfinite(x[0, f] + x[1, f] + x[2, f] + x[3, f] + x[4, f] + x[5, f]):
                code[f] = STATE_NON_FINITE
            if alive[f]:
                if code[f] != OK:
                    alive[f] = False
                    status[lo + f], reached[lo + f] = code[f], k
                else:
                    for c in range(3):
                        q[lo + f, k + 1, c], v[lo + f, k + 1, c] = x[c, f], x[3 + c, f]


@njit(**SERIAL)
def _accelerations(m, y, tau, force, out, trig, n):
    """q'' of every finger at stage state y (6 × n) into out[3:6] (6 × n): `numerics.accelerations`
    with `generalized_force`, the same operations in the same order, a loop over fingers each (the
    elements' laws as `tile_element_force` writes them out from their source), the sines and cosines
    of θ1, θ2, θ3 and θ1 − θ3 − α a row at a time (`sincos_row`; trig: TRIG_ROWS × n work)."""
    for f in range(n):
        force[0, f], force[1, f], force[2, f] = tau[f], 0.0, 0.0
    o = HEADER + 1
    for _ in range(int(m[HEADER, 0])):
        law, size = int(m[o, 0]), int(m[o + 1, 0])
        o += 2
        tile_element_force(law, m, o, y, force, n)
        o += size
    for f in range(n):
        trig[U, f] = y[0, f] - y[2, f] - m[7, f]
    _sincos_angles(y, trig, n)
    sincos_row(trig[U], trig[SU], trig[CU], n)
    for f in range(n):
        v0, v1, v2 = y[3, f], y[4, f], y[5, f]
        m11, m22, m33, cc, r1, r2, r3 = m[0, f], m[1, f], m[2, f], m[3, f], m[4, f], m[5, f], m[6, f]
        s1, c1, s2, c2, s3, c3 = trig[S1, f], trig[C1, f], trig[S2, f], trig[C2, f], trig[S3, f], trig[C3, f]
        su, cu = trig[SU, f], trig[CU, f]
        f1 = force[0, f] - cc * su * v2 * v2
        f2 = force[1, f]
        f3 = force[2, f] + cc * su * v0 * v0
        b = cc * cu
        det = m11 * m33 - b * b  # the 2 × 2 mass block of (θ1, θ3), inverted in closed form
        i11, i13, i33 = m33 / det, -b / det, m11 / det
        i22 = 1.0 / m22
        x1, x2, x3 = i11 * f1 + i13 * f3, i22 * f2, i13 * f1 + i33 * f3
        g11, g12, g13 = -r1 * s1, r2 * s2, r3 * s3
        g21, g22, g23 = r1 * c1, -r2 * c2, -r3 * c3
        y11, y12, y13 = i11 * g11 + i13 * g13, i22 * g12, i13 * g11 + i33 * g13
        y21, y22, y23 = i11 * g21 + i13 * g23, i22 * g22, i13 * g21 + i33 * g23
        a11 = g11 * y11 + g12 * y12 + g13 * y13
        a12 = g11 * y21 + g12 * y22 + g13 * y23
        a22 = g21 * y21 + g22 * y22 + g23 * y23
        gam1 = r1 * c1 * v0 * v0 - r2 * c2 * v1 * v1 - r3 * c3 * v2 * v2
        gam2 = r1 * s1 * v0 * v0 - r2 * s2 * v1 * v1 - r3 * s3 * v2 * v2
        b1 = gam1 - (g11 * x1 + g12 * x2 + g13 * x3)
        b2 = gam2 - (g21 * x1 + g22 * x2 + g23 * x3)
        dw = a11 * a22 - a12 * a12  # the 2 × 2 Schur complement, solved in closed form
        lam1 = (a22 * b1 - a12 * b2) / dw
        lam2 = (a11 * b2 - a12 * b1) / dw
        out[3, f] = x1 + lam1 * y11 + lam2 * y21
        out[4, f] = x2 + lam1 * y12 + lam2 * y22
        out[5, f] = x3 + lam1 * y13 + lam2 * y23


@njit(**SERIAL)
def _sincos_angles(x, trig, n):
    """trig[S1 … C3] = sin, cos of θ1, θ2, θ3 (x's rows 0-2) of every finger."""
    sincos_row(x[0], trig[S1], trig[C1], n)
    sincos_row(x[1], trig[S2], trig[C2], n)
    sincos_row(x[2], trig[S3], trig[C3], n)


@njit(**SERIAL)
def _project(m, x, grad, resid, trig, done, code, n):
    """`numerics.project` of every finger's x (6 × n, in place) into code[f]: Newton on Φ = 0
    until each finger's |Φ|₁ ≤ POSITION_TOLERANCE (a converged finger is left alone while the
    others iterate), then the rates onto Φ_q q' = 0 with that finger's last gradient."""
    for f in range(n):
        done[f] = False
    left = n
    for _ in range(MAX_ITERATIONS):
        _sincos_angles(x, trig, n)  # every finger's, converged or not: a row at a time is cheaper
        for f in range(n):
            if done[f]:
                continue
            r1, r2, r3, k1, k2 = m[4, f], m[5, f], m[6, f], m[8, f], m[9, f]
            t1, t2, t3 = x[0, f], x[1, f], x[2, f]
            s1, c1, s2, c2, s3, c3 = trig[S1, f], trig[C1, f], trig[S2, f], trig[C2, f], trig[S3, f], trig[C3, f]
            f1 = r1 * c1 + k1 - r2 * c2 - r3 * c3
            f2 = r1 * s1 + k2 - r2 * s2 - r3 * s3
            g11, g12, g13 = -r1 * s1, r2 * s2, r3 * s3
            g21, g22, g23 = r1 * c1, -r2 * c2, -r3 * c3
            grad[0, f], grad[1, f], grad[2, f], grad[3, f], grad[4, f], grad[5, f] = g11, g12, g13, g21, g22, g23
            resid[0, f], resid[1, f] = f1, f2
            if abs(f1) + abs(f2) <= POSITION_TOLERANCE:
                done[f] = True
                left -= 1
                continue
            a11 = g11 * g11 + g12 * g12 + g13 * g13
            a12 = g11 * g21 + g12 * g22 + g13 * g23
            a22 = g21 * g21 + g22 * g22 + g23 * g23
            det = a11 * a22 - a12 * a12
            l1 = (a22 * f1 - a12 * f2) / det
            l2 = (a11 * f2 - a12 * f1) / det
            x[0, f] = t1 - (g11 * l1 + g21 * l2)
            x[1, f] = t2 - (g12 * l1 + g22 * l2)
            x[2, f] = t3 - (g13 * l1 + g23 * l2)
        if left == 0:
            break
    for f in range(n):
        code[f] = OK
        g11, g12, g13, g21, g22, g23 = grad[0, f], grad[1, f], grad[2, f], grad[3, f], grad[4, f], grad[5, f]
        if not done[f]:
            t1, t2, t3 = x[0, f], x[1, f], x[2, f]
            if not (math.isfinite(t1) and math.isfinite(t2) and math.isfinite(t3)):
                code[f] = NON_FINITE
                continue
            bound = ACCEPTED_RESIDUAL_FACTOR * POSITION_TOLERANCE * (1.0 + max(abs(t1), abs(t2), abs(t3)))
            if math.hypot(resid[0, f], resid[1, f]) > bound:
                code[f] = NOT_CONVERGED
                continue
        a11 = g11 * g11 + g12 * g12 + g13 * g13
        a12 = g11 * g21 + g12 * g22 + g13 * g23
        a22 = g21 * g21 + g22 * g22 + g23 * g23
        det = a11 * a22 - a12 * a12
        w1, w2, w3 = x[3, f], x[4, f], x[5, f]
        e1 = g11 * w1 + g12 * w2 + g13 * w3
        e2 = g21 * w1 + g22 * w2 + g23 * w3
        l1 = (a22 * e1 - a12 * e2) / det
        l2 = (a11 * e2 - a12 * e1) / det
        x[3, f], x[4, f], x[5, f] = w1 - g11 * l1 - g21 * l2, w2 - g12 * l1 - g22 * l2, w3 - g13 * l1 - g23 * l2


@njit(**PARALLEL)
def max_residuals(models, q, counts, out):
    """out[i] = max(out[i], |Φ(q[i, k])| for k = 1 … counts[i]) (`event_checks.residual`), m:
    a batch's max_constraint_residual after `run_lockstep`; models: as `run_lockstep` reads them."""
    for i in prange(q.shape[0]):
        m = models[:, i].copy()
        x = np.empty(3)
        worst = out[i]
        for k in range(1, counts[i] + 1):
            x[0], x[1], x[2] = q[i, k, 0], q[i, k, 1], q[i, k, 2]
            r = residual(m, x)
            if r > worst:
                worst = r
        out[i] = worst
