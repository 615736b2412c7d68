"""A gain sweep of the grip PI over one task, its rows stepped together in the kernel.

`run_task_rows(task, factory, columns)` gives, for every (label, params) column, the `TaskRun`
that `run_task(task, factory, label=label, params=params)` gives, bit for bit (tested), but
steps all columns in one compiled loop (`finger_sim.kernel.closed_loop.run`, numba `prange`
over the rows): the controller law compiled from its one definition, the Simulator's step, the
contact geometry and its event tests in the kernel. Python takes only the steps that the
kernel hands over (a contact onset or release to locate, DOP853's first internal step, a crush
to check, a tip-force switch), with each row's own `SceneChanges` and Simulator, the internal
solution handed over and read back, so those steps are the offline path's own.

What it takes (`batch_reason` says why not): the shipped grip PI (`grip_pi`,
`grip_pi_aggressive`) on a torque task without sensors whose scene steps with the compiled
DOP853 (what `auto` picks on the contact scenes) and a contact law with a compiled form (one
law for all objects, its own or the scene's; no moving object). The drive tasks' controllers
(`grip_voltage`, `grip_current`) go through `finger_sim.tasks.batch_drive`. Other tasks run
`run_task` row by row.
"""

from __future__ import annotations

import dataclasses
import math
import time
from collections.abc import Mapping, Sequence

import numpy as np

from finger_sim.effects.contact import Contact
from finger_sim.effects.contact_outputs import GRIP_FORCE
from finger_sim.errors import ConfigError, SimulationDiverged
from finger_sim.grasp_objects import Crush
from finger_sim.integrators.base import HeldTorque
from finger_sim.integrators.dop853 import DormandPrince853
from finger_sim.kernel.layout import CONTACT, HEADER
from finger_sim.runtime.grip import PHASE_NUMBERS, GripController, GripSettings
from finger_sim.runtime.parameters import ParameterError
from finger_sim.scene import Scene
from finger_sim.scene_changes import SceneChanges
from finger_sim.simulate import Simulator
from finger_sim.tasks import controllers
from finger_sim.tasks.controllers import Factory
from finger_sim.tasks.metrics import judge, task_scores
from finger_sim.tasks.runner import COLUMNS, TaskRun, _outputs
from finger_sim.tasks.schema import Task
from finger_sim.tip_force_profile import first_step

#: The factories whose law the kernel compiles, and the settings each starts from.
GRIP_FACTORIES = {controllers.grip_pi: {}, controllers.grip_pi_aggressive: controllers.AGGRESSIVE}


def batch_reason(task: Task, factory: Factory) -> str | None:
    """Why `run_task_rows` cannot step `task` against `factory`'s controllers, or None when it can."""
    from finger_sim.tasks import batch_drive  # the drive controllers' sweep (it imports this module)

    if factory in batch_drive.DRIVE_FACTORIES:
        return batch_drive.batch_reason(task, factory)
    if factory not in GRIP_FACTORIES:
        return "the controller is not the shipped grip PI"
    if task.input != "torque" or task.scene.drive is not None:
        return "a drive scene"
    if task.scene.sensors is not None:
        return "the scene has sensors"
    return _sim_reason(SceneChanges(task.scene).sim)


def rows_reason(tasks: Sequence[Task], factory: Factory) -> str | None:
    """`batch_reason` for rows that are `tasks` (one per row: the same script, each its own scene),
    or why they cannot be rows of one sweep (their steps, dt or tip-force switches differ)."""
    first = tasks[0].scene
    if any((t.scene.dt, t.scene.step_count, t.scene.tip_force_profile) !=
           (first.dt, first.step_count, first.tip_force_profile) for t in tasks):
        return "the rows' scenes differ in dt, duration or tip-force profile"
    distinct = list({id(t.scene): t for t in tasks}.values())
    reason = next((r for r in (batch_reason(t, factory) for t in distinct) if r is not None), None)
    if reason is None:
        integrators = [SceneChanges(t.scene).sim.integrator for t in distinct]
        if len({(i.rtol, i.atol) for i in integrators if isinstance(i, DormandPrince853)}) > 1:
            return "the rows' scenes differ in DOP853's tolerances"
    return reason


