"""DOP853's first step in the kernel: the initial step size (`dop853.initial_step`, one plain function that
Python calls and the kernel compiles) and the run's first output step (`kernel.event_step`).

References: the rule written here with numpy's norms (tight tolerance), and Python's own path
(`_event_step` switched off), bit for bit.
"""

from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("numba")
from helpers import EVENT_SCENES, event_scene  # noqa: E402
from finger_sim import stepper_slot  # noqa: E402
from finger_sim.integrators import dop853  # noqa: E402
from finger_sim.kernel import event_step as compiled_step  # noqa: E402
from finger_sim.simulate import Simulator  # noqa: E402


def start(name: str) -> tuple[np.ndarray, np.ndarray, float, float, float]:
    """(y, y', rtol, atol, dt) at the start of shipped scene `name`, y' by the compiled right-hand side, as
    `DormandPrince853._restart` evaluates it."""
    scene = event_scene(name)
    sim = Simulator(scene)
    integ = sim.integrator
    y, f = np.array([*sim.q, *sim.v]), np.empty(6)
    stepper_slot.kernel().compiled_numerics()._rhs(integ._model, 0.0, y, scene.torque(0.0), f)
    return y, f, integ.rtol, integ.atol, scene.dt


def rule(y: np.ndarray, f: np.ndarray, rtol: float, atol: float, dt: float) -> float:
    """Hairer's d0/d1 rule with numpy's norms (the reference)."""
    scale = atol + np.abs(y) * rtol
    d0, d1 = np.linalg.norm(y / scale), np.linalg.norm(f / scale)
    return min(1e-6 if d0 < 1e-5 or d1 < 1e-5 else 0.01 * d0 / d1, dt)


@pytest.mark.parametrize("name", EVENT_SCENES + ("stiff_spring",))
def test_the_compiled_initial_step_equals_pythons_bit_for_bit_on_the_shipped_scenes(name):
    y, f, rtol, atol, dt = start(name)
    h = dop853.initial_step(y, f, rtol, atol, dt)
    assert compiled_step.initial_step(y, f, rtol, atol, dt) == h
    assert h == pytest.approx(rule(y, f, rtol, atol, dt), rel=1e-14)
    assert 0.0 < h <= dt


def test_the_compiled_initial_step_equals_pythons_on_random_states_and_tolerances():
    rng = np.random.default_rng(3)
    for _ in range(300):
        y, f = rng.normal(0.0, 10.0 ** rng.uniform(-8, 2), 6), rng.normal(0.0, 10.0 ** rng.uniform(-8, 4), 6)
        if rng.random() < 0.1:
            y[:] = 0.0  # the tiny-norm branch
        rtol, atol, dt = 10.0 ** rng.uniform(-12, -3), 10.0 ** rng.uniform(-12, -3), 10.0 ** rng.uniform(-5, -1)
        h = dop853.initial_step(y, f, rtol, atol, dt)
        assert compiled_step.initial_step(y, f, rtol, atol, dt) == h
        assert h == pytest.approx(rule(y, f, rtol, atol, dt), rel=1e-14)


@pytest.mark.parametrize("name", EVENT_SCENES)
def test_the_runs_first_step_is_the_kernels_on_pythons_numbers(name):
    """The first `Simulator.step` of a new Simulator (its initial step size chosen) is taken in one kernel call
    (before: always in Python), with Python's state, torque and error estimate bit for bit; a reset's new
    integrator is started in the kernel too."""
    scene = event_scene(name)
    sims = [Simulator(scene), Simulator(scene)]
    sims[1]._event_step = None  # the Python step alone
    for _ in range(2):
        rows = [(*s.step().q, *s.v, s.torque, s.error_estimate) for s in sims]
        assert rows[0] == rows[1]
        assert sims[0]._event_step.taken == 1
        assert sims[0].integrator.accepted == 0  # no internal step in Python
        for s in sims:
            s.reset()
        sims[0]._event_step.taken = 0
