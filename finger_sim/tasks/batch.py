"""A gain sweep of the grip PI over one task, its rows stepped together in the kernel.

`run_task_rows(task, factory, columns)` gives, for every (label, params) column, the `TaskRun`
that `run_task(task, factory, label=label, params=params)` gives, bit for bit (tested), but
steps all columns in one compiled loop (`finger_sim.kernel.closed_loop.run`, numba `prange`
over the rows): the controller law compiled from its one definition, the Simulator's step, the
contact geometry and its event tests in the kernel. Python takes only the steps that the
kernel hands over (a contact onset or release to locate, DOP853's first internal step, a crush
to check, a tip-force switch), with each row's own `SceneChanges` and Simulator, the internal
solution handed over and read back, so those steps are the offline path's own (the rows'
set-up, that hand-over and the scoring are `finger_sim.tasks.batch_rows`', shared with the drive sweep).

What it takes (`batch_reason` says why not): the shipped grip PI (`grip_pi`,
`grip_pi_aggressive`) on a torque task without sensors whose scene steps with the compiled
DOP853 (what `auto` picks on the contact scenes) and a contact law with a compiled form (one
law for all objects, its own or the scene's; no moving object). The drive tasks' controllers
(`grip_voltage`, `grip_current`) go through `finger_sim.tasks.batch_drive`. Other tasks run
`run_task` row by row.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping, Sequence

import numpy as np

from finger_sim import stick_slip
from finger_sim.effects.contact import Contact
from finger_sim.errors import ConfigError
from finger_sim.integrators.dop853 import DormandPrince853
from finger_sim.runtime.grip import PHASE_NUMBERS, GripController, GripSettings
from finger_sim.runtime.parameters import ParameterError
from finger_sim.scene import Scene
from finger_sim.scene_changes import SceneChanges
from finger_sim.simulate import Simulator
from finger_sim.tasks import controllers
from finger_sim.tasks.batch_rows import Rows, SweepRow, step_rows, task_runs
from finger_sim.tasks.controllers import Factory
from finger_sim.tasks.runner import TaskRun
from finger_sim.tasks.schema import Task

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


def row_scenes(task: Task, factory: Factory, columns: Sequence[tuple[str, Mapping[str, float]]],
               scenes: Sequence[Scene] | None) -> list[Scene]:
    """Each column's scene (`scenes`, else the task's); ConfigError when they are not one per column
    or `rows_reason` says why they cannot be rows of one compiled sweep."""
    scenes = [task.scene] * len(columns) if scenes is None else list(scenes)
    if len(scenes) != len(columns):
        raise ConfigError("scenes", f"one per column ({len(columns)})", len(scenes))
    reason = rows_reason([dataclasses.replace(task, scene=s) for s in scenes], factory)
    if reason is not None:
        raise ConfigError(f"task '{task.name}'", "a task the compiled gain sweep steps", reason)
    return scenes


def _sim_reason(sim: Simulator) -> str | None:
    integ = sim.integrator
    if stick_slip.element(sim.system) is not None or sim._timed:  # noqa: SLF001
        return "stick-slip friction or a moving object"
    if sim.fast_stepper is not None:  # the lean path (no contact, no drive)
        return None if _plan_parts(sim.fast_stepper.plan)[2].shape[1] > 0 else "the paper's Euler"
    if not isinstance(integ, DormandPrince853) or not integ.compiled or sim.system.actuator is not None:
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
    scenes = row_scenes(task, factory, columns, scenes)
    from finger_sim.kernel import closed_loop as kl

    laws = [_law(factory, task.sample_steps * task.scene.dt, params) for _, params in columns]
    gains = np.array([[getattr(s, name) for name in kl.GAINS] for s, _ in laws])
    law = np.array([[PHASE_NUMBERS[c.phase], c.pi.integral, c._opening_left, c.setpoint] for _, c in laws])  # noqa: SLF001
    rows = Rows(task, scenes, _Row)
    dop = next((r for r in rows.rows if r.tab is None), None)  # type: ignore[attr-defined]
    rtol, atol = (dop.rtol, dop.atol) if dop is not None else (0.0, 0.0)  # type: ignore[attr-defined]

    def run(r: Rows) -> np.ndarray:
        return kl.run(r.models, r.contact_at, r.lean, r.tab, r.depth, r.depths, r.break_min, rtol, atol, r.dt,
                      task.sample_steps, task.delay_steps, r.set_k, r.set_v, gains, law, r.pend_k, r.pend_u, r.pend_n,
                      r.command, r.states, r.measured[:, 0], r.integ, r.ys, r.fs, r.y_olds, r.denses, r.steps, r.until,
                      r.last, r.scene_rec, r.record)

    return task_runs(rows, columns, step_rows(rows, run))


class _Row(SweepRow):
    """A grip PI row: DOP853's model and tolerances, or on a scene without contact the lean path's
    model and tableau."""

    def __init__(self, sim: Simulator) -> None:
        reason = _sim_reason(sim)
        if reason is not None:  # a scene change the kernel cannot follow (not one of today's)
            raise ConfigError(f"scene '{sim.scene.name}'", "a scene the compiled gain sweep steps", reason)
        integ = sim.integrator
        #: the lean path's tableau (a scene without contact), else None (DOP853)
        self.tab: np.ndarray | None = None
        if sim.fast_stepper is not None:
            _, model, self.tab = _plan_parts(sim.fast_stepper.plan)
        else:
            assert isinstance(integ, DormandPrince853)
            model = integ._model  # noqa: SLF001
            self.rtol, self.atol = integ.rtol, integ.atol
        super().__init__(sim, model)

    def load(self, i: int, rows: Rows, changes: SceneChanges) -> None:
        super().load(i, rows, changes)
        rows.lean[i] = self.tab is not None
        rows.tab = _shared_tableau(rows.tab, self)


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