def _sim_reason(sim: Simulator) -> str | None:
    integ = sim.integrator
    if sim._friction is not None or sim._timed:  # noqa: SLF001
        return "stick-slip friction or a moving object"
    if sim.fast_stepper is not None:  # the lean path (no contact, no drive)
        return None if _plan_parts(sim.fast_stepper.plan)[2].shape[1] > 0 else "the paper's Euler"
    if not isinstance(integ, DormandPrince853) or not integ.compiled or integ._drive is not None:  # noqa: SLF001
        return f"the scene steps with {sim.method} on the {sim.kernel} kernel, not the compiled dop853"
    contacts = [e for e in sim.system.elements if not e.smooth]
    if contacts and (len(contacts) > 1 or type(contacts[0]) is not Contact):
        return "a non-smooth element other than one contact"
    return None


def run_task_rows(task: Task, factory: Factory, columns: Sequence[tuple[str, Mapping[str, float]]],
                  scenes: Sequence[Scene] | None = None) -> list[TaskRun]:
    """The TaskRun of every (label, params) column of `factory` on `task` (module docstring); with
    `scenes`, column i runs on scenes[i] instead of the task's (object parameters swept; the
    same dt, duration and tip-force profile). ConfigError when `rows_reason` is not None, or
    names a column's bad parameter. A shipped drive controller's columns: `batch_drive.run_task_rows`."""
    from finger_sim.tasks import batch_drive

    if factory in batch_drive.DRIVE_FACTORIES:
        return batch_drive.run_task_rows(task, factory, columns, scenes)
    scenes = [task.scene] * len(columns) if scenes is None else list(scenes)
    if len(scenes) != len(columns):
        raise ConfigError("scenes", f"one per column ({len(columns)})", len(scenes))
    reason = rows_reason([dataclasses.replace(task, scene=s) for s in scenes], factory)
    if reason is not None:
        raise ConfigError(f"task '{task.name}'", "a task the compiled gain sweep steps", reason)
    from finger_sim.kernel import closed_loop as kl

    dt, last = task.scene.dt, task.scene.step_count
    period = task.sample_steps * dt
    laws = [_law(factory, period, params) for _, params in columns]
    nrow = len(columns)
    changes = [SceneChanges(s) for s in scenes]
    rows = [_Row(c.sim) for c in changes]
    width = max(len(r.model) for r in rows)
    ncand = max(1, max(len(r.depths) for r in rows))
    models = np.zeros((nrow, width))
    contact_at = np.full(nrow, -1, dtype=np.int64)
    lean = np.zeros(nrow, dtype=np.bool_)
    tab = np.zeros((3, 1))  # the lean rows' tableau, once one has it
    depth = np.zeros(nrow, dtype=np.bool_)
    depths = np.zeros((nrow, ncand))
    break_min = np.empty(nrow)
    set_steps = [(first_step(t, dt), v) for t, v in task.setpoints]
    set_k = np.array([k for k, _ in set_steps], dtype=np.int64)
    set_v = np.array([v for _, v in set_steps])
    gains = np.array([[getattr(s, name) for name in kl.GAINS] for s, _ in laws])
    law = np.array([[PHASE_NUMBERS[c.phase], c.pi.integral, c._opening_left, c.setpoint] for _, c in laws])  # noqa: SLF001
    depth_of_queue = task.delay_steps // task.sample_steps + 2  # pending commands at most
    pend_k = np.zeros((nrow, depth_of_queue), dtype=np.int64)
    pend_u = np.zeros((nrow, depth_of_queue))
    pend_n = np.zeros(nrow, dtype=np.int64)
    command = np.zeros(nrow)
    states = np.empty((nrow, 6))
    grip = np.empty(nrow)
    integ = np.empty((nrow, len(kl.INTEGRATOR)))
    ys, fs, y_olds, denses = np.empty((nrow, 6)), np.empty((nrow, 6)), np.empty((nrow, 6)), np.empty((nrow, 7, 6))
    steps = np.zeros(nrow, dtype=np.int64)
    switches = sorted(k for k in changes[0].switches if k > 0)  # step 0's force is the static scene's
    until = np.array([_next_switch(switches, 0, last)] * nrow, dtype=np.int64)
    scene_rec = np.zeros((nrow, 3))
    record = np.empty((nrow, last + 1, len(COLUMNS)))
    crushes: list[list[Crush]] = [[] for _ in range(nrow)]
    stopped = [False] * nrow
    ends = [last] * nrow
    for i, row in enumerate(rows):
        sim = changes[i].sim
        states[i] = (*sim.q, *sim.v)
        grip[i] = _outputs(sim).get(GRIP_FORCE.name, 0.0)
        scene_rec[i, :2] = sim.scene.tip_force
        row.load(i, models, contact_at, lean, depth, depths, break_min, changes[i])
        tab = _shared_tableau(tab, row)
        _read_back(sim, integ[i], ys[i], fs[i], y_olds[i], denses[i])
    dop = next((r for r in rows if r.tab is None), None)
    rtol, atol = (dop.rtol, dop.atol) if dop is not None else (0.0, 0.0)
    start = time.perf_counter()
    while True:
        status = kl.run(models, contact_at, lean, tab, depth, depths, break_min, rtol, atol, dt, task.sample_steps,
                        task.delay_steps, set_k, set_v, gains, law, pend_k, pend_u, pend_n, command, states, grip,
                        integ, ys, fs, y_olds, denses, steps, until, last, scene_rec, record)
        if (status == kl.DONE).all():
            break
        for i in np.flatnonzero(status != kl.DONE).tolist():
            k, ch = int(steps[i]), changes[i]
            if status[i] == kl.PAUSE:  # a tip-force switch: SceneChanges makes the new Simulator
                _hand_over(ch.sim, k, states[i], integ[i], ys[i], fs[i], y_olds[i], denses[i])
                ch.before_step()
                until[i] = _next_switch(switches, k, last)
                scene_rec[i, :2] = ch.sim.scene.tip_force
            elif status[i] == kl.EVENT:  # the Simulator takes step k, as run_task does
                sim = ch.sim
                _hand_over(sim, k, states[i], integ[i], ys[i], fs[i], y_olds[i], denses[i])
                try:
                    sim.step(float(command[i]))
                except SimulationDiverged:  # run_task's rule: the run stops, the task fails
                    stopped[i], ends[i], steps[i], until[i] = True, k, last, last
                    continue
                grip[i] = _outputs(sim, float(command[i])).get(GRIP_FORCE.name, 0.0)
                crushes[i] += ch.after_step()
                steps[i] = k + 1
            else:  # WATCH: the crush rule on the state after the step
                _hand_over(ch.sim, k, states[i], integ[i], ys[i], fs[i], y_olds[i], denses[i])
                crushes[i] += ch.after_step()
            sim = ch.sim
            if sim is not rows[i].sim:  # a new scene: its model, and a fresh internal solution
                rows[i] = _Row(sim)
                models, depths = _fit(models, len(rows[i].model)), _fit(depths, len(rows[i].depths))
                tab = _shared_tableau(tab, rows[i])
                rows[i].load(i, models, contact_at, lean, depth, depths, break_min, ch)
            scene_rec[i, 2] = len(crushes[i])
            states[i] = (*sim.q, *sim.v)
            _read_back(sim, integ[i], ys[i], fs[i], y_olds[i], denses[i])
    wall = (time.perf_counter() - start) / nrow
    runs = []
    grid = tuple((k * dt, v) for k, v in set_steps)
    for i, (label, _) in enumerate(columns):
        n = ends[i]
        if not stopped[i]:  # the last sample: the state after the last step
            record[i, n] = (n * dt, grip[i], set_v[set_k <= n - 1][-1], states[i, 0], states[i, 3], command[i],
                            scene_rec[i, 0], scene_rec[i, 1], scene_rec[i, 2])
        samples = {name: np.ascontiguousarray(record[i, : n + 1, c]) for c, name in enumerate(COLUMNS)}
        scores = task_scores(samples["t"], samples[GRIP_FORCE.name], grid, task.hold_after, bool(crushes[i]),
                             outputs={}, torque=(samples["command"], samples["theta1"]))
        passed = judge(scores, task.limits)
        if stopped[i]:
            passed["completed"] = False
        runs.append(TaskRun(task.name, label, samples, crushes[i], scores, passed, grid, dict(task.limits), wall))
    return runs


