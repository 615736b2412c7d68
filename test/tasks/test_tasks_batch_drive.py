"""The compiled gain sweep of the drive tasks (finger_sim.tasks.batch_drive, finger_sim.kernel.closed_loop_drive).

Reference: the offline task path, `run_task` (one Simulator per run, the controller in Python,
the mesh modes located by `actuators.stepping`), run here for every column: each row of the
sweep must equal it bit for bit (every sample of every column including the drive's voltage and
current, every score including the electrical energy, every verdict). The kernel's share is
checked by counting the steps the Python Simulator still takes, and the mesh's mode changes by
the recorded motion (a stuck mesh holds θ1 exactly).
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from finger_sim import drive_grip_law as law
from finger_sim.cli import main
from finger_sim.errors import ConfigError
from finger_sim.kernel import closed_loop_drive
from finger_sim.simulate import Simulator
from finger_sim.tasks.batch import batch_reason, run_task_rows
from finger_sim.tasks.controllers import grip_pi, grip_voltage
from finger_sim.tasks.current_grip import grip_current
from finger_sim.tasks.report import to_json
from finger_sim.tasks.runner import COLUMNS, DRIVE_COLUMNS, run_task
from finger_sim.tasks.schema import load_task
from finger_sim.tasks.suite import parse_controllers, run_suite

TASKS = Path(__file__).resolve().parents[2] / "config" / "tasks"
NAMES = COLUMNS + DRIVE_COLUMNS


def assert_same_run(row, ref):
    assert row.controller == ref.controller and row.task == ref.task
    assert list(row.samples) == list(NAMES) == list(ref.samples)
    for name in NAMES:
        assert np.array_equal(row.samples[name], ref.samples[name]), name  # bit for bit, NaN-free
    assert row.scores == ref.scores and row.passed == ref.passed and row.setpoints == ref.setpoints
    assert row.crushes == ref.crushes


def python_steps(monkeypatch) -> list[int]:
    """A counter of `Simulator.step` calls (the real method, counted)."""
    count = [0]
    step = Simulator.step

    def counted(self, *args, **kwargs):
        count[0] += 1
        return step(self, *args, **kwargs)

    monkeypatch.setattr(Simulator, "step", counted)
    return count


def stuck_steps(run) -> int:
    """Steps over which θ1 did not move at all (a stuck mesh holds q exactly)."""
    return int(np.count_nonzero(np.diff(run.samples["theta1"]) == 0.0))


#: Current-loop gains around grip_current's (kp V/A, ki V/(A·s)): slower, shipped, faster.
CURRENT_GRID = [(f"kp={kp:g},ki={ki:g}", {"kp": kp, "ki": ki}) for kp, ki in ((2.0, 200.0), (4.0, 400.0), (8.0, 800.0))]
#: Force-loop gains around grip_voltage's (kp V/N, ki V/(N·s)), and its closing voltage (V).
VOLTAGE_GRID = [(f"kp={kp:g},ki={ki:g},c={c:g}", {"kp": kp, "ki": ki, "closing_voltage": c})
                for kp, ki, c in ((1.0, 20.0, 2.0), (0.5, 40.0, 1.5), (2.0, 10.0, 2.0))]


@pytest.mark.parametrize("name, factory, grid", [("hold_current", grip_current, CURRENT_GRID),
                                                 ("hold_voltage_off", grip_voltage, VOLTAGE_GRID)])
def test_a_gain_grid_on_a_drive_task_equals_the_offline_runs_bit_for_bit(monkeypatch, name, factory, grid):
    task = load_task(TASKS / f"{name}.yaml")
    assert batch_reason(task, factory) is None
    refs = [run_task(task, factory, label=label, params=params) for label, params in grid]
    count = python_steps(monkeypatch)
    rows = run_task_rows(task, factory, grid)
    for row, ref in zip(rows, refs, strict=True):
        assert_same_run(row, ref)
        assert row.scores["electrical_energy"] > 0.0
        assert stuck_steps(row) > 100  # the self-locking hold: the mesh stuck, θ1 held to the bit
    assert len({r.scores["electrical_energy"] for r in rows}) == len(grid)  # three different runs
    # the kernel took most steps; Python the mode changes (the current loop's mesh sticks at each turning
    # point: 378 of 3000 steps on hold_current), contact onsets and DOP853 restarts it handed over
    print(f"{name}: {count[0]} of {len(grid) * task.scene.step_count} steps in Python")
    assert count[0] < 0.15 * len(grid) * task.scene.step_count


def test_grip_voltage_on_the_motor_current_equals_the_offline_run():
    """grip_voltage fed the motor current (feedback=motor_current, force_per_unit N/A): the law reads
    the drive's output computed in the kernel."""
    task = load_task(TASKS / "hold_voltage_off.yaml")
    columns = [(f"fpu={s:g}", {"feedback": "motor_current", "force_per_unit": s}) for s in (7.0, 9.0)]
    refs = [run_task(task, grip_voltage, label=label, params=params) for label, params in columns]
    for row, ref in zip(run_task_rows(task, grip_voltage, columns), refs, strict=True):
        assert_same_run(row, ref)


