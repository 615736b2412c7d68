"""Event location inside a step: the crossing predicted from a step's ends, and Illinois regula falsi.

Both are plain functions of floats and callables: the Simulator's gap events, the drive's mesh
guards (`actuators.stepping`, `actuators.inductive_stepping`) and the stick–slip turn all locate
their crossings with them; the compiled event checks compile `predicted_crossing` itself
(`kernel.event_checks`). `first_guard_crossing` is the one loop over a step's declared guards (an
element's mode guards, or the gaps of the non-smooth elements) that finds the earliest one it crosses.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import NamedTuple, TypeVar

#: A gap crossing (a stop) is located to this tolerance on the gap (rad for the MCP stops);
#: a gap counts as closed below −EVENT_TOLERANCE.
EVENT_TOLERANCE = 1e-12

#: A one-sided mode guard counts as crossed below −GUARD_TOLERANCE (its units: rad/s, N·m, ...).
GUARD_TOLERANCE = 1e-12
#: A located mode guard crossing is bracketed to this fraction of the step.
LOCATE_TOLERANCE = 1e-13
MAX_LOCATE_ITERATIONS = 100

#: What a trial step returns besides the guard's value: the state at the trial time (opaque here).
Payload = TypeVar("Payload")


class GuardCrossing(NamedTuple):
    """A located mode guard crossing: its time (s), the state there (the trial step's payload) and
    the guard's index in its owner's declaration."""

    t: float
    state: tuple
    guard: int


#: A guard declared ON_GAP (`first_guard_crossing`): a gap, two-sided and predicted from the step's ends
#: (it may close and open again inside the step), located onto its value by `regula_falsi_gap`.
ON_GAP = "gap"
#: A guard's declaration: one-sided (False), two-sided (True) or ON_GAP.
GuardKind = bool | str
#: An ON_GAP guard's search: onto_gap(k, g0, g1) → its located crossing in the step, or None.
OntoGap = Callable[[int, tuple, tuple], "GuardCrossing | None"]

#: A guard's value at the step's start: a number, or (a one-sided guard only) a callable that gives
#: it, called only when the step crosses (a start value that costs, or that can raise off the crossing).
StartValue = float | Callable[[], float]


def first_guard_crossing(kinds: tuple[GuardKind, ...], g0: tuple, g1: tuple,
                         at: Callable[[int, float], tuple[float, tuple]] | None, a: float, b: float,
                         far: tuple, onto_gap: OntoGap | None = None) -> GuardCrossing | None:
    """The earliest crossing of a step's guards in (a, b], located; None if the step crosses none.

    The guards are declared by `kinds` (one entry per guard, ≥ 0 while its mode holds): a
    one-sided guard (False, a mode's condition) crosses where its end value g1 is below
    −GUARD_TOLERANCE, located from max(g0, 0); a two-sided one (True, a kink of a mode guard) where
    g0 and g1 lie on opposite sides of 0. g0, g1: the guards at a and b (s), a one-sided guard's g0
    may be lazy (`StartValue`); `far` the state at b; at(k, s) → (guard k at s, state at s) takes a
    trial step. Each such crossing is located by `illinois` to LOCATE_TOLERANCE of the step, on the
    bracket's far side (the guard crossed). An ON_GAP guard's g0, g1 are its (gap, rate) at a and b,
    searched and located by `onto_gap` (a prediction between the ends, `regula_falsi_gap`). Of
    crossings at the same time the first declared counts.
    """
    first: GuardCrossing | None = None
    for k, kind in enumerate(kinds):
        if kind == ON_GAP:
            found = onto_gap(k, g0[k], g1[k])
            if found is not None and (first is None or found.t < first.t):
                first = found
            continue
        crossed = (g0[k] < 0.0) != (g1[k] < 0.0) if kind else g1[k] < -GUARD_TOLERANCE
        if not crossed:
            continue
        start = g0[k]
        ga = start if kind else max(start() if callable(start) else start, 0.0)
        s, state = illinois(lambda s, k=k: at(k, s), crossing_test(kind, ga), a, ga, b, g1[k], far,
                            width=LOCATE_TOLERANCE * (b - a), iterations=MAX_LOCATE_ITERATIONS)
        if first is None or s < first.t:
            first = GuardCrossing(s, state, k)
    return first


def crossing_test(two_sided: bool, ga: float) -> Callable[[float], bool]:
    """Whether a guard's value has crossed: a one-sided guard below 0, a two-sided one to the other
    side than its start value ga."""
    if not two_sided:
        return lambda g: g < 0.0
    side = ga < 0.0
    return lambda g: (g < 0.0) != side


def illinois(at: Callable[[float], tuple[float, Payload]], crossed: Callable[[float], bool], a: float, ga: float,
             b: float, gb: float, far: Payload, *, width: float, iterations: int) -> tuple[float, Payload]:
    """Where a guard g(s) crosses in (a, b]: Illinois regula falsi on the time s (s).

    ga = g(a) on the near side, gb = g(b) across (`crossed(gb)`), `far` the state at b;
    at(s) → (g(s), state at s) takes a trial step. The bracket shrinks until it is at most `width`
    long (s) or `iterations` trials are spent; a trial outside the open bracket (or a flat secant)
    bisects. Returns (s, state) at the bracket's far side, where the guard has crossed, so that the
    rest of the step does not see the crossing again.
    """
    keep = 0
    for _ in range(iterations):
        if b - a <= width:
            break
        s = b - gb * (b - a) / (gb - ga) if gb != ga else 0.5 * (a + b)
        if not a < s < b:
            s = 0.5 * (a + b)
        gs, state = at(s)
        across = crossed(gs)
        if across:
            far = state
        a, ga, b, gb, keep = illinois_update(a, ga, b, gb, keep, s, gs, across)
    return b, far


def illinois_update(a: float, ga: float, b: float, gb: float, keep: int, s: float, gs: float,
                    across: bool) -> tuple[float, float, float, float, int]:
    """The bracket [a, b] (g(a) = ga on the near side, g(b) = gb across) after a trial g(s) = gs,
    `across` or not, and `keep`: which end was kept last (1: a, −1: b, 0: none). Illinois: an end
    kept twice in a row has its value halved, so that the secant does not stall on a convex guard."""
    if across:
        return a, ga / 2 if keep == 1 else ga, s, gs, 1
    return s, gs, b, gb / 2 if keep == -1 else gb, -1


def regula_falsi_gap(ctx: object, t: float, q: tuple, v: tuple, a: float, ga: float, b: float, gb: float,
                     qb: tuple, vb: tuple, kink: bool, iterations: int) -> tuple[float, tuple, tuple]:
    """Where in (a, b] a gap crosses zero inside the step from (t, q, q'): Illinois regula falsi on
    g(s) = gap(q(s)), q(s) the step from t to s (s). Returns (s, q(s), q'(s)) of the crossing.

    g(a) = ga and g(b) = gb lie on opposite sides; (qb, vb) is the state at b. `trial(ctx, s)` →
    (g(s), q(s), q'(s)) takes a trial step, `gap_value(ctx, s, q)` → g at a given state: the Python
    path binds them to the Simulator's step and its element (`crossings.locate_gap`), the compiled one
    to the step's dense output and the compiled gaps (`kernel.locate_event`), so this loop is written
    once. The bracket's update is `illinois_update`; unlike `illinois`, this loop stops on the gap's
    value (or a trial outside the bracket, without bisecting) and keeps the last trial: an impact needs
    the point on the gap. A kink's crossing (`kink`) ends on the bracket's far side instead, so that the
    rest of the step does not see the crossing again.
    """
    s, gs, qs, vs = b, gb, qb, vb
    keep = 0
    for _ in range(iterations):
        s = b - gb * (b - a) / (gb - ga)
        # A step that starts on the gap (g(t) = 0) crosses at t itself: stepping a
        # zero-length interval would divide by zero in rattle and fail in scipy.
        if s > t:
            gs, qs, vs = trial(ctx, s)
        else:
            gs, qs, vs = gap_value(ctx, t, q), q, v
        if abs(gs) <= EVENT_TOLERANCE or s <= a or s >= b:
            break
        across = (gs > 0) == (gb > 0)
        if across:
            qb, vb = qs, vs
        a, ga, b, gb, keep = illinois_update(a, ga, b, gb, keep, s, gs, across)
    if kink and (gs < -EVENT_TOLERANCE) != (gap_value(ctx, b, qb) < -EVENT_TOLERANCE):
        return b, qb, vb  # the kink's far side
    return s, qs, vs


def trial(ctx: tuple, s: float) -> tuple[float, tuple, tuple]:
    """The Python path's trial step of `regula_falsi_gap`: ctx = (at, gap_at), at(s) → (g, q, q')."""
    return ctx[0](s)


def gap_value(ctx: tuple, s: float, q: tuple) -> float:
    """The Python path's gap at a given state of `regula_falsi_gap`: ctx[1](s, q)."""
    return ctx[1](s, q)


def predicted_crossing(ga: float, ra: float, gb: float, rb: float, h: float, closed: bool,
                       start_rate: bool = True) -> float | None:
    """Where (a fraction x of h, in (0, 1)) a gap that is on the same side at both ends of an
    interval of length h (s) may cross and come back inside it; None if nothing suggests so.

    ga, gb: the gap at the ends; ra, rb: its rates (gap units/s); closed: the side at both
    ends (below −EVENT_TOLERANCE). Two predictions, the earlier one counts (start_rate False:
    the second only):
    - the start's rate: ga + x h ra reaches zero at x < 1 (the start state is the trustworthy
      one: a step straddling a whole contact bounces in its stages and ends on the open side);
    - the cubic Hermite interpolant of (gap, rate) at both ends has an extremum across the
      side's bound at x (the contact, or the release, lies wholly inside the interval).
    """
    sign = 1.0 if closed else -1.0  # the direction that crosses
    best = None
    if start_rate and sign * ra > 0.0 and sign * (ga + h * ra) > -sign * EVENT_TOLERANCE:
        best = min(1.0, max(0.0, -ga / (h * ra)))
    # H(x) = ((a x + b) x + c) x + ga; H'(x) = 3a x² + 2b x + c
    a = 2.0 * (ga - gb) + h * (ra + rb)
    b = 3.0 * (gb - ga) - h * (2.0 * ra + rb)
    c = h * ra
    disc = b * b - 3.0 * a * c
    if disc >= 0.0:
        root = -(b + math.copysign(math.sqrt(disc), b))  # the stable quadratic formula
        for x in ((root / (3.0 * a)) if a != 0.0 else 2.0, (c / root) if root != 0.0 else 2.0):
            if 0.0 < x < 1.0 and ((((a * x + b) * x + c) * x + ga) < -EVENT_TOLERANCE) != closed:
                best = x if best is None else min(best, x)
    return best if best is not None and 0.0 < best < 1.0 else None
