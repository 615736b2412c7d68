"""The gap events of a Simulator's non-smooth force elements: a stop impact, a contact onset or release.

Every gap of every non-smooth element (`ForceElement.gaps`) is an event function, declared to the one
guard loop (`locate.first_guard_crossing`) as an ON_GAP guard. A step whose ends, or whose predicted
path (`locate.predicted_crossing`), show a gap crossing is searched for it (`bracket`), and the crossing
located by Illinois regula falsi on the gap (`locate_gap`, `locate.regula_falsi_gap`); the Simulator
ends the step there. The functions read the Simulator's set-up (`_gaps`, `_gap_elements`,
`_depth_sources`, `_timed`) and take its trial steps (`Simulator._step`).
"""

from __future__ import annotations

from typing import TYPE_CHECKING, NamedTuple

import numpy as np

from finger_sim.depth_guard import DepthLimit
from finger_sim.effects import ForceElement
from finger_sim.integrators import TorqueFn
from finger_sim.integrators.dop853 import DormandPrince853
from finger_sim.kinematics import ZERO, Vec3
from finger_sim.simulation.locate import (EVENT_TOLERANCE, GapSearch, GuardCrossing, first_guard_crossing,
                                         predicted_crossing, regula_falsi_gap)

if TYPE_CHECKING:
    from finger_sim.simulation.driver import Simulator

#: Regula-falsi iterations allowed to locate one crossing.
MAX_LOCATE_ITERATIONS = 60
#: A NamedTuple made without its Python-level __new__ (as `locate._new`).
_new = tuple.__new__
#: q' = 0: the gaps' values alone are asked (`closed_sides`).
#: How deep `bracket` refines a predicted crossing inside a step that its check did not confirm
#: (each level probes both halves: at most 2^depth − 1 extra integrator steps).
BRACKET_DEPTH = 3


class Gap(NamedTuple):
    """One event function of a non-smooth element: gap `index` of `element`, and the restitution
    of its impact (None: crossing it is a kink only)."""

    element: ForceElement
    index: int
    restitution: float | None


class Crossing(NamedTuple):
    """A located crossing: where the sub-step ends (t, q, q') and the gap that crossed."""

    t: float
    q: Vec3
    v: Vec3
    gap: Gap


def first_crossing(sim: Simulator, t: float, q: Vec3, v: Vec3, t1: float, q1: Vec3, v1: Vec3,
                   torque: TorqueFn) -> Crossing | None:
    """The earliest gap crossing in (t, t1] of the step (t, q, q') → (t1, q1, q1'), or None.

    A gap crosses when it is closed at one end of the step and open at the other (an impact
    gap, a stop, counts as open at the start: the step starts off it), or when it closes and
    opens again inside the step, which the ends alone do not show (a contact shorter than
    a step): `bracket` looks for that between the ends. A step that the compiled check clears
    (`Simulator._gap_screen`, the same numbers and tests) returns None at once.
    """
    screen = sim._gap_screen
    if screen is not None and screen.clear(t, q, v, t1, q1, v1):
        return None
    gaps = sim._gaps

    def across(k: int, g0: float, g1: float) -> GuardCrossing:
        crossing = sim._locate(gaps[k], t, q, v, (t, g0), (t1, g1, q1, v1), torque)  # `locate_gap`
        return GuardCrossing(crossing.t, (crossing.q, crossing.v), k)

    def inside(k: int, g0: float, r0: float, g1: float, r1: float, x: float) -> GuardCrossing | None:
        found = bracket(sim, gaps[k], t, q, v, torque, (t, g0, r0), (t1, g1, r1, q1, v1), x, BRACKET_DEPTH)
        if found is None:
            return None
        crossing = sim._locate(gaps[k], t, q, v, (t, g0), found, torque)
        return GuardCrossing(crossing.t, (crossing.q, crossing.v), k)

    search = _new(GapSearch, (sim._gap_impacts, across, inside))
    start = gap_states(sim, t, q, v)
    event = first_guard_crossing(sim._gap_kinds, start, gap_states(sim, t1, q1, v1), None, t, t1, (q1, v1), search)
    first = None if event is None else Crossing(event.t, *event.state, gaps[event.guard])
    if first is not None and isinstance(first.gap.element, DepthLimit):  # a phalanx axis reached an object
        raise first.gap.element.crossed(first.gap.index, first.t, first.q, first.v, sim.method)
    cut = getattr(sim.integrator, "cut_at", None)
    if first is not None and first.gap.restitution is None and cut is not None:
        # a kink: its state from internal steps that end there (`DormandPrince853.cut_at`), the rest of the
        # step continued from it, so that no internal step straddles the non-smooth force
        onset = not start[event.guard][0] < -EVENT_TOLERANCE  # open at the step's start: the contact closes
        ended = cut(first.t, t, q, v, torque, onset)
        if ended is not None:
            first = Crossing(first.t, *ended, first.gap)
    return first


