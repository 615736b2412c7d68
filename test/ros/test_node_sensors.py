"""finger_node publishes a scene's measured motor current beside the true one (finger_sim.sensors),
in its own process over real DDS; reference: the offline run of the same scene, read back from the
node's log with rosbags."""

from __future__ import annotations

from pathlib import Path

import pytest

rclpy = pytest.importorskip("rclpy")

from rosbags.highlevel import AnyReader  # noqa: E402

from finger_sim.log import read_log  # noqa: E402
from finger_sim.run_log import load_run, resimulate  # noqa: E402
from finger_sim.scene import load_scene  # noqa: E402
from finger_sim.scene_yaml import dump_scene  # noqa: E402
from finger_sim.simulate import simulate  # noqa: E402
from helpers import NODE  # noqa: E402

CONFIG = Path(__file__).resolve().parents[2] / "config"
RATE = 1000.0
SUBPROCESS_TIMEOUT_S = 60.0
#: a noisy, lagging, quantised current sensor (A, s) on drive_grasp, cut to 0.35 s (past the drop to 0 V)
SENSORS = {"seed": 11, "motor_current": {"noise": 0.005, "time_constant": 0.004, "resolution": 0.001}}


def test_measured_current_is_the_offline_reading_and_resims(launcher, tmp_path):
    data = {**load_scene(CONFIG / "drive_grasp.yaml").to_dict(), "duration": 0.35, "sensors": SENSORS}
    scene_path = tmp_path / "drive_sensed.yaml"
    scene_path.write_text(dump_scene(data))
    bags = tmp_path / "bags"
    node = launcher.node(NODE, dict(scene=str(scene_path), torque_source="scene", realtime_factor=0.0, record_dir=str(bags)))
    assert node.wait(SUBPROCESS_TIMEOUT_S) == 0
    (path,) = sorted(bags.glob("*.mcap"))
    assert resimulate(load_run(read_log(path))).exact
    with AnyReader([path]) as reader:
        topics: dict[str, list[float]] = {}
        for c, _, raw in reader.messages():
            if c.topic in ("/motor/current", "/motor/current_measured"):
                topics.setdefault(c.topic, []).append(reader.deserialize(raw, c.msgtype).data)
    offline = simulate(load_scene(scene_path).with_overrides(dt=1.0 / RATE), kernel="python")
    assert topics["/motor/current"] == offline.outputs["motor_current"].tolist()
    assert topics["/motor/current_measured"] == offline.outputs["motor_current_measured"].tolist()
    assert topics["/motor/current_measured"] != topics["/motor/current"]  # the reading is not the truth
