"""What the two compiled task sweeps share (`finger_sim.tasks.batch` for the grip PI,
`finger_sim.tasks.batch_drive` for the drive controllers), written once.

- `SweepRow`: what a kernel reads of one row's Simulator (its flat model, contact block and depth
  gaps), and the hand-over of the row's state and DOP853 internal solution to that Simulator and
  back (`hand_over`, `read_back`), so that the steps Python takes are the offline path's own;
- `Rows`: every row's arrays, as `kernel.closed_loop.run` and `closed_loop_drive.run` take them
  (the setpoint schedule, pending commands, state, internal solution, record), and what Python
  keeps per row (its `SceneChanges`, crushes, where it stopped);
- `step_rows`: the kernel called until every row is DONE, each step it hands over (EVENT, WATCH,
  PAUSE: `kernel.closed_loop`'s docstring) taken by the row's own Simulator, as `run_task` takes it;
- `task_runs`: each row's samples scored and judged as `run_task` does.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Mapping, Sequence

import numpy as np

from finger_sim.effects.contact_outputs import GRIP_FORCE
from finger_sim.errors import SimulationDiverged
from finger_sim.grasp_objects import Crush
from finger_sim.integrators.base import HeldTorque
from finger_sim.integrators.dop853 import DormandPrince853
from finger_sim.kernel.layout import CONTACT, HEADER
from finger_sim.scene import Scene
from finger_sim.scene_changes import SceneChanges
from finger_sim.simulate import Simulator
from finger_sim.tasks.metrics import judge, task_scores
from finger_sim.tasks.runner import COLUMNS, DRIVE_COLUMNS, TaskRun, _outputs
from finger_sim.tasks.schema import Task
from finger_sim.tip_force_profile import first_step

#: A row's status after a kernel call (`kernel.closed_loop`: DONE, EVENT, WATCH, PAUSE).
DONE, EVENT, WATCH, PAUSE = 0, 1, 2, 3
#: The scalars of a row's DOP853 internal solution (`kernel.closed_loop.INTEGRATOR`), in this order.
I_T, I_H, I_T_OLD, I_H_OLD, I_VALUE, I_CONTINUES, I_LAST_T, I_ORIGIN = range(8)


class SweepRow:
    """What the kernel reads of one row's Simulator: its flat model (`model`), where its contact
    block starts (−1: none), each contact candidate's depth ρ (m) and whether it checks them."""

    def __init__(self, sim: Simulator, model: np.ndarray) -> None:
        self.sim, self.model = sim, model
        self.contact_at = _contact_offset(model)
        rho = dict(sim._depth_sources)  # noqa: SLF001 (gap position → ρ; the contact's gaps come first)
        count = len(sim._gaps) - len(rho)  # noqa: SLF001
        self.depths = np.array([rho.get(c, 0.0) for c in range(count)])
        self.depth = bool(rho)

    def load(self, i: int, rows: Rows, changes: SceneChanges) -> None:
        """This row's model, contact block, depths and smallest watched break force into row i."""
        rows.models[i] = 0.0
        rows.models[i, : len(self.model)] = self.model
        rows.widths[i], rows.contact_at[i], rows.depth[i] = len(self.model), self.contact_at, self.depth
        rows.depths[i] = 0.0
        rows.depths[i, : len(self.depths)] = self.depths
        forces = [o.properties.break_force for o in self.sim.scene.objects if o.properties.break_force is not None]
        rows.break_min[i] = min(forces) if changes.watching and forces else math.inf

    def sync(self, i: int, rows: Rows) -> None:
        """The Simulator's discrete state into row i after Python stepped it (none here)."""

    def hand_over(self, i: int, rows: Rows) -> None:
        """Row i's state at its step and the kernel's internal solution into its Simulator, as the
        offline run has them there (`closed_loop.INTEGRATOR`)."""
        sim, st, k = self.sim, rows.integ[i], int(rows.steps[i])
        integ = sim.integrator
        x = rows.states[i]
        sim.step_index, sim.q, sim.v = k, tuple(x[:3].tolist()), tuple(x[3:].tolist())
        if not isinstance(integ, DormandPrince853):  # the lean path keeps no state of its own
            return
        integ._t, integ._h, integ._t_old, integ._h_old = (float(st[I_T]), float(st[I_H]), float(st[I_T_OLD]),  # noqa: SLF001
                                                          float(st[I_H_OLD]))
        integ._y, integ._y_old = rows.ys[i].copy(), rows.y_olds[i].copy()  # noqa: SLF001
        integ._f[:], integ._dense[:] = rows.fs[i], rows.denses[i]  # noqa: SLF001
        integ._history[:] = [(integ._t_old, integ._h_old, integ._y_old, integ._dense.copy(), 0.0, 0.0)]  # noqa: SLF001
        integ._history_starts[:] = [integ._t_old]  # noqa: SLF001
        value = float(st[I_VALUE])
        if math.isnan(value):
            integ._torque = None  # noqa: SLF001
        else:
            if sim._held is None or sim._held[0] != value:  # noqa: SLF001
                sim._held = (value, HeldTorque(value))  # noqa: SLF001
            integ._torque = sim._held[1]  # noqa: SLF001
        integ._last = (float(st[I_LAST_T]), sim.q, sim.v) if st[I_CONTINUES] else None  # noqa: SLF001
        integ._origin = (sim.time, sim.q, sim.v) if st[I_ORIGIN] else None  # noqa: SLF001

    def read_back(self, i: int, rows: Rows) -> None:
        """The Simulator's state and internal solution after it stepped, into row i's arrays."""
        sim = self.sim
        rows.states[i] = (*sim.q, *sim.v)
        integ = sim.integrator
        if not isinstance(integ, DormandPrince853):
            return
        st = rows.integ[i]
        st[I_T], st[I_H], st[I_T_OLD], st[I_H_OLD] = integ._t, integ._h, integ._t_old, integ._h_old  # noqa: SLF001
        rows.ys[i], rows.fs[i], rows.y_olds[i], rows.denses[i] = integ._y, integ._f, integ._y_old, integ._dense  # noqa: SLF001
        held = sim._held  # noqa: SLF001
        st[I_VALUE] = held[0] if held is not None and integ._torque is held[1] else math.nan  # noqa: SLF001
        last = integ._last  # noqa: SLF001
        st[I_CONTINUES] = float(last is not None and last[1] == sim.q and last[2] == sim.v)
        st[I_LAST_T] = last[0] if last is not None else 0.0
        st[I_ORIGIN] = float(integ._origin == (sim.time, sim.q, sim.v))  # noqa: SLF001


