"""The bench's reference floor is claimed only where its check follows the scene.

grasp_release (86 impacts, rests on the stops, contact with the cup) has a reference that locates
every event (`adaptive` through the Simulator, itself held to test/hybrid_reference.py within
3.2e-9 rad by test/core/test_rest_is_step_independent.py). The bench's check, a plain scipy Radau
solve without contact or rest events, follows another path through the impacts: docs/performance.md
printed its 4.7 rad difference as grasp_release's "reference floor". That is not a bound on the
reference's error, and the report must not print it as one; a check that follows its scene keeps
its floor.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from finger_sim.bench.markdown import render_scene
from finger_sim.bench.plan import scene_file
from finger_sim.bench.reference import MAX_CHECK_DIFFERENCE, GridSolution, Reference
from finger_sim.scene import load_scene

#: grasp_release's check difference in docs/performance.md (bench of 2026-11-25), rad
GRASP_RELEASE_CHECK = 4.7


def header(difference: float) -> tuple[Reference, str]:
    """A grasp_release reference whose check differs by `difference` rad, and its section's header line."""
    scene = load_scene(scene_file("grasp_release"))
    grid = np.array([0.0])
    solution = GridSolution("adaptive (Simulator, contact events located)", 1e-12, grid, np.zeros((1, 6)), 0.9)
    check = GridSolution("Radau", 1e-12, grid, np.zeros((1, 6)), 1.0)
    ref = Reference(scene.name, solution, check, difference)
    return ref, next(line for line in render_scene(scene, ref, "wp.png", []) if line.startswith("Reference:"))


def test_a_check_radians_away_is_not_printed_as_a_reference_floor():
    ref, line = header(GRASP_RELEASE_CHECK)
    assert math.isnan(ref.floor)
    assert "reference floor 4.7" not in line
    assert "it differs by 4.7e+00 rad" in line and "no reference floor is claimed" in line


@pytest.mark.parametrize("difference", [2.6e-13, MAX_CHECK_DIFFERENCE])
def test_a_check_that_follows_its_scene_keeps_its_floor(difference):
    ref, line = header(difference)
    assert ref.floor == difference
    assert line.endswith(f"reference floor {difference:.1e} rad.")
