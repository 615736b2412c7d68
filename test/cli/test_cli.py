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


# -- issue 8: resource bounds, paths, one line per failure, the default method -----------------------------

def one_error_line(err: str, command: str = "simulate") -> str:
    lines = err.splitlines()
    assert len(lines) == 1 and "Traceback" not in err, err
    assert lines[0].startswith(f"finger-sim {command}: error: "), lines[0]
    return lines[0]


@pytest.mark.parametrize(("scene_text", "args", "steps", "memory"), [
    (None, ("--dt", "1e-9", "--t-end", "100"), "100,000,000,000 steps", "60 TB"),
    ("integrator: {dt: 1e-5}\nduration: 100\n", (), "10,000,000 steps", "6 GB"),
], ids=["dt_1e-9", "long_duration"])
def test_a_run_too_big_for_memory_is_refused_up_front(tmp_path, capsys, scene_text, args, steps, memory):
    """Refused at once (nothing runs), naming the steps, the memory and both ways to go ahead."""
    scene = PAPER
    if scene_text is not None:
        scene = tmp_path / "long.yaml"
        scene.write_text(scene_text)
    assert main(["simulate", str(scene), *args]) == 2
    captured = capsys.readouterr()
    assert captured.out == ""
    line = one_error_line(captured.err)
    assert f"a run of {steps} would hold about {memory} in memory, over the limit of 2,000,000 steps" in line
    count = steps.split()[0].replace(",", "")
    assert f"--max-steps {count}" in line and "--csv FILE" in line


def test_a_scene_asking_for_1e38_seconds_is_refused(tmp_path, capsys):
    scene = tmp_path / "huge.yaml"
    scene.write_text("duration: 1e38\n")
    assert main(["simulate", str(scene)]) == 2
    line = one_error_line(capsys.readouterr().err)
    assert "huge.yaml: duration: expected a run of at most 1e+12 steps" in line and "1e+41 steps" in line


def test_max_steps_refuses_or_lets_a_run_go_ahead(tmp_path, capsys):
    """The paper's run is 300 steps: a cap of 299 refuses it (held in memory or streamed), 300 runs it."""
    assert main(["simulate", str(PAPER), "--max-steps", "299"]) == 2
    line = one_error_line(capsys.readouterr().err)
    assert "a run of 300 steps would hold about 181 kB in memory, over the limit of 299 steps" in line
    assert "--max-steps 300" in line
    assert main(["simulate", str(PAPER), "--max-steps", "299", "--csv", str(tmp_path / "run.csv")]) == 2
    line = one_error_line(capsys.readouterr().err)
    assert line.endswith("--max-steps: expected at least the run's 300 steps (duration 0.3 s at dt = 0.001 s), got 299")
    assert not (tmp_path / "run.csv").exists()
    assert main(["simulate", str(PAPER), "--max-steps", "300"]) == 0
    assert "steps = 300" in capsys.readouterr().out


def test_csv_alone_streams_the_same_file_and_summary(tmp_path, capsys):
    """--csv without --plot writes row by row: byte for byte the in-memory run's CSV, the same summary."""
    streamed, held = tmp_path / "streamed.csv", tmp_path / "held.csv"
    assert main(["simulate", str(PAPER), "--csv", str(streamed)]) == 0
    out = capsys.readouterr().out.splitlines()
    traj = simulate(load_scene(PAPER))
    traj.write_csv(held)
    assert streamed.read_bytes() == held.read_bytes()
    without_wall = re.compile(r"  wall = \S+ s$")
    assert without_wall.sub("", out[0]) == without_wall.sub("", traj.summary())
    assert out[1] == f"method auto → {traj.method}: {traj.method_reason}"
    assert out[2] == f"wrote {streamed}"


def test_a_streamed_run_takes_constant_memory(tmp_path):
    """tracemalloc peak of stream_csv: four times the steps, the same peak (within 4 KiB), and under a
    quarter of the same run held in memory."""
    import tracemalloc

    from finger_sim import simulate as simulate_module
    from finger_sim.streaming import stream_csv

    base = load_scene(ref.CONFIG / "free_swing.yaml").with_overrides(method="rk4")
    stream_csv(base.with_overrides(duration=0.01), tmp_path / "warm.csv")  # first-call costs out of the way

    def peak(run, steps: int) -> int:
        simulate_module._setup.cache_clear()  # each run builds its set-up alike (the cache would hold it or evict others)
        tracemalloc.start()
        try:
            run(base.with_overrides(duration=steps * base.dt))
            return tracemalloc.get_traced_memory()[1]
        finally:
            tracemalloc.stop()

    # at least a few of the stream's output blocks each (a shorter run fills less than one: its peak is lower)
    short = peak(lambda s: stream_csv(s, tmp_path / "short.csv"), 1000)
    long = peak(lambda s: stream_csv(s, tmp_path / "long.csv"), 4000)
    held = peak(simulate, 4000)
    assert long < short + 4096, (short, long)
    assert long < held / 4, (long, held)
    assert len((tmp_path / "long.csv").read_text().splitlines()) == 4000 + 2  # header, t = 0, every step


PATH_CASES = {
    "csv_folder": (["--csv", "{tmp}"], "--csv: expected a file path, not a folder, got '{tmp}'"),
    "csv_missing_folder": (["--csv", "{tmp}/missing/run.csv"],
                           "--csv: expected a file in an existing folder (no folder {tmp}/missing), got '{tmp}/missing/run.csv'"),
    "csv_proc": (["--csv", "/proc"], "--csv: expected a file path, not a folder, got '/proc'"),
    "plot_unknown_extension": (["--plot", "{tmp}/run.xyz"], "--plot: expected an image file ending in one of .avif, .eps, "),
    "plot_no_extension": (["--plot", "{tmp}/some/dir"], "--plot: expected an image file ending in one of .avif, .eps, "),
    "plot_folder": (["--plot", "{tmp}/some"], "--plot: expected a file path, not a folder, got '{tmp}/some'"),
}


