"""`rollout`: many runs of one scene, arrays in and arrays out, shaped like `mujoco.rollout`.

    from finger_sim import rollout
    res = rollout("config/paper_flexion.yaml", control=u, initial_state=x0,
                  params={"model.spring_stiffness": k})
    res.q[i, n]   # (θ1, θ2, θ3) of row i after n steps, rad

Row i is the scene with `params[key][i]` set at each dotted key (as `sweep --vary` takes
them), started at `initial_state[i]` = (θ1, θ1') (the assembly gives θ2, θ3 and their rates),
and driven by `control[i, n]`, the scene's input held over step n (what `Simulator.step(value)`
takes: the motor torque, N·m, today) in place of its scripted profile. Each row equals
`simulate` (or `Simulator.step(control[i, n])` step by step) of that row's scene.

Where it runs: rows whose scene has the Simulator's lean compiled path (a fixed-step explicit
method on a smooth scene) are stepped in the kernel, nothing per step in Python: rows sharing a
Runge-Kutta method, force-element layout and smooth input (ramp, sine, constant, held control)
by `kernel.rollout_loop.run_lockstep`, the Simulator's step in lock-step across tiles of rows
(structure of arrays; the same operations, so the same bits); the others (Euler, contact, a
switch inside a step) by `kernel.rollout_loop.run`, which loops the Simulator's own compiled
step row by row. Both use every thread. Other rows (events: stops, contact; implicit or
adaptive methods; no numba) are stepped by that scene's `Simulator`, as `simulate` steps them. Scenes are built and checked once per distinct
parameter set, not per row.

The module is `rollouts` so that `finger_sim.rollout` stays the function (`finger_sim.__getattr__`).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from finger_sim.effects.contact import build_contact
from finger_sim.errors import ConfigError, SimulationDiverged
from finger_sim.inputs import HELD_ARRAY
from finger_sim.kernel.layout import BREAKPOINT, OK
from finger_sim.kernel.runner import advance
from finger_sim.scene import Scene, load_scene, scene_from_dict
from finger_sim.sensors import SOURCES, SensorBank
from finger_sim.simulate import Simulator, output_names, state_columns
from finger_sim.sweep import set_key

if TYPE_CHECKING:
    from finger_sim.kernel.integrators import FastStepper

#: Most bytes of q and v that `rollout` allocates itself (pass q= and v= to go beyond on purpose).
MAX_ALLOCATED_BYTES = 8e9
#: Bytes per finger-step of q and v (six float64).
BYTES_PER_STEP = 48


@dataclass(frozen=True)
class RolloutResult:
    """Every row at every step, t = 0 included. t: (nstep + 1,) s; q, v: (nbatch, nstep + 1, 3)
    rad and rad/s; outputs: the force elements' outputs (as `Trajectory.outputs`, e.g.
    grip_force, N) name → (nbatch, nstep + 1), NaN for rows whose scene lacks that output;
    methods: each row's method (auto resolved); compiled: (nbatch,) bool, stepped in the compiled loop;
    scenes: each row's scene (rows with the same params share one)."""

    t: np.ndarray
    q: np.ndarray
    v: np.ndarray
    outputs: dict[str, np.ndarray]
    methods: tuple[str, ...]
    compiled: np.ndarray
    scenes: tuple[Scene, ...]


