"""`finger-sim` as a user runs it: the venv's console script in a subprocess.

The numbers it prints and writes are checked against the in-process Trajectory and the
independent reference (`reference.py`); the CSV is read back with the standard `csv`
module, the PNG only for its signature and size.
"""

from __future__ import annotations

import csv
import math
import re
import struct
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import yaml

import reference as ref
from finger_sim.cli import main
from finger_sim.scene import load_scene
from finger_sim.simulate import Trajectory, simulate

FINGER_SIM = Path(sys.executable).with_name("finger-sim")
PAPER = ref.CONFIG / "paper_flexion.yaml"
PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"
HEADER = "t,theta1,theta2,theta3,theta1_dot,theta2_dot,theta3_dot,energy,constraint_residual"
NUMBER = r"(-?\d+\.\d+)"


def run(*args: str, cwd: Path | None = None) -> subprocess.CompletedProcess:
    return subprocess.run([str(FINGER_SIM), *args], capture_output=True, text=True, timeout=120, cwd=cwd)


def png_size(path: Path) -> tuple[int, int]:
    data = path.read_bytes()
    assert data[:8] == PNG_SIGNATURE and data[12:16] == b"IHDR"
    return struct.unpack(">II", data[16:24])


@pytest.fixture(scope="module")
def paper_cli(tmp_path_factory):
    out = tmp_path_factory.mktemp("cli")
    proc = run("simulate", str(PAPER), "--csv", str(out / "run.csv"), "--plot", str(out / "run.png"))
    return proc, out


def test_simulate_prints_the_spec_check_values(paper_cli):
    proc, _ = paper_cli
    assert proc.returncode == 0, proc.stderr
    assert "Traceback" not in proc.stderr
    first = proc.stdout.splitlines()[0]
    m = re.search(rf"θ = \({NUMBER}°, {NUMBER}°, {NUMBER}°\)", first)
    assert m, first
    assert tuple(float(x) for x in m.groups()) == (34.34, 54.39, -53.02)
    # the same digits from the independent reference
    y = ref.solve_scene(yaml.safe_load(PAPER.read_text())).y(0.3)
    assert tuple(round(math.degrees(a), 2) for a in y[:3]) == (34.34, 54.39, -53.02)
    assert "t = 0.3 s" in first and "steps = 300" in first and "method = rk6" in first
    assert float(re.search(r"max\|Φ\| = (\S+) m", first).group(1)) < 1e-10
    assert float(re.search(r"ΔE = (\S+) J", first).group(1)) == pytest.approx(1.868e-3, abs=5e-7)
    assert "method auto → rk6" in proc.stdout


def test_simulate_csv_is_the_trajectory(paper_cli):
    proc, out = paper_cli
    assert f"wrote {out / 'run.csv'}" in proc.stdout
    with open(out / "run.csv", newline="") as fh:
        rows = list(csv.reader(fh))
    assert ",".join(rows[0]) == HEADER
    data = np.array(rows[1:], dtype=float)
    traj = simulate(load_scene(PAPER))
    assert data.shape == (301, 9)  # one row per step, t = 0 included
    np.testing.assert_array_equal(data[:, 0], traj.t)
    np.testing.assert_array_equal(data[:, 1:4], traj.q)  # %.17g round-trips exactly
    np.testing.assert_array_equal(data[:, 4:7], traj.v)
    np.testing.assert_array_equal(data[:, 7], traj.energy)
    np.testing.assert_array_equal(data[:, 8], traj.residual)
    assert data[0, 0] == 0.0 and data[-1, 0] == pytest.approx(0.3, abs=1e-15)
    np.testing.assert_allclose(np.degrees(data[-1, 1:4]), (34.34, 54.39, -53.02), atol=0.005)


def test_simulate_plot_is_a_png(paper_cli):
    proc, out = paper_cli
    png = out / "run.png"
    assert f"wrote {png}" in proc.stdout
    assert png.stat().st_size > 10_000
    assert png_size(png) == (770, 770)  # 7 × 7 in at 110 dpi


def test_csv_header_is_the_documented_one():
    assert Trajectory.CSV_HEADER == HEADER