def watch_for(sim: Simulator) -> GapWatch | None:
    """What the Simulator's steps in its gap loop watch (`step_to_crossing`), or None: they are not watched (the
    Simulator takes its plain step, `Simulator._step`). Watched: our DOP853 without substeps (its integrator's
    class is set when it is built)."""
    if not issubclass(sim._integrator_cls, DormandPrince853) or (sim.substeps != 1 and sim._kinks):
        return None
    return GapWatch(sim)


def step_to_crossing(sim: Simulator, t: float, q: Vec3, v: Vec3, t1: float,
                     torque: TorqueFn) -> tuple[float, Vec3, Vec3]:
    """The step of a watched Simulator (`watch_for`) from (t, q, q') toward t1 (s) that `first_crossing` then
    searches: (its end time, q1, q1'). DOP853 stops it one internal step past the first that ends before t1 with
    a gap on the other side than at t (`DormandPrince853.step`'s watch: the internal state's gaps, an impact gap
    open at t), so that the internal steps past a kink, which the cut drops (`DormandPrince853.cut_at`), are not
    taken to t1; the end is then that step's. The one step past it keeps the location's far end off the crossing
    (regula falsi's far side, which a kink's location returns, may never move from a bracket end that close) and
    gives the restart after an onset its step (`dop853.restart_step`). The kernel's event step stops at the same
    internal step (`kernel.event_step._advance_to`), and so does the compiled chunk of internal steps
    (`GapWatch.compiled`)."""
    integ = sim.integrator
    q1, v1 = integ.step(t, q, v, t1 - t, torque, sim._watch)
    end = integ._last[0]  # noqa: SLF001  (the output's time: t + (t1 − t), or the watched stop before it)
    return (end if end < t + (t1 - t) else t1), q1, v1


class GapWatch:
    """What `DormandPrince853.step` watches in a Simulator's watched steps (`watch_for`, `dop853.Watch`): whether an
    internal step's end shows a gap on the other side than at the step's start (`closed_sides`, an impact gap open
    at the start), the start's sides found once per start. The compiled chunk of internal steps asks the same of
    the gap plan (`compiled`: `kernel.gap_screen.crossed`, the same numbers)."""

    __slots__ = ("_sim", "_gaps", "_start", "_sides")

    def __init__(self, sim: Simulator) -> None:
        self._sim = sim
        screen = sim._gap_screen
        self._gaps = None if screen is None else screen.for_watch()
        self._start: tuple[float, Vec3] | None = None  # the start (t, q) whose sides _sides holds
        self._sides: list[bool] = []

    def crossed(self, t: float, q: Vec3, s: float, y: np.ndarray) -> bool:
        """Whether the internal state y = (q, q') at s (s) has a gap on its other side than the step's start (t, q)."""
        start = self._start
        if start is None or start[1] is not q or start[0] != t:
            self._start, self._sides = (t, q), closed_sides(self._sim, t, q, open_impacts=True)
        return closed_sides(self._sim, s, (float(y[0]), float(y[1]), float(y[2]))) != self._sides

    def compiled(self) -> tuple[np.ndarray, np.ndarray] | None:
        """The gap plan and a work array of its own (4 × n_gaps) for the compiled chunk
        (`kernel.internal_steps.advance_to`); None: the gaps have no compiled form (`simulation.gap_screen`)."""
        return self._gaps


def closed_sides(sim: Simulator, t: float, q: Vec3, open_impacts: bool = False) -> list[bool]:
    """Whether each gap (in `_gaps` order) is closed (below −EVENT_TOLERANCE) at (t, q); with `open_impacts` an
    impact gap counts as open (a step's start: `locate.gap_guard`)."""
    states = gap_states(sim, t, q, ZERO)
    if open_impacts:
        return [g < -EVENT_TOLERANCE and not impact for (g, _), impact in zip(states, sim._gap_impacts)]
    return [g < -EVENT_TOLERANCE for g, _ in states]


def gap_states(sim: Simulator, t: float, q: Vec3, v: Vec3) -> list[tuple[float, float]]:
    """(gap, gap') of every gap at (t, q, q') in `_gaps` order: gap' = ∂gap/∂q · q' (+ ∂gap/∂t
    for a moving object). The last state asked is kept: a step's end is the next one's start."""
    cached = sim._gap_cache
    if cached is not None and cached[0] is q and cached[1] is v and (not sim._timed or cached[3] == t):
        return cached[2]
    out = []
    for element, indices in sim._gap_elements:
        if element in sim._timed:
            values, rates = element.gaps_at(t, q), element.gap_rates(t, q, v)
            out.extend((values[i], rates[i]) for i in indices)
            continue
        values = element.gaps(q)
        for i in indices:
            n = element.gap_gradient(i, q)
            out.append((values[i], n[0] * v[0] + n[1] * v[1] + n[2] * v[2]))
    out.extend((out[p][0] + rho, out[p][1]) for p, rho in sim._depth_sources)  # ρ − δ, at the rate of −δ
    sim._gap_cache = (q, v, out, t)
    return out


