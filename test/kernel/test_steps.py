"""DOP853's attempt written once (`integrators.steps`): the kernel's is that plain function compiled; run
in Python on lists (the system's own accelerations) and compiled (the flat model) it gives the same bits
on random states of a contact scene, accepted and rejected; its solution and stages equal scipy's own
`rk_step` (numpy matrix products) to round-off."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from scipy.integrate._ivp.rk import rk_step as scipy_rk_step

from finger_sim import kinematics
from finger_sim.effects.contact import Contact
from finger_sim.integrators import dop853, steps
from finger_sim.scene import load_scene

pytest.importorskip("numba")
from finger_sim.kernel import numerics  # noqa: E402  (needs numba to mean "compiled")
from finger_sim.kernel.layout import model_array  # noqa: E402

CONFIG = Path(__file__).resolve().parents[2] / "config"
#: Random states per case: poses around the grasp (some in contact with the cylinder), any velocities.
STATES = 40
COEFFICIENTS = (dop853._A, dop853._B, dop853._C, dop853._E3, dop853._E5, dop853._D)


def grasp_states(seed: int) -> tuple[object, list[np.ndarray]]:
    """grasp_cylinder's system and STATES states on its constraints (assembled poses, consistent rates),
    every other one pressing on the cylinder (δ > 0)."""
    system = load_scene(CONFIG / "grasp_cylinder.yaml").build_system()
    rng = np.random.default_rng(seed)
    contact = next(e for e in system.elements if isinstance(e, Contact))
    lo, hi = kinematics.assembly_range(system.params)
    states: list[np.ndarray] = []
    for _ in range(100_000):
        q = kinematics.assemble(system.params, rng.uniform(lo, hi))
        pressing = max(-g for g in contact.gaps(q)) > 0.0
        if pressing == (len(states) % 2 == 0):
            states.append(np.array([*q, *kinematics.dependent_rates(system.params, q, rng.uniform(-3.0, 3.0))]))
            if len(states) == STATES:
                break
    assert len(states) == STATES
    return system, states


def test_kernel_compiles_the_plain_attempt() -> None:
    for name in ("dop853_attempt", "_stage_state"):
        assert getattr(numerics, name).py_func.__code__ is getattr(steps, name).__code__, name


def test_dop853_attempt_python_equals_compiled_and_scipy() -> None:
    system, states = grasp_states(2)
    m, model = model_array(system), steps.StageModel(system)
    lists = tuple(c.tolist() for c in COEFFICIENTS)
    accepted = 0
    for x in states:
        f = [0.0] * 6
        steps.rhs(model, 0.1, x.tolist(), 0.05, f)
        taus = np.full(16, 0.05)
        for h in (1e-5, 1e-3):
            kk, y_new, dense = np.empty((16, 6)), np.empty(6), np.zeros((7, 6))
            norm = numerics.dop853_attempt(m, *COEFFICIENTS, 0.1, x, np.array(f), h, taus, 1e-10, 1e-12, kk, y_new,
                                           dense)
            kk_py, new_py, dense_py = [[0.0] * 6 for _ in range(16)], [0.0] * 6, np.zeros((7, 6)).tolist()
            norm_py = steps.dop853_attempt(model, *lists, 0.1, x.tolist(), f, h, taus.tolist(), 1e-10, 1e-12, kk_py,
                                           new_py, dense_py)
            assert norm == norm_py and y_new.tolist() == new_py
            assert kk.tolist()[:13] == kk_py[:13]
            if norm < 1.0:
                accepted += 1
                assert kk.tolist() == kk_py and dense.tolist() == dense_py
            # scipy's own step (its stages by numpy matrix products): the same solution to round-off
            stages = np.empty((13, 6))

            def fun(t: float, y: np.ndarray) -> np.ndarray:
                out = [0.0] * 6
                steps.rhs(model, t, y.tolist(), 0.05, out)
                return np.array(out)

            y_sc, f_sc = scipy_rk_step(fun, 0.1, x, np.array(f), h, dop853._A[:12, :12], dop853._B, dop853._C[:12],
                                       stages)
            scale = np.max(np.abs(kk[:13]), axis=0) * h + np.abs(x)
            assert np.all(np.abs(y_new - y_sc) <= 1e-13 * scale)  # stiff contact stages amplify round-off
            assert np.allclose(kk[12], f_sc, rtol=1e-9, atol=1e-9 * np.max(np.abs(f_sc)))
    assert 0 < accepted < 2 * STATES  # both branches seen
