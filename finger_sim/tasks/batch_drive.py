"""A gain sweep of a shipped drive controller over one drive task, its rows stepped together in the kernel.

`run_task_rows(task, factory, columns)` gives, for every (label, params) column, the `TaskRun`
that `run_task(task, factory, label=label, params=params)` gives, bit for bit (tested): the
samples with the drive's columns, the scores with the electrical energy, the verdict. All
columns step in one compiled loop (`finger_sim.kernel.closed_loop_drive.run`): the controller's
law compiled from its one definition (`finger_sim.drive_grip_law`), DOP853 on the driven
right-hand side, the mesh guards and the contact's gap tests in the kernel. Python takes only the
steps the kernel hands over, with each row's own `SceneChanges` and Simulator (as
`finger_sim.tasks.batch`): a mode change of the mesh (drive, back, stuck) or a contact event that
may fall in the step, a stuck mesh that may break free, DOP853's first internal step, a crush to
check, a tip-force switch.

What it takes (`batch_reason` says why not): `grip_voltage` reading the grip force or the motor
current, or `grip_current` reading the motor current, on a voltage task without sensors whose
scene has a drive with L = 0 and one contact, stepped by the compiled DOP853 (what `auto` picks
on the drive tasks). A controller fed a sensor's reading (`finger_sim.sensors`) runs row by row.
"""

from __future__ import annotations

import dataclasses
import math
import time
from collections.abc import Mapping, Sequence

import numpy as np

from finger_sim.actuators.drive_outputs import MOTOR_CURRENT, MOTOR_VOLTAGE
from finger_sim.effects.contact import Contact
from finger_sim.effects.contact_outputs import GRIP_FORCE
from finger_sim.errors import ConfigError, SimulationDiverged
from finger_sim.grasp_objects import Crush
from finger_sim.integrators.dop853 import DormandPrince853
from finger_sim.scene import Scene
from finger_sim.scene_changes import SceneChanges
from finger_sim.simulate import Simulator
from finger_sim.tasks import controllers, current_grip
from finger_sim.tasks.batch import _contact_offset, _fit, _hand_over, _next_switch, _read_back
from finger_sim.tasks.controllers import Factory
from finger_sim.tasks.metrics import judge, task_scores
from finger_sim.tasks.runner import COLUMNS, DRIVE_COLUMNS, TaskRun, _outputs
from finger_sim.tasks.schema import Task
from finger_sim.tip_force_profile import first_step

#: The drive controllers whose law the kernel compiles: their defaults, the order of their settings
#: in the law (`drive_grip_law`), and the signal each reads by default.
DRIVE_FACTORIES = {
    controllers.grip_voltage: (controllers.GRIP_VOLTAGE, controllers.VOLTAGE_LAW, GRIP_FORCE.name),
    current_grip.grip_current: (current_grip.GRIP_CURRENT, current_grip.CURRENT_LAW, MOTOR_CURRENT.name),
}
#: The signals the kernel feeds a law (`closed_loop_drive.FEEDBACK_GRIP`, `FEEDBACK_CURRENT`).
FEEDBACKS = (GRIP_FORCE.name, MOTOR_CURRENT.name)
#: `closed_loop_drive.run`'s gains row: the longest law's settings and grip_current's current setpoint.
GAIN_WIDTH = 13


def batch_reason(task: Task, factory: Factory) -> str | None:
    """Why `run_task_rows` cannot step `task` against `factory`'s controllers, or None when it can."""
    if factory not in DRIVE_FACTORIES:
        return "the controller is not a shipped drive controller"
    if task.input != "voltage" or task.scene.drive is None:
        return "not a drive task"
    if task.scene.sensors is not None:
        return "the scene has sensors"
    return sim_reason(SceneChanges(task.scene).sim)


def sim_reason(sim: Simulator) -> str | None:
    """Why the kernel cannot step a row on this drive scene's Simulator, or None."""
    drive = sim._drive  # noqa: SLF001
    if drive is None or drive.inductive:
        return "a drive with an inductance (L > 0)" if drive is not None else "no drive"
    if sim._friction is not None or sim._timed:  # noqa: SLF001
        return "stick-slip friction or a moving object"
    integ = sim.integrator
    if not isinstance(integ, DormandPrince853) or not integ.compiled:
        return f"the scene steps with {sim.method} on the {sim.kernel} kernel, not the compiled dop853"
    contacts = [e for e in sim.system.elements if not e.smooth]
    if len(contacts) != 1 or type(contacts[0]) is not Contact:
        return "a drive scene without exactly one contact"
    return None


