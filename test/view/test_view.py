"""`finger-sim view` without a browser: the thinning rules, the signals a run brings, the size of a
long run's page, refusals, and the Foxglove layout (test_view_browser.py opens the pages).

References: a brute-force min/max per time bin written here; the spec §1 frame rate rule
(one frame per sample, at most MAX_FRAMES); ROS's own message classes for the layout's paths.
"""

from __future__ import annotations

import csv
import json
import math
import re
from pathlib import Path

import numpy as np
import pytest

from finger_sim.cli import main
from finger_sim.joints import JOINT_NAMES
from finger_sim.scene import load_scene
from finger_sim.simulate import simulate
from finger_sim.view.figure import build_figure
from finger_sim.view.frames import MAX_FRAMES, PLOT_BUCKETS, envelope, frame_indices, frame_times
from finger_sim.view.page import PLOTLY_BUNDLE, view_data
from finger_sim.view.source import read_run

ROOT = Path(__file__).resolve().parents[2]
CONFIG = ROOT / "config"
LAYOUT = CONFIG / "foxglove" / "finger_sim.json"
#: The page budget of a 60 s run at 1 kHz (the issue's), bytes.
PAGE_BUDGET = 10_000_000
EXIT_ERROR = 2


def test_envelope_keeps_every_bins_min_and_max() -> None:
    rng = np.random.default_rng(7)
    t = np.arange(100_000) * 1e-3
    y = np.cumsum(rng.normal(size=t.size))
    y[[123, 45_678, 99_000]] = [500.0, -500.0, 300.0]  # one-sample spikes must survive
    tt, yy = envelope(t, y, t[0], t[-1])
    assert len(tt) <= 2 * PLOT_BUCKETS and np.all(np.diff(tt) > 0)
    assert set(tt.tolist()) <= set(t.tolist())
    edges = np.linspace(t[0], t[-1], PLOT_BUCKETS + 1)
    for lo, hi, last in zip(edges[:-1], edges[1:], [False] * (PLOT_BUCKETS - 1) + [True]):
        inside = (t >= lo) & ((t <= hi) if last else (t < hi))
        shown = (tt >= lo) & ((tt <= hi) if last else (tt < hi))
        if inside.any():
            assert yy[shown].min() == y[inside].min() and yy[shown].max() == y[inside].max(), (lo, hi)
    short = t[:2 * PLOT_BUCKETS]
    assert envelope(short, y[:short.size], short[0], short[-1])[0] is short  # few samples: kept whole


def test_frames_at_one_fixed_rate() -> None:
    t = np.round(np.arange(60_001) * 1e-3, 9)  # 60 s at 1 kHz
    times = frame_times(t[0], t[-1], 1e-3)
    assert len(times) == MAX_FRAMES + 1 and np.allclose(np.diff(times), 60.0 / MAX_FRAMES, rtol=0, atol=1e-12)
    idx = frame_indices(t, times)
    assert np.array_equal(idx, np.arange(0, 60_001, 10))  # every 10th state, none interpolated
    short = np.round(np.arange(301) * 1e-3, 9)  # the paper's run: every state is a frame
    assert np.array_equal(frame_indices(short, frame_times(0.0, 0.3, 1e-3)), np.arange(301))


