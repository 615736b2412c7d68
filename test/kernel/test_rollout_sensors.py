"""A rollout applies each row's scene sensors (finger_sim.sensors) as `simulate` does: its readings,
seeded by the row's scene, equal `simulate`'s of that scene (the reference: each row's own run)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from finger_sim import rollout
from finger_sim.errors import ConfigError
from finger_sim.scene import load_scene, scene_from_dict
from finger_sim.simulate import simulate
from finger_sim.sweep import set_key

CONFIG = Path(__file__).resolve().parents[2] / "config"
#: an FSR that lags, is noisy and saturates (no rounding: a 1e-15 difference of the truth can not flip a step)
FSR = {"noise": 0.05, "time_constant": 0.005, "range": [0.0, 0.3]}


def _scene(**values: object):
    data = load_scene(CONFIG / "grasp_cylinder.yaml").to_dict()
    data["sensors"] = {"seed": 7, "fsr_distal": FSR, "fsr_proximal": {}}
    for key, value in values.items():
        set_key(data, key, value)
    return scene_from_dict(data)


def test_each_rows_readings_equal_simulate_of_its_scene():
    springs = [0.001, 0.002]
    res = rollout(_scene(), params={"model.spring_stiffness": springs})
    rows = []
    for i, k in enumerate(springs):
        ref = simulate(_scene(**{"model.spring_stiffness": k})).outputs
        for name in ("fsr_distal", "fsr_distal_measured", "fsr_proximal", "fsr_proximal_measured"):
            np.testing.assert_allclose(res.outputs[name][i], ref[name], rtol=0, atol=1e-9, err_msg=f"{name} row {i}")
        rows.append(res.outputs["fsr_distal_measured"][i])
    assert rows[0].max() > 0.1 and np.ptp(rows[0] - res.outputs["fsr_distal"][0]) > 0.1  # it touched; noise is there
    other = simulate(_scene(**{"sensors.seed": 8})).outputs["fsr_distal_measured"]
    assert not np.allclose(rows[0], other)  # the seed is the scene's: another seed, other noise


def test_a_drive_sensor_is_refused_naming_it():
    data = load_scene(CONFIG / "drive_grasp.yaml").to_dict()
    data["sensors"] = {"motor_current": {"noise": 0.001}}
    with pytest.raises(ConfigError, match="sensors.motor_current"):
        rollout(scene_from_dict(data), nstep=5)
