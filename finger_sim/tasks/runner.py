"""Run a task against a controller: the scene stepped at its dt, the controller sampled and delayed.

Timing (whole steps of the scene's dt): at every `sample_steps`-th step k the controller gets
the state at t_k = k·dt (its measured signals) and the setpoint in force at t_k; its command
acts from step k + `delay_steps` on and is held (zero-order hold) until the next one acts. A
delay of 0 is an ideal controller answering within the sample; 1, a command that arrives one
step late (finger_node's loop). Before the first command acts the input is 0.

Scene changes happen at step boundaries (`finger_sim.scene_changes`, as finger_node steps them):
a tip-force disturbance (the task's, in its scene's `input.tip_force`) switches on and off at the
first step at or after its start and end; an object whose break force is exceeded at the end of a
step is crushed and taken out.
"""

from __future__ import annotations

import logging
import math
import numbers
import time
from collections import deque
from collections.abc import Mapping
from dataclasses import dataclass, field

import numpy as np

from finger_sim.actuators.drive_outputs import MOTOR_CURRENT, MOTOR_VOLTAGE
from finger_sim.effects import declared_outputs
from finger_sim.effects.contact_outputs import GRIP_FORCE
from finger_sim.errors import FingerSimError, SimulationDiverged
from finger_sim.grasp_objects import Crush
from finger_sim.scene_changes import SceneChanges
from finger_sim.sensors import SOURCES, SensorBank
from finger_sim.simulate import Simulator, output_names, output_values
from finger_sim.tip_force_profile import first_step
from finger_sim.tasks.controllers import MEASURED, Factory
from finger_sim.tasks.metrics import Scores, judge, task_scores
from finger_sim.tasks.schema import Task

LOG = logging.getLogger(__name__)

#: The columns a task run records at every sample, in this order (N, rad, rad/s, N·m, N).
COLUMNS = ("t", GRIP_FORCE.name, "setpoint", "theta1", "theta1_dot", "command", "tip_force_x", "tip_force_y", "crushed")
#: The drive's outputs a run on a drive scene records too (V, A; spec §8), for electrical_energy.
DRIVE_COLUMNS = (MOTOR_VOLTAGE.name, MOTOR_CURRENT.name)
#: Element outputs that are not measurements a real controller has (declared so: the contact wrenches
#: and the power of a prescribed object motion).
UNMEASURED = frozenset(o.name for o in declared_outputs().values() if not o.measurable)


@dataclass
class TaskRun:
    """One task run: its samples (COLUMNS, one array each), crushes, scores and pass/fail per limit."""

    task: str
    controller: str
    samples: dict[str, np.ndarray]
    crushes: list[Crush]
    scores: Scores
    passed: dict[str, bool]
    setpoints: tuple[tuple[float, float], ...]  # on the step grid
    limits: dict[str, float | bool] = field(default_factory=dict)
    wall_time: float = 0.0

    @property
    def ok(self) -> bool:
        return all(self.passed.values())