class _Row:
    """What the kernel reads of one row's Simulator: its flat model, contact block, depth gaps."""

    def __init__(self, sim: Simulator) -> None:
        reason = _sim_reason(sim)
        if reason is not None:  # a scene change the kernel cannot follow (not one of today's)
            raise ConfigError(f"scene '{sim.scene.name}'", "a scene the compiled gain sweep steps", reason)
        self.sim = sim
        integ = sim.integrator
        #: the lean path's tableau (a scene without contact), else None (DOP853)
        self.tab: np.ndarray | None = None
        if sim.fast_stepper is not None:
            _, self.model, self.tab = _plan_parts(sim.fast_stepper.plan)
        else:
            assert isinstance(integ, DormandPrince853)
            self.model = integ._model  # noqa: SLF001
            self.rtol, self.atol = integ.rtol, integ.atol
        self.contact_at = _contact_offset(self.model)
        rho = dict(sim._depth_sources)  # noqa: SLF001 (gap position → ρ; the contact's gaps come first)
        count = len(sim._gaps) - len(rho)  # noqa: SLF001
        self.depths = np.array([rho.get(c, 0.0) for c in range(count)])
        self.depth = bool(rho)

    def load(self, i: int, models: np.ndarray, contact_at: np.ndarray, lean: np.ndarray, depth: np.ndarray, depths: np.ndarray,
             break_min: np.ndarray, changes: SceneChanges) -> None:
        models[i] = 0.0
        models[i, : len(self.model)] = self.model
        contact_at[i], depth[i], lean[i] = self.contact_at, self.depth, self.tab is not None
        depths[i] = 0.0
        depths[i, : len(self.depths)] = self.depths
        forces = [o.properties.break_force for o in self.sim.scene.objects if o.properties.break_force is not None]
        break_min[i] = min(forces) if changes.watching and forces else math.inf


