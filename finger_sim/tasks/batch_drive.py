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

import math
from collections.abc import Mapping, Sequence

import numpy as np

from finger_sim import stick_slip
from finger_sim.actuators.drive_outputs import MOTOR_CURRENT
from finger_sim.effects.contact import Contact
from finger_sim.effects.contact_outputs import GRIP_FORCE
from finger_sim.errors import ConfigError
from finger_sim.integrators.dop853 import DormandPrince853
from finger_sim.scene import Scene
from finger_sim.scene_changes import SceneChanges
from finger_sim.simulate import Simulator
from finger_sim.tasks import controllers, current_grip
from finger_sim.tasks.batch_rows import I_VALUE, Rows, SweepRow, step_rows, task_runs
from finger_sim.tasks.controllers import Factory
from finger_sim.tasks.runner import TaskRun
from finger_sim.tasks.schema import Task

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
    drive = getattr(sim.system, "drive", None)
    if drive is None or drive.inductive:
        return "a drive with an inductance (L > 0)" if drive is not None else "no drive"
    if stick_slip.element(sim.system) is not None or sim._timed:  # noqa: SLF001
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


class _Row(SweepRow):
    """A drive row: its flat model ends in the drive's block; the drive's discrete state (mesh mode,
    direction) and its DOP853 solution's mode follow the Simulator's."""

    def __init__(self, sim: Simulator) -> None:
        reason = sim_reason(sim)
        if reason is not None:  # a scene change the kernel cannot follow
            raise ConfigError(f"scene '{sim.scene.name}'", "a scene the compiled gain sweep steps", reason)
        integ = sim.integrator
        assert isinstance(integ, DormandPrince853)
        self.rtol, self.atol = integ.rtol, integ.atol
        super().__init__(sim, integ._model)  # noqa: SLF001 (its mode slot follows the drive: `Drive.mirror`)

    def sync(self, i: int, rows: Rows) -> None:
        """The drive's discrete state (mesh mode, direction) into row i's arrays."""
        drive = self.sim.system.drive  # type: ignore[attr-defined]
        p = drive.params
        rows.models[i, len(self.model) - len(drive.kernel_block())] = float(drive.mode)
        rows.drives[i] = (drive.direction, p.efficiency, p.backward_efficiency)

    def hand_over(self, i: int, rows: Rows) -> None:
        """`SweepRow.hand_over`; a solution the kernel continued is under the drive's current mode."""
        super().hand_over(i, rows)
        if not math.isnan(rows.integ[i, I_VALUE]):
            self.sim.integrator.adopt_modes()  # type: ignore[attr-defined]

    def read_back(self, i: int, rows: Rows) -> None:
        """`SweepRow.read_back`; a solution computed under another mesh mode than the current one restarts."""
        super().read_back(i, rows)
        if not self.sim.integrator.under_current_modes():  # type: ignore[attr-defined]
            rows.integ[i, I_VALUE] = math.nan


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
    from finger_sim.kernel import closed_loop_drive as kd
    from finger_sim.tasks.batch import row_scenes

    scenes = row_scenes(task, factory, columns, scenes)
    laws = [_law_row(factory, task.sample_steps * task.scene.dt, params) for _, params in columns]
    kind = np.array([law[0] for law in laws], dtype=np.int64)
    feedback = np.array([law[1] for law in laws], dtype=np.int64)
    scale = np.array([law[2] for law in laws])
    gains = np.array([law[3] for law in laws])
    state = np.zeros((len(columns), 7))  # the controllers' initial state: setpoint 0, nothing integrated
    rows = Rows(task, scenes, _Row)
    assert rows.record.shape[2] == kd.N_COLUMNS and rows.measured.shape[1] == 3
    rtol, atol = rows.rows[0].rtol, rows.rows[0].atol  # type: ignore[attr-defined]

    def run(r: Rows) -> np.ndarray:
        return kd.run(r.models, r.widths, r.contact_at, r.depth, r.depths, r.break_min, rtol, atol, r.dt,
                      task.sample_steps, task.delay_steps, r.set_k, r.set_v, kind, feedback, scale, gains, state,
                      r.pend_k, r.pend_u, r.pend_n, r.command, r.states, r.measured, r.drives, r.integ, r.ys, r.fs,
                      r.y_olds, r.denses, r.steps, r.until, r.last, r.scene_rec, r.record)

    return task_runs(rows, columns, step_rows(rows, run))