@pytest.fixture(scope="module")
def drive_csv(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """grasp_cylinder's simulate CSV with a DC-motor drive's columns appended (spec §8 outputs)."""
    path = tmp_path_factory.mktemp("drive") / "drive.csv"
    traj = simulate(load_scene(CONFIG / "grasp_cylinder.yaml"), kernel="python")
    traj.write_csv(path)
    with path.open() as file:
        rows = list(csv.reader(file))
    extra = ["motor_voltage", "motor_current", "motor_angle", "encoder", "mesh_mode", "mesh_loss"]
    out = [rows[0] + extra]
    for i, row in enumerate(rows[1:]):
        mode = "drive" if i < 200 else "stuck" if i < 400 else "back"
        out.append(row + ["6.0", f"{0.5 * math.sin(i / 50):.6f}", f"{300 * float(row[1]):.9f}", str(i // 3), mode, "0.01"])
    with path.open("w", newline="") as file:
        csv.writer(file).writerows(out)
    return path


def test_new_columns_appear_without_code_changes(drive_csv: Path) -> None:
    runs = read_run(drive_csv, load_scene(CONFIG / "grasp_cylinder.yaml"))
    data = view_data(runs)
    values = data["fingers"][0]["frames"]["values"]
    for name in ("motor_voltage", "motor_current", "motor_angle", "encoder", "mesh_mode", "mesh_loss", "grip_force",
                 "mcp_angle", "coupler_angle", "pip_angle"):
        assert name in values, name
    assert values["mesh_mode"][0] == "drive" and values["mesh_mode"][-1] == "back"
    assert data["units"]["motor_current"] == "A" and data["units"]["motor_voltage"] == "V"
    figure = build_figure(runs, data["t0"], data["t1"])
    titles = [a.text for a in figure.layout.annotations]
    for title in ("joint angles (°)", "voltage (V)", "force (N)", "current (A)", "mode", "motor_angle", "encoder", "mesh_loss"):
        assert title in titles, (title, titles)
    assert "torque (N·m)" not in titles  # a drive's CSV has a voltage command: no scripted torque is invented
    (mode,) = [tr for tr in figure.data if tr.name == "mesh_mode"]
    assert list(mode.y) == ["drive", "stuck", "back", "back"] and mode.line.shape == "hv"  # the changes, exact


def test_paper_csv_gets_the_scenes_torque(tmp_path: Path) -> None:
    scene = load_scene(CONFIG / "paper_flexion.yaml")
    path = tmp_path / "paper.csv"
    simulate(scene, kernel="python").write_csv(path)
    (run,) = read_run(path, scene)
    (torque,) = [s for s in run.signals if s.name == "torque"]
    assert np.allclose(torque.values, 0.01 * run.t + 0.001, rtol=0, atol=1e-15)  # spec §5: τ = 0.01 t + 0.001 N·m


def test_a_minute_at_1khz_stays_under_the_budget(tmp_path: Path) -> None:
    scene = load_scene(CONFIG / "grasp_cylinder.yaml").with_overrides(duration=60.0)
    path = tmp_path / "minute.csv"
    simulate(scene).write_csv(path)
    out = tmp_path / "minute.html"
    assert main(["view", str(path), "--scene", str(CONFIG / "grasp_cylinder.yaml"), "-o", str(out)]) == 0
    assert out.stat().st_size < PAGE_BUDGET
    text = out.read_text()
    assert not re.search(r"<(script|img|iframe)[^>]*\bsrc=|<link\b", text)  # everything inline


@pytest.mark.parametrize(("content", "problem"), [
    (b"", "an empty file"),
    (b"t,x\n0,1\n", "expected the state columns theta1, theta2, theta3"),
    (b"t,theta1,theta2,theta3\n0,0,0\n", "row 2 has 3 values"),
    (b"\x89MCAP0\r\nnot really", "not a finger_node or finger_hand log"),
])
def test_bad_runs_are_one_line(tmp_path: Path, capsys: pytest.CaptureFixture[str], content: bytes, problem: str) -> None:
    path = tmp_path / "run.csv"
    path.write_bytes(content)
    assert main(["view", str(path), "-o", str(tmp_path / "run.html")]) == EXIT_ERROR
    *warnings, error = capsys.readouterr().err.splitlines()  # a cut log is warned about first, as by export
    assert error.startswith("finger-sim view: error: ") and problem.lower() in error.lower(), error
    assert all(w.startswith("finger-sim: warning: ") for w in warnings), warnings
    assert not (tmp_path / "run.html").exists()


def test_vendored_plotly_is_the_plotly_packages_version() -> None:
    from plotly.offline import get_plotlyjs_version

    head = (ROOT / "finger_sim" / "view" / "vendor" / PLOTLY_BUNDLE).read_text()[:200]
    assert f"v{get_plotlyjs_version()}" in head, head  # the figure's JSON is written for this plotly.js


def test_foxglove_layout_shows_the_nodes_topics() -> None:
    pytest.importorskip("rclpy")  # the message classes come with the ros extra
    from finger_sim.ros.interfaces import OUTPUTS

    layout = json.loads(LAYOUT.read_text())
    panels = layout["configById"]

    def leaves(node: object) -> list[str]:
        return [node] if isinstance(node, str) else leaves(node["first"]) + leaves(node["second"])  # type: ignore[index]

    assert sorted(leaves(layout["layout"])) == sorted(panels)
    topics = {"/" + spec.topic.lstrip("/"): spec.msg_type for spec in OUTPUTS.values()}
    urdf = panels["3D!finger"]["layers"]["finger-urdf"]
    assert urdf["layerId"] == "foxglove.Urdf" and urdf["sourceType"] == "topic"
    assert topics[urdf["topic"]].__name__ == "String" and topics[urdf["jointStatesTopic"]].__name__ == "JointState"
    plotted = set()
    for panel in (p for key, p in panels.items() if key.startswith("Plot!")):
        for path in panel["paths"]:
            topic, field = path["value"].split(".", 1)
            message = topics[topic]()
            name = field.split("[")[0]
            assert hasattr(message, name), path
            plotted.add(topic)
            if field.startswith("position["):  # labelled by the joint the node puts at that index
                assert path["label"] == JOINT_NAMES[int(field[9])], path
    assert plotted == {"/joint_states", "/grip_force"}


def test_ros_columns_map_back_to_the_paper_state(tmp_path: Path) -> None:
    scene_path = CONFIG / "paper_flexion.yaml"
    paper, ros = tmp_path / "paper.csv", tmp_path / "ros.csv"
    assert main(["simulate", str(scene_path), "--csv", str(paper)]) == 0
    assert main(["simulate", str(scene_path), "--csv", str(ros), "--columns", "ros"]) == 0
    scene = load_scene(scene_path)
    (a,), (b,) = read_run(paper, scene), read_run(ros, scene)
    assert np.array_equal(a.t, b.t)
    assert np.abs(a.q - b.q).max() < 1e-12 and np.abs(a.v - b.v).max() < 1e-12  # spec §6 and back
    assert {"mcp_effort", "torque"} <= {s.name for s in b.signals}
    assert not {"mcp_position", "tip_x"} & {s.name for s in b.signals}  # drawn, not plotted again
