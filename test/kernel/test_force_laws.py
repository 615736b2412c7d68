"""The kernel's force-law dispatch is generated from the registry (`finger_sim.kernel.force_laws`): the
committed module is what the shipped registry generates, and a law is refused at registration when the
dispatch could not call it."""

from __future__ import annotations

import pytest

from finger_sim.effects.base import KERNEL_ARGUMENTS, KERNEL_LAWS, SPRING, Vec3, kernel_law
from finger_sim.effects.spring import spring_force
from finger_sim.kernel.force_laws import COMMITTED, compiled_laws, dispatch_source, uncommitted_source


def test_the_committed_dispatch_is_the_registry_s() -> None:
    """After adding a law: `python -m finger_sim.kernel.force_laws` rewrites it."""
    assert COMMITTED.read_text(encoding="utf-8") == dispatch_source(compiled_laws())
    assert uncommitted_source() == ""  # so the numba cache of a plain install is keyed by the package alone


def test_each_law_is_called_with_its_parameters_then_the_state_it_names() -> None:
    spring = KERNEL_LAWS[SPRING]
    assert (spring.force, spring.parameters, spring.state) == (spring_force, 2, ("q0", "q2"))
    assert "return law_1(m[o], m[o + 1], q0, q2)" in dispatch_source((spring,))


def _law(k: float, w: float) -> Vec3:
    return (k * w, 0.0, 0.0)


@pytest.mark.parametrize(("state", "code", "message"), [
    (("v0",), SPRING, "compiled force law code 1 registered twice (_law)"),
    (("omega",), None, f"_law: state must be trailing arguments among {list(KERNEL_ARGUMENTS)}, got ['omega']"),
    (("q0", "q1", "q2"), None, f"_law: state must be trailing arguments among {list(KERNEL_ARGUMENTS)}, "
                               "got ['q0', 'q1', 'q2']"),
])
def test_a_law_the_dispatch_cannot_call_is_refused(state: tuple[str, ...], code: int | None, message: str) -> None:
    before = dict(KERNEL_LAWS)
    with pytest.raises(ValueError) as refused:
        kernel_law(_law, state, code=code)
    assert str(refused.value) == message and KERNEL_LAWS == before
