"""The bench's whole runs (`runners.run_states(whole_run=True)`, `simulate`'s `kernel.advance`) take the same states as
its step-by-step runs (one `Simulator.step` per step), and goal 2 at 1e-8 rad is scored on the whole runs.

The goal's table compares the project's whole runs with scipy's (both timed whole), so the CPU it credits must buy
the very states the error was measured on: each case below runs a scene both ways from the same start and holds
every state equal, bit for bit. The cases are the paths `kernel.advance` takes: a fixed-step method's compiled
fast path (paper_flexion), dop853's whole output grid (free_swing), a drive scene's steps with the stuck mesh's hold
taken at once (drive_grasp: dop853 as the method, dop8 and `auto` at a loose tolerance, the goal's front there), and a
scene's event stretches (paper_to_stop, grasp_cylinder).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("numba")
from finger_sim.bench import analysis as an  # noqa: E402
from finger_sim.bench.plan import AUTO_DT  # noqa: E402
from finger_sim.bench.runners import (  # noqa: E402
    AUTO,
    AUTO_TOLERANCE,
    FAMILY_PROJECT,
    FAMILY_SCIPY,
    WHOLE_RUN_SUFFIX,
    Run,
    run_states,
)
from finger_sim.scene import load_scene  # noqa: E402
from finger_sim.simulate import Simulator  # noqa: E402

CONFIG = Path(__file__).resolve().parents[2] / "config"

#: (scene, method, dt s, integrator.tolerance rad or None for the scene's own)
CASES = (
    ("paper_flexion", "rk4", 1e-3, None),
    ("free_swing", "dop853", 1e-3, None),
    ("drive_grasp", "dop853", 5e-3, None),
    ("drive_grasp", "dop8", 1e-3, None),
    ("drive_grasp", AUTO, 1e-3, 1e-4),
    ("paper_to_stop", "dop853", 1e-3, None),
    ("grasp_cylinder", AUTO, 1e-3, 1e-5),
)


@pytest.mark.parametrize(("name", "method", "dt", "tolerance"), CASES)
def test_whole_run_takes_the_step_by_step_states_bit_for_bit(name: str, method: str, dt: float, tolerance: float | None):
    scene = load_scene(CONFIG / f"{name}.yaml").with_overrides(method=method, dt=dt, tolerance=tolerance)
    n = round(scene.duration / dt)
    whole, _ = run_states(Simulator(scene), n, whole_run=True)
    stepped, _ = run_states(Simulator(scene), n, whole_run=False)
    assert len(whole) == len(stepped) == n + 1
    # q, q' after every step equal bit for bit; t as the Simulator forms it (k·dt)
    assert np.array_equal([s.q + s.v for s in whole], [s.q + s.v for s in stepped])
    assert [s.t for s in whole] == pytest.approx([s.t for s in stepped], abs=1e-12)


def _run(method: str, cpu: float, error: float, *, family: str = FAMILY_PROJECT, knob: str = "dt",
         value: float = 1e-3) -> Run:
    run = Run("s", family, method, knob, value, 1.0)
    run.cpu, run.error = cpu, error
    return run


#: scipy's front: 10 ms at 1e-6 rad, 100 ms at 1e-10 rad, so 10^-1.5 s at 1e-8 rad (log-log halfway).
SCIPY = [_run("scipy LSODA", 1e-2, 1e-6, family=FAMILY_SCIPY, knob="rtol", value=1e-6),
         _run("scipy LSODA", 1e-1, 1e-10, family=FAMILY_SCIPY, knob="rtol", value=1e-10)]
SCIPY_AT_TARGET = 10 ** -1.5


def test_the_goal_counts_each_run_at_its_whole_run_cpu_where_measured_else_step_by_step():
    runs = [
        *SCIPY,
        _run("dop853", 4e-3, 1e-9, value=5e-3),
        _run("dop853" + WHOLE_RUN_SUFFIX, 2.5e-3, 1e-9, value=5e-3),  # the same states: the same error
        _run("radau", 3e-3, 1e-9, value=1e-3),  # steps in Python: no whole run, its stepped CPU stands in
        _run(AUTO_TOLERANCE, 5e-3, 1e-8, knob="tolerance", value=1e-4),
        _run(AUTO_TOLERANCE + WHOLE_RUN_SUFFIX, 1e-3, 1e-8, knob="tolerance", value=1e-4),
    ]
    whole = an.compare_scipy(runs, "s", whole_run=True)
    assert (whole.ours_method, whole.ours) == (AUTO_TOLERANCE + WHOLE_RUN_SUFFIX, 1e-3)
    assert whole.ratio == pytest.approx(SCIPY_AT_TARGET / 1e-3)
    stepped = an.compare_scipy(runs, "s")
    assert (stepped.ours_method, stepped.ours) == ("radau", 3e-3)
    # 1 ms output: the tolerance runs step at AUTO_DT (1 ms), dop853 at 5 ms does not count
    dense = an.compare_scipy(runs, "s", max_dt=AUTO_DT, whole_run=True)
    assert dense.ours == 1e-3
    without_tolerance = [r for r in runs if r.knob == "dt"]
    assert an.compare_scipy(without_tolerance, "s", whole_run=True).ours == 2.5e-3  # dop853's whole run
    assert an.compare_scipy(without_tolerance, "s", max_dt=AUTO_DT, whole_run=True).ours == 3e-3  # radau stands in


def test_whole_runs_and_tolerance_runs_are_not_candidates_of_auto_s_table():
    scene = an.KINDS["discontinuous"][0]
    runs = [_run("rk4", 1e-3, 1e-8), _run("rk4" + WHOLE_RUN_SUFFIX, 2e-4, 1e-8),
            _run(AUTO_TOLERANCE, 5e-4, 1e-9, knob="tolerance", value=1e-3)]
    for r in runs:
        r.scene, r.steps = scene, 1000
    assert [c.method for c in an.candidates(runs, "discontinuous", 1000)] == ["rk4"]