class Rows:
    """One row per column of a compiled task sweep: the arrays its kernel works on (named as in
    `kernel.closed_loop.run`), what Python keeps per row, and `measured` (N_MEASURED values per
    row: the grip force (N), then with a drive the motor current (A) and terminal voltage (V))."""

    def __init__(self, task: Task, scenes: Sequence[Scene], make_row: Callable[[Simulator], SweepRow]) -> None:
        nrow = len(scenes)
        self.task, self.make_row = task, make_row
        self.dt, self.last = task.scene.dt, task.scene.step_count
        self.changes = [SceneChanges(s) for s in scenes]
        self.rows = [make_row(c.sim) for c in self.changes]
        width = max(len(r.model) for r in self.rows)
        ncand = max(1, max(len(r.depths) for r in self.rows))
        self.models, self.widths = np.zeros((nrow, width)), np.zeros(nrow, dtype=np.int64)
        self.contact_at = np.full(nrow, -1, dtype=np.int64)
        self.lean = np.zeros(nrow, dtype=np.bool_)  # the grip PI's rows: the fixed-step path of `tab`
        self.tab = np.zeros((3, 1))  # the lean rows' tableau, once one has it
        self.depth, self.depths = np.zeros(nrow, dtype=np.bool_), np.zeros((nrow, ncand))
        self.break_min = np.empty(nrow)
        self.drives = np.zeros((nrow, 3))  # the drive rows' mesh (`closed_loop_drive.DIRECTION` …)
        self.set_steps = set_steps = [(first_step(t, self.dt), v) for t, v in task.setpoints]
        self.set_k = np.array([k for k, _ in set_steps], dtype=np.int64)
        self.set_v = np.array([v for _, v in set_steps])
        queue = task.delay_steps // task.sample_steps + 2  # pending commands at most
        self.pend_k, self.pend_u = np.zeros((nrow, queue), dtype=np.int64), np.zeros((nrow, queue))
        self.pend_n, self.command = np.zeros(nrow, dtype=np.int64), np.zeros(nrow)
        self.states = np.empty((nrow, 6))
        self.drive_columns = DRIVE_COLUMNS if task.scene.drive is not None else ()
        self.measured = np.empty((nrow, 1 + len(self.drive_columns)))
        self.integ = np.empty((nrow, 8))
        self.ys, self.fs, self.y_olds = np.empty((nrow, 6)), np.empty((nrow, 6)), np.empty((nrow, 6))
        self.denses = np.empty((nrow, 7, 6))
        self.steps = np.zeros(nrow, dtype=np.int64)
        self.switches = sorted(k for k in self.changes[0].switches if k > 0)  # step 0's force is the static scene's
        self.until = np.array([self.next_switch(0)] * nrow, dtype=np.int64)
        self.scene_rec = np.zeros((nrow, 3))
        self.record = np.empty((nrow, self.last + 1, len(COLUMNS) + len(self.drive_columns)))
        self.crushes: list[list[Crush]] = [[] for _ in range(nrow)]
        self.stopped = [False] * nrow
        self.ends = [self.last] * nrow
        for i, row in enumerate(self.rows):
            sim = self.changes[i].sim
            self.measure(i, sim, 0.0)
            self.scene_rec[i, :2] = sim.scene.tip_force
            row.load(i, self, self.changes[i])
            row.sync(i, self)
            row.read_back(i, self)

    def next_switch(self, k: int) -> int:
        """The first tip-force switch after step k, or the last step."""
        return next((s for s in self.switches if s > k), self.last)

    def measure(self, i: int, sim: Simulator, command: float) -> None:
        """Row i's measured signals at its Simulator's state under the held command (`runner._outputs`)."""
        out = _outputs(sim, command)
        self.measured[i] = (out.get(GRIP_FORCE.name, 0.0), *(out[c] for c in reversed(self.drive_columns)))


