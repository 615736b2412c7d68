"""`locate.first_guard_crossing` with a lazy start value: located where the analytic guard crosses, the
same bits as an eager start, and never asked of a step that does not cross; with a gap guard (ON_GAP):
located onto the gap, and the earliest of the step's guards counts."""

import math

from finger_sim.simulation.locate import (EVENT_TOLERANCE, LOCATE_TOLERANCE, ON_GAP, GapSearch, GuardCrossing,
                                         first_guard_crossing, regula_falsi_gap)

ONE_SIDED = (False,)


def _at(_: int, s: float) -> tuple[float, tuple[float]]:
    """The guard g(s) = cos s and the 'state' s itself."""
    return math.cos(s), (s,)


def test_lazy_start_value_is_located_at_the_analytic_crossing() -> None:
    a, b = 1.0, 2.0
    lazy = first_guard_crossing(ONE_SIDED, (lambda: math.cos(a),), (math.cos(b),), _at, a, b, (b,))
    eager = first_guard_crossing(ONE_SIDED, (math.cos(a),), (math.cos(b),), _at, a, b, (b,))
    assert lazy == eager  # the same floats, bit for bit
    assert lazy.guard == 0 and lazy.state == (lazy.t,)
    assert math.pi / 2 <= lazy.t <= math.pi / 2 + LOCATE_TOLERANCE * (b - a)  # the far side, to the tolerance


def test_lazy_start_value_is_not_asked_of_a_step_that_does_not_cross() -> None:
    def refuse() -> float:
        raise AssertionError("the start value was asked of a step that ends on the near side")

    assert first_guard_crossing(ONE_SIDED, (refuse,), (math.cos(1.5),), _at, 1.0, 1.5, (1.5,)) is None



def _gap_guard(root: float, a: float, b: float):
    """An ON_GAP guard for the gap g(s) = sin(s − root) on the step [a, b] (|s − root| < π/2: monotonic, its ends
    on opposite sides), its (gap, rate) at both ends, and its search: located by `regula_falsi_gap` with the
    trial 'state' (s, s') = (s, 1); a crossing predicted inside the step would be a fault here."""
    def gap_at(s: float, _: tuple) -> float:
        return math.sin(s - root)

    def trial(s: float) -> tuple[float, tuple, tuple]:
        return gap_at(s, (s,)), (s,), (1.0,)

    def across(k: int, ga: float, gb: float) -> GuardCrossing:
        s, qs, vs = regula_falsi_gap((trial, gap_at), a, (a,), (1.0,), a, ga, b, gb, (b,), (1.0,), False, 60)
        return GuardCrossing(s, (qs, vs), k)

    def inside(*_: float) -> None:
        raise AssertionError("a crossing predicted inside a step whose ends lie on opposite sides")
    search = GapSearch((False, False), across, inside)
    return (gap_at(a, ()), math.cos(a - root)), (gap_at(b, ()), math.cos(b - root)), search


def test_a_gap_guard_is_located_onto_the_gap_and_the_earliest_guard_counts() -> None:
    a = 1.0  # the one-sided mode guard cos s crosses at π/2: not on [1, 1.5]; on [1, 1.6] before the gap at 1.58
    for root, b, want in ((1.25, 1.5, 1), (1.58, 1.6, 0)):
        start, end, search = _gap_guard(root, a, b)
        found = first_guard_crossing((False, ON_GAP), (math.cos(a), start), (math.cos(b), end), _at, a, b, (b,),
                                     search)
        assert found is not None and found.guard == want
        if want == 1:  # on the gap to EVENT_TOLERANCE: the point an impact needs
            assert abs(math.sin(found.t - root)) <= EVENT_TOLERANCE
            assert abs(found.t - root) <= 2 * EVENT_TOLERANCE
            assert found.state == ((found.t,), (1.0,))
        else:  # the mode guard, on its far side to the tolerance
            assert math.pi / 2 <= found.t <= math.pi / 2 + LOCATE_TOLERANCE * (b - a)


def test_a_gap_closed_only_inside_the_step_is_predicted_and_a_far_one_skipped() -> None:
    """g(s) = (s − c)² − w², closed on (c − w, c + w) inside the step [0, 1] and open at both ends: `gap_guard`
    asks `inside` at the fraction x its prediction gives, the start's tangent reaching zero before the convex
    gap does (a < s < c − w); raised by 3 (farther than h·(|r0| + |r1|) = 2 at both ends), nothing is asked."""
    a, b, c, w = 0.0, 1.0, 0.5, 0.05
    asked = []

    def inside(k: int, g0: float, r0: float, g1: float, r1: float, x: float) -> None:
        asked.append((k, x))

    def across(*_: float) -> GuardCrossing:
        raise AssertionError("located across, though both ends lie on the open side")

    for lift, want in ((0.0, 1), (3.0, 0)):
        ends = [((s - c) ** 2 - w * w + lift, 2.0 * (s - c)) for s in (a, b)]
        asked.clear()
        assert first_guard_crossing((ON_GAP,), (ends[0],), (ends[1],), None, a, b, (b,),
                                    GapSearch((False,), across, inside)) is None
        assert len(asked) == want
        if want:
            assert asked[0][0] == 0 and a < a + asked[0][1] * (b - a) < c - w