@pytest.mark.parametrize("case", sorted(PATH_CASES))
def test_a_bad_output_path_is_refused_before_the_run(tmp_path, capsys, case):
    """One line naming the argument; nothing run (stdout empty), nothing written (not even dir.png)."""
    args, message = PATH_CASES[case]
    (tmp_path / "some").mkdir()
    before = sorted(tmp_path.rglob("*"))
    assert main(["simulate", str(PAPER), *(a.format(tmp=tmp_path) for a in args)]) == 2
    captured = capsys.readouterr()
    assert captured.out == ""
    line = one_error_line(captured.err)
    assert message.format(tmp=tmp_path) in line
    if case.startswith("plot_") and "extension" in case:
        assert all(f".{ext}," in line for ext in ("pdf", "png", "svg", "jpg")) and ".xyz" not in line.split("got")[0]
        assert line.endswith(f"got '{args[1].format(tmp=tmp_path)}'")
    assert sorted(tmp_path.rglob("*")) == before


def test_a_file_the_system_refuses_is_one_line(capsys):
    """/proc takes no new files: the write itself fails; main() reports the OSError in one line."""
    assert main(["simulate", str(PAPER), "--csv", "/proc/run.csv"]) == 2
    captured = capsys.readouterr()
    assert captured.out == ""
    assert "/proc/run.csv" in one_error_line(captured.err)


def test_plot_writes_the_format_its_extension_names(tmp_path, capsys):
    """What `wrote` names is the file written, in its format: an SVG for .svg."""
    svg = tmp_path / "run.svg"
    assert main(["simulate", str(PAPER), "--plot", str(svg)]) == 0
    assert capsys.readouterr().out.splitlines()[-1] == f"wrote {svg}"
    head = svg.read_bytes()[:400]
    assert head.startswith(b"<?xml") and b"<svg" in head
    assert sorted(p.name for p in tmp_path.iterdir()) == ["run.svg"]


@pytest.mark.parametrize(("argv", "command", "message"), [
    (["kinematics", "--plot", "{tmp}/k.xyz"], "kinematics", "--plot: expected an image file ending in one of"),
    (["kinematics", "--plot", "{tmp}/k"], "kinematics", "--plot: expected an image file ending in one of"),
    (["bench", "--out", "{tmp}/file/docs"], "bench", "--out: expected a folder ({tmp}/file is a file), got '{tmp}/file/docs'"),
], ids=["kinematics_extension", "kinematics_no_extension", "bench_out_under_a_file"])
def test_other_commands_check_their_paths(tmp_path, capsys, argv, command, message):
    (tmp_path / "file").write_text("")
    assert main([a.format(tmp=tmp_path) for a in argv]) == 2
    captured = capsys.readouterr()
    assert captured.out == ""
    assert message.format(tmp=tmp_path) in one_error_line(captured.err, command)


@pytest.mark.parametrize("argv", [
    [], ["simulate"], ["frobnicate"], ["simulate", str(PAPER), "--method", "nope"],
    ["simulate", str(PAPER), "--method", "rk4\nrk6"], ["simulate", str(PAPER), "--max-steps", "0"],
    ["simulate", str(PAPER), "--dt", "fast"], ["simulate", str(PAPER), "--unknown\nflag"],
], ids=["nothing", "no_scene", "unknown_command", "unknown_method", "newline_in_value", "max_steps_0", "dt_text",
        "newline_in_unknown"])
def test_a_usage_error_is_one_line(capsys, argv):
    """argparse's refusals too: one line (no usage block), exit status 2."""
    with pytest.raises(SystemExit) as exit_info:
        main(argv)
    assert exit_info.value.code == 2
    captured = capsys.readouterr()
    assert captured.out == ""
    lines = captured.err.splitlines()
    assert len(lines) == 1 and lines[0].startswith("finger-sim") and ": error: " in lines[0], captured.err


@pytest.mark.parametrize(("content", "message"), [
    (b"name: caf\xe9\n", "bad.yaml: byte 0xe9 at offset 9 is not UTF-8"),
    (b"[" * 100_000 + b"]" * 100_000, "nesting deeper than"),
    (b"integrator: {method: [rk4]}\n", "integrator.method"),
], ids=["not_utf8", "nested_100k_deep", "unhashable_method"])
def test_scenes_that_gave_tracebacks_are_one_line(tmp_path, content, message):
    scene = tmp_path / "bad.yaml"
    scene.write_bytes(content)
    proc = run("simulate", str(scene), cwd=tmp_path)
    assert proc.returncode == 2 and proc.stdout == ""
    assert message in one_error_line(proc.stderr)


def test_the_default_method_is_auto(tmp_path, capsys):
    """A scene that names no method runs with auto, as the help says; --method still overrides it."""
    scene = tmp_path / "plain.yaml"
    scene.write_text("duration: 0.01\n")
    assert main(["simulate", str(scene)]) == 0
    assert "method auto → " in capsys.readouterr().out
    assert main(["simulate", str(scene), "--method", "rk4"]) == 0
    assert "method = rk4" in capsys.readouterr().out
    with pytest.raises(SystemExit):
        main(["simulate", "--help"])
    assert "a scene that names none uses auto" in " ".join(capsys.readouterr().out.split())
