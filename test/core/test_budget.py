"""Resource bounds of an offline run (issue 8.2): `--dt 1e-9 --t-end 100` is refused up front
with its step count, its memory and how to go ahead; the per-step memory it states is
measured here with tracemalloc on a real run."""

from __future__ import annotations

import gc
import tracemalloc

import pytest

from finger_sim.budget import BYTES_PER_STEP, DEFAULT_MAX_STEPS, check_budget, run_memory
from finger_sim.errors import FingerSimError, ResourceError
from finger_sim.scene import scene_from_dict
from finger_sim.simulate import simulate


def test_a_run_too_long_to_hold_is_refused_with_its_count_memory_and_way_out():
    scene = scene_from_dict({}).with_overrides(dt=1e-9, duration=100.0)
    with pytest.raises(ResourceError) as info:
        check_budget(scene, max_steps=DEFAULT_MAX_STEPS, streaming=False)
    assert isinstance(info.value, FingerSimError)
    assert info.value.steps == scene.step_count == 100_000_000_000
    assert str(info.value) == (
        "a run of 100,000,000,000 steps would hold about 60 TB in memory, over the limit of 2,000,000 steps; "
        "duration 100 s at dt = 1e-09 s; to go ahead on purpose pass --max-steps 100000000000, or write the run "
        "to a file with --csv FILE, which streams it instead of holding it in memory"
    )
    # going ahead on purpose: a raised limit, or a streamed run
    check_budget(scene, max_steps=scene.step_count, streaming=False)
    check_budget(scene, max_steps=DEFAULT_MAX_STEPS, streaming=True)


def test_ordinary_runs_pass():
    # 600 s at 1 ms (issue 8.8's long rattle run) is within the default
    check_budget(scene_from_dict({"duration": 600.0}), max_steps=DEFAULT_MAX_STEPS, streaming=False)


def test_the_stated_memory_per_step_is_measured():
    """Peak traced memory of a real in-memory run stays within BYTES_PER_STEP per step."""
    scene = scene_from_dict({"duration": 0.5, "integrator": {"method": "rk4", "dt": 1e-4},
                             "input": {"torque": {"type": "constant", "value": 0.0}}, "initial": {"theta1_dot": 1.0}})
    simulate(scene_from_dict({"duration": 0.01, "integrator": {"method": "rk4"}}))  # imports and caches first
    gc.collect()
    tracemalloc.start()
    try:
        traj = simulate(scene)
        _, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    assert len(traj.t) == scene.step_count + 1 == 5_001
    assert 0.5 * run_memory(scene) < peak <= run_memory(scene)
    assert peak / scene.step_count > 0.5 * BYTES_PER_STEP  # the figure is not a loose overestimate
