"""Many steps of a Simulator on a scene with events, in stretches of one compiled call each.

`advance(sim, n)` steps the Simulator n times under its scene's torque, as n calls of `sim.step()`
would, with the same numbers. Where the Simulator's compiled common step (`simulation.event_step`)
holds the solution, the steps that need no Python decision run in one kernel call
(`kernel.event_run`): the same compiled step, looped, its outputs in a preallocated array. The
call returns at the first step that needs Python (a crossing to locate, an impact, a release from a
stop the kernel does not decide), and at the last step before a switch of a
piecewise-constant profile; that step goes through `sim.step()`, and the next stretch follows (taking
the solution over from Python's step as `EventStep.step` does).

What `EventStep.step` does after each of its steps is done once per stretch (`EventStep._took`): the
Simulator's state, torque and step index, the integrator's torque function; and its estimates
(`DormandPrince853.defer_estimates`, which builds the dict of estimates only when it is read;
`_remember_all` where a drop is due).
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

import numpy as np

from finger_sim.inputs import steps_on_segment
from finger_sim.integrators.dop853 import KEEP_OUTPUTS, MAX_OUTPUTS
from finger_sim.kernel import event_run
from finger_sim.kinematics import ZERO
from finger_sim.simulation.event_step import EventStep

#: The columns of `event_run.run`'s rows that `DormandPrince853.defer_estimates` keeps: q, the estimate.
ESTIMATE_COLUMNS = [0, 1, 2, 6]

if TYPE_CHECKING:
    from finger_sim.simulation.driver import Simulator


def advance(sim: Simulator, n: int) -> np.ndarray:
    """Step `sim` n times under its scene's torque; the (n, 6) states (q, q') after each step."""
    events = sim._event_step  # noqa: SLF001
    assert events is not None
    xs = np.empty((n, 6))
    rows = np.empty((n, event_run.ROW))
    done = 0
    while done < n:
        done += _stretch(sim, events, event_run, rows[done:], xs[done:], n - done)
        if done < n:  # the step that needs Python (or the one the kernel takes over from it)
            state = sim.step()
            xs[done] = (*state.q, *state.v)
            done += 1
    return xs


def _stretch(sim: Simulator, events: EventStep, compiled: Any, rows: np.ndarray, xs: np.ndarray, n: int) -> int:
    """Up to n steps of `sim` in one kernel call, their states into xs; the number taken (0: the next
    step is Python's, or the kernel must take it over first through `EventStep.step`)."""
    integ = sim.integrator
    if not events.claim(integ):  # as `EventStep.step`: another hand stepped the solution (Python takes the step)
        return 0
    k, dt, profile = sim.step_index, sim.dt, sim.scene.torque
    n = min(n, steps_on_segment(profile, k, dt, n))
    if n <= 0:
        return 0
    if events._constant is not None:  # noqa: SLF001  (the scene's constant torque)
        fn, value, flags = events._constant, events._constant_value, 0  # noqa: SLF001
    else:
        fn, value, flags = events._profile_step(profile, k * dt, (k + 1) * dt)  # noqa: SLF001
    if fn is None:
        return 0
    if events.locates and (fn is events._constant or flags != 0):  # noqa: SLF001  (as `EventStep.step`)
        flags |= events._locate  # noqa: SLF001
    if sim._resting is not None:  # noqa: SLF001  (the stop's rest mode: `EventStep._rest`, looped)
        events.release()
        gap, q = sim._resting, sim.q  # noqa: SLF001
        count, end = compiled.rest_run(events._ws, k, n, dt, value, flags,  # noqa: SLF001
                                       gap.element.gap_gradient(gap.index, q)[0], *q)
        if count:
            xs[:count, :3], xs[:count, 3:] = q, ZERO
            sim.v, sim.torque, sim.step_index = ZERO, end, k + count
            events.taken += count
        return count
    if not events._holds:  # noqa: SLF001
        events._take_over(integ)  # noqa: SLF001  (the solution Python's last step left)
    if fn is integ._torque:  # noqa: SLF001
        flags |= events._same  # noqa: SLF001
    if sim.q is events._q and sim.v is events._v:  # noqa: SLF001
        flags |= events._at_last  # noqa: SLF001
    else:  # a state the kernel did not produce
        events._st[events._x] = (*sim.q, *sim.v)  # noqa: SLF001
    count, end = compiled.run(events._ws, k, n, dt, value, flags, rows)  # noqa: SLF001
    events.count_impacts(sim)  # bounces on a stop applied in the stretch
    if count:
        xs[:count] = rows[:count, :6]
        last = rows[count - 1].tolist()
        q, v = (last[0], last[1], last[2]), (last[3], last[4], last[5])
        block = rows[:count - 1, ESTIMATE_COLUMNS]  # (a copy: rows is the next stretch's buffer)
        if not integ.defer_estimates(block, q, last[6]):  # the dict is built when read, if ever
            _remember_all(integ, rows[:count], q, last[6])
        events._took(sim, integ, fn, k + count - 1, (k + count) * dt, q, v, end, q)  # noqa: SLF001  (as its last step)
        events.taken += count
    return count


def _remember_all(integ: Any, rows: np.ndarray, q: tuple, estimate: float) -> None:
    """The integrator's estimates after one `_remember` per row (q, q', estimate), as `EventStep.step`
    records them: at MAX_OUTPUTS the oldest are dropped down to KEEP_OUTPUTS. Only the rows that
    survive the drops are made into keys; the last one is the state q itself (the same tuple)."""
    estimates = integ._estimates  # noqa: SLF001
    count, size = len(rows), len(estimates)
    if size + count <= MAX_OUTPUTS:  # no drop: every row, in place
        new = count
    else:  # the first drop at insertion MAX_OUTPUTS − size, then one per MAX_OUTPUTS − KEEP_OUTPUTS insertions
        after = count - max(0, MAX_OUTPUTS - size)  # insertions from the first drop on
        final = KEEP_OUTPUTS + 1 + (after - 1) % (MAX_OUTPUTS - KEEP_OUTPUTS)
        new = min(count, final)
        estimates = integ._estimates = dict(list(estimates.items())[size - (final - new):] if final > new else [])  # noqa: SLF001
    estimates.update(((r[0], r[1], r[2]), r[6]) for r in rows[count - new:count - 1].tolist())
    estimates[q] = estimate