def _law(factory: Factory, period: float, params: Mapping[str, float]) -> tuple[GripSettings, GripController]:
    """The settings `factory(period, **params)` runs with, and a controller in its initial state."""
    try:
        settings = GripSettings.from_values({**GRIP_FACTORIES[factory], **params, "sample_period": period})
    except ParameterError as exc:
        raise ConfigError("controller parameter", "values within GRIP_PARAMETERS' ranges", str(exc)) from None
    return settings, GripController(settings)


def _shared_tableau(tab: np.ndarray, row: _Row) -> np.ndarray:
    """The lean rows' one tableau: `row`'s when it is the first lean row; ConfigError when two differ."""
    if row.tab is None:
        return tab
    if not tab.any():
        return np.ascontiguousarray(row.tab)
    if tab.shape != row.tab.shape or not (tab == row.tab).all():
        raise ConfigError(f"scene '{row.sim.scene.name}'", "one fixed-step method for every row without contact",
                          row.sim.method)
    return tab


def _plan_parts(plan: np.ndarray) -> tuple[float, np.ndarray, np.ndarray]:
    """(dt, model, tableau) of a step plan (`numerics.plan_parts`)."""
    nm, rows, cols = int(plan[1]), int(plan[2]), int(plan[3])
    return float(plan[0]), plan[4: 4 + nm], plan[4 + nm: 4 + nm + rows * cols].reshape(rows, cols)