def rollout(scene: str | Path | Scene, *, control: Any = None, initial_state: Any = None,
            params: Mapping[str, Any] | None = None, nstep: int | None = None, nthread: int | None = None,
            q: np.ndarray | None = None, v: np.ndarray | None = None) -> RolloutResult:
    """Run nbatch rows of `scene` for nstep steps of its dt; see the module docstring.

    control: (nbatch, nstep) input held over each step (N·m); None: the scene's own profile.
    initial_state: (nbatch, 2) (θ1 rad, θ1' rad/s); None: the scene's. params: dotted scene key →
    (nbatch,) values. nstep: steps (default: control's, else the scene's duration / dt). nthread:
    threads of the compiled loop (default: numba's). q, v: preallocated (nbatch, nstep + 1, 3)
    float64 C-contiguous outputs, filled in place. nbatch is the common leading size of the
    arrays given (1 when none is). ConfigError names the argument, what it expected and what came.
    """
    base = scene if isinstance(scene, Scene) else load_scene(scene)
    control_arr = None if control is None else _array("control", control, 2)
    start_arr = None if initial_state is None else _array("initial_state", initial_state, 2)
    if start_arr is not None and start_arr.shape[1] != 2:
        raise ConfigError("initial_state", "trailing dimension 2 (θ1 rad, θ1' rad/s)", f"shape {start_arr.shape}")
    param_arrs = {key: _array(f"params[{key!r}]", value, 1) for key, value in (params or {}).items()}
    nbatch = _batch_size(control_arr, start_arr, param_arrs)
    rows_scene, scenes = _scenes(base, param_arrs, nbatch)
    dt = scenes[0].dt
    if any(s.dt != dt for s in scenes):
        raise ConfigError("params", "one integrator.dt for every row (the rows share t)", sorted({s.dt for s in scenes}))
    nstep = _step_count(nstep, control_arr, scenes)
    q = _output("q", q, nbatch, nstep)
    v = _output("v", v, nbatch, nstep)
    sims = [Simulator(s) for s in scenes]
    starts: dict[tuple[int, float, float], tuple[tuple[float, ...], tuple[float, ...]]] = {}
    for i, j in enumerate(rows_scene.tolist()):
        theta1, rate = (scenes[j].theta1, scenes[j].theta1_dot) if start_arr is None else start_arr[i].tolist()
        start = starts.get((j, theta1, rate))
        if start is None:  # assembled and checked once per distinct (scene, θ1, θ1')
            start = starts[(j, theta1, rate)] = _start(scenes[j], theta1, rate, i)
        q[i, 0], v[i, 0] = start
    held = control_arr is not None
    compiled = np.array([sims[j].fast_stepper is not None and (held or sims[j].fast_stepper.profile is not None)
                         for j in rows_scene.tolist()], dtype=bool)
    if compiled.any():
        _run_compiled(sims, rows_scene, control_arr, q, v, compiled, nthread)
    for i in np.flatnonzero(~compiled).tolist():
        _run_stepped(sims[rows_scene[i]], q, v, i, 0, None if control_arr is None else control_arr[i])
    t = np.arange(nstep + 1) * dt  # k·dt, as Simulator.time
    rows = rows_scene.tolist()
    return RolloutResult(t, q, v, _outputs(sims, rows_scene, t, q, v), tuple(sims[j].method for j in rows), compiled,
                         tuple(scenes[j] for j in rows))


def _array(name: str, value: Any, ndim: int) -> np.ndarray:
    try:
        arr = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError):
        raise ConfigError(name, f"a {ndim}-D array of numbers", value) from None
    if arr.ndim != ndim:
        raise ConfigError(name, f"a {ndim}-D array", f"{arr.ndim}-D, shape {arr.shape}")
    if not np.isfinite(arr).all():
        raise ConfigError(name, "finite values", f"{int((~np.isfinite(arr)).sum())} non-finite")
    return np.ascontiguousarray(arr)


def _batch_size(control: np.ndarray | None, start: np.ndarray | None, params: Mapping[str, np.ndarray]) -> int:
    sizes = {name: a.shape[0] for name, a in (("control", control), ("initial_state", start)) if a is not None}
    sizes.update({f"params[{k!r}]": a.shape[0] for k, a in params.items()})
    if not sizes:
        return 1
    first, nbatch = next(iter(sizes.items()))
    for name, size in sizes.items():
        if size != nbatch:
            raise ConfigError(name, f"leading dimension nbatch = {nbatch} (from {first})", f"{size}")
    if nbatch == 0:
        raise ConfigError(first, "at least one row", "0 rows")
    return nbatch


