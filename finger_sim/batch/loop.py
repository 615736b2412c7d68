"""The batch's compiled loop: many fingers, each stepped as `Simulator.step` steps it, in parallel.

One call advances every finger from its own step to its own end (numba `prange` over the
fingers: both cores). Each step is cut at the finger's torque switches (its profile is
data here, `PROFILE_*` codes) and every piece is one `finger_sim.kernel.numerics.rk_step`
(or `euler_step`): the kernel's own jitted step, so the numbers are the Simulator's.

A step in which something happens that the loop does not resolve itself (a stop closes, a
contact gap opens or closes, or the Simulator predicts it may inside the step, a contact shorter
than the step: `simulate._predicted_crossing`; the kernel reports a status other than OK) is not taken: the
finger stops *before* it with `EVENT` and the Python driver (`finger_sim.batch`) hands that
step to a `Simulator`, which locates the event exactly as it always does.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit, prange

from finger_sim import simulate
from finger_sim.inputs import BREAK_EPS
from finger_sim.kernel.layout import CONTACT, HEADER
from finger_sim.kernel.numerics import OK, euler_step, rk_step

#: A finger's status after `run`: reached its last step, or stopped before a step that the
#: Simulator must take (an event, or a kernel status other than OK).
DONE = 0
EVENT = 1

#: Torque profile codes (finger_sim.inputs), and their three parameters in order.
PROFILE_CONSTANT = 0  # value
PROFILE_RAMP = 1  # offset, slope
PROFILE_STEP = 2  # before, after, at
PROFILE_SQUARE = 3  # amplitude, frequency, offset
PROFILE_SINE = 4  # amplitude, frequency, offset
#: Most switches of one step: a scene's dt is at most its profile's shortest interval, so a
#: step holds at most two.
MAX_CUTS = 8

#: `simulate.EVENT_TOLERANCE`: a gap counts as closed below −EVENT_TOLERANCE.
EVENT_TOLERANCE = simulate.EVENT_TOLERANCE
#: A gap's rate is the forward difference of the gap along q' over this fraction of the step.
RATE_STEP = 1e-4

#: The Simulator's prediction of a crossing inside a step, compiled (the same function).
predicted_crossing = njit(cache=True, nogil=True, error_model="numpy")(simulate._predicted_crossing)

PARALLEL = {"cache": True, "nogil": True, "error_model": "numpy", "parallel": True}
SERIAL = {"cache": True, "nogil": True, "error_model": "numpy"}


@njit(**SERIAL)
def torque(code, p, t):
    """τ(t), N·m: `Profile.__call__` of each profile, the same arithmetic."""
    if code == PROFILE_CONSTANT:
        return p[0]
    if code == PROFILE_RAMP:
        return p[0] + p[1] * t
    if code == PROFILE_STEP:
        return p[0] if t < p[2] else p[1]
    if code == PROFILE_SQUARE:
        phase = (t * p[1]) % 1.0
        return p[2] + (p[0] if phase < 0.5 else -p[0])
    return p[2] + p[0] * math.sin(2.0 * math.pi * p[1] * t)


@njit(**SERIAL)
def cuts(code, p, t0, t1, eps, out):
    """The switches strictly inside (t0 + eps, t1 − eps) into out; their count (`Profile.breakpoints`)."""
    n = 0
    if code == PROFILE_STEP:
        if t0 < p[2] < t1 and t0 + eps < p[2] < t1 - eps:
            out[0] = p[2]
            n = 1
    elif code == PROFILE_SQUARE:
        half = 0.5 / p[1]
        k = math.floor(t0 / half) + 1
        while k * half < t1 and n < MAX_CUTS:
            b = k * half
            if t0 + eps < b < t1 - eps:
                out[n] = b
                n += 1
            k += 1
    return n


@njit(**SERIAL)
def contact_gaps(m, o, q0, q2, gap):
    """Each contact candidate's gap −δ (m) into `gap`: `Contact.gaps`, in its order and with its
    arithmetic (`Contact._hits`, every candidate); returns their count."""
    r1, l3, alpha = m[o], m[o + 1], m[o + 2]
    n_prox, n_dist, n_ends, n_tips = int(m[o + 8]), int(m[o + 9]), int(m[o + 10]), int(m[o + 11])
    j = o + 12
    c1, s1 = math.cos(q0), math.sin(q0)
    bx, by = r1 * c1, r1 * s1
    i = 0
    for _ in range(n_prox):
        cx, cy, rad = m[j], m[j + 1], m[j + 2]
        j += 3
        s = (cx * bx + cy * by) / (r1 * r1)
        s = 0.0 if s < 0.0 else (1.0 if s > 1.0 else s)
        gap[i] = -(rad - math.hypot(s * bx - cx, s * by - cy))
        i += 1
    psi = q2 + alpha
    ux, uy = math.cos(psi), math.sin(psi)
    for _ in range(n_dist):
        cx, cy, rad = m[j], m[j + 1], m[j + 2]
        j += 4
        dx, dy = cx - bx, cy - by
        ell = dx * ux + dy * uy
        ell = 0.0 if ell < 0.0 else (l3 if ell > l3 else ell)
        px, py = bx + ell * ux, by + ell * uy
        gap[i] = -(rad - math.hypot(px - cx, py - cy))
        i += 1
    for _ in range(n_ends):
        ox, oy, nx, ny, rho = m[j], m[j + 1], m[j + 2], m[j + 3], m[j + 4]
        j += 5
        gap[i] = -(rho - (nx * (bx - ox) + ny * (by - oy)))
        i += 1
    for _ in range(n_tips):
        ox, oy, nx, ny, rho = m[j], m[j + 1], m[j + 2], m[j + 3], m[j + 4]
        j += 6
        px, py = bx + l3 * ux, by + l3 * uy
        gap[i] = -(rho - (nx * (px - ox) + ny * (py - oy)))
        i += 1
    return i


@njit(**SERIAL)
def kink(m, xa, xb, h, ga, gb, shifted, depth):
    """Whether a step of length h (s) from state xa to xb may hold a contact event that the
    Simulator would split it at: a contact gap of model m is closed at one end and open at the
    other, or `simulate._predicted_crossing` (the Simulator's own test, from the gaps and their
    rates at both ends) predicts a crossing inside it; the same for the depth gap depth − δ
    (`depth_guard`: depth is the thinner phalanx's radius ρ, m, so the Simulator sees every
    candidate that may reach its own). ga, gb, shifted: scratch arrays (one per candidate).
    The rates are forward differences along q' over RATE_STEP·h."""
    o = HEADER + 1
    eps = RATE_STEP * h
    for _ in range(int(m[HEADER])):
        code, n = int(m[o]), int(m[o + 1])
        o += 2
        if code == CONTACT:
            count = contact_gaps(m, o, xa[0], xa[2], ga)
            contact_gaps(m, o, xb[0], xb[2], gb)
            for c in range(count):
                if (ga[c] < -EVENT_TOLERANCE) != (gb[c] < -EVENT_TOLERANCE) or gb[c] + depth < -EVENT_TOLERANCE:
                    return True
            contact_gaps(m, o, xa[0] + eps * xa[3], xa[2] + eps * xa[5], shifted)
            for c in range(count):
                shifted[c] = (shifted[c] - ga[c]) / eps  # the start's rate
            rates_a = shifted.copy()
            contact_gaps(m, o, xb[0] + eps * xb[3], xb[2] + eps * xb[5], shifted)
            for c in range(count):
                rate_b = (shifted[c] - gb[c]) / eps
                if predicted_crossing(ga[c], rates_a[c], gb[c], rate_b, h, ga[c] < -EVENT_TOLERANCE) is not None:
                    return True
                if predicted_crossing(ga[c] + depth, rates_a[c], gb[c] + depth, rate_b, h, False) is not None:
                    return True
        o += n
    return False


