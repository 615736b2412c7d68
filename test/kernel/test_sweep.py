"""`finger-sim sweep`: its CSV against individual `finger-sim simulate` runs, refusals that name
the key, the step budget, and chunks whose rows make up the whole sweep."""

from __future__ import annotations

import csv
import itertools
from pathlib import Path

import numpy as np
import pytest

from finger_sim.cli import main
from finger_sim.scene import load_scene, scene_from_dict
from finger_sim.sweep import run_chunk, set_key

CONFIG = Path(__file__).resolve().parents[2] / "config"
PAPER = str(CONFIG / "paper_flexion.yaml")
SPRINGS = ("0.0005", "1e-3")
SLOPES = ("0.01", "0.02", "0.03")
VARY = ["--vary", f"model.spring_stiffness={','.join(SPRINGS)}", "--vary", f"input.torque.slope={','.join(SLOPES)}"]


def _read(path: Path) -> tuple[list[str], list[list[str]]]:
    with path.open(newline="") as f:
        rows = list(csv.reader(f))
    return rows[0], rows[1:]


def test_rows_equal_individual_simulate_runs(tmp_path: Path) -> None:
    out = tmp_path / "sweep.csv"
    assert main(["sweep", PAPER, *VARY, "--out", str(out), "--plot", str(tmp_path / "tips.png")]) == 0
    header, rows = _read(out)
    assert header == ["model.spring_stiffness", "input.torque.slope", "theta1", "theta2", "theta3", "theta1_dot",
                      "theta2_dot", "theta3_dot", "max_constraint_residual", "energy_change"]
    assert [r[:2] for r in rows] == [list(c) for c in itertools.product(SPRINGS, SLOPES)]
    assert (tmp_path / "tips.png").stat().st_size > 0
    for row in (rows[0], rows[-1]):  # the first and last combination, each run on its own
        data = load_scene(PAPER).to_dict()
        set_key(data, "model.spring_stiffness", float(row[0]))
        set_key(data, "input.torque.slope", float(row[1]))
        scene_file, run_csv = tmp_path / "one.yaml", tmp_path / "one.csv"
        scene_file.write_text(scene_from_dict(data).to_yaml())
        assert main(["simulate", str(scene_file), "--csv", str(run_csv)]) == 0
        run = np.genfromtxt(run_csv, delimiter=",", names=True)
        values = dict(zip(header, map(float, row)))
        for name in ("theta1", "theta2", "theta3", "theta1_dot", "theta2_dot", "theta3_dot"):
            assert values[name] == pytest.approx(run[name][-1], abs=1e-12)
        assert values["max_constraint_residual"] == pytest.approx(run["constraint_residual"].max(), rel=1e-6, abs=1e-15)
        assert values["energy_change"] == pytest.approx(run["energy"][-1] - run["energy"][0], rel=1e-9)


def test_contact_scene_has_grip_force(tmp_path: Path) -> None:
    out = tmp_path / "grasp.csv"
    scene = str(CONFIG / "grasp_cylinder.yaml")
    assert main(["sweep", scene, "--vary", "objects.0.radius=0.012,0.013", "--vary", "integrator.method=rk4",
                 "--out", str(out)]) == 0
    header, rows = _read(out)
    assert header[-1] == "grip_force" and header[:2] == ["objects.0.radius", "integrator.method"]
    assert float(rows[0][-1]) == pytest.approx(0.17, abs=0.01)  # grasp_cylinder.yaml's comment
    assert float(rows[1][-1]) > 0


@pytest.mark.parametrize(("vary", "named"), [
    ("model.sprng=1", "model.sprng"),
    ("model.geometry.r9=0.05", "model.geometry.r9"),
    ("input.torque.slope=0.01,abc", "input.torque.slope"),
    ("initial.theta1=3.0", "initial.theta1"),
    ("model.spring_stiffness=-1", "model.spring_stiffness"),
    ("objects.3.radius=0.01", "objects.3.radius"),
    ("model.spring_stiffness=", "--vary"),
])
def test_bad_keys_and_values_are_refused_naming_the_key(tmp_path: Path, capsys, vary: str, named: str) -> None:
    out = tmp_path / "bad.csv"
    assert main(["sweep", PAPER, "--vary", vary, "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert named in err and err.count("\n") == 1, err
    assert not out.exists()


def test_budget_states_the_step_count(capsys, tmp_path: Path) -> None:
    assert main(["sweep", PAPER, *VARY, "--out", str(tmp_path / "x.csv"), "--max-steps", "1000"]) == 2
    assert "6 runs, 1,800 steps" in capsys.readouterr().err  # 6 runs of 300 steps


def test_chunks_concatenate_to_the_whole_sweep(tmp_path: Path) -> None:
    vary = ["model.spring_stiffness=0.0005,0.001,0.002", "initial.theta1=0.0,0.1,0.2"]
    whole = run_chunk(PAPER, vary).rows
    parts = []
    for i in (1, 2, 3, 4):
        out = tmp_path / f"chunk{i}.csv"
        assert main(["sweep", PAPER, "--vary", vary[0], "--vary", vary[1], "--chunk", f"{i}/4", "--out", str(out)]) == 0
        header, rows = _read(out)
        parts += rows
    assert len(parts) == len(whole) == 9
    for got, want in zip(parts, whole):
        assert [float(x) for x in got] == [float(want[c]) for c in header]
    assert main(["sweep", PAPER, "--vary", vary[0], "--chunk", "5/4", "--out", str(tmp_path / "x.csv")]) == 2
