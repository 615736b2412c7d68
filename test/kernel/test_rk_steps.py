"""The kernel's explicit Runge–Kutta steps are generated from one template (`finger_sim.kernel.rk_template`):
the committed module is the template's expansion, the kernel compiles it as it is, and the steps give the
Python path's numbers (`explicit.rk_stage_loop`, then the projection) bit for bit."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest

from finger_sim.kernel import rk_steps
from finger_sim.kernel.rk_template import COMMITTED, STEPS, module_source
from finger_sim.scene import load_scene
from finger_sim.simulate import Simulator

pytest.importorskip("numba")
from finger_sim.kernel import drive, numerics  # noqa: E402  (needs numba to mean "compiled")

CONFIG = Path(__file__).resolve().parents[2] / "config"
#: Steps compared per run: paper_to_stop reaches its stop (≈ 0.43 s) only in whole runs, so its first
#: steps are smooth; grasp_cylinder is in contact from ≈ 0.1 s; drive_grasp's mesh rolls then sticks.
STEPS_COMPARED = 300
#: The winding's inductance of the drive run, H: the current is a seventh state (`inductive_rk_step`).
INDUCTANCE = 0.02


def test_the_committed_steps_are_the_template_s() -> None:
    """After editing the template: `python -m finger_sim.kernel.rk_template` rewrites it."""
    assert COMMITTED.read_text(encoding="utf-8") == module_source()
    assert [s.name for s in STEPS] == ["rk_step", "inductive_rk_step"]


def test_the_kernel_compiles_the_generated_steps() -> None:
    assert numerics.rk_step.py_func.__code__ is rk_steps.rk_step.__code__
    assert drive.inductive_rk_step.py_func.__code__ is rk_steps.inductive_rk_step.__code__
    # the drive's step at L = 0: the same code under its own name, `accelerations` rebound
    assert drive.driven_rk_step.py_func.__code__.co_code == rk_steps.rk_step.__code__.co_code


def _states(scene, kernel: str) -> np.ndarray:
    sim = Simulator(scene, kernel=kernel)
    rows = []
    for _ in range(STEPS_COMPARED):
        state = sim.step()
        rows.append((*state.q, *state.v))
    return np.array(rows)


@pytest.mark.parametrize("method", ["rk4", "rk6"])
@pytest.mark.parametrize("name", ["paper_flexion", "free_swing", "drive_grasp"])
def test_compiled_steps_equal_the_python_path_bit_for_bit(name: str, method: str) -> None:
    scene = load_scene(CONFIG / f"{name}.yaml").with_overrides(method=method)
    assert np.array_equal(_states(scene, "compiled"), _states(scene, "python"))


@pytest.mark.parametrize("method", ["rk4", "rk6"])
def test_the_inductive_step_equals_the_python_path_bit_for_bit(method: str) -> None:
    base = load_scene(CONFIG / "drive_grasp.yaml").with_overrides(method=method)
    scene = dataclasses.replace(base, drive=dataclasses.replace(base.drive, inductance=INDUCTANCE))
    compiled = Simulator(scene, kernel="compiled")
    assert type(compiled.integrator).__name__.startswith("Compiled")  # the compiled inductive step runs
    assert np.array_equal(_states(scene, "compiled"), _states(scene, "python"))