def _scenes(base: Scene, params: Mapping[str, np.ndarray], nbatch: int) -> tuple[np.ndarray, list[Scene]]:
    """Each row's index into the distinct scenes, and those scenes (validated as a scene file is)."""
    if not params:
        return np.zeros(nbatch, dtype=np.int64), [base]
    keys = list(params)
    rows = list(zip(*(params[k].tolist() for k in keys)))
    index: dict[tuple[float, ...], int] = {}
    which = np.empty(nbatch, dtype=np.int64)
    scenes: list[Scene] = []
    for i, combo in enumerate(rows):
        j = index.get(combo)
        if j is None:
            data = base.to_dict()
            try:
                for key, value in zip(keys, combo):
                    set_key(data, key, value)
                scenes.append(scene_from_dict(data))
            except ConfigError as exc:
                given = ", ".join(f"{k}={val!r}" for k, val in zip(keys, combo))
                raise ConfigError(f"params row {i} ({given}): {exc.key.removeprefix('--vary ')}", exc.allowed, exc.got,
                                  problem=exc.problem) from None
            j = index[combo] = len(scenes) - 1
        which[i] = j
    return which, scenes


def _step_count(nstep: int | None, control: np.ndarray | None, scenes: list[Scene]) -> int:
    if control is not None:
        if nstep is not None and nstep != control.shape[1]:
            raise ConfigError("nstep", f"control's second dimension ({control.shape[1]})", nstep)
        nstep = control.shape[1]
    if nstep is None:
        counts = {s.step_count for s in scenes}
        if len(counts) > 1:
            raise ConfigError("nstep", "a step count when the rows' durations differ", f"None (counts {sorted(counts)})")
        nstep = counts.pop()
    if not isinstance(nstep, (int, np.integer)) or isinstance(nstep, bool) or nstep < 1:
        raise ConfigError("nstep", "a positive integer", nstep)
    return int(nstep)


def _output(name: str, given: np.ndarray | None, nbatch: int, nstep: int) -> np.ndarray:
    shape = (nbatch, nstep + 1, 3)
    if given is None:
        size = nbatch * (nstep + 1) * BYTES_PER_STEP
        if size > MAX_ALLOCATED_BYTES:
            raise ConfigError("nbatch × nstep", f"at most {MAX_ALLOCATED_BYTES:.3g} bytes of q and v "
                              "(pass preallocated q= and v= to go beyond, or split the batch)", f"{size:.3g} bytes")
        return np.empty(shape)
    if not isinstance(given, np.ndarray) or given.shape != shape or given.dtype != np.float64 \
            or not given.flags.c_contiguous or not given.flags.writeable:
        got = f"shape {given.shape}, {given.dtype}" if isinstance(given, np.ndarray) else type(given).__name__
        raise ConfigError(name, f"a writeable C-contiguous float64 array of shape {shape}", got)
    return given


def _start(scene: Scene, theta1: float, rate: float, row: int) -> tuple[tuple[float, ...], tuple[float, ...]]:
    """(q, q') at t = 0 for (θ1, θ1'), checked as `scene_from_dict` checks the scene's own."""
    try:
        start = dataclasses.replace(scene, theta1=theta1, theta1_dot=rate)
        q0, v0 = start.initial_state()
        if scene.mcp_limits is not None and not scene.mcp_limits[0] <= theta1 <= scene.mcp_limits[1]:
            raise ConfigError("θ1", f"an angle within model.joint_limits.mcp {list(scene.mcp_limits)} rad", theta1)
        contact = build_contact(start)
        if contact is not None:
            contact.check_clearance(q0)
    except ConfigError as exc:
        raise ConfigError(f"initial_state[{row}]: {exc.key}", exc.allowed, exc.got, problem=exc.problem) from None
    return q0, v0