def test_the_compiled_drive_laws_are_the_python_laws_bit_for_bit():
    rng = np.random.default_rng(11)
    for _ in range(2000):
        state = (rng.normal(0.0, 0.05), float(rng.choice([0.0, 0.03, 0.06])), bool(rng.integers(0, 2)),
                 bool(rng.integers(0, 2)), float(rng.choice([0.0, 0.1])))
        t, setpoint, period = float(rng.uniform(0.0, 0.5)), float(rng.choice([0.0, 1.5, 2.5])), 0.001
        gains = (2.0, rng.uniform(0, 4), rng.uniform(0, 800), 6.0, 0.05, 0.05, 0.01, 2.0, 0.2)
        args = (*state, t, setpoint, rng.uniform(-0.1, 3.0), period, *gains)
        assert closed_loop_drive.voltage_update(*args) == law.voltage_update(*args)
        cgains = (1.0, 0.06, 0.03, rng.uniform(0, 8), rng.uniform(0, 800), 6.0, 0.05, 0.05, 2.0, 0.2)
        cargs = (*state, t, setpoint, rng.uniform(0.1, 0.5), rng.uniform(-0.1, 0.6), period, *cgains)
        assert closed_loop_drive.current_update(*cargs) == law.current_update(*cargs)


def test_what_the_drive_sweep_cannot_step_is_said_in_one_line():
    task = load_task(TASKS / "hold_voltage_off.yaml")
    assert batch_reason(load_task(TASKS / "hold_cup.yaml"), grip_voltage) == "not a drive task"
    assert batch_reason(task, grip_pi) is not None  # a torque controller on a voltage task
    with pytest.raises(ConfigError, match="feedback"):  # a sensor's reading: row by row only
        run_task_rows(task, grip_voltage, [("a", {"feedback": "fsr_distal_measured"}), ("b", {})])
    with pytest.raises(ConfigError, match="nope"):
        run_task_rows(task, grip_voltage, [("a", {"nope": 1.0}), ("b", {})])


def test_the_suite_sweeps_a_drive_controller_through_the_kernel(tmp_path, monkeypatch):
    """`finger-sim tasks --controller grip_current=… --vary`: the columns run as rows of one kernel
    loop, and the written metrics equal the offline runs'."""
    count = python_steps(monkeypatch)
    out = tmp_path / "r"
    assert main(["tasks", str(TASKS / "hold_current.yaml"), "--controller",
                 "gc=finger_sim.tasks.current_grip:grip_current", "--out", str(out), "--no-figures",
                 "--vary", "ki=300,500"]) in (0, 1)
    assert count[0] < 200  # two rows of 1000 steps, nearly all in the kernel
    data = json.loads((out / "metrics.json").read_text())
    assert [d["controller"] for d in data] == ["gc[ki=300]", "gc[ki=500]"]
    task = load_task(TASKS / "hold_current.yaml")
    refs = [run_task(task, grip_current, label=d["controller"], params={"ki": float(d["controller"][6:9])})
            for d in data]
    assert data == json.loads(to_json(refs))
    specs = parse_controllers(["gc=finger_sim.tasks.current_grip:grip_current"], [], ["kp=2,4"])
    runs = run_suite([task], specs)
    for row, ref in zip(runs, [run_task(task, grip_current, label=c.label, params=c.params) for c in specs],
                        strict=True):
        assert_same_run(row, ref)
