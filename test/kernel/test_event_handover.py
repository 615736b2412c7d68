"""A kernel step that may hold a crossing is handed to Python advanced (`simulation.event_handover`).

The kernel's common step answers EVENT where its end gaps show a possible onset, release or impact, and
keeps its solution and the internal steps it took; Python locates the crossing from them instead of
integrating the step again. The reference is the Python step alone (`_event_step` off: main's path),
stepped side by side: after every step the states, torques and error estimates, and the integrator's
whole internal solution (state, step size, error sums, the history its trial steps are answered from),
bit for bit; the hand-over must have happened on every scene listed.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("numba")
from finger_sim.errors import SimulationDiverged  # noqa: E402
from finger_sim.scene import load_scene  # noqa: E402
from finger_sim.simulate import Simulator  # noqa: E402
from finger_sim.simulation import event_step  # noqa: E402

CONFIG = Path(__file__).resolve().parents[2] / "config"
#: Scenes with located contact onsets and releases (the impact scenes), a held grasp, and stop impacts.
SCENES = ("grasp_impact", "grasp_rigid", "grasp_cylinder", "press_table", "hard/elastic_impact", "hard/rigid_fast",
          "hard/soft_pass_through", "hard/stops_elastic")


def solution(sim: Simulator) -> list:
    """The integrator's internal solution: scalars, arrays and every history entry, as plain lists."""
    integ = sim.integrator
    history = [[t, h, y.tolist(), dense.tolist(), e0, e1] for t, h, y, dense, e0, e1 in integ._history]
    return [integ._t, integ._h, integ._t_old, integ._h_old, integ._err, integ._err_old, integ._y.tolist(),
            integ._y_old.tolist(), integ._f.tolist(), integ._dense.tolist(), integ._origin, integ._last, history,
            integ._history_starts]


def attempt(sim: Simulator, command):
    """The state after a step, or the error that ended the run."""
    try:
        return sim.step(command)
    except SimulationDiverged as exc:
        return str(exc)


def run_side_by_side(scene, command=lambda k: None, monkeypatch=None) -> int:
    """Steps a kernel Simulator and a Python one together, comparing after every step; the hand-overs."""
    handed = []
    original = event_step.hand_over
    monkeypatch.setattr(event_step, "hand_over", lambda *args: (handed.append(1), original(*args)))
    kernel, python = Simulator(scene), Simulator(scene)
    kernel._event_step.locates = False  # every possible crossing handed over (not located by the kernel itself)
    python._event_step = None
    for k in range(scene.step_count):
        before = len(handed)
        a, b = attempt(kernel, command(k)), attempt(python, command(k))
        assert a == b, k
        if isinstance(a, str):  # the run ended (a phalanx axis inside the object): with the same error
            break
        assert (kernel.torque, kernel.error_estimate) == (python.torque, python.error_estimate), k
        if len(handed) > before:  # Python's step ran on the handed-over solution: it is Python's own
            assert solution(kernel) == solution(python), k
    return len(handed)


@pytest.mark.parametrize("name", SCENES)
def test_handed_over_steps_equal_the_python_step_bit_for_bit(name, monkeypatch):
    assert run_side_by_side(load_scene(CONFIG / f"{name}.yaml"), monkeypatch=monkeypatch) >= 1


def test_held_commands_hand_over_too(monkeypatch):
    scene = load_scene(CONFIG / "grasp_impact.yaml").with_overrides(duration=0.3)
    values = np.repeat([0.0, 0.02, -0.01, 0.03], 75)  # onto the cup, away and back
    assert run_side_by_side(scene, lambda k: float(values[k]), monkeypatch) >= 1