def _run_compiled(sims: list[Simulator], rows_scene: np.ndarray, control: np.ndarray | None, q: np.ndarray,
                  v: np.ndarray, compiled: np.ndarray, nthread: int | None) -> None:
    """The compiled rows through `rollout_loop.run`; a row stopped by a torque switch inside a
    step goes on in its Simulator from there; a failed row raises, naming the row."""
    import numba

    from finger_sim.kernel import rollout_loop

    held = control is not None
    rows = np.flatnonzero(compiled)
    which = np.ascontiguousarray(rows_scene[rows])
    status, reached = np.empty(len(rows), dtype=np.int64), np.empty(len(rows), dtype=np.int64)
    groups: dict[object, list[int]] = {}
    keys = [_lockstep_key(s, held) for s in sims]
    for j, scene_row in enumerate(which.tolist()):
        groups.setdefault(keys[scene_row], []).append(j)
    threads = numba.get_num_threads()
    if nthread is not None:
        if not isinstance(nthread, int) or not 1 <= nthread <= numba.config.NUMBA_NUM_THREADS:
            raise ConfigError("nthread", f"an integer in 1..{numba.config.NUMBA_NUM_THREADS}", nthread)
        numba.set_num_threads(nthread)
    try:
        for key, members in groups.items():
            part = rows[members]
            every = len(part) == q.shape[0]
            qs, vs = (q, v) if every else (np.ascontiguousarray(q[part]), np.ascontiguousarray(v[part]))
            ctl = np.zeros((len(part), 0)) if control is None else \
                (control if every else np.ascontiguousarray(control[part]))
            st, re = np.empty(len(part), dtype=np.int64), np.empty(len(part), dtype=np.int64)
            scene_rows = which[members]
            if key is None:  # a row's own compiled step, row by row
                plans = _padded([s.fast_stepper.plan if s.fast_stepper is not None else np.zeros(1) for s in sims])
                profiles = _padded([HELD_ARRAY if held or s.fast_stepper is None else s.fast_stepper.profile
                                    for s in sims])
                rollout_loop.run(plans, profiles, np.ascontiguousarray(scene_rows), ctl, qs, vs, st, re)
            else:  # the same step in lock-step, the rows' models and inputs as columns
                first = sims[scene_rows[0]].fast_stepper
                dt, model, tab = _plan_parts(first.plan)  # type: ignore[union-attr]
                distinct = np.unique(scene_rows)
                models = np.empty((len(model), len(distinct)))
                inputs = np.empty((len(_input_array(first, held)), len(distinct)))  # type: ignore[arg-type]
                for c, j in enumerate(distinct.tolist()):
                    models[:, c] = _plan_parts(sims[j].fast_stepper.plan)[1]  # type: ignore[union-attr]
                    inputs[:, c] = _input_array(sims[j].fast_stepper, held)  # type: ignore[arg-type]
                column = np.searchsorted(distinct, scene_rows)
                rollout_loop.run_lockstep(dt, tab, np.ascontiguousarray(models[:, column]),
                                          np.ascontiguousarray(inputs[:, column]), ctl, qs, vs, st, re)
            if not every:
                q[part], v[part] = qs, vs
            status[members], reached[members] = st, re
    finally:
        numba.set_num_threads(threads)
    for j in np.flatnonzero(status != OK).tolist():
        i, k, sim = int(rows[j]), int(reached[j]), sims[which[j]]
        if status[j] != BREAKPOINT:
            try:
                sim.fast_stepper.fail(int(status[j]), k, tuple(q[i, k].tolist()))  # type: ignore[union-attr]
            except SimulationDiverged as exc:
                raise SimulationDiverged(f"row {i}: {exc.reason}", method=exc.method, t=exc.t, dt=exc.dt) from None
        _run_stepped(sim, q, v, i, k, None if control is None else control[i])


