"""The compiled gain sweep (finger_sim.tasks.batch, finger_sim.kernel.closed_loop).

Reference: the offline task path, `run_task` (one Simulator per run, the controller in Python),
run here for every column: each row of the sweep must equal it bit for bit (every sample of
every column, every score, every verdict, every crush with its step and force). The kernel's
share is checked by counting the steps the Python Simulator still takes.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from finger_sim.cli import main
from finger_sim.errors import ConfigError
from finger_sim.kernel import closed_loop
from finger_sim import grip_law as grip
from finger_sim.simulate import Simulator
from finger_sim.tasks import batch
from finger_sim.tasks.batch import batch_reason, run_task_rows
from finger_sim.tasks.controllers import grip_pi, grip_pi_aggressive, grip_voltage
from finger_sim.tasks.report import to_json
from finger_sim.tasks.runner import COLUMNS, run_task
from finger_sim.tasks.schema import load_task
from finger_sim.tasks.suite import parse_controllers, run_suite, with_scene_keys

TASKS = Path(__file__).resolve().parents[2] / "config" / "tasks"
#: A gain grid around the shipped PI (kp N·m/N, ki N·m/(N·s)): slow, shipped and overshooting on the soft side.
GRID = [(f"kp={kp:g},ki={ki:g}", {"kp": kp, "ki": ki}) for kp in (0.0025, 0.01) for ki in (2.0, 4.0, 8.0)]


def assert_same_run(row, ref):
    assert row.controller == ref.controller and row.task == ref.task
    assert list(row.samples) == list(COLUMNS)
    for name in COLUMNS:
        assert np.array_equal(row.samples[name], ref.samples[name]), name  # bit for bit, NaN-free
    assert row.scores == ref.scores and row.passed == ref.passed and row.setpoints == ref.setpoints
    assert row.crushes == ref.crushes  # object, t, step, force, break force


def python_steps(monkeypatch) -> list[int]:
    """A counter of `Simulator.step` calls (the real method, counted)."""
    count = [0]
    step = Simulator.step

    def counted(self, *args, **kwargs):
        count[0] += 1
        return step(self, *args, **kwargs)

    monkeypatch.setattr(Simulator, "step", counted)
    return count


def test_a_gain_grid_on_the_cup_equals_the_offline_runs_bit_for_bit(monkeypatch):
    task = load_task(TASKS / "hold_cup.yaml")
    refs = [run_task(task, grip_pi, label=label, params=params) for label, params in GRID]
    count = python_steps(monkeypatch)
    rows = run_task_rows(task, grip_pi, GRID)
    for row, ref in zip(rows, refs, strict=True):
        assert_same_run(row, ref)
    # the verdicts differ across the grid (the sweep is not six copies of one run)
    assert len({(r.scores["settle_time"], r.scores["hold_rms"]) for r in rows}) == len(GRID)
    # the kernel took the steps: Python only the first (DOP853's first internal step) and the contact onset's
    assert count[0] <= 4 * len(GRID) and task.scene.step_count == 1500


def test_a_crush_happens_in_the_same_row_at_the_same_step_as_offline():
    """The aggressive PI on the egg (break_force 0.6 N): crushed or not depending on the closing
    torque and ki; after the crush the row goes on without the object (the lean path, no contact)."""
    task = load_task(TASKS / "fragile.yaml")
    columns = [(f"c={c:g},ki={ki:g}", {"closing_torque": c, "ki": ki}) for c in (0.015, 0.03) for ki in (4.0, 20.0)]
    refs = [run_task(task, grip_pi_aggressive, label=label, params=params) for label, params in columns]
    rows = run_task_rows(task, grip_pi_aggressive, columns)
    for row, ref in zip(rows, refs, strict=True):
        assert_same_run(row, ref)
    crushed = [[(c.object, c.step) for c in r.crushes] for r in rows]
    assert crushed == [[], [("egg", 302)], [("egg", 149)], [("egg", 149)]]
    for r in rows[1:]:  # the crushed column counts from the crush step on
        k = r.crushes[0].step  # the state after step k − 1 broke it
        assert r.samples["crushed"][k - 1] == 0 and r.samples["crushed"][k] == 1 and r.samples["grip_force"][k] > 0.6
        assert r.scores["peak_force"] > 0.6


@pytest.mark.parametrize("name", ["staircase", "tip_pull", "release_reopen"])
def test_setpoint_scripts_and_tip_force_switches_equal_the_offline_runs(name):
    task = load_task(TASKS / f"{name}.yaml")
    columns = GRID[1:3]
    refs = [run_task(task, grip_pi, label=label, params=params) for label, params in columns]
    for row, ref in zip(run_task_rows(task, grip_pi, columns), refs, strict=True):
        assert_same_run(row, ref)


@pytest.mark.parametrize("name", ["hold_soft", "hold_rigid"])
def test_an_object_with_its_own_contact_law_equals_the_offline_runs(name, monkeypatch):
    """The foam cup (k_c = 1e3) and the near-rigid one (1e7): the object's own law is the scene's one
    compiled law, so the rows run in the kernel, each equal to run_task bit for bit."""
    task = load_task(TASKS / f"{name}.yaml")
    assert batch_reason(task, grip_pi) is None
    columns = GRID[::2]
    refs = [run_task(task, grip_pi, label=label, params=params) for label, params in columns]
    count = python_steps(monkeypatch)
    rows = run_task_rows(task, grip_pi, columns)
    for row, ref in zip(rows, refs, strict=True):
        assert_same_run(row, ref)
    assert len({r.scores["hold_rms"] for r in rows}) == len(columns)
    # the kernel took the steps; Python the first, and those around an onset or release (a rigid cup's bounces)
    assert count[0] <= 0.02 * task.scene.step_count * len(columns)


def test_the_compiled_law_is_the_python_law_bit_for_bit():
    rng = np.random.default_rng(7)
    for _ in range(2000):
        args = (int(rng.integers(0, 4)), rng.normal(0.0, 0.05), rng.uniform(-0.01, 0.2), rng.uniform(0.0, 1.0),
                rng.uniform(-0.1, 1.2), rng.choice([0.001, 0.002, 0.01]), rng.uniform(0, 0.02), rng.uniform(0, 20),
                0.1, 0.015, 0.01, 0.01)
        assert closed_loop.grip_update(*args) == grip.grip_update(*args)
        change = (args[0], args[2], float(rng.choice([0.0, 0.5])), 0.2)
        assert closed_loop.grip_setpoint(*change) == grip.grip_setpoint(*change)


def test_tasks_the_kernel_cannot_step_say_why_and_the_suite_runs_them_one_by_one(tmp_path):
    pushed = load_task(TASKS / "push_while_holding.yaml")
    assert "moving object" in batch_reason(pushed, grip_pi)  # a prescribed motion: Python stages
    assert batch_reason(load_task(TASKS / "hold_cup.yaml"), grip_voltage) is not None
    with pytest.raises(ConfigError, match="push_while_holding"):
        run_task_rows(pushed, grip_pi, GRID[:2])
    out = tmp_path / "r"
    assert main(["tasks", str(TASKS / "push_while_holding.yaml"), str(TASKS / "fragile.yaml"), "--out", str(out),
                 "--no-figures", "--vary", "ki=2,4"]) in (0, 1)
    data = json.loads((out / "metrics.json").read_text())
    assert [(d["task"], d["controller"]) for d in data] == [
        ("push_while_holding", "grip_pi[ki=2]"), ("push_while_holding", "grip_pi[ki=4]"),
        ("fragile", "grip_pi[ki=2]"), ("fragile", "grip_pi[ki=4]")]
    refs = [run_task(load_task(TASKS / f"{d['task']}.yaml"), grip_pi, label=d["controller"],
                     params={"ki": float(d["controller"][-2])}) for d in data]
    assert data == json.loads(to_json(refs))


def test_object_parameters_swept_with_the_gains_equal_the_offline_runs():
    """--vary scene.KEY: the egg's break force and the contact stiffness, swept with ki: each column
    on its own scene, rows of one kernel loop, each equal to run_task on that scene."""
    fragile, cup = load_task(TASKS / "fragile.yaml"), load_task(TASKS / "hold_cup.yaml")
    specs = parse_controllers(["hot=finger_sim.tasks.controllers:grip_pi_aggressive"], [],
                              ["scene.objects.0.break_force=0.65,2.5", "ki=4,20"])
    assert [c.label for c in specs][:2] == ["hot[scene.objects.0.break_force=0.65,ki=4]",
                                            "hot[scene.objects.0.break_force=0.65,ki=20]"]
    stiff = parse_controllers(["pi=finger_sim.tasks.controllers:grip_pi"], [],
                              ["scene.model.contact.stiffness=5e4,2e5", "kp=0.0025,0.01"])
    for task, columns in ((fragile, specs), (cup, stiff)):
        assert batch.rows_reason([with_scene_keys(task, c.scene_keys) for c in columns], columns[0].factory) is None
        runs = run_suite([task], columns)
        refs = [run_task(with_scene_keys(task, c.scene_keys), c.factory, label=c.label, params=c.params)
                for c in columns]
        for row, ref in zip(runs, refs, strict=True):
            assert_same_run(row, ref)
        if task is fragile:  # the stronger egg survives the hits that break the weaker one
            assert [bool(r.crushes) for r in runs] == [True, True, False, False]
    with pytest.raises(ConfigError, match="scene.objects.5"):
        run_suite([fragile], parse_controllers([], [], ["scene.objects.5.break_force=1,2"]))
