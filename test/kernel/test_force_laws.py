"""The kernel's force-law dispatch is generated from the registry (`finger_sim.kernel.force_laws`): the
committed module is what the shipped registry generates, and a law is refused at registration when the
dispatch could not call it. Its lock-step tile form is each law's own statements: it adds what the law
returns, bit for bit, and a law it cannot hold is left out."""

from __future__ import annotations

import numpy as np
import pytest

from finger_sim.effects.base import KERNEL_ARGUMENTS, KERNEL_LAWS, SPRING, KernelLaw, Vec3, kernel_law
from finger_sim.effects.spring import spring_force
from finger_sim.kernel.force_laws import (COMMITTED, compiled_laws, dispatch_source, element_forces, tile_statements,
                                          uncommitted_source)


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


#: Fingers of the tile each law is checked on.
TILE_FINGERS = 257


def test_every_shipped_law_is_tiled_as_the_law_computes_it() -> None:
    """The lock-step tile form generated from each law's source (`tile_statements`) adds, for every finger,
    what the law itself returns, bit for bit (random parameters and states; the force sum adds in the same
    order)."""
    pytest.importorskip("numba")
    tiles = element_forces()
    rng = np.random.default_rng(23)
    for law in compiled_laws():
        assert law.code in tiles.TILE_CODES
        m = rng.uniform(-2.0, 2.0, (3 + law.parameters, TILE_FINGERS))  # the law's block at o = 3
        y = rng.uniform(-3.0, 3.0, (6, TILE_FINGERS))
        start = rng.uniform(-1.0, 1.0, (3, TILE_FINGERS))
        force = start.copy()
        tiles.tile_element_force(law.code, m, 3, y, force, TILE_FINGERS)
        rows = {name: row for row, name in enumerate(("q0", "q1", "q2", "v0", "v1", "v2"))}
        for f in range(TILE_FINGERS):
            q = law.force(*m[3:, f].tolist(), *(float(y[rows[name], f]) for name in law.state))
            assert tuple(force[:, f].tolist()) == tuple(s + e for s, e in zip(start[:, f].tolist(), q)), (law, f)


def _branching(k: float, q0: float) -> Vec3:
    if q0 > 0.0:
        return (k, 0.0, 0.0)
    return (0.0, 0.0, 0.0)


def _timed(k: float, t: float) -> Vec3:
    return (k * t, 0.0, 0.0)


def _naming_a_tile_column(k: float, q0: float) -> Vec3:
    f = k * q0
    return (f, 0.0, -f)


@pytest.mark.parametrize(("force", "state", "callees"), [
    (_branching, ("q0",), ()),
    (_timed, ("t",), ()),
    (_naming_a_tile_column, ("q0",), ()),
    (_law, ("q0",), (spring_force,)),
])
def test_a_law_the_tile_cannot_hold_is_left_to_the_row_loop(force, state, callees) -> None:
    law = KernelLaw(99, force, state, callees)
    assert tile_statements(law) is None
    assert tile_statements(KERNEL_LAWS[SPRING]) is not None  # the shipped one is
