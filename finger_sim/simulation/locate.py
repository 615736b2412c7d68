"""Event location inside a step: the crossing predicted from a step's ends, and Illinois regula falsi.

Both are plain functions of floats and callables: the Simulator's gap events, the drive's mesh
guards (`actuators.stepping`, `actuators.inductive_stepping`) and the stick–slip turn all locate
their crossings with them; the compiled event checks compile `predicted_crossing` itself
(`kernel.event_checks`). `first_guard_crossing` is the one loop over a step's declared guards (an
element's mode guards, or the gaps of the non-smooth elements) that finds the earliest one it crosses:
`guard_loop` with `gap_guard`, written once for Python and for the compiled event step.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
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


#: A guard's declaration (`first_guard_crossing`): one-sided (a mode's condition, ≥ 0 while the mode
#: holds; False declares it too), two-sided (a kink of a mode guard; True too), or ON_GAP: a gap, two-sided
#: and predicted from the step's ends (it may close and open again inside the step), located onto its
#: value by `regula_falsi_gap`.
ONE_SIDED, TWO_SIDED, ON_GAP = 0, 1, 2
GuardKind = int
#: A guard's search answers (`guard_loop`): no crossing; one crossed, located; the caller must look (a
#: compiled search that cannot answer, before it changed anything).
NONE, FOUND, DECLINE = 0, 1, 2

#: A guard's value at the step's start: a number, or (a one-sided guard only) a callable that gives
#: it, called only when the step crosses (a start value that costs, or that can raise off the crossing).
StartValue = float | Callable[[], float]


class GapSearch(NamedTuple):
    """How the Python path searches a step's ON_GAP guards past `gap_guard`'s tests: impact[k], whether
    guard k is an impact gap (a stop: it counts as open at the step's start); across(k, g0, g1) → the
    crossing located between ends on opposite sides; inside(k, g0, r0, g1, r1, x) → the crossing that
    `predicted_crossing` predicts at the fraction x of the step between ends on the same side, found by
    trial steps and located, or None."""

    impact: Sequence[bool]
    across: Callable[[int, float, float], GuardCrossing]
    inside: Callable[[int, float, float, float, float, float], GuardCrossing | None]


def first_guard_crossing(kinds: Sequence[GuardKind], g0: Sequence, g1: Sequence,
                         at: Callable[[int, float], tuple[float, tuple]] | None, a: float, b: float,
                         far: tuple, gaps: GapSearch | None = None) -> GuardCrossing | None:
    """The earliest crossing of a step's guards in (a, b], located; None if the step crosses none.

    The guards are declared by `kinds` (one entry per guard): a one-sided guard crosses where its end
    value g1 is below −GUARD_TOLERANCE, located from max(g0, 0); a two-sided one where g0 and g1 lie on
    opposite sides of 0. g0, g1: the guards at a and b (s), a one-sided guard's g0 may be lazy
    (`StartValue`); `far` the state at b; at(k, s) → (guard k at s, state at s) takes a trial step. Each
    such crossing is located by `illinois` to LOCATE_TOLERANCE of the step, on the bracket's far side (the
    guard crossed). An ON_GAP guard's g0, g1 are its (gap, rate) at a and b, tested by `gap_guard` and
    searched and located by `gaps`. Of crossings at the same time the first declared counts. The loop is
    `guard_loop`, which the compiled event step compiles from its source (`kernel.event_crossing`).
    """
    ctx = _new(_Guards, (kinds, g0, g1, at, far, gaps, {}))
    status, k = guard_loop(ctx, len(kinds), a, b)
    return ctx.found[k] if status == FOUND else None


def guard_loop(ctx, n: int, a: float, b: float) -> tuple[int, int]:  # type: ignore[no-untyped-def]
    """The earliest of n declared guards to cross in the step (a, b] (s): (FOUND, its index), (NONE, −1),
    or (DECLINE, the guard whose search or `keep` declined). Of crossings at the same time the first
    declared counts.

    Written once for both paths: the per-guard work is behind the functions it calls by name,
    `guard_kind(ctx, k)` (its declaration), `gap_guard(ctx, k, a, b)` and `mode_guard(ctx, k, kind, a, b)`
    (each → (status, the crossing's time)) and `keep(ctx, k, t)` (the crossing becomes the earliest so far
    → FOUND or DECLINE).
    `first_guard_crossing` runs it with this module's (ctx a `_Guards`); the compiled event step compiles
    it with its own bound under those names (`kernel.jit.compiled`).
    """
    first, first_t = -1, 0.0
    for k in range(n):
        kind = guard_kind(ctx, k)
        if kind == ON_GAP:
            status, t = gap_guard(ctx, k, a, b)
        else:
            status, t = mode_guard(ctx, k, kind, a, b)
        if status == FOUND and (first < 0 or t < first_t):
            status = keep(ctx, k, t)
            first, first_t = k, t
        if status == DECLINE:
            return DECLINE, k
    if first < 0:
        return NONE, first
    return FOUND, first


def gap_guard(ctx, k: int, a: float, b: float) -> tuple[int, float]:  # type: ignore[no-untyped-def]
    """An ON_GAP guard's search in the step (a, b] (s) → (status, the crossing's time): its (gap, rate) at
    both ends from `gap_ends(ctx, k)`; an impact gap counts as open at the start. A gap open at both ends
    and too far to close inside is skipped; ends on opposite sides cross (`onto_gap` locates it); ends on
    the same side cross only where `predicted_crossing` predicts it (`inside_step` looks there).
    Written once for both paths, as `guard_loop`."""
    g0, r0, g1, r1, impact = gap_ends(ctx, k)
    if impact:
        g0 = max(g0, 0.0)  # an impact gap: the step starts on the open side
    h = b - a
    if min(g0, g1) > h * (abs(r0) + abs(r1)):
        return NONE, 0.0  # open at both ends, and too far for `predicted_crossing` to see a crossing between
    closed = g0 < -EVENT_TOLERANCE
    if (g1 < -EVENT_TOLERANCE) != closed:
        return onto_gap(ctx, k, g0, g1, impact)
    x = predicted_crossing(g0, r0, g1, r1, h, closed)
    if x is None:
        return NONE, 0.0
    return inside_step(ctx, k, g0, r0, g1, r1, x)


#: A NamedTuple made without its Python-level __new__, which costs about as much as a guard's tests.
_new = tuple.__new__


class _Guards(NamedTuple):
    """The Python path's ctx of `guard_loop`: `first_guard_crossing`'s arguments, and the crossings
    found, by guard."""

    kinds: Sequence[GuardKind]
    g0: Sequence
    g1: Sequence
    at: Callable[[int, float], tuple[float, tuple]] | None
    far: tuple
    gaps: GapSearch | None
    found: dict[int, GuardCrossing]


def guard_kind(ctx: _Guards, k: int) -> GuardKind:
    """Guard k's declaration (Python path)."""
    return ctx.kinds[k]


