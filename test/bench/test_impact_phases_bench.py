"""The per-phase split of a whole run with a stop (`bench.impact_phases_bench`): its phases add up to the run."""

from __future__ import annotations

import pytest

pytest.importorskip("numba")
from finger_sim.bench.impact_phases_bench import phases  # noqa: E402
from finger_sim.bench.plan import config_dir  # noqa: E402
from finger_sim.kernel import run_stretch  # noqa: E402
from finger_sim.scene import load_scene  # noqa: E402


def test_the_phases_take_every_step_once_and_no_more_time_than_the_run():
    """paper_to_stop (the finger reaches the stop at t ≈ 0.425 s and rests on it, restitution 0): one impact
    step, the steps before it and the rest on the stop in stretches; every one of the 600 steps counted once."""
    inner = run_stretch._stretch
    scene = load_scene(config_dir() / "paper_to_stop.yaml")
    medians, steps = phases(scene, 3)
    assert run_stretch._stretch is inner  # the timing wrapper is taken off again
    assert sum(steps.values()) == scene.step_count == 600
    assert steps["steps one by one, impact"] == 1
    assert 400 < steps["stretches free"] < 430 and 170 < steps["stretches resting"] < 200  # the stop at ≈ 0.425 s
    whole = medians.pop("whole run")
    assert 0.0 < sum(medians.values()) <= 1.5 * whole  # medians of parts: near the median whole, never far above
