"""A Simulator's located gap crossing in one compiled call (`kernel.locate_event`), where the step allows.

`crossings.locate_gap` locates a crossing by Illinois regula falsi, each trial a `DormandPrince853.step`
from the step's start that its history answers (the internal steps already taken cover the bracket), and
the gap of the trial state from its element. `CompiledLocate` runs that loop in one kernel call on the
same numbers: the internal steps that can answer a trial (the history around the bracket, the current one)
go in as arrays, the gap comes from the compiled gap plan (`simulation.gap_screen`). Afterwards the
integrator is left as the trials would have left it: its last output is the last trial, and every trial
state's error estimate is recorded in order. Where a trial would need more than the history (a step not
continued from the trial's start, a trial past the internal solution, a failed dense output), it answers
None and Python locates the crossing as always.
"""

from __future__ import annotations

import bisect
import math
from typing import TYPE_CHECKING, Any

import numpy as np

from finger_sim import stepper_slot
from finger_sim.integrators import TorqueFn
from finger_sim.integrators.dop853 import DormandPrince853
from finger_sim.kinematics import Vec3
from finger_sim.simulation.crossings import MAX_LOCATE_ITERATIONS, Gap

if TYPE_CHECKING:
    from finger_sim.simulation.driver import Simulator

#: History rows kept on each side of the bracket's ends: a trial a rounding error outside the bracket
#: still finds the internal step `DormandPrince853._segment` would.
MARGIN_ROWS = 1


class CompiledLocate:
    """`crossings.locate_gap` in one kernel call (`__call__`), with its scratch arrays."""

    def __init__(self, plan: np.ndarray, compiled: Any) -> None:
        self._plan, self._k = plan, compiled
        self._meta = np.zeros(compiled.META_SIZE)
        self._work, self._x = np.empty((2, int(plan[0]))), np.empty(6)
        self._log = np.empty((MAX_LOCATE_ITERATIONS, compiled.LOG_SIZE))
        #: located crossings answered here (the rest went to Python), for tests and benchmarks
        self.taken = 0

    def compiled_calls(self) -> tuple[stepper_slot.CompiledCall, ...]:
        """`__call__`'s compiled call, with arguments of its types (`stepper_slot.CompiledCall`): 1-D, 2-D and 3-D
        float arrays (the model, the rows of the history), floats, (q, q') tuples and the kink flag."""
        q, rows = (0.0, 0.0, 0.0), np.empty((0, 6))
        return ((self._k.locate, (self._plan, self._plan, np.empty((0, 4)), rows, np.empty((0, 7, 6)), self._meta,
                                  self._work, self._x, self._log, 0.0, q, q, 0.0, 0.0, 0.0, 0.0, q, q, True)),)

    def __call__(self, sim: Simulator, gap: Gap, t: float, q: Vec3, v: Vec3, lo: tuple[float, float],
                 hi: tuple[float, float, Vec3, Vec3], torque: TorqueFn) -> tuple[float, Vec3, Vec3] | None:
        """(s, q(s), q'(s)) of `crossings.locate_gap(sim, gap, …)`, or None: Python locates it."""
        integ = sim.integrator
        if (not isinstance(integ, DormandPrince853) or torque is not integ._torque  # noqa: SLF001
                or integ._origin != (t, q, v)):  # noqa: SLF001
            return None  # a trial would restart the solution: Python's step does that
        k, meta = self._k, self._meta
        a, ga = lo
        b, gb, qb, vb = hi
        starts, history = integ._history_starts, integ._history  # noqa: SLF001
        n = len(starts)
        i0 = max(0, bisect.bisect_right(starts, a) - MARGIN_ROWS) if n else 0
        i1 = min(n, bisect.bisect_right(starts, b) + MARGIN_ROWS) if n else 0
        rows = history[i0:i1]
        current = (integ._t_old, integ._h_old, integ._y_old, integ._dense, integ._err_old, integ._err)  # noqa: SLF001
        rows.append(current)
        segs = np.array([(t_old, h_old, err_old, err) for t_old, h_old, _, _, err_old, err in rows])
        y_olds = np.array([row[2] for row in rows])
        denses = np.array([row[3] for row in rows])
        meta[:] = (len(rows) - 1, sim._gaps.index(gap), 0.0, 0.0, starts[i0] if i0 > 0 else -math.inf,  # noqa: SLF001
                   starts[i1] if i1 < n else math.inf, integ._t)  # noqa: SLF001
        s, qs, vs = k.locate(integ._model, self._plan,  # noqa: SLF001
                             segs, y_olds, denses, meta, self._work, self._x, self._log, t, q, v,
                             a, ga, b, gb, qb, vb, gap.restitution is None)
        if meta[k.META_FAILED] != 0.0:
            return None  # Python takes the trials again (their effects on the integrator are the same)
        count = int(meta[k.META_COUNT])
        if count:
            last = None
            for row in self._log[:count].tolist():
                q_trial = (row[1], row[2], row[3])
                integ.store_estimate(q_trial, row[7])
                last = (row[0], q_trial, (row[4], row[5], row[6]))
            integ._last = last  # noqa: SLF001
        self.taken += 1
        return s, qs, vs


def for_simulator(sim: Simulator) -> CompiledLocate | None:
    """The compiled location of `sim`'s crossings, or None (no compiled gap plan, not the compiled DOP853)."""
    screen = sim._gap_screen  # noqa: SLF001
    integ = sim.integrator
    if screen is None or type(integ) is not DormandPrince853 or not integ.compiled:
        return None
    return CompiledLocate(screen._plan, stepper_slot.kernel().compiled_locate_event())  # noqa: SLF001
