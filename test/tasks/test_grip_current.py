"""grip_current (finger_sim.tasks.current_grip): the device's grip loop closed on the motor current
(spec §8), on the drive task of config/tasks/hold_voltage_off.yaml at setpoints the current limit allows.

References: the task metric's own definition (settle_time: within 5 % of the setpoint for good) applied
to the current against its setpoint, and an independent statics solve (test_contact.equilibrium: the
§7 rest state on the cup under a constant MCP torque) at the torque the forward-rolling mesh passes,
η_f N k_t i, for the current i at which the controller switched the voltage off."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest

from finger_sim.errors import ConfigError
from finger_sim.sensors import sensors_from_dict
from finger_sim.tasks.current_grip import GRIP_CURRENT, current_setpoint, grip_current
from finger_sim.tasks.metrics import SETTLE_BAND, Segment, settle_time
from finger_sim.tasks.runner import run_task
from finger_sim.tasks.schema import load_task
from effects.test_contact import equilibrium

TASK = load_task(Path(__file__).resolve().parents[2] / "config" / "tasks" / "hold_voltage_off.yaml")
#: Spec §8's defaults typed in again: η_f N k_t (N·m/A) and the current limit (A).
TORQUE_PER_AMPERE, I_MAX = 0.4 * 300.0 * 4.0e-3, 0.5


@pytest.mark.parametrize("setpoint", [1.2, 2.0])
def test_the_current_loop_settles_then_the_unpowered_gear_holds_the_statics_grip(setpoint):
    task = dataclasses.replace(TASK, setpoints=((0.0, setpoint),))
    run = run_task(task, grip_current)
    s = run.samples
    target = current_setpoint(setpoint, GRIP_CURRENT)
    assert target < I_MAX
    off = int(np.flatnonzero(s["command"] != 0.0)[-1]) + 1  # the sample at which the voltage went off for good
    assert s["t"][off] < task.scene.duration - 0.2
    # the loop: after the approach (the closing voltage), the current settles within the metric's band
    start = int(np.flatnonzero(s["command"] != GRIP_CURRENT["closing_voltage"])[0])
    loop = Segment(s["t"][start], target, start, off + 1)
    assert settle_time(s["t"], s["motor_current"], loop) < s["t"][off] - s["t"][start]
    assert abs(s["motor_current"][off] - target) <= SETTLE_BAND * target
    # the hold: the command acts one step late; from then on no current and the grip constant, bit for bit
    held = slice(off + 2, None)
    assert np.all(s["motor_current"][held] == 0.0) and np.all(s["theta1"][held] == s["theta1"][-1])
    assert np.all(s["grip_force"][held] == s["grip_force"][-1])
    # ... and it is the statics grip under the torque the creeping mesh passed at the last current
    raw = task.scene.to_dict()
    raw["input"] = {"torque": {"type": "constant", "value": TORQUE_PER_AMPERE * s["motor_current"][off]}}
    theta, delta = equilibrium(raw)
    contact = raw["model"]["contact"]
    assert s["theta1"][-1] == pytest.approx(theta, abs=1e-6)  # measured 1e-7 rad
    assert s["grip_force"][-1] == pytest.approx(contact["stiffness"] * delta ** contact["exponent"], rel=1e-4)  # 3e-5
    # the task as judged on the true grip force: settled, no overshoot, held
    assert run.ok and run.scores["settle_time"] <= task.limits["settle_time"]


def test_bad_parameters_are_refused_naming_them():
    with pytest.raises(ConfigError, match="lever"):
        grip_current(0.001, lever=0.0)
    with pytest.raises(ConfigError, match="one of"):
        grip_current(0.001, gain=1.0)


@pytest.mark.parametrize("seed", [1, 2])
def test_a_noisy_lagging_current_sensor_still_ends_in_the_unpowered_statics_hold(seed):
    """On `motor_current_measured` (σ 2 mA, τ 2 ms, 1 mA steps, ±0.5 A): the task passes, and the held
    grip is the statics at η_f N k_t i for the true current when the voltage went off to 1 %: the noisy
    loop's last current steps leave the finger short of its creep when the voltage drops (measured
    0.37 % and 0.44 % for seeds 1, 2; 3e-5 on the noiseless current)."""
    sensors = sensors_from_dict({"seed": seed, "motor_current": {"noise": 0.002, "time_constant": 0.002,
                                                                 "resolution": 0.001, "range": [-0.5, 0.5]}},
                                has_drive=True, has_objects=True)
    task = dataclasses.replace(TASK, setpoints=((0.0, 1.5),), scene=dataclasses.replace(TASK.scene, sensors=sensors))
    run = run_task(task, grip_current, params={"feedback": "motor_current_measured"})
    s = run.samples
    off = int(np.flatnonzero(s["command"] != 0.0)[-1]) + 1
    assert run.ok and np.all(s["grip_force"][off + 2:] == s["grip_force"][-1])
    raw = task.scene.to_dict()
    raw["input"] = {"torque": {"type": "constant", "value": TORQUE_PER_AMPERE * s["motor_current"][off]}}
    _, delta = equilibrium(raw)
    contact = raw["model"]["contact"]
    assert s["grip_force"][-1] == pytest.approx(contact["stiffness"] * delta ** contact["exponent"], rel=1e-2)
    assert s["grip_force"][-1] != run_task(dataclasses.replace(task, scene=TASK.scene), grip_current).samples["grip_force"][-1]
