"""A Simulator's step-end gap check in one compiled call (`kernel.gap_screen`), where the scene allows.

`crossings.first_crossing` evaluates every gap and its rate at both ends of a step in Python and
looks for a crossing; on nearly every step there is none. `GapScreen.clear` answers that common
case in one kernel call on the same numbers and tests, keeping the step's end gaps as the next
step's start; a step it cannot clear goes through the Python check unchanged. A screen exists
when the Simulator runs compiled and every gap is a stop's, a fixed-object contact's
(`Contact`, spec §7) or a depth gap (`depth_guard`); else the Python check runs alone.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

import numpy as np

from finger_sim import stepper_slot
from finger_sim.effects.contact import Contact
from finger_sim.effects.stops import JointStops
from finger_sim.kinematics import Vec3

if TYPE_CHECKING:
    from finger_sim.simulation.driver import Simulator

#: The kinds of a gap plan's groups (`kernel.gap_screen`).
STOPS, CONTACT = 1.0, 2.0


def plan_for(sim: Simulator) -> np.ndarray | None:
    """The gap plan of `sim`'s gaps (layout in `kernel.gap_screen`), or None when a gap has no
    compiled form (a moving object, another element's gap) or its gaps are not in their element's order."""
    if sim._timed:
        return None
    body: list[float] = []
    for element, indices in sim._gap_elements:
        if type(element) is JointStops and indices == (0, 1):
            params = (element.lower, element.upper)
            kind = STOPS
        elif type(element) is Contact and indices == tuple(range(len(element.candidates()))):
            params = element.kernel_params()
            kind = CONTACT
        else:
            return None
        body += [kind, float(len(params)), *params]
    depth = [x for p, rho in sim._depth_sources for x in (float(p), rho)]
    n = len(sim._gaps)
    if n != sum(len(indices) for _, indices in sim._gap_elements) + len(sim._depth_sources):
        return None
    # an impact gap's flag: its gradient's θ1 component (±1 for the stops), which the kernel's rest test reads
    impacts = [0.0 if gap.restitution is None else gap.element.gap_gradient(gap.index, (0.0, 0.0, 0.0))[0]
               for gap in sim._gaps]
    return np.array([float(n), float(len(sim._gap_elements)), *body, float(len(sim._depth_sources)), *depth,
                     *impacts], dtype=np.float64)


class GapScreen:
    """The compiled check of a Simulator's steps (`clear`), with the last step's end gaps kept."""

    def __init__(self, plan: np.ndarray, compiled: Any) -> None:
        self._plan, self._screen = plan, compiled.screen
        self._work = np.empty((4, int(plan[0])))
        self.reset()

    def compiled_calls(self) -> tuple[stepper_slot.CompiledCall, ...]:
        """`clear`'s compiled call, with arguments of its types (`stepper_slot.CompiledCall`)."""
        q = (0.0, 0.0, 0.0)
        return ((self._screen, (self._plan, self._work, 0, False, 0.0, q, q, q, q)),)

    def for_watch(self) -> tuple[np.ndarray, np.ndarray]:
        """The gap plan and a work array of its own, for the compiled watch of DOP853's internal steps
        (`crossings.GapWatch`)."""
        return self._plan, np.empty_like(self._work)

    def reset(self) -> None:
        """Forget the kept gaps (a new run, or a state the screen did not produce)."""
        self._end: tuple[Vec3, Vec3] | None = None  # the state whose gaps rows _side, _side + 1 hold
        self._side = 0

    def clear(self, t: float, q: Vec3, v: Vec3, t1: float, q1: Vec3, v1: Vec3) -> bool:
        """Whether the step (t, q, q') → (t1, q1, q1') certainly holds no gap crossing, so that
        `crossings.first_crossing` would return None; False: let it look."""
        end, a = self._end, self._side
        known = end is not None and end[0] is q and end[1] is v
        if self._screen(self._plan, self._work, a, known, t1 - t, q, v, q1, v1):
            self._end = None
            return False
        self._end, self._side = (q1, v1), 2 - a
        return True


def for_simulator(sim: Simulator) -> GapScreen | None:
    """The compiled gap check of `sim`, or None (the Python kernel, no gaps, a gap without a compiled form)."""
    if not sim._gaps or not sim.kernel.startswith("numba"):
        return None
    plan = plan_for(sim)
    return None if plan is None else GapScreen(plan, stepper_slot.kernel().compiled_gap_screen())
