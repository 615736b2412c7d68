"""`locate.first_guard_crossing` with a lazy start value: located where the analytic guard crosses, the
same bits as an eager start, and never asked of a step that does not cross."""

import math

from finger_sim.simulation.locate import LOCATE_TOLERANCE, first_guard_crossing

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