def test_kinematics_prints_the_spec_values(tmp_path):
    proc = run("kinematics", "--plot", str(tmp_path / "k.png"))
    assert proc.returncode == 0, proc.stderr
    text = proc.stdout
    toggles = re.search(rf"toggle angles θ1 = {NUMBER}° \(flexion\), {NUMBER}° \(extension\)", text)
    assert (float(toggles.group(1)), float(toggles.group(2))) == ref.TOGGLES_DEG
    assert tuple(round(math.degrees(a), 4) for a in ref.toggles()) == ref.TOGGLES_DEG
    ext = re.search(rf"θ_ext = \({NUMBER}°, {NUMBER}°, {NUMBER}°\)", text)
    assert tuple(float(x) for x in ext.groups()) == ref.THETA_EXT_DEG
    pip = re.search(rf"PIP range over MCP 0..90°: {NUMBER}° .. {NUMBER}°", text)
    lo, hi = float(pip.group(1)), float(pip.group(2))
    assert lo == 0.0
    assert round(hi, 1) == 102.4  # spec §1
    assert hi == round(math.degrees(ref.beta(ref.assemble(math.pi / 2))), 2)
    tip = re.search(rf"fingertip at extension \({NUMBER}, {NUMBER}\) m", text)
    assert (float(tip.group(1)), float(tip.group(2))) == (0.0885, 0.0)
    assert png_size(tmp_path / "k.png")[0] > 0


BAD_SCENES = {
    "negative_damping": ("model: {damping: -1}\n", (), "bad.yaml: model.damping: expected a number ≥ 0, got -1"),
    "unknown_key": ("modle: {}\n", (), "bad.yaml: scene: expected only the keys"),
    "invalid_yaml": ("model: [1, 2\n", (), "scene: expected valid YAML"),
    "missing_file": (None, (), "scene: expected a readable scene file"),
    "theta1_range": ("initial: {theta1: 2.0}\n", (), "bad.yaml: initial.theta1: expected an MCP angle in the assemblable range"),
    "dt_zero": ("{}\n", ("--dt", "0"), "integrator.dt: expected a number > 0, got 0.0"),
    "unstable": ("model: {spring_stiffness: 1000.0}\n", ("--method", "rk4"), "integrator.method: rk4 is unstable for scene 'bad' at dt = 0.001 s"),
}


def bad_scene(tmp_path: Path, case: str) -> tuple[Path, tuple[str, ...], str]:
    write, args, message = BAD_SCENES[case]
    scene = tmp_path / "bad.yaml"
    if write is not None:
        scene.write_text(write)
    return scene, args, message


@pytest.mark.parametrize("case", ["negative_damping", "invalid_yaml", "missing_file", "unstable"])
def test_a_bad_scene_exits_nonzero_with_one_line(tmp_path, case):
    """The console script in a subprocess: exit status 2, one line on stderr, no traceback."""
    scene, args, message = bad_scene(tmp_path, case)
    proc = run("simulate", str(scene), *args, cwd=tmp_path)
    assert proc.returncode == 2
    assert proc.stdout == ""
    lines = proc.stderr.splitlines()
    assert len(lines) == 1, proc.stderr
    assert "Traceback" not in proc.stderr
    assert lines[0].startswith("finger-sim simulate: error: ")
    assert message in lines[0]


@pytest.mark.parametrize("case", sorted(BAD_SCENES))
def test_every_bad_scene_is_one_line_in_process(tmp_path, capsys, case):
    """The same through main() (no exception escapes it), for every kind of refusal."""
    scene, args, message = bad_scene(tmp_path, case)
    assert main(["simulate", str(scene), *args]) == 2
    captured = capsys.readouterr()
    assert captured.out == ""
    lines = captured.err.splitlines()
    assert len(lines) == 1 and lines[0].startswith("finger-sim simulate: error: ")
    assert message in lines[0]


def test_overrides_in_process(capsys):
    """--method, --dt and --t-end reach the run (main() called directly, same code path)."""
    assert main(["simulate", str(PAPER), "--method", "radau", "--dt", "0.002", "--t-end", "0.1"]) == 0
    first = capsys.readouterr().out.splitlines()[0]
    assert "t = 0.1 s" in first and "method = radau" in first and "steps = 50" in first
    y = ref.solve_scene(yaml.safe_load(PAPER.read_text()), t_end=0.1).y(0.1)
    shown = tuple(float(x) for x in re.search(rf"θ = \({NUMBER}°, {NUMBER}°, {NUMBER}°\)", first).groups())
    assert shown == tuple(round(math.degrees(a), 2) for a in y[:3])