def run_task(task: Task, factory: Factory, *, label: str = "", params: Mapping[str, float] | None = None,
             kernel: str = "auto") -> TaskRun:
    """Run `task` against the controller `factory(sample_period, **params)`; score and judge it."""
    scene = task.scene
    dt, n = scene.dt, scene.step_count
    changes = SceneChanges(scene, kernel=kernel)  # the tip-force profile and crushing, as finger_node steps them
    sim = changes.sim
    controller = factory(task.sample_steps * dt, **(params or {}))
    set_steps = [(first_step(t, dt), v) for t, v in task.setpoints]
    drive_columns = DRIVE_COLUMNS if scene.drive is not None else ()
    rows = np.empty((n + 1, len(COLUMNS) + len(drive_columns)))
    pending: deque[tuple[int, float]] = deque()
    command, setpoint, crushes = 0.0, 0.0, []
    si = 0
    # the scene's sensors (finger_sim.sensors), read at the samples: their readings are measured too
    sensors = SensorBank(scene.sensors, dt) if scene.sensors is not None else None
    sensed_at: int | None = None
    start = time.perf_counter()

    def record(k: int, outputs: Mapping[str, float]) -> None:
        rows[k] = (k * dt, outputs.get(GRIP_FORCE.name, 0.0), setpoint, sim.q[0], sim.v[0], command,
                   sim.scene.tip_force[0], sim.scene.tip_force[1], len(crushes), *(outputs[c] for c in drive_columns))

    outputs = _outputs(sim)
    for k in range(n):
        while si < len(set_steps) and set_steps[si][0] <= k:
            setpoint = set_steps[si][1]
            si += 1
        changes.before_step()
        sim = changes.sim
        if k % task.sample_steps == 0:
            sensed = {GRIP_FORCE.name: outputs.get(GRIP_FORCE.name, 0.0), "theta1": sim.q[0], "theta1_dot": sim.v[0]}
            measured = {name: sensed[name] for name in MEASURED}
            measured.update({k_: v for k_, v in outputs.items()
                             if k_ not in UNMEASURED})
            if sensors is not None:  # an FSR reads 0 N once its object is gone (crushed)
                truth = {src: np.array([outputs.get(src, 0.0)]) for name in sensors.sensors.models for src in SOURCES[name]}
                readings = sensors.measure(truth, elapsed=0.0 if sensed_at is None else (k - sensed_at) * dt)
                measured.update({name: float(r[0]) for name, r in readings.items() if name.endswith("_measured")})
                sensed_at = k
            answer = controller(k * dt, setpoint, measured)
            if isinstance(answer, bool) or not (isinstance(answer, numbers.Real) and math.isfinite(answer)):
                raise FingerSimError(f"controller '{label}' returned {answer!r} at t = {k * dt:g} s in task "
                                     f"'{task.name}': expected a finite {task.input} command")
            pending.append((k + task.delay_steps, float(answer)))
        while pending and pending[0][0] <= k:
            command = pending.popleft()[1]
        record(k, outputs)
        try:
            sim.step(command)
        except SimulationDiverged as exc:  # e.g. pressed through an object (depth_guard): the task fails
            LOG.warning("task '%s', controller '%s': %s", task.name, label, exc)
            n, rows = k, rows[: k + 1]
            stopped = True
            break
        outputs = _outputs(sim, command)
        crushes += changes.after_step()  # the sample at the crush keeps the force that broke it
        sim = changes.sim
    else:
        stopped = False
        record(n, outputs)
    wall = time.perf_counter() - start
    samples = {name: np.ascontiguousarray(rows[:, i]) for i, name in enumerate(COLUMNS + drive_columns)}
    grid = tuple((k * dt, v) for k, v in set_steps)
    torque = (samples["command"], samples["theta1"]) if task.input == "torque" else None
    scores = task_scores(samples["t"], samples[GRIP_FORCE.name], grid, task.hold_after, bool(crushes),
                         outputs={c: samples[c] for c in drive_columns}, torque=torque)
    passed = judge(scores, task.limits)
    if stopped:  # a run the simulation had to stop fails its task
        passed["completed"] = False
    return TaskRun(task.name, label, samples, crushes, scores, passed, grid, dict(task.limits), wall)


def _outputs(sim: Simulator, voltage: float = 0.0) -> dict[str, float]:
    """The scene's element outputs at the simulator's state (grip_force, N, ...), and with a drive
    its outputs under the held `voltage` command (motor_voltage V, motor_current A, ...; spec §8)."""
    elements = sim.system.elements
    out = dict(zip(output_names(elements, sim.q), output_values(elements, sim.time, sim.q, sim.v)))
    if sim.scene.drive is not None:
        out.update(sim.system.motor_outputs(sim.time, sim.q, sim.v, voltage))
    return out

