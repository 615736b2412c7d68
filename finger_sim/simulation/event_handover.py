"""A kernel step that may hold a gap crossing, handed to Python advanced: its internal steps are not taken twice.

The kernel's common step (`kernel.event_step.common_step`) integrates the whole step before its end gaps
show a possible crossing (an onset, a release, an impact). It then answers EVENT and keeps the solution
advanced to the step's end, with each internal step it took in its log (`kernel.internal_steps.record`).
`hand_over` writes that solution into the integrator as Python's own step would have left it:

- the state at the last internal step;
- the history since the step's start: the internal step that covers the start (continued), then the new ones;
- the origin: the step's start;
- the torque function it ran under;
- where its watched internal steps stopped, if they did (a gap on its other side: `crossings.step_to_crossing`).

Python's step then answers its first step and every trial step of the event's location
(`simulation.crossings`) from that history (`DormandPrince853.step`'s first branch), on the same numbers.
Before, Python integrated the step again, around a stiff contact's onset tens of internal steps.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING, Any

from finger_sim.integrators.dop853 import DormandPrince853

if TYPE_CHECKING:
    from finger_sim.simulation.event_step import EventStep


def hand_over(step: EventStep, integ: DormandPrince853, fn: Any) -> None:
    """After `common_step` answered EVENT: its advanced solution and its history into `integ`, under the
    torque function `fn` (the object Python's step integrates under)."""
    k, steps = step._k, step._k.internal_steps  # noqa: SLF001
    log = step._log  # noqa: SLF001
    step._write_back(integ)  # noqa: SLF001  (the state at the last internal step, the origin and last output)
    history = []
    if log[steps.BRANCH] == steps.CONTINUED:  # the internal step covering the start, as it was before the step
        saved = step._st[k.SAVED:k.SAVED + k.N_SCALARS].tolist()  # noqa: SLF001
        before = step._arr[k.ROWS - k.KEPT:]  # noqa: SLF001  (y, f, y_old, dense before the step)
        history.append((saved[k.T_OLD], saved[k.H_OLD], before[k.Y_OLD].copy(), before[k.DENSE:k.KK].copy(),
                        saved[k.ERR_OLD], saved[k.ERR]))
    n = int(log[steps.COUNT])
    rows = log[steps.ROWS_AT:steps.ROWS_AT + n * steps.ROW_SIZE].reshape(n, steps.ROW_SIZE).copy()
    y_olds, denses = rows[:, steps.ROW_Y_OLD:steps.ROW_DENSE], rows[:, steps.ROW_DENSE:].reshape(n, 7, 6)  # views
    for (t_old, h_old, err_old, err), y_old, dense in zip(rows[:, :steps.ROW_Y_OLD].tolist(), y_olds, denses):
        history.append((t_old, h_old, y_old, dense, err_old, err))
    integ._history[:] = history  # noqa: SLF001
    integ._history_starts[:] = [entry[0] for entry in history]  # noqa: SLF001
    integ._torque = fn  # noqa: SLF001
    hit = float(step._st[k.HIT])  # noqa: SLF001  (a watched pass stopped: Python's watched step stops there too)
    integ._hit = hit if hit > -math.inf else None  # noqa: SLF001
