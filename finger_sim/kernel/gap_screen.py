"""The Simulator's gap check of a step, compiled: the common step, with no crossing, in one call.

`simulation.crossings.first_crossing` asks, for every gap of the scene's non-smooth elements, its
value and rate at both ends of the step, and looks for a crossing where a gap is not clearly open
at both ends. `screen` takes the same numbers (the contact's as `closed_loop.contact_states` gives them,
`Contact._hits` in its order and arithmetic; the stops' θ1 − lower, upper − θ1; the depth gaps
ρ − δ) and the same tests (`closed_loop.may_cross`: the skip test of `first_crossing`, then
`crossings.bracket`'s side test and `locate.predicted_crossing`), so when it finds nothing the
Python check would have found nothing either; otherwise the Python check runs as it always did.

The gap plan (`simulation.gap_screen.plan_for`) is one float64 array:

    [n_gaps, n_groups, then per group: kind, n_params, its params,
     n_depth, then per depth gap: (position of its contact gap, ρ), then n_gaps impact flags (1/0)]

kind STOPS: (lower, upper), rad; kind CONTACT: `Contact.kernel_params()`.
"""

from __future__ import annotations

from finger_sim.kernel import use_writable_cache

use_writable_cache()  # before numba reads NUMBA_CACHE_DIR
from numba import njit  # noqa: E402  (after the cache folder is set)

from finger_sim.kernel.closed_loop import gap_and_rate, may_cross  # noqa: E402
from finger_sim.kernel.event_checks import EVENT_TOLERANCE  # noqa: E402
from finger_sim.kernel.numerics import JIT, LAW, candidate_walk  # noqa: E402

#: The kinds of a gap plan's groups (module docstring).
STOPS, CONTACT = 1, 2


@njit(**LAW)
def _store_gap(acc, ctx, i, geometry):
    """work[row, acc] = −δ (m) and work[row + 1, acc] = ∂gap/∂q · q' (m/s) of the candidate visited, the
    next column returned (`closed_loop.contact_states`' numbers, without the grip force the screen does not
    read, and with no view of work made)."""
    work, row, v0, v1, v2 = ctx
    work[row, acc], work[row + 1, acc] = gap_and_rate(geometry, v0, v1, v2)
    return acc + 1


#: The candidate loop (`effects.contact_candidates`) storing every candidate's gap and rate into the screen's rows.
_walk_gaps = candidate_walk(_store_gap)


@njit(**JIT)
def gap_states(plan, x, work, row):
    """Every gap (in the Simulator's `_gaps` order) and its rate at the state x = (q, q') (a 6-tuple) into
    work[row] and work[row + 1]: `crossings.gap_states`' numbers."""
    groups = int(plan[1])
    o = 2
    i = 0
    for _ in range(groups):
        kind, n = int(plan[o]), int(plan[o + 1])
        o += 2
        if kind == STOPS:
            work[row, i], work[row, i + 1] = x[0] - plan[o], plan[o + 1] - x[0]
            # ∂gap/∂q · q' with ∂gap/∂q = (±1, 0, 0), in `crossings.gap_states`' order of terms
            work[row + 1, i] = 1.0 * x[3] + 0.0 * x[4] + 0.0 * x[5]
            work[row + 1, i + 1] = -1.0 * x[3] + 0.0 * x[4] + 0.0 * x[5]
            i += 2
        else:  # every candidate, in order
            i = _walk_gaps(plan, o, x[0], x[2], True, i, (work, row, x[3], x[4], x[5]))
        o += n
    depth = int(plan[o])
    o += 1
    for _ in range(depth):
        p, rho = int(plan[o]), plan[o + 1]
        o += 2
        work[row, i], work[row + 1, i] = work[row, p] + rho, work[row + 1, p]  # ρ − δ, at the rate of −δ
        i += 1


@njit(**JIT)
def screen(plan, work, a, known, h, q, v, q1, v1):
    """Whether the step (q, q') → (q1, q1') of length h (s) needs the Simulator's gap check: some
    gap is not clearly open at both ends and may cross inside (`closed_loop.may_cross`).

    work: 4 × n_gaps; rows a, a + 1 (a = 0 or 2) hold the start's gaps and rates when `known`
    (else they are computed here), rows 2 − a, 3 − a receive the end's: the next step's start.
    """
    n = int(plan[0])
    b = 2 - a
    if not known:
        gap_states(plan, (q[0], q[1], q[2], v[0], v[1], v[2]), work, a)
    gap_states(plan, (q1[0], q1[1], q1[2], v1[0], v1[1], v1[2]), work, b)
    flags = plan.shape[0] - n
    for i in range(n):
        g0 = work[a, i]
        if plan[flags + i] != 0.0 and 0.0 > g0:  # an impact gap: the step starts on the open side
            g0 = 0.0
        if may_cross(g0, work[a + 1, i], work[b, i], work[b + 1, i], h):
            return True
    return False


@njit(**JIT)
def crossed(plan, work, a, y):
    """Whether some gap at the internal state y = (q, q') lies on the other side (closed below −EVENT_TOLERANCE)
    than in work's start rows a, an impact gap counting as open at the start (`crossings.closed_sides`): the watch
    of DOP853's internal steps (`event_step._advance_to`, `internal_steps.advance_to`). y's gaps go to the end
    rows 2 − a (the screen writes them again)."""
    b, n = 2 - a, int(plan[0])
    gap_states(plan, (y[0], y[1], y[2], y[3], y[4], y[5]), work, b)
    flags = plan.shape[0] - n
    for i in range(n):
        closed = work[a, i] < -EVENT_TOLERANCE and plan[flags + i] == 0.0
        if (work[b, i] < -EVENT_TOLERANCE) != closed:
            return True
    return False