def _fit(arr: np.ndarray, width: int) -> np.ndarray:
    """`arr` (rows × columns), zero-padded to at least `width` columns (a scene change that adds an element)."""
    return arr if width <= arr.shape[1] else np.pad(arr, ((0, 0), (0, width - arr.shape[1])))


def _contact_offset(model: np.ndarray) -> int:
    """Where the contact element's parameters start in a flat model (`kernel.layout`), or −1."""
    o = HEADER + 1
    for _ in range(int(model[HEADER])):
        code, size = int(model[o]), int(model[o + 1])
        if code == CONTACT:
            return o + 2
        o += 2 + size
    return -1


def _next_switch(switches: list[int], k: int, last: int) -> int:
    return next((s for s in switches if s > k), last)


def _hand_over(sim: Simulator, k: int, x: np.ndarray, st: np.ndarray, y: np.ndarray, f: np.ndarray,
               y_old: np.ndarray, dense: np.ndarray) -> None:
    """The row's state at step k and the kernel's internal solution into its Simulator, as the
    offline run has them there (`closed_loop.INTEGRATOR`)."""
    from finger_sim.kernel import closed_loop as kl

    integ = sim.integrator
    sim.step_index, sim.q, sim.v = k, tuple(x[:3].tolist()), tuple(x[3:].tolist())
    if not isinstance(integ, DormandPrince853):  # the lean path keeps no state of its own
        return
    integ._t, integ._h, integ._t_old, integ._h_old = (float(st[kl.I_T]), float(st[kl.I_H]), float(st[kl.I_T_OLD]),  # noqa: SLF001
                                                      float(st[kl.I_H_OLD]))
    integ._y, integ._y_old = y.copy(), y_old.copy()  # noqa: SLF001
    integ._f[:], integ._dense[:] = f, dense  # noqa: SLF001
    integ._history[:] = [(integ._t_old, integ._h_old, integ._y_old, integ._dense.copy(), 0.0, 0.0)]  # noqa: SLF001
    integ._history_starts[:] = [integ._t_old]  # noqa: SLF001
    value = float(st[kl.I_VALUE])
    if math.isnan(value):
        integ._torque = None  # noqa: SLF001
    else:
        if sim._held is None or sim._held[0] != value:  # noqa: SLF001
            sim._held = (value, HeldTorque(value))  # noqa: SLF001
        integ._torque = sim._held[1]  # noqa: SLF001
    integ._last = (float(st[kl.I_LAST_T]), sim.q, sim.v) if st[kl.I_CONTINUES] else None  # noqa: SLF001
    integ._origin = (sim.time, sim.q, sim.v) if st[kl.I_ORIGIN] else None  # noqa: SLF001


def _read_back(sim: Simulator, st: np.ndarray, y: np.ndarray, f: np.ndarray, y_old: np.ndarray,
               dense: np.ndarray) -> None:
    """The Simulator's internal solution after it stepped, into the kernel's arrays."""
    from finger_sim.kernel import closed_loop as kl

    integ = sim.integrator
    if not isinstance(integ, DormandPrince853):
        return
    st[kl.I_T], st[kl.I_H], st[kl.I_T_OLD], st[kl.I_H_OLD] = integ._t, integ._h, integ._t_old, integ._h_old  # noqa: SLF001
    y[:], f[:], y_old[:], dense[:] = integ._y, integ._f, integ._y_old, integ._dense  # noqa: SLF001
    held = sim._held  # noqa: SLF001
    st[kl.I_VALUE] = held[0] if held is not None and integ._torque is held[1] else math.nan  # noqa: SLF001
    last = integ._last  # noqa: SLF001
    st[kl.I_CONTINUES] = float(last is not None and last[1] == sim.q and last[2] == sim.v)
    st[kl.I_LAST_T] = last[0] if last is not None else 0.0
    st[kl.I_ORIGIN] = float(integ._origin == (sim.time, sim.q, sim.v))  # noqa: SLF001
