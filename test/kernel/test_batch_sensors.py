"""The batch and the sweep read each scene's sensors (finger_sim.sensors) as `simulate` does: the
readings at a run's end, seeded by its scene, equal `simulate`'s last ones (the reference: each
row's own run); a scene without sensors has none (NaN)."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from finger_sim.batch import run_batch
from finger_sim.scene import load_scene, scene_from_dict
from finger_sim.simulate import simulate
from finger_sim.sweep import run_chunk, set_key

CONFIG = Path(__file__).resolve().parents[2] / "config"
SENSORS = {"seed": 3, "fsr_distal": {"noise": 0.05, "time_constant": 0.005}, "fsr_proximal": {"resolution": 0.01}}


def _scene(sensors: dict | None = SENSORS, **values: object):
    data = load_scene(CONFIG / "grasp_cylinder.yaml").to_dict()
    if sensors is not None:
        data["sensors"] = sensors
    for key, value in values.items():
        set_key(data, key, value)
    return scene_from_dict(data)


def test_batch_end_readings_equal_simulate_of_each_scene():
    scenes = [_scene(), _scene(**{"model.spring_stiffness": 0.002}), _scene(None), _scene({**SENSORS, "seed": 4})]
    result = run_batch(scenes)
    assert set(result.measured) == {"fsr_distal_measured", "fsr_proximal_measured"}
    ends = []
    for i, scene in enumerate(scenes):
        ref = simulate(scene)
        assert result.q[i].tolist() == ref.q[-1].tolist()
        for name, values in result.measured.items():
            if scene.sensors is None:
                assert math.isnan(values[i])
            else:
                assert values[i] == ref.outputs[name][-1]
        ends.append(result.measured["fsr_distal_measured"][i])
    assert ends[0] > 0.05 and ends[0] != ends[3]  # it grips; another seed, another reading
    assert result.compiled[2] or not result.compiled.any()  # the scene without sensors keeps the compiled loop


def test_sweep_rows_carry_the_last_readings():
    chunk = run_chunk(_scene(), ["model.spring_stiffness=0.001,0.002"])
    assert set(chunk.header[-2:]) == {"fsr_distal_measured", "fsr_proximal_measured"}
    for row, k in zip(chunk.rows, (0.001, 0.002)):
        ref = simulate(_scene(**{"model.spring_stiffness": k})).outputs
        assert row["fsr_distal_measured"] == ref["fsr_distal_measured"][-1]
        assert row["fsr_proximal_measured"] == ref["fsr_proximal_measured"][-1]
