"""Sensors as a controller sees them (finger_sim.sensors): each model against a reference written here."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from finger_sim.errors import ConfigError
from finger_sim.scene import load_scene, scene_from_dict, scene_from_yaml
from finger_sim.sensors import SensorBank, SensorModel, SensorSet
from finger_sim.simulate import simulate
from finger_sim.streaming import stream_csv

CONFIG = Path(__file__).resolve().parents[2] / "config"
#: drive_grasp cut to 0.35 s (past the voltage drop at 0.3 s: the current's step to 0), the sensors added.
DURATION = 0.35


def drive_scene(sensors: dict) -> object:
    data = load_scene(CONFIG / "drive_grasp.yaml").to_dict()
    return scene_from_dict({**data, "duration": DURATION, "sensors": sensors})


@pytest.fixture(scope="module")
def truth():
    """The drive_grasp run without sensors: the truth every reading is checked against."""
    return simulate(drive_scene({}))


def bank(dt: float, **model: float) -> SensorBank:
    return SensorBank(SensorSet(seed=3, pairs=(("motor_current", SensorModel(**model)),)), dt)


def test_lag_step_response_is_first_order_at_the_samples():
    dt, tau = 1e-3, 0.02
    step = np.r_[0.0, np.ones(200)]  # a unit step at t = 0⁺
    y = bank(dt, time_constant=tau).measure({"motor_current": step})["motor_current_measured"]
    k = np.arange(len(step))
    np.testing.assert_allclose(y, 1.0 - np.exp(-k * dt / tau), rtol=0, atol=1e-14)
    assert y[int(tau / dt)] == pytest.approx(1.0 - math.exp(-1.0), abs=1e-14)  # 63.2 % after one τ


def test_blocks_read_as_one_call():
    """The lag's state and the noise stream carry over from block to block (streamed runs)."""
    x = np.sin(np.arange(500) * 0.01)
    whole = bank(1e-3, time_constant=0.01, noise=0.1).measure({"motor_current": x})["motor_current_measured"]
    split = bank(1e-3, time_constant=0.01, noise=0.1)
    parts = [split.measure({"motor_current": x[a:b]})["motor_current_measured"] for a, b in ((0, 1), (1, 201), (201, 500))]
    np.testing.assert_array_equal(np.concatenate(parts), whole)


def test_noise_statistics():
    sigma, n = 0.01, 20000
    y = bank(1e-3, noise=sigma).measure({"motor_current": np.full(n, 0.25)})["motor_current_measured"] - 0.25
    assert abs(y.mean()) < 4.0 * sigma / math.sqrt(n)  # the sample mean's 4-sigma bound
    assert y.std() == pytest.approx(sigma, rel=0.03)  # the sample std's σ/√(2n) ≈ 0.5 %, 6 of them
    assert abs(np.corrcoef(y[:-1], y[1:])[0, 1]) < 4.0 / math.sqrt(n)  # white: no lag-1 correlation


def test_quantisation_and_saturation_on_a_run(truth):
    q, lo, hi = 0.01, 0.05, 0.3
    traj = simulate(drive_scene({"motor_current": {"resolution": q, "range": [lo, hi]}}))
    current = truth.outputs["motor_current"]
    assert current.max() > hi and current.min() < lo  # the run's current crosses both ends of the range
    expected = [q * math.floor(min(max(x, lo), hi) / q + 0.5) for x in current]
    np.testing.assert_allclose(traj.outputs["motor_current_measured"], expected, rtol=0, atol=1e-15)
    np.testing.assert_array_equal(traj.outputs["motor_current"], current)  # the truth beside the reading
    np.testing.assert_array_equal(traj.q, truth.q)  # the sensors never touch the dynamics
    np.testing.assert_array_equal(traj.v, truth.v)


def test_fsr_reads_the_phalanx_force(truth):
    traj = simulate(drive_scene({"fsr_distal": {"range": [0.0, 2.0]}, "fsr_proximal": {}}))
    for side in ("proximal", "distal"):
        force = [math.hypot(x, y) for x, y in zip(truth.outputs[f"contact_force_{side}_x"],
                                                  truth.outputs[f"contact_force_{side}_y"])]
        np.testing.assert_allclose(traj.outputs[f"fsr_{side}"], force, rtol=1e-15, atol=0)
    assert max(traj.outputs["fsr_distal"]) > 2.0
    np.testing.assert_allclose(traj.outputs["fsr_distal_measured"], np.minimum(traj.outputs["fsr_distal"], 2.0), rtol=1e-15)
    np.testing.assert_array_equal(traj.outputs["fsr_proximal_measured"], traj.outputs["fsr_proximal"])


def test_same_seed_same_readings_other_seed_other_readings(tmp_path):
    sensors = {"motor_current": {"noise": 0.002, "time_constant": 0.003}, "encoder": {"noise": 0.01, "resolution": 0.005},
               "fsr_distal": {"noise": 0.05}}
    first = simulate(drive_scene({"seed": 7, **sensors}))
    again = simulate(scene_from_yaml(_yaml(drive_scene({"seed": 7, **sensors}))))  # as a log's metadata re-runs it
    other = simulate(drive_scene({"seed": 8, **sensors}))
    for name in ("motor_current_measured", "encoder_measured", "fsr_distal_measured"):
        np.testing.assert_array_equal(first.outputs[name], again.outputs[name])
        assert np.any(first.outputs[name] != other.outputs[name])
    # the streamed CSV (block by block) is the in-memory run's file, byte for byte
    stream_csv(drive_scene({"seed": 7, **sensors}), tmp_path / "streamed.csv", kernel="python")
    first.write_csv(tmp_path / "memory.csv")
    assert (tmp_path / "streamed.csv").read_bytes() == (tmp_path / "memory.csv").read_bytes()
    assert "motor_current_measured" in (tmp_path / "memory.csv").read_text().splitlines()[0].split(",")


def _yaml(scene) -> str:
    from finger_sim.scene_yaml import dump_scene

    return dump_scene(scene.to_dict())


@pytest.mark.parametrize("sensors, key", [
    ({"motor_current": {"noise": -0.1}}, "sensors.motor_current.noise"),
    ({"encoder": {"resolution": math.inf}}, "sensors.encoder.resolution"),
    ({"fsr_distal": {"time_constant": -1.0}}, "sensors.fsr_distal.time_constant"),
    ({"fsr_distal": {"range": [1.0, 0.0]}}, "sensors.fsr_distal.range"),
    ({"seed": -1}, "sensors.seed"),
    ({"seed": 1.5}, "sensors.seed"),
    ({"thermometer": {}}, "sensors"),
    ({"motor_current": {"gain": 2.0}}, "sensors.motor_current"),
])
def test_bad_values_are_refused_naming_the_key(sensors, key):
    with pytest.raises(ConfigError) as err:
        drive_scene(sensors)
    line = str(err.value)
    assert key in line and "\n" not in line


def test_a_drive_sensor_without_a_drive_is_refused():
    with pytest.raises(ConfigError, match="sensors.motor_current"):
        scene_from_dict({"sensors": {"motor_current": {}}})
    with pytest.raises(ConfigError, match="sensors.fsr_distal"):
        scene_from_dict({"sensors": {"fsr_distal": {}}})