@njit(**SERIAL)
def residual(m, x):
    """|Φ(q)|, m: `kinematics.constraint_norm` from the model's r1, r2, r3 and r4 e(θ4)."""
    f1 = m[4] * math.cos(x[0]) + m[8] - m[5] * math.cos(x[1]) - m[6] * math.cos(x[2])
    f2 = m[4] * math.sin(x[0]) + m[9] - m[5] * math.sin(x[1]) - m[6] * math.sin(x[2])
    return math.hypot(f1, f2)


@njit(**SERIAL)
def _finger(m, tab, nodes, code, p, dt, stop, limits, gaps, depth, x, step, last, max_res, traj, record):
    """Steps one finger from `step` up to `last`; returns (status, step reached, max |Φ|)."""
    s = tab.shape[1]
    k = np.empty((max(s, 1), 6))
    taus = np.empty(nodes.shape[0])
    cut = np.empty(MAX_CUTS)
    edges = np.empty(MAX_CUTS + 2)
    start = np.empty(6)
    before = np.empty(gaps)
    after = np.empty(gaps)
    shifted = np.empty(gaps)
    xa = np.empty(6)
    eps = BREAK_EPS * dt
    while step < last:
        t0, t1 = step * dt, (step + 1) * dt
        count = cuts(code, p, t0, t1, eps, cut)
        edges[0] = t0
        for c in range(count):
            edges[c + 1] = cut[c]
        edges[count + 1] = t1
        start[:] = x
        event = False
        for seg in range(count + 1):
            a, b = edges[seg], edges[seg + 1]
            h = b - a
            xa[:] = x
            piecewise = code == PROFILE_STEP or code == PROFILE_SQUARE
            middle = torque(code, p, 0.5 * (a + b)) if piecewise else 0.0
            for j in range(nodes.shape[0]):
                taus[j] = middle if piecewise else torque(code, p, a + nodes[j] * h)
            if s == 0:
                status = euler_step(m, a, x, h, taus[0])
            else:
                status = rk_step(m, tab, a, x, h, taus, k)
            if status != OK or not np.isfinite(x).all():
                event = True
            elif stop and (x[0] - limits[0] < -EVENT_TOLERANCE or limits[1] - x[0] < -EVENT_TOLERANCE):
                event = True
            elif gaps > 0 and kink(m, xa, x, h, before, after, shifted, depth):
                event = True
            if event:
                break
        if event:
            x[:] = start
            return EVENT, step, max_res
        step += 1
        r = residual(m, x)
        if r > max_res:
            max_res = r
        if record:
            traj[step, 0], traj[step, 1], traj[step, 2] = x[0], x[1], x[2]
    return DONE, step, max_res


@njit(**PARALLEL)
def run(models, tab, nodes, codes, params, dts, stops, limits, gaps, depths, states, steps, lasts, max_res, trajs,
        record):
    """Advance every finger i from step steps[i] to lasts[i] (in place: states (N × 6), steps,
    max_res; trajs[i, k] = q after step k when record). Returns each finger's status (DONE or EVENT).

    models: N × L flat models (`kernel.layout.model_array`, zero-padded); tab, nodes: the method's
    tableau and distinct nodes (one method per call); codes, params: each torque profile; stops,
    limits: whether finger i has MCP stops, and (lower, upper) rad; gaps: contact candidates; depths:
    the thinner phalanx radius, m (`kink`).
    """
    n = states.shape[0]
    status = np.empty(n, dtype=np.int64)
    for i in prange(n):
        status[i], steps[i], max_res[i] = _finger(
            models[i], tab, nodes, codes[i], params[i], dts[i], stops[i], limits[i], gaps[i], depths[i],
            states[i], steps[i], lasts[i], max_res[i], trajs[i], record,
        )
    return status
