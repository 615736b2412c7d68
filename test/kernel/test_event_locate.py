"""A located gap crossing in one compiled call (`simulation.event_locate`, `kernel.locate_event`).

The reference is Python's location of the same crossing (`crossings.locate_gap` with the compiled one
switched off: main's path), both running `locate.regula_falsi_gap`. Two Simulators step side by side on
every shipped event scene, and under the event inputs on four of them; after every step the states, torque
and error estimate, the integrator's last output and its whole table of error estimates are equal bit for
bit, and so is every located crossing (time, q, q'). Each scene with a located crossing must have had
them located in the kernel.
"""

from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("numba")
from finger_sim.errors import SimulationDiverged  # noqa: E402
from finger_sim.simulate import Simulator  # noqa: E402
from helpers import EVENT_PROFILES, EVENT_SCENES, event_scene, with_profile  # noqa: E402

#: Scenes under the event inputs: stop impacts, contact onsets and releases.
PROFILE_SCENES = ("paper_to_stop", "grasp_impact", "grasp_rigid", "hard/stops_elastic")


def recording(sim: Simulator) -> list:
    """The crossings `sim` locates, recorded as they are returned (its `_locate`, observed)."""
    found: list = []
    locate = sim._locate

    def observed(*args):  # type: ignore[no-untyped-def]
        crossing = locate(*args)
        found.append((crossing.t, crossing.q, crossing.v, sim._gaps.index(crossing.gap)))
        return crossing

    sim._locate = observed
    return found


def attempt(sim: Simulator):
    """The state after a step, or the error that ended the run."""
    try:
        return sim.step()
    except SimulationDiverged as exc:
        return str(exc)


def run_side_by_side(scene) -> tuple[int, int]:
    """Steps a Simulator with the compiled location and one without, comparing after every step;
    returns (crossings located, of them in the kernel)."""
    kernel, python = Simulator(scene), Simulator(scene)
    assert kernel._event_step is not None and kernel._event_step.locate is not None
    python._event_step.locate = None
    kernel._event_step.locates = python._event_step.locates = False  # crossings handed over to Python's loop
    found_kernel, found_python = recording(kernel), recording(python)
    for k in range(scene.step_count):
        a, b = attempt(kernel), attempt(python)
        assert a == b, k
        assert found_kernel == found_python, k
        if isinstance(a, str):  # the run ended (a phalanx axis reached the object), with the same error
            break
        assert (kernel.torque, kernel.error_estimate, kernel.impacts) == (python.torque, python.error_estimate,
                                                                          python.impacts), k
        assert kernel.integrator._last == python.integrator._last, k
        assert list(kernel.integrator._estimates.items()) == list(python.integrator._estimates.items()), k
    return len(found_kernel), kernel._event_step.locate.taken


@pytest.mark.parametrize("name", EVENT_SCENES)
def test_located_crossings_equal_python_bit_for_bit(name: str) -> None:
    located, compiled = run_side_by_side(event_scene(name))
    assert compiled == located  # every crossing of these scenes is located in the kernel


@pytest.mark.parametrize("profile", sorted(EVENT_PROFILES))
@pytest.mark.parametrize("name", PROFILE_SCENES)
def test_located_crossings_under_inputs(name: str, profile: str) -> None:
    located, compiled = run_side_by_side(with_profile(name, EVENT_PROFILES[profile]))
    assert compiled <= located


def test_impact_scenes_locate_in_the_kernel() -> None:
    """The impact scenes, the goal of the change: their onsets and releases are located in the kernel."""
    for name in ("grasp_impact", "grasp_rigid", "paper_to_stop"):
        located, compiled = run_side_by_side(event_scene(name))
        assert located >= 1 and compiled == located, name


def test_whole_run_states_equal() -> None:
    """`simulate`'s path (stretches of compiled steps, `kernel.run_stretch`) with and without it: every state."""
    from finger_sim.kernel import run_stretch

    scene = event_scene("grasp_rigid")
    kernel, python = Simulator(scene), Simulator(scene)
    python._event_step.locate = None
    kernel._event_step.locates = python._event_step.locates = False  # crossings handed over to Python's loop
    a, b = run_stretch.advance(kernel, scene.step_count), run_stretch.advance(python, scene.step_count)
    assert np.array_equal(a, b)
    assert kernel._event_step.locate.taken >= 2
