"""grip_voltage closing its loop on a sensor's reading (finger_sim.sensors) on the drive task
(config/tasks/hold_voltage_off.yaml). References: the run on the ideal force sensor (the cup touches
the distal phalanx only, without friction: its FSR reads the grip force itself), and the
self-locking claim (after the voltage goes off: current 0, grip constant bit for bit)."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest

from finger_sim.errors import ConfigError
from finger_sim.sensors import sensors_from_dict
from finger_sim.tasks.controllers import grip_voltage
from finger_sim.tasks.runner import run_task
from finger_sim.tasks.schema import load_task

TASK = load_task(Path(__file__).resolve().parents[2] / "config" / "tasks" / "hold_voltage_off.yaml")
#: a realistic FSR: σ 0.02 N noise, 5 ms lag, 0.01 N steps; the contact threshold (N) then 5σ above it
NOISY = {"noise": 0.02, "time_constant": 0.005, "resolution": 0.01}
THRESHOLD = 0.1


def sensed(sensors: dict) -> object:
    scene = dataclasses.replace(TASK.scene, sensors=sensors_from_dict(sensors, has_drive=True, has_objects=True))
    return dataclasses.replace(TASK, scene=scene)


def test_an_ideal_fsr_on_the_distal_phalanx_is_the_grip_force_sensor():
    ideal = run_task(TASK, grip_voltage)
    fsr = run_task(sensed({"fsr_distal": {}}), grip_voltage, params={"feedback": "fsr_distal_measured"})
    for column in ("command", "grip_force", "motor_current"):  # |F_distal| = Σ F_n to round-off (hypot vs sum)
        np.testing.assert_allclose(fsr.samples[column], ideal.samples[column], rtol=0, atol=1e-12)
    assert fsr.samples["command"][-1] == 0.0 and fsr.scores["settle_time"] == ideal.scores["settle_time"]


@pytest.mark.parametrize("seed", [1, 2])
def test_a_noisy_lagging_fsr_still_ends_in_the_unpowered_hold(seed):
    run = run_task(sensed({"seed": seed, "fsr_distal": NOISY}), grip_voltage,
                   params={"feedback": "fsr_distal_measured", "contact_threshold": THRESHOLD})
    s = run.samples
    off = np.flatnonzero(s["command"] != 0.0)[-1] + 1  # the first sample with the voltage off for good
    assert s["t"][off] < TASK.scene.duration - 0.05
    held = s["grip_force"][off + 2:]  # the command acts one step late (delay_steps 1)
    assert np.all(s["motor_current"][off + 2:] == 0.0) and np.all(held == held[0])
    setpoint = TASK.setpoints[0][1]
    # locked once the reading was within the band: the truth within it plus 4σ of the noise
    assert abs(held[0] - setpoint) <= 0.05 * setpoint + 4 * NOISY["noise"]
    assert held[0] != run_task(TASK, grip_voltage).samples["grip_force"][-1]  # the reading, not the truth, closed the loop


def test_an_unknown_feedback_signal_is_refused_naming_the_parameter():
    with pytest.raises(ConfigError, match="feedback.*fsr_distal_measured"):
        run_task(sensed({"fsr_distal": {}}), grip_voltage, params={"feedback": "fsr_proximal_measured"})
    with pytest.raises(ConfigError, match="force_per_unit"):
        grip_voltage(0.001, force_per_unit=0.0)