def _run_stepped(sim: Simulator, q: np.ndarray, v: np.ndarray, row: int, k: int, control: np.ndarray | None) -> None:
    """Row `row` from step k to the end in its Simulator, as `simulate` runs it (`kernel.runner.advance`),
    or one `Simulator.step(control[n])` per step."""
    sim.reset()
    sim.step_index, sim.q, sim.v = k, tuple(q[row, k].tolist()), tuple(v[row, k].tolist())
    nstep = q.shape[1] - 1
    try:
        if control is None:
            xs = advance(sim, nstep - k)
            q[row, k + 1:], v[row, k + 1:] = xs[:, :3], xs[:, 3:]
        else:
            for n in range(k, nstep):
                state = sim.step(float(control[n]))
                q[row, n + 1], v[row, n + 1] = state.q, state.v
    except SimulationDiverged as exc:
        raise SimulationDiverged(f"row {row}: {exc.reason}", method=exc.method, t=exc.t, dt=exc.dt) from None


def _plan_parts(plan: np.ndarray) -> tuple[float, np.ndarray, np.ndarray]:
    """(dt, model, tableau) of a step plan (`numerics.plan_parts` in Python)."""
    nm, rows, cols = int(plan[1]), int(plan[2]), int(plan[3])
    return float(plan[0]), plan[4: 4 + nm], plan[4 + nm: 4 + nm + rows * cols].reshape(rows, cols)


def _input_array(fast: FastStepper, held: bool) -> np.ndarray:
    return HELD_ARRAY if held else fast.profile  # type: ignore[return-value]


def _lockstep_key(sim: Simulator, held: bool) -> tuple | None:
    """What rows stepped together by `rollout_loop.run_lockstep` share (`rollout_loop.lockstep_layout`),
    or None when the row needs `rollout_loop.run`."""
    from finger_sim.kernel.rollout_loop import lockstep_layout

    fast = sim.fast_stepper
    if fast is None or (not held and fast.profile is None):
        return None
    _, model, tab = _plan_parts(fast.plan)
    return lockstep_layout(model, tab, _input_array(fast, held))


def _padded(arrays: list[np.ndarray]) -> np.ndarray:
    out = np.zeros((len(arrays), max(len(a) for a in arrays)))
    for j, a in enumerate(arrays):
        out[j, : len(a)] = a
    return out


def _outputs(sims: list[Simulator], rows_scene: np.ndarray, t: np.ndarray, q: np.ndarray,
             v: np.ndarray) -> dict[str, np.ndarray]:
    """The elements' outputs of every row at every step (`simulate.state_columns`); {} when no
    scene has any. Evaluated row by row in Python, only for scenes with outputs (contact, stops)."""
    names = [output_names(s.system.elements, s.q) for s in sims]
    every = list(dict.fromkeys(n for ns in names for n in ns))
    out = {name: np.full(q.shape[:2], np.nan) for name in every}
    for i, j in enumerate(rows_scene.tolist()):
        if names[j]:
            _, _, values = state_columns(sims[j].system, t, np.hstack([q[i], v[i]]))
            for c, name in enumerate(names[j]):
                out[name][i] = values[:, c]
    return _sensed(sims, rows_scene, out)


def _sensed(sims: list[Simulator], rows_scene: np.ndarray, out: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
    """`out` with the readings of each row's scene sensors (finger_sim.sensors) added, read from the
    row's outputs after the run with the scene's seed, as `simulate` reads them; NaN for rows
    without that sensor. A sensor of a drive output is refused: a rollout has no drive outputs."""
    for i, j in enumerate(rows_scene.tolist()):
        sensors = sims[j].scene.sensors
        if sensors is None:
            continue
        for name in sensors.models:
            if not all(src in out for src in SOURCES[name]):
                raise ConfigError(f"sensors.{name}", "a sensor of a rollout's outputs (fsr_proximal, fsr_distal): "
                                  "a rollout has no drive outputs", name)
        readings = SensorBank(sensors, sims[j].dt).measure({name: column[i] for name, column in out.items()})
        for name, values in readings.items():
            out.setdefault(name, np.full((len(rows_scene), len(values)), np.nan))[i] = values
    return out