def bracket(sim: Simulator, gap: Gap, t: float, q: Vec3, v: Vec3, torque: TorqueFn,
            lo: tuple[float, float, float], hi: tuple[float, float, float, Vec3, Vec3], x: float,
            depth: int) -> tuple[float, float, Vec3, Vec3] | None:
    """(s, gap, q, q') at a time s in (lo, hi] where the gap is on the other side than at lo,
    or None. lo = (s, gap, gap'), hi = (s, gap, gap', q, q'): states of the step from
    (t, q, q') on the same side of the gap, so the state at s is one step from t.

    The gap crosses and comes back inside, as `predicted_crossing` predicts from the ends' values
    and rates (at the fraction x of the interval, `locate.gap_guard`): checked by stepping to the
    predicted time; a check that finds no crossing checks the cubic's extremum too (the start's
    rate falls short of a convex gap's crossing, e.g. an axis passing a circle), then refines on
    both halves where their ends predict a crossing, `depth` levels deep in all (≥ 1).
    """
    sa, ga, ra = lo
    sb, gb, rb, _, _ = hi
    closed = ga < -EVENT_TOLERANCE
    s = sa + x * (sb - sa)
    qs, vs = sim._step(t, q, v, s - t, torque)
    gs, rs = gap_states(sim, s, qs, vs)[sim._gaps.index(gap)]
    if (gs < -EVENT_TOLERANCE) != closed:
        return s, gs, qs, vs
    extremum = predicted_crossing(ga, ra, gb, rb, sb - sa, closed, False)
    if extremum is not None and extremum > x:
        s2 = sa + extremum * (sb - sa)
        q2, v2 = sim._step(t, q, v, s2 - t, torque)
        g2, _ = gap_states(sim, s2, q2, v2)[sim._gaps.index(gap)]
        if (g2 < -EVENT_TOLERANCE) != closed:
            return s2, g2, q2, v2
    if depth == 1:
        return None
    for part_lo, part_hi in ((lo, (s, gs, rs, qs, vs)), ((s, gs, rs), hi)):  # both halves on lo's side
        y = predicted_crossing(part_lo[1], part_lo[2], part_hi[1], part_hi[2], part_hi[0] - part_lo[0], closed)
        found = None if y is None else bracket(sim, gap, t, q, v, torque, part_lo, part_hi, y, depth - 1)
        if found is not None:
            return found
    return None


def locate_gap(sim: Simulator, gap: Gap, t: float, q: Vec3, v: Vec3, lo: tuple[float, float],
               hi: tuple[float, float, Vec3, Vec3], torque: TorqueFn) -> Crossing:
    """Where in (lo, hi] the gap crosses zero: Illinois regula falsi on g(s) = gap(q(s)),
    q(s) the step from (t, q, q') to s. lo = (s, gap), hi = (s, gap, q, q') (`bracket`).

    An impact is applied at the located point (|g| ≤ EVENT_TOLERANCE); a kink's step ends
    on its far side, so that the rest of the step does not see the crossing again. The loop is
    `locate.regula_falsi_gap`; with the compiled event step it runs in one kernel call on the step's
    dense output (`simulation.event_locate`), else here with the Simulator's trial steps.
    """
    events = sim._event_step
    if events is not None and events.locate is not None:  # every trial from the logged dense output, compiled
        found = events.locate(sim, gap, t, q, v, lo, hi, torque)
        if found is not None:
            return Crossing(*found, gap)
    step, element, index = sim._step, gap.element, gap.index
    timed = element in sim._timed

    def gap_at(s: float, qs: Vec3) -> float:
        return element.gaps_at(s, qs)[index] if timed else element.gaps(qs)[index]

    def at(s: float) -> tuple[float, Vec3, Vec3]:
        qs, vs = step(t, q, v, s - t, torque)
        return gap_at(s, qs), qs, vs

    # g(a) and g(b) lie on opposite sides.
    a, ga = lo
    b, gb, qb, vb = hi
    s, qs, vs = regula_falsi_gap((at, gap_at), t, q, v, a, ga, b, gb, qb, vb, gap.restitution is None,
                                 MAX_LOCATE_ITERATIONS)
    return Crossing(s, qs, vs, gap)
