"""A stretch of `Simulator` steps on a scene with events, in one compiled call (`kernel.run_stretch`).

`run` loops the one compiled common step (`event_step.common_step`) over consecutive output steps
k0, k0 + 1, … on the time grid t = k·dt, writing each step's (q, q', error estimate) into a
preallocated array (a step whose contact onsets or releases it located itself, SETTLED, included),
and stops at the first step that answers PYTHON or EVENT (a crossing the kernel does not locate, an
impact, an error-control case the kernel does not take): that step is left to Python, with the
workspace as it was before it. `rest_run` does the same with `event_step.stays_at_rest` for a
finger resting on a stop. No second stepping implementation: the same calls, the same numbers
as one `Simulator.step` per step.
"""

from __future__ import annotations

from finger_sim.kernel import use_writable_cache

use_writable_cache()  # before numba reads NUMBA_CACHE_DIR
from numba import njit  # noqa: E402  (after the cache folder is set)

from finger_sim.kernel.event_step import (AT_LAST, ENDED, EVENT, RESTED, SAME, SETTLED, log_of, parts,  # noqa: E402
                                          profile_of, pushes_at, restore_views, stays_at_rest, step_on)
from finger_sim.kernel.numerics import JIT, OK  # noqa: E402

#: Columns of `run`'s output rows: q (3), q' (3), the θ error estimate (rad).
ROW = 7


@njit(**JIT)
def run(ws, k0, n, dt, command, flags, out):
    """Up to n steps from step index k0 (steps of dt, s) under the held `command` (N·m) or st's profile
    (`common_step`'s flags for the first step; the later ones continue it: SAME | AT_LAST); row i of
    out (n × ROW) gets step k0 + i's (q, q', estimate). Returns (steps taken, τ at the last one's end
    in N·m): fewer than n where a step must go to Python."""
    end = 0.0
    m, plan, st, arr, work = parts(ws)
    log, prof = log_of(ws), profile_of(st, flags)  # (flags' PROFILE bit is the same for every step)
    for i in range(n):
        k = k0 + i
        status, q, v, estimate, tau = step_on(m, plan, st, arr, work, log, prof, k * dt, (k + 1) * dt, command, flags)
        if status != OK and status != SETTLED:  # (SETTLED: crossings located and stepped past, as OK)
            if status == EVENT or status == ENDED or status == RESTED:  # a stretch hands Python the step as it
                restore_views(st, arr)  # was (`sim.step()` takes it again; after ENDED the next step does not start at the last
                # output; after RESTED the Simulator enters the rest mode)
            return i, end
        out[i, 0], out[i, 1], out[i, 2], out[i, 3], out[i, 4], out[i, 5] = q[0], q[1], q[2], v[0], v[1], v[2]
        out[i, 6] = estimate
        end = tau
        flags |= SAME | AT_LAST
    return n, end


@njit(**JIT)
def rest_run(ws, k0, n, dt, command, flags, sign, q0, q1, q2):
    """Up to n steps from step index k0 resting on a stop at q (q' = 0), while `stays_at_rest` keeps the
    rest (its arguments). Returns (steps taken, τ at the last one's end in N·m). A step's test at its start
    is the last one's at its end (the same state, time and torque): taken once (`pushes_at`)."""
    if n == 0:
        return 0, 0.0
    stays, end = stays_at_rest(ws, k0 * dt, (k0 + 1) * dt, command, flags, sign, q0, q1, q2)
    if not stays:
        return 0, 0.0
    m, _, st, _, _ = parts(ws)
    prof = profile_of(st, flags)
    for i in range(1, n):
        k = k0 + i
        stays, tau = pushes_at(m, prof, (k + 1) * dt, command, sign, q0, q1, q2)
        if not stays:
            return i, end
        end = tau
    return n, end
