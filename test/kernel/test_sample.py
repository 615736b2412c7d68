"""`finger-sim sample`: seeded draws, each run equal to `simulate` of its scene, and Sobol indices
checked where the answer is known (a key that cannot matter has index 0; the only key that
matters carries all the variance), spreads bounded by the extreme runs simulated here.
"""

from __future__ import annotations

import csv
from pathlib import Path

import numpy as np
import pytest

from finger_sim import kinematics
from finger_sim.cli import main
from finger_sim.errors import ConfigError
from finger_sim.sample import draw, parse_dist, run_sample
from finger_sim.scene import Scene, load_scene, scene_from_dict
from finger_sim.simulate import simulate
from finger_sim.sweep import set_key

CONFIG = Path(__file__).resolve().parents[2] / "config"
PAPER = CONFIG / "paper_flexion.yaml"
TOLERANCE = 1e-12  # rad
#: The spring's uniform range (N·m/rad) and a contact stiffness on a scene without objects: no effect.
SPRING = (0.0008, 0.0012)
DISTS = [f"model.spring_stiffness=uniform({SPRING[0]},{SPRING[1]})", "model.contact.stiffness=uniform(1e4,1e6)"]


def _scene(**values: object) -> Scene:
    data = load_scene(PAPER).to_dict()
    for key, value in values.items():
        set_key(data, key, value)
    return scene_from_dict(data)


@pytest.fixture(scope="module")
def result():
    return run_sample(PAPER, DISTS, 16, seed=3, at=0.2)


def test_draws_are_seeded_and_each_run_equals_simulate(result):
    dists = [parse_dist(d) for d in DISTS]
    np.testing.assert_array_equal(draw(dists, 16, 3), result.draws)  # the runs are a function of the draws
    assert not np.array_equal(draw(dists, 16, 4), result.draws)
    assert result.draws.shape == (16 * 4, 2)
    assert SPRING[0] <= result.draws[:, 0].min() and result.draws[:, 0].max() <= SPRING[1]
    nominal = simulate(load_scene(PAPER))
    alpha = kinematics.distal_offset(load_scene(PAPER).params)
    for i in (0, 29, 63):
        run = simulate(_scene(**{"model.spring_stiffness": float(result.draws[i, 0]),
                                 "model.contact.stiffness": float(result.draws[i, 1])}))
        np.testing.assert_allclose([result.outputs[f"theta{j + 1}"][i] for j in range(3)], run.q[200], rtol=0,
                                   atol=TOLERANCE)
        tips = np.array([kinematics.fingertip(load_scene(PAPER).params, tuple(q), alpha)[:2] for q in run.q])
        nominal_tips = np.array([kinematics.fingertip(load_scene(PAPER).params, tuple(q), alpha)[:2] for q in nominal.q])
        assert result.outputs["tip_x"][i] == pytest.approx(tips[200, 0], abs=1e-15)
        deviation = np.hypot(*(tips - nominal_tips).T).max()
        assert result.outputs["tip_deviation"][i] == pytest.approx(deviation, rel=1e-9, abs=1e-15)


def test_sobol_indices_where_the_answer_is_known(result):
    s = result.sobol["theta1"]
    # the contact stiffness acts on nothing here: its runs are bit-identical, so its indices are zero
    assert s["S1"][1] == pytest.approx(0.0, abs=1e-12) and s["ST"][1] == pytest.approx(0.0, abs=1e-12)
    # the spring is the only key that acts: it carries all the variance
    assert s["ST"][0] == pytest.approx(1.0, abs=max(0.05, s["ST_conf"][0]))
    assert s["S1"][0] == pytest.approx(1.0, abs=max(0.1, s["S1_conf"][0]))
    # θ1 falls as the spring stiffens: every run lies between the two extreme springs' runs
    stiff, soft = (simulate(_scene(**{"model.spring_stiffness": k})).q[200, 0] for k in (SPRING[1], SPRING[0]))
    theta1 = result.outputs["theta1"]
    assert stiff < theta1.min() and theta1.max() < soft


def test_the_command_writes_csv_parquet_and_envelope(tmp_path, capsys):
    pq = pytest.importorskip("pyarrow.parquet")
    args = ["sample", str(PAPER), "--dist", "model.geometry.r1=normal(0.046,0.00005)",
            "--dist", "model.geometry.L3=normal(0.0425,0.00005)", "-n", "8", "--seed", "1",
            "--out", str(tmp_path / "runs.csv"), "--parquet", str(tmp_path / "runs.parquet"),
            "--plot", str(tmp_path / "envelope.png")]
    assert main(args) == 0
    report = capsys.readouterr().out
    assert "32 runs (n = 8, seed 1), outputs at t = 0.3 s" in report and "| tip_deviation |" in report
    with (tmp_path / "runs.csv").open(newline="") as f:
        rows = list(csv.DictReader(f))
    table = pq.read_table(tmp_path / "runs.parquet").to_pylist()
    assert len(rows) == len(table) == 32
    for got, want in zip(table, rows, strict=True):
        assert got == {k: float(v) for k, v in want.items()}
    assert (tmp_path / "envelope.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


@pytest.mark.parametrize(("text", "message"), [
    ("model.spring_stiffness=normal(0.001)", "--dist: expected KEY=normal(mean,sd) or KEY=uniform(low,high)"),
    ("model.spring_stiffness=normal(0.001,-1)", "--dist model.spring_stiffness: expected a standard deviation > 0"),
    ("model.damping=uniform(1,0)", "--dist model.damping: expected low < high"),
])
def test_bad_distributions_are_refused_by_name(text, message):
    with pytest.raises(ConfigError) as err:
        parse_dist(text)
    assert message in str(err.value)


def test_the_command_refuses_in_one_line(capsys):
    assert main(["sample", str(PAPER), "--dist", "model.spring_stiffness=uniform(0.001,0.002)", "-n", "6"]) == 2
    assert capsys.readouterr().err.strip() == ("finger-sim sample: error: -n: expected a power of two ≥ 2 "
                                               "(the Sobol sequence's balance), got 6")
    assert main(["sample", str(PAPER), "--dist", "model.spring_stiffness=uniform(-1,0.002)", "-n", "4"]) == 2
    assert "model.spring_stiffness" in capsys.readouterr().err