def rows_reason(tasks: Sequence[Task], factory: Factory) -> str | None:
    """`batch.rows_reason` for the drive tasks."""
    from finger_sim.tasks import batch

    return batch.rows_reason(tasks, factory)


class _Row:
    """What the kernel reads of one row's Simulator: its flat model (ending in the drive's block),
    contact block, depth gaps and drive."""

    def __init__(self, sim: Simulator) -> None:
        reason = sim_reason(sim)
        if reason is not None:  # a scene change the kernel cannot follow
            raise ConfigError(f"scene '{sim.scene.name}'", "a scene the compiled gain sweep steps", reason)
        self.sim = sim
        integ = sim.integrator
        assert isinstance(integ, DormandPrince853)
        self.model = integ._model  # noqa: SLF001 (its mode slot follows the drive: `Drive.mirror`)
        self.rtol, self.atol = integ.rtol, integ.atol
        self.contact_at = _contact_offset(self.model)
        rho = dict(sim._depth_sources)  # noqa: SLF001 (gap position → ρ; the contact's gaps come first)
        count = len(sim._gaps) - len(rho)  # noqa: SLF001
        self.depths = np.array([rho.get(c, 0.0) for c in range(count)])
        self.depth = bool(rho)

    def load(self, i: int, a: _Arrays, changes: SceneChanges) -> None:
        a.models[i] = 0.0
        a.models[i, : len(self.model)] = self.model
        a.widths[i], a.contact_at[i], a.depth[i] = len(self.model), self.contact_at, self.depth
        a.depths[i] = 0.0
        a.depths[i, : len(self.depths)] = self.depths
        forces = [o.properties.break_force for o in self.sim.scene.objects if o.properties.break_force is not None]
        a.break_min[i] = min(forces) if changes.watching and forces else math.inf
        self.sync(i, a)

    def sync(self, i: int, a: _Arrays) -> None:
        """The drive's discrete state (mesh mode, direction) into row i's arrays."""
        drive = self.sim._drive  # noqa: SLF001
        p = drive.params
        a.models[i, len(self.model) - len(drive.kernel_block())] = float(drive.mode)
        a.drives[i] = (drive.direction, p.efficiency, p.backward_efficiency)


@dataclasses.dataclass
class _Arrays:
    """The per-row arrays `closed_loop_drive.run` works on (its docstring)."""

    models: np.ndarray
    widths: np.ndarray
    contact_at: np.ndarray
    depth: np.ndarray
    depths: np.ndarray
    break_min: np.ndarray
    drives: np.ndarray


def _law_row(factory: Factory, period: float, params: Mapping[str, float]) -> tuple[int, int, float, list[float]]:
    """(law kind, feedback code, scale, gains row) of `factory(period, **params)`; the factory itself
    checks the parameters (its ConfigError names a bad one)."""
    from finger_sim.kernel import closed_loop_drive as kd

    factory(period, **params)
    defaults, order, signal = DRIVE_FACTORIES[factory]
    settings = {k: v for k, v in params.items() if k in defaults}
    p = {**defaults, **settings}
    feedback = params.get("feedback", signal)
    if feedback not in FEEDBACKS:
        raise ConfigError("controller parameter feedback", f"one of {list(FEEDBACKS)} in the compiled gain sweep",
                          feedback)
    gains = [float(p[name]) for name in order]
    if factory is current_grip.grip_current:
        gains += [p["lever"], p["load_torque"], p["torque_per_ampere"]]
        kind, scale = kd.LAW_CURRENT, 1.0
    else:
        kind, scale = kd.LAW_VOLTAGE, float(params.get("force_per_unit", 1.0))
    return kind, FEEDBACKS.index(feedback), scale, gains + [0.0] * (GAIN_WIDTH - len(gains))


