"""The compiled loops' event checks: whether a step may hold an event the Simulator must locate.

A finger stepped in the kernel (`kernel.rollout_loop.run_rows`) has its step checked after it
is taken: a stop closed, a contact gap opened or closed, or the Simulator predicts a crossing
inside the step (`simulation.locate.predicted_crossing`, compiled here: the same function). Such a step
is taken back and handed to the finger's `Simulator`, which locates the event exactly as it
always does. |Φ| is tracked here too (`residual`), for a batch's max_constraint_residual.
"""

from __future__ import annotations

import math

from finger_sim.kernel import use_writable_cache

use_writable_cache()  # before numba reads NUMBA_CACHE_DIR
from numba import njit  # noqa: E402  (after the cache folder is set)

from finger_sim.simulation import locate  # noqa: E402
from finger_sim.kernel.layout import CONTACT, HEADER  # noqa: E402
from finger_sim.kernel.jit import LAW  # noqa: E402
from finger_sim.kernel.numerics import candidate_walk  # noqa: E402

#: `locate.EVENT_TOLERANCE`: a gap counts as closed below −EVENT_TOLERANCE.
EVENT_TOLERANCE = locate.EVENT_TOLERANCE
#: A gap's rate is the forward difference of the gap along q' over this fraction of the step.
RATE_STEP = 1e-4

SERIAL = {"cache": True, "nogil": True, "error_model": "numpy"}

#: The Simulator's prediction of a crossing inside a step, compiled (the same function).
predicted_crossing = njit(**SERIAL)(locate.predicted_crossing)


@njit(**SERIAL)
def stop_closed(x, limits):
    """Whether θ1 = x[0] lies beyond an MCP stop (lower, upper) by more than EVENT_TOLERANCE."""
    return x[0] - limits[0] < -EVENT_TOLERANCE or limits[1] - x[0] < -EVENT_TOLERANCE


@njit(**LAW)
def _store_gap(count, gap, i, geometry):
    """gap[i] = −δ of candidate i (m); count + 1."""
    gap[i] = -geometry[0]
    return count + 1


#: The candidate loop (`effects.contact_candidates`) storing every candidate's gap.
_walk_gaps = candidate_walk(_store_gap)


@njit(**SERIAL)
def contact_gaps(m, o, q0, q2, gap):
    """Each contact candidate's gap −δ (m) into `gap`: `Contact.gaps`, in its order and with its
    arithmetic; returns their count."""
    return _walk_gaps(m, o, q0, q2, True, 0, gap)


@njit(**SERIAL)
def kink(m, xa, xb, h, ga, gb, shifted, rates_a, rates_b, depth, known_eps):
    """Whether a step of length h (s) from state xa to xb may hold a contact event that the
    Simulator would split it at: a contact gap of model m is closed at one end and open at the
    other, or `locate.predicted_crossing` (the Simulator's own test, from the gaps and their
    rates at both ends) predicts a crossing inside it; the same for the depth gap depth − δ
    (`depth_guard`: depth is the thinner phalanx's radius ρ, m, so the Simulator sees every
    candidate that may reach its own). The rates are forward differences along q' over
    eps = RATE_STEP·h. ga, gb, shifted, rates_a, rates_b: arrays of one entry per candidate.

    When known_eps == eps, ga and rates_a already hold xa's gaps and its rates over eps (the
    previous step's end, xb and rates_b of the last call that found no event): they are not
    evaluated again, which halves the gap evaluations of a run of steps and changes no bit.
    After a call that returns False, gb and rates_b hold xb's gaps and rates."""
    o = HEADER + 1
    eps = RATE_STEP * h
    start_known = known_eps == eps
    base = 0
    for _ in range(int(m[HEADER])):
        code, n = int(m[o]), int(m[o + 1])
        o += 2
        if code == CONTACT:
            a, b, sh = ga[base:], gb[base:], shifted[base:]
            if start_known:
                count = contact_gaps(m, o, xb[0], xb[2], b)
            else:
                count = contact_gaps(m, o, xa[0], xa[2], a)
                contact_gaps(m, o, xb[0], xb[2], b)
            for c in range(count):
                if (a[c] < -EVENT_TOLERANCE) != (b[c] < -EVENT_TOLERANCE) or b[c] + depth < -EVENT_TOLERANCE:
                    return True
            if not start_known:
                contact_gaps(m, o, xa[0] + eps * xa[3], xa[2] + eps * xa[5], sh)
                for c in range(count):
                    rates_a[base + c] = (sh[c] - a[c]) / eps  # the start's rate
            contact_gaps(m, o, xb[0] + eps * xb[3], xb[2] + eps * xb[5], sh)
            for c in range(count):
                rate_b = (sh[c] - b[c]) / eps
                rates_b[base + c] = rate_b
                if predicted_crossing(a[c], rates_a[base + c], b[c], rate_b, h, a[c] < -EVENT_TOLERANCE) is not None:
                    return True
                if predicted_crossing(a[c] + depth, rates_a[base + c], b[c] + depth, rate_b, h, False) is not None:
                    return True
            base += count
        o += n
    return False


@njit(**SERIAL)
def residual(m, x):
    """|Φ(q)|, m: `kinematics.constraint_norm` from the model's r1, r2, r3 and r4 e(θ4)."""
    f1 = m[4] * math.cos(x[0]) + m[8] - m[5] * math.cos(x[1]) - m[6] * math.cos(x[2])
    f2 = m[4] * math.sin(x[0]) + m[9] - m[5] * math.sin(x[1]) - m[6] * math.sin(x[2])
    return math.hypot(f1, f2)