def mode_guard(ctx: _Guards, k: int, kind: GuardKind, a: float, b: float) -> tuple[int, float]:
    """A one-sided or two-sided guard's search in (a, b] (Python path): `first_guard_crossing`'s tests,
    located by `illinois` on ctx.at."""
    g0, g1 = ctx.g0[k], ctx.g1[k]
    crossed = (g0 < 0.0) != (g1 < 0.0) if kind else g1 < -GUARD_TOLERANCE
    if not crossed:
        return NONE, 0.0
    ga = g0 if kind else max(g0() if callable(g0) else g0, 0.0)
    s, state = illinois(lambda s: ctx.at(k, s), crossing_test(kind, ga), a, ga, b, g1, ctx.far,
                        width=LOCATE_TOLERANCE * (b - a), iterations=MAX_LOCATE_ITERATIONS)
    return _found(ctx, k, GuardCrossing(s, state, k))


def gap_ends(ctx: _Guards, k: int) -> tuple[float, float, float, float, bool]:
    """ON_GAP guard k's (gap, rate) at the step's start and end, and whether it is an impact gap (Python path)."""
    (g0, r0), (g1, r1) = ctx.g0[k], ctx.g1[k]
    return g0, r0, g1, r1, ctx.gaps.impact[k]


def onto_gap(ctx: _Guards, k: int, g0: float, g1: float, impact: bool) -> tuple[int, float]:
    """The crossing of ON_GAP guard k between ends on opposite sides (Python path: `GapSearch.across`)."""
    return _found(ctx, k, ctx.gaps.across(k, g0, g1))


def inside_step(ctx: _Guards, k: int, g0: float, r0: float, g1: float, r1: float, x: float) -> tuple[int, float]:
    """The crossing of ON_GAP guard k predicted at the fraction x of the step (Python path: `GapSearch.inside`)."""
    return _found(ctx, k, ctx.gaps.inside(k, g0, r0, g1, r1, x))


def keep(ctx: _Guards, k: int, t: float) -> int:
    """Guard k's crossing is the earliest so far (Python path: ctx.found holds it already)."""
    return FOUND


def _found(ctx: _Guards, k: int, crossing: GuardCrossing | None) -> tuple[int, float]:
    """(NONE, 0) or (FOUND, its time), the crossing kept in ctx.found."""
    if crossing is None:
        return NONE, 0.0
    ctx.found[k] = crossing
    return FOUND, crossing.t


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
