"""The rollout's compiled loop: many fingers, each stepped by the Simulator's own compiled step.

`run` loops `numerics._profile_step`, the one function that `Simulator.step` (through
`FastStepper`) and `simulate` (through `numerics.fast_run`) call for a smooth scene, over the
fingers (numba `prange`: every thread) and their steps. Nothing here steps a finger any other
way, so a row's numbers are the Simulator's bit for bit. A finger stops at a step whose status
is not OK (a torque switch inside the step, BREAKPOINT, which the Python side hands to the
finger's Simulator; or a failure, which it raises) and reports where.
"""

from __future__ import annotations

import numpy as np

from finger_sim.kernel import use_writable_cache

use_writable_cache()  # before numba reads NUMBA_CACHE_DIR
from numba import njit, prange  # noqa: E402  (after the cache folder is set)

from finger_sim.kernel.numerics import OK, _profile_step, plan_parts  # noqa: E402

PARALLEL = {"cache": True, "nogil": True, "error_model": "numpy", "parallel": True}


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