def run_task_rows(task: Task, factory: Factory, columns: Sequence[tuple[str, Mapping[str, float]]],
                  scenes: Sequence[Scene] | None = None) -> list[TaskRun]:
    """The TaskRun of every (label, params) column of `factory` on the drive task `task` (module
    docstring); with `scenes`, column i runs on scenes[i] (the same dt, duration and tip-force
    profile). ConfigError when `rows_reason` is not None, or names a column's bad parameter."""
    scenes = [task.scene] * len(columns) if scenes is None else list(scenes)
    if len(scenes) != len(columns):
        raise ConfigError("scenes", f"one per column ({len(columns)})", len(scenes))
    reason = rows_reason([dataclasses.replace(task, scene=s) for s in scenes], factory)
    if reason is not None:
        raise ConfigError(f"task '{task.name}'", "a task the compiled gain sweep steps", reason)
    from finger_sim.kernel import closed_loop as kl
    from finger_sim.kernel import closed_loop_drive as kd

    dt, last = task.scene.dt, task.scene.step_count
    period = task.sample_steps * dt
    laws = [_law_row(factory, period, params) for _, params in columns]
    nrow = len(columns)
    changes = [SceneChanges(s) for s in scenes]
    rows = [_Row(c.sim) for c in changes]
    width = max(len(r.model) for r in rows)
    ncand = max(1, max(len(r.depths) for r in rows))
    a = _Arrays(np.zeros((nrow, width)), np.zeros(nrow, dtype=np.int64), np.full(nrow, -1, dtype=np.int64),
                np.zeros(nrow, dtype=np.bool_), np.zeros((nrow, ncand)), np.empty(nrow), np.empty((nrow, 3)))
    set_steps = [(first_step(t, dt), v) for t, v in task.setpoints]
    set_k = np.array([k for k, _ in set_steps], dtype=np.int64)
    set_v = np.array([v for _, v in set_steps])
    kind = np.array([law[0] for law in laws], dtype=np.int64)
    feedback = np.array([law[1] for law in laws], dtype=np.int64)
    scale = np.array([law[2] for law in laws])
    gains = np.array([law[3] for law in laws])
    state = np.zeros((nrow, 7))  # the controllers' initial state: setpoint 0, nothing integrated
    depth_of_queue = task.delay_steps // task.sample_steps + 2  # pending commands at most
    pend_k = np.zeros((nrow, depth_of_queue), dtype=np.int64)
    pend_u = np.zeros((nrow, depth_of_queue))
    pend_n = np.zeros(nrow, dtype=np.int64)
    command = np.zeros(nrow)
    states = np.empty((nrow, 6))
    signals = np.empty((nrow, 3))
    integ = np.empty((nrow, len(kl.INTEGRATOR)))
    ys, fs, y_olds, denses = np.empty((nrow, 6)), np.empty((nrow, 6)), np.empty((nrow, 6)), np.empty((nrow, 7, 6))
    steps = np.zeros(nrow, dtype=np.int64)
    switches = sorted(k for k in changes[0].switches if k > 0)  # step 0's force is the static scene's
    until = np.array([_next_switch(switches, 0, last)] * nrow, dtype=np.int64)
    scene_rec = np.zeros((nrow, 3))
    record = np.empty((nrow, last + 1, kd.N_COLUMNS))
    crushes: list[list[Crush]] = [[] for _ in range(nrow)]
    stopped = [False] * nrow
    ends = [last] * nrow
    for i, row in enumerate(rows):
        sim = changes[i].sim
        states[i] = (*sim.q, *sim.v)
        signals[i] = _signals(sim, 0.0)
        scene_rec[i, :2] = sim.scene.tip_force
        row.load(i, a, changes[i])
        _read_back_drive(sim, integ[i], ys[i], fs[i], y_olds[i], denses[i])
    rtol, atol = rows[0].rtol, rows[0].atol
    start = time.perf_counter()
    while True:
        status = kd.run(a.models, a.widths, a.contact_at, a.depth, a.depths, a.break_min, rtol, atol, dt,
                        task.sample_steps, task.delay_steps, set_k, set_v, kind, feedback, scale, gains, state, pend_k,
                        pend_u, pend_n, command, states, signals, a.drives, integ, ys, fs, y_olds, denses, steps, until,
                        last, scene_rec, record)
        if (status == kd.DONE).all():
            break
        for i in np.flatnonzero(status != kd.DONE).tolist():
            k, ch = int(steps[i]), changes[i]
            if status[i] == kd.PAUSE:  # a tip-force switch: SceneChanges makes the new Simulator
                _hand_over_drive(ch.sim, k, states[i], integ[i], ys[i], fs[i], y_olds[i], denses[i])
                ch.before_step()
                until[i] = _next_switch(switches, k, last)
                scene_rec[i, :2] = ch.sim.scene.tip_force
            elif status[i] == kd.EVENT:  # the Simulator takes step k, as run_task does
                sim = ch.sim
                _hand_over_drive(sim, k, states[i], integ[i], ys[i], fs[i], y_olds[i], denses[i])
                try:
                    sim.step(float(command[i]))
                except SimulationDiverged:  # run_task's rule: the run stops, the task fails
                    stopped[i], ends[i], steps[i], until[i] = True, k, last, last
                    continue
                signals[i] = _signals(sim, float(command[i]))
                crushes[i] += ch.after_step()
                steps[i] = k + 1
            else:  # WATCH: the crush rule on the state after the step
                _hand_over_drive(ch.sim, k, states[i], integ[i], ys[i], fs[i], y_olds[i], denses[i])
                crushes[i] += ch.after_step()
            sim = ch.sim
            if sim is not rows[i].sim:  # a new scene: its model, and a fresh internal solution
                rows[i] = _Row(sim)
                a.models, a.depths = _fit(a.models, len(rows[i].model)), _fit(a.depths, len(rows[i].depths))
                rows[i].load(i, a, ch)
            rows[i].sync(i, a)
            scene_rec[i, 2] = len(crushes[i])
            states[i] = (*sim.q, *sim.v)
            _read_back_drive(sim, integ[i], ys[i], fs[i], y_olds[i], denses[i])
    wall = (time.perf_counter() - start) / nrow
    runs = []
    grid = tuple((k * dt, v) for k, v in set_steps)
    names = COLUMNS + DRIVE_COLUMNS
    assert names[kd.MOTOR_VOLTAGE] == MOTOR_VOLTAGE.name and names[kd.MOTOR_CURRENT] == MOTOR_CURRENT.name
    for i, (label, _) in enumerate(columns):
        n = ends[i]
        if not stopped[i]:  # the last sample: the state after the last step
            record[i, n] = (n * dt, signals[i, 0], set_v[set_k <= n - 1][-1], states[i, 0], states[i, 3], command[i],
                            scene_rec[i, 0], scene_rec[i, 1], scene_rec[i, 2], signals[i, 2], signals[i, 1])
        samples = {name: np.ascontiguousarray(record[i, : n + 1, c]) for c, name in enumerate(names)}
        scores = task_scores(samples["t"], samples[GRIP_FORCE.name], grid, task.hold_after, bool(crushes[i]),
                             outputs={c: samples[c] for c in DRIVE_COLUMNS}, torque=None)
        passed = judge(scores, task.limits)
        if stopped[i]:
            passed["completed"] = False
        runs.append(TaskRun(task.name, label, samples, crushes[i], scores, passed, grid, dict(task.limits), wall))
    return runs


