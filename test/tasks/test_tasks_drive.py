"""The drive task: hold with the voltage off (config/tasks/hold_voltage_off.yaml, spec §8).

References: the self-locking claim itself (after the controller switches the voltage off, the
current is 0 and the grip force does not change at all, bit for bit); a plain-loop trapezoid of
u·i over the samples for electrical_energy; the motor equation u = R i + k ω of spec §8 at stall
(ω = 0: i = u/R), which fixes the power of a powered hold to u²/R independently of the drive code.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from finger_sim.tasks.controllers import grip_voltage
from finger_sim.tasks.runner import run_task
from finger_sim.tasks.schema import load_task

TASK = Path(__file__).resolve().parents[2] / "config" / "tasks" / "hold_voltage_off.yaml"
#: A lock_after longer than the run: grip_voltage then holds with the voltage on (for comparison).
NEVER = 100.0


def test_the_grip_holds_with_the_voltage_off_and_the_energy_is_the_integral_of_u_i():
    task = load_task(TASK)
    run = run_task(task, grip_voltage, label="grip_voltage")
    assert run.ok, run.passed
    s = run.samples
    off = np.flatnonzero(s["command"] != 0.0)[-1] + 1  # the first sample with the voltage off for good
    assert s["t"][off] < task.hold_after  # it settled and switched off before the holding window
    held = s["grip_force"][off + 2:]  # the command acts one step late (delay_steps 1)
    assert np.all(s["motor_current"][off + 2:] == 0.0)
    assert np.all(held == held[0])  # the self-locking gear holds the grip exactly, unpowered
    assert abs(held[0] - task.setpoints[0][1]) <= 0.05 * task.setpoints[0][1]
    power = s["motor_voltage"] * s["motor_current"]
    dt = s["t"][1] - s["t"][0]
    trapezoid = sum((power[k] + power[k + 1]) / 2 * dt for k in range(len(power) - 1))
    assert run.scores["electrical_energy"] == pytest.approx(trapezoid, rel=1e-12)


def test_a_powered_hold_costs_u_squared_over_r_at_stall():
    task = load_task(TASK)
    powered = run_task(task, grip_voltage, params={"lock_after": NEVER})
    s = powered.samples
    stalled = slice(int(np.searchsorted(s["t"], task.hold_after)), None)
    resistance = task.scene.drive.resistance
    np.testing.assert_allclose(s["theta1_dot"][stalled], 0.0, atol=0.0)  # the mesh is stuck
    np.testing.assert_allclose(s["motor_current"][stalled], s["motor_voltage"][stalled] / resistance, rtol=1e-12)
    unpowered = run_task(task, grip_voltage)
    hold_power = float(np.mean(s["motor_voltage"][stalled] ** 2 / resistance))
    assert hold_power > 0.0
    # the voltage-off hold saves at least the powered hold's energy over the holding window
    saved = powered.scores["electrical_energy"] - unpowered.scores["electrical_energy"]
    assert saved >= 0.9 * hold_power * (task.scene.duration - task.hold_after)


def test_a_torque_controller_cannot_run_the_drive_task_in_a_suite():
    from finger_sim.tasks.suite import parse_controllers, run_suite

    controllers = parse_controllers(["grip_pi=finger_sim.tasks.controllers:grip_pi",
                                     "grip_voltage=finger_sim.tasks.controllers:grip_voltage"], [], [])
    runs = run_suite([load_task(TASK)], controllers)
    assert [r.controller for r in runs] == ["grip_voltage"]


def test_the_default_suite_runs_both_drive_controllers_and_the_current_loop_passes_hold_current():
    """Without --controller, each drive task runs `grip_voltage` and `grip_current` side by side:
    hold_current, written for the current loop, is passed by it; the force loop overshoots it
    (its overshoot recomputed from the samples: the largest grip force past the setpoint, % of it)."""
    from finger_sim.tasks.suite import parse_controllers, run_suite

    controllers = parse_controllers([], [], [])
    assert [c.label for c in controllers] == ["grip_pi", "grip_pi_aggressive", "grip_voltage", "grip_current"]
    task = load_task(TASK.with_name("hold_current.yaml"))
    runs = {r.controller: r for r in run_suite([task], controllers)}
    assert list(runs) == ["grip_voltage", "grip_current"]  # the torque controllers skip a drive task
    assert runs["grip_current"].ok, runs["grip_current"].passed
    voltage = runs["grip_voltage"]
    setpoint = task.setpoints[0][1]
    overshoot = (voltage.samples["grip_force"].max() - setpoint) / setpoint * 100.0
    assert overshoot > task.limits["overshoot"]
    assert voltage.scores["overshoot"] == pytest.approx(overshoot, rel=1e-12)
    assert [k for k, ok in voltage.passed.items() if not ok] == ["overshoot"]