def step_rows(rows: Rows, run: Callable[[Rows], np.ndarray]) -> float:
    """`run(rows)` (one kernel call over every row, returning their statuses) until every row is
    DONE; each step a row hands over is taken by its own Simulator as `run_task` takes it. Returns
    the wall time per row, s."""
    start = time.perf_counter()
    while True:
        status = run(rows)
        if (status == DONE).all():
            break
        for i in np.flatnonzero(status != DONE).tolist():
            k, ch, row = int(rows.steps[i]), rows.changes[i], rows.rows[i]
            row.hand_over(i, rows)
            if status[i] == PAUSE:  # a tip-force switch: SceneChanges makes the new Simulator
                ch.before_step()
                rows.until[i] = rows.next_switch(k)
                rows.scene_rec[i, :2] = ch.sim.scene.tip_force
            elif status[i] == EVENT:  # the Simulator takes step k, as run_task does
                command = float(rows.command[i])
                try:
                    ch.sim.step(command)
                except SimulationDiverged:  # run_task's rule: the run stops, the task fails
                    rows.stopped[i], rows.ends[i], rows.steps[i], rows.until[i] = True, k, rows.last, rows.last
                    continue
                rows.measure(i, ch.sim, command)
                rows.crushes[i] += ch.after_step()
                rows.steps[i] = k + 1
            else:  # WATCH: the crush rule on the state after the step
                rows.crushes[i] += ch.after_step()
            if ch.sim is not row.sim:  # a new scene: its model, and a fresh internal solution
                row = rows.rows[i] = rows.make_row(ch.sim)
                rows.models, rows.depths = _fit(rows.models, len(row.model)), _fit(rows.depths, len(row.depths))
                row.load(i, rows, ch)
            row.sync(i, rows)
            rows.scene_rec[i, 2] = len(rows.crushes[i])
            row.read_back(i, rows)
    return (time.perf_counter() - start) / len(rows.rows)


def task_runs(rows: Rows, columns: Sequence[tuple[str, Mapping[str, float]]], wall: float) -> list[TaskRun]:
    """Every row's TaskRun: its record (and the state after its last step as the last sample), scored
    and judged as `run_task` does."""
    task, dt = rows.task, rows.dt
    names = COLUMNS + rows.drive_columns
    grid = tuple((k * dt, v) for k, v in rows.set_steps)
    runs = []
    for i, (label, _) in enumerate(columns):
        n = rows.ends[i]
        if not rows.stopped[i]:  # the last sample: the state after the last step
            grip, *drive = rows.measured[i]
            rows.record[i, n] = (n * dt, grip, rows.set_v[rows.set_k <= n - 1][-1], rows.states[i, 0],
                                 rows.states[i, 3], rows.command[i], *rows.scene_rec[i], *reversed(drive))
        samples = {name: np.ascontiguousarray(rows.record[i, : n + 1, c]) for c, name in enumerate(names)}
        torque = (samples["command"], samples["theta1"]) if task.input == "torque" else None
        scores = task_scores(samples["t"], samples[GRIP_FORCE.name], grid, task.hold_after, bool(rows.crushes[i]),
                             outputs={c: samples[c] for c in rows.drive_columns}, torque=torque)
        passed = judge(scores, task.limits)
        if rows.stopped[i]:
            passed["completed"] = False
        runs.append(TaskRun(task.name, label, samples, rows.crushes[i], scores, passed, grid, dict(task.limits), wall))
    return runs


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