def _signals(sim: Simulator, voltage: float) -> tuple[float, float, float]:
    """(grip force N, motor current A, terminal voltage V) at the Simulator's state under `voltage`
    (`runner._outputs`, as run_task measures them)."""
    out = _outputs(sim, voltage)
    return out.get(GRIP_FORCE.name, 0.0), out[MOTOR_CURRENT.name], out[MOTOR_VOLTAGE.name]


def _hand_over_drive(sim: Simulator, k: int, x: np.ndarray, st: np.ndarray, y: np.ndarray, f: np.ndarray,
                     y_old: np.ndarray, dense: np.ndarray) -> None:
    """`batch._hand_over`; a solution the kernel continued is under the drive's current mode."""
    from finger_sim.kernel import closed_loop as kl

    _hand_over(sim, k, x, st, y, f, y_old, dense)
    if not math.isnan(st[kl.I_VALUE]):
        sim.integrator._changes = sim._drive.changes  # type: ignore[attr-defined]  # noqa: SLF001


def _read_back_drive(sim: Simulator, st: np.ndarray, y: np.ndarray, f: np.ndarray, y_old: np.ndarray,
                     dense: np.ndarray) -> None:
    """`batch._read_back`; a solution computed under another mesh mode than the current one restarts."""
    from finger_sim.kernel import closed_loop as kl

    _read_back(sim, st, y, f, y_old, dense)
    if sim.integrator._changes != sim._drive.changes:  # type: ignore[attr-defined]  # noqa: SLF001
        st[kl.I_VALUE] = math.nan
