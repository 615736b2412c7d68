"""`finger-sim export` and `resim` on a finger_hand log (issue 19, item 2): every finger, or one
with --finger NAME; resim reproduces every finger bit for bit. The export of a contact finger
has simulate's force columns, from the log's contact topics (item 6).

References: each finger's own offline run (a Simulator of its scene at the hand's 1 kHz, the
scene's torque profile), and the log's own joint states (resim compares with them exactly).
The hand runs three different scenes (one with contact) to their end, as fast as possible.
"""

from __future__ import annotations

import csv
import io
from pathlib import Path

import numpy as np
import pytest

from finger_sim.scene import load_scene
from finger_sim.simulate import Simulator, Trajectory, output_names, output_values
from helpers import run_cli, run_cli_here

HAND = "finger_sim.ros.hand"
CONFIG = Path(__file__).resolve().parents[2] / "config"
SCENES = {"index": "paper_flexion", "middle": "bang_bang", "ring": "grasp_cylinder"}  # the shortest: 0.3 s
STEPS = 300  # the run ends with its shortest scene
RATE = 1000.0
TIMEOUT_S = 60.0
TOL = 1e-12  # rad, rad/s: the joint states → paper coordinates round trip
EXIT_ERROR = 2


def offline(scene: str) -> np.ndarray:
    """t, θ1..θ3, θ1'..θ3' of the scene's own run at the hand's rate, states 0..STEPS."""
    sim = Simulator(load_scene(CONFIG / f"{scene}.yaml").with_overrides(dt=1.0 / RATE))
    states = [sim.state] + [sim.step(None) for _ in range(STEPS)]
    return np.array([[n / RATE, *s.q, *s.v] for n, s in enumerate(states)])


def paper_rows(path: Path) -> np.ndarray:
    header, _, body = path.read_text().partition("\n")
    assert header.startswith("t,theta1,theta2,theta3,theta1_dot,theta2_dot,theta3_dot"), header
    return np.array([[float(x) for x in row[:7]] for row in csv.reader(io.StringIO(body)) if row])


def offline_forces(scene: str) -> tuple[str, np.ndarray]:
    """`simulate --csv`'s header and force columns (the elements' outputs) of the scene's own run."""
    sim = Simulator(load_scene(CONFIG / f"{scene}.yaml").with_overrides(dt=1.0 / RATE))
    states = [sim.state] + [sim.step(None) for _ in range(STEPS)]
    names = output_names(sim.system.elements, sim.q)
    values = [output_values(sim.system.elements, s.t, s.q, s.v) for s in states]
    return Trajectory.csv_header(names), np.array(values)


@pytest.fixture(scope="module")
def hand_log(tmp_path_factory: pytest.TempPathFactory) -> Path:
    pytest.importorskip("rclpy")
    from conftest import Launcher, allocate_domain_id, ros_environment

    tmp = tmp_path_factory.mktemp("hand_log")
    hand = tmp / "three_scenes.yaml"
    hand.write_text("fingers:\n" + "".join(
        f"  - name: {name}\n    scene: {CONFIG / scene}.yaml\n    pose: [0.0, {0.02 * i}, 0.0, 0.0, 0.0, 0.0]\n"
        for i, (name, scene) in enumerate(SCENES.items())))
    launcher = Launcher(ros_environment(allocate_domain_id()), tmp)
    try:
        node = launcher.node(HAND, dict(hand=str(hand), torque_source="scene", realtime_factor=0.0,
                                        record_dir=str(tmp / "bags"), marker_rate_hz=0.0))
        assert node.wait(TIMEOUT_S) == 0, node.output()
    finally:
        launcher.stop_all()
    (path,) = (tmp / "bags").glob("three_scenes_*.mcap")
    return path


def test_resim_reproduces_every_finger_bit_for_bit(hand_log: Path) -> None:
    done = run_cli("resim", hand_log)
    assert done.returncode == 0, done.stdout + done.stderr
    assert done.stdout.splitlines() == [f"{name}: resim: {STEPS + 1} recorded states reproduced bit for bit "
                                        "(max deviation 0)" for name in SCENES]
    one = run_cli_here("resim", hand_log, "--finger", "ring")  # the whole log ran through the console script
    assert one.returncode == 0 and one.stdout.splitlines() == done.stdout.splitlines()[2:], one.stdout + one.stderr


def test_export_writes_one_csv_per_finger_or_the_one_asked_for(hand_log: Path, tmp_path: Path) -> None:
    done = run_cli("export", hand_log, "--csv", tmp_path / "hand.csv", "--plot", tmp_path / "hand.png")
    assert done.returncode == 0, done.stdout + done.stderr
    for name, scene in SCENES.items():
        got = paper_rows(tmp_path / f"hand_{name}.csv")
        np.testing.assert_allclose(got, offline(scene), rtol=0, atol=TOL, err_msg=name)
        assert (tmp_path / f"hand_{name}.png").stat().st_size > 0
    assert not (tmp_path / "hand.csv").exists()
    # the contact finger's forces: the columns (and values) simulate writes, from the log's contact topics
    header, forces = offline_forces(SCENES["ring"])
    text = (tmp_path / "hand_ring.csv").read_text()
    assert text.partition("\n")[0] == header and "grip_force" in header
    rows = np.array([[float(x) for x in row] for row in csv.reader(io.StringIO(text.partition("\n")[2])) if row])
    np.testing.assert_allclose(rows[:, 9:], forces, rtol=1e-12, atol=1e-12)
    assert forces[:, 0].max() > 0.1  # it did grip
    assert (tmp_path / "hand_index.csv").read_text().partition("\n")[0] == Trajectory.csv_header(())

    one = run_cli_here("export", hand_log, "--finger", "middle", "--csv", tmp_path / "middle.csv")
    assert one.returncode == 0, one.stdout + one.stderr
    assert (tmp_path / "middle.csv").read_text() == (tmp_path / "hand_middle.csv").read_text()


@pytest.mark.parametrize("command", ["export", "resim"])
def test_an_unknown_finger_is_one_line_naming_the_fingers(hand_log: Path, command: str) -> None:
    done = run_cli_here(command, hand_log, "--finger", "thumb")
    assert done.returncode == EXIT_ERROR
    assert "Traceback" not in done.stderr and len(done.stderr.splitlines()) == 1, done.stderr
    assert "--finger 'thumb'" in done.stderr and "'index', 'middle', 'ring'" in done.stderr
