"""`locate.first_guard_crossing` with a lazy start value: located where the analytic guard crosses, the
same bits as an eager start, and never asked of a step that does not cross; with a gap guard (ON_GAP):
located onto the gap, and the earliest of the step's guards counts."""

import math

from finger_sim.simulation.locate import (EVENT_TOLERANCE, LOCATE_TOLERANCE, ON_GAP, GuardCrossing, first_guard_crossing,
                                         regula_falsi_gap)

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
    """An ON_GAP guard for the gap g(s) = sin(s) − sin(root) on the step [a, b] in (0, π/2), its (gap, rate)
    at both ends, and its search: located by `regula_falsi_gap` with the trial 'state' (s, s') = (s, 1)."""
    def gap_at(s: float, _: tuple) -> float:
        return math.sin(s) - math.sin(root)

    def trial(s: float) -> tuple[float, tuple, tuple]:
        return gap_at(s, (s,)), (s,), (1.0,)

    def onto_gap(k: int, start: tuple[float, float], end: tuple[float, float]) -> GuardCrossing | None:
        ga, gb = start[0], end[0]
        if (ga < 0.0) == (gb < 0.0):
            return None
        s, qs, vs = regula_falsi_gap((trial, gap_at), a, (a,), (1.0,), a, ga, b, gb, (b,), (1.0,), False, 60)
        return GuardCrossing(s, (qs, vs), k)
    return (gap_at(a, ()), math.cos(a)), (gap_at(b, ()), math.cos(b)), onto_gap


def test_a_gap_guard_is_located_onto_the_gap_and_the_earliest_guard_counts() -> None:
    a = 1.0  # the one-sided mode guard cos s crosses at π/2: not on [1, 1.5]; on [1, 1.6] before the gap at 1.58
    for root, b, want in ((1.25, 1.5, 1), (1.58, 1.6, 0)):
        start, end, onto_gap = _gap_guard(root, a, b)
        found = first_guard_crossing((False, ON_GAP), (math.cos(a), start), (math.cos(b), end), _at, a, b, (b,),
                                     onto_gap)
        assert found is not None and found.guard == want
        if want == 1:  # on the gap to EVENT_TOLERANCE: the point an impact needs
            assert abs(math.sin(found.t) - math.sin(root)) <= EVENT_TOLERANCE
            assert abs(found.t - root) <= 2 * EVENT_TOLERANCE
            assert found.state == ((found.t,), (1.0,))
        else:  # the mode guard, on its far side to the tolerance
            assert math.pi / 2 <= found.t <= math.pi / 2 + LOCATE_TOLERANCE * (b - a)
