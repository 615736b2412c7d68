"""Many scenes stepped at once: the compiled kernel looped over fingers on every core.

`run_batch(scenes)` runs N scenes to their ends with the numbers of `Simulator` (same method
per scene, `auto` resolved as the Simulator resolves it; tested to 1e-12 rad). The scenes may
differ in anything (geometry, spring, damping, torque profile and its parameters, initial state,
duration, dt): each finger's model is data for the kernel (`kernel.layout.model_array`).

What runs where:
- compiled (`finger_sim.kernel.rollout_loop.run_rows`, numba `prange` over the fingers): every
  fixed-step explicit method (euler, rk4, rk6, dop8) on a scene whose force elements all have a
  compiled form, with a constant, ramp, step, square or sine torque, each step the Simulator's own
  compiled step (`numerics._profile_step`, as `simulate` and `rollout` step). A step in which a
  stop closes, a contact gap opens or closes, a torque switch falls, or the kernel fails is
  handed to that finger's own `Simulator` (compiled kernel), which splits it at the switch,
  locates the event, applies the impact and keeps the finger while it rests on a stop; the
  finger then goes back to the loop.
- a per-finger `Simulator` loop (`simulate`) for the rest: implicit and adaptive methods
  (radau, rattle, dop853, adaptive: `auto` picks radau for stiff scenes), contact scenes under
  `auto` whose steps near contact are split into substeps (`auto.contact_substeps`), an element
  or profile without a compiled form, no numba, or kernel="python". These fingers run one after
  another in this process.
"""

from __future__ import annotations

import importlib.util
import time
from collections import defaultdict
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

import numpy as np

from finger_sim import kinematics, stick_slip
from finger_sim.tip_force_profile import refuse_profile
from finger_sim.auto import choose_method, contact_substeps
from finger_sim.dynamics import FingerSystem
from finger_sim.effects import contact_outputs
from finger_sim.effects.base import has_kinks
from finger_sim.errors import ConfigError, StabilityError
from finger_sim.inputs import profile_array
from finger_sim.integrators import METHODS
from finger_sim.kernel import KERNELS, PYTHON, use_writable_cache
from finger_sim.kernel.layout import OK
from finger_sim.scene import AUTO, Scene
from finger_sim.simulate import Simulator, simulate
from finger_sim.stability import fastest_mode, largest_stable_dt, mcp_range, stable_at

#: The output a contact element reports as the grip force (N): a column of contact sweeps.
GRIP_FORCE = contact_outputs.GRIP_FORCE.name

#: Most bytes of paths that the lock-step loop keeps at once (a group runs in blocks of rows).
LOCKSTEP_BYTES = 64 * 2**20
#: Bytes per finger-step of those paths: q and q', six float64.
BYTES_PER_STEP = 48


@dataclass(frozen=True)
class BatchResult:
    """The end of every run, in the order of the scenes given. Angles rad, rates rad/s, |Φ| m, J, N."""

    q: np.ndarray  # (N, 3) final (θ1, θ2, θ3)
    v: np.ndarray  # (N, 3) final rates
    max_residual: np.ndarray  # (N,) max |Φ| over each run, t = 0 included
    energy_change: np.ndarray  # (N,) E(end) − E(0)
    grip_force: np.ndarray | None  # (N,) at the end; None when no scene has contact
    methods: tuple[str, ...]  # the method each run used (auto resolved)
    compiled: np.ndarray  # (N,) bool: stepped in the compiled loop (else a per-finger Simulator loop)
    handed_over: np.ndarray  # (N,) steps of compiled runs that their Simulator took (events, rest)
    trajectories: list[np.ndarray] | None  # per run, (steps + 1) × 3 angles, when recorded
    wall_time: float  # s, stepping and set-up
    cpu_time: float  # s of process CPU (every thread), stepping and set-up
    #: the scene sensors' readings at the end, `<sensor>_measured` → (N,), NaN for runs without that sensor
    measured: dict[str, np.ndarray] = field(default_factory=dict)


@dataclass
class _Plan:
    """One scene made ready for the loop: its system, method, compiled model and profile."""

    scene: Scene
    system: FingerSystem
    method: str
    model: np.ndarray | None  # None: not compiled
    profile: np.ndarray | None  # `inputs.profile_array`; None: no compiled form
    stops: bool  # the scene's impact gaps are its MCP stops


def compiled_available() -> bool:
    """Whether numba is installed (the compiled loop can run)."""
    return importlib.util.find_spec("numba") is not None


def run_batch(
    scenes: Sequence[Scene],
    *,
    kernel: str = "auto",
    record: bool = False,
    progress: Callable[[int], None] | None = None,
) -> BatchResult:
    """Run every scene to its end; see the module docstring for which fingers run compiled.

    kernel: "auto" (compiled where it can run), "compiled" (refused, naming the first scene,
    where it cannot), or "python" (every finger through `simulate(kernel="python")`: the
    reference). record: keep every run's angles at every step (`BatchResult.trajectories`).
    progress: called with a count of runs finished, as they finish.
    StabilityError names the scene whose method is unstable at its dt.
    """
    if kernel not in KERNELS:
        raise ConfigError("kernel", f"one of {list(KERNELS)}", kernel)
    wall0, cpu0 = time.perf_counter(), time.process_time()
    planner = _Planner(compile_=kernel != PYTHON and compiled_available())
    plans = [planner.plan(i, s) for i, s in enumerate(scenes)]
    if kernel == "compiled":
        for i, p in enumerate(plans):
            if p.model is None:
                raise ConfigError(f"scenes[{i}] ({p.scene.name})", "a scene the compiled batch can step "
                                  "(an explicit method, compiled force elements and torque profile)", kernel)
    n = len(plans)
    q, v = np.zeros((n, 3)), np.zeros((n, 3))
    max_res, energy = np.zeros(n), np.zeros(n)
    handed = np.zeros(n, dtype=np.int64)
    trajs: list[np.ndarray] | None = [np.empty(0)] * n if record else None
    groups: dict[str, list[int]] = defaultdict(list)
    # a scene with sensors runs through `simulate`, which reads them (finger_sim.sensors) from its outputs
    compiled = np.array([p.model is not None and p.scene.sensors is None for p in plans], dtype=bool)
    for i, p in enumerate(plans):
        if compiled[i]:
            groups[p.method].append(i)
    for method, members in groups.items():
        _run_compiled(method, [plans[i] for i in members], members, q, v, max_res, handed, trajs, progress)
    measured: dict[str, np.ndarray] = {}
    for i, p in enumerate(plans):
        if not compiled[i]:
            traj = simulate(p.scene, kernel=PYTHON if kernel == PYTHON else "auto")
            q[i], v[i], max_res[i] = traj.q[-1], traj.v[-1], traj.residual.max()
            for name in _measured_names(p.scene):
                measured.setdefault(name, np.full(n, np.nan))[i] = traj.outputs[name][-1]
            if trajs is not None:
                trajs[i] = traj.q
            if progress is not None:
                progress(1)
    grip = np.zeros(n)
    has_grip = False
    for i, p in enumerate(plans):
        qi, vi = tuple(q[i].tolist()), tuple(v[i].tolist())
        energy[i] = p.system.energy(qi, vi) - p.system.energy(*p.scene.initial_state())
        t_end = p.scene.step_count * p.scene.dt
        for element in p.system.elements:
            value = element.outputs(t_end, qi, vi).get(GRIP_FORCE)
            if value is not None:
                grip[i] += value
                has_grip = True
    return BatchResult(
        q=q, v=v, max_residual=max_res, energy_change=energy, grip_force=grip if has_grip else None,
        methods=tuple(p.method for p in plans), compiled=compiled, handed_over=handed, trajectories=trajs,
        wall_time=time.perf_counter() - wall0, cpu_time=time.process_time() - cpu0, measured=measured,
    )


def _measured_names(scene: Scene) -> tuple[str, ...]:
    """The `<sensor>_measured` outputs of a scene's sensors (none without `sensors:`)."""
    return () if scene.sensors is None else tuple(f"{name}_measured" for name in scene.sensors.models)


class _Planner:
    """Resolves each scene's method and checks its stability as `Simulator.__init__` does, with the
    fastest mode (the costly part, ~1 ms) computed once per distinct finger model."""

    def __init__(self, *, compile_: bool) -> None:
        self.compile = compile_
        self._roots: dict[tuple, complex] = {}
        self._auto: dict[tuple, str] = {}
        self._stable: dict[tuple, bool] = {}
        if compile_:
            use_writable_cache()
            from finger_sim.kernel.integrators import compiled_twin
            from finger_sim.kernel.layout import model_array

            self._twin, self._model_array = compiled_twin, model_array

    def plan(self, index: int, scene: Scene) -> _Plan:
        refuse_profile(scene, "batch, sweep or sample")
        system = scene.build_system()
        model = self._model_array(system) if self.compile else None
        key = None if model is None else (scene.params, model.tobytes(), mcp_range(scene))
        method = scene.method
        if method == AUTO and stick_slip.in_scene(scene):  # its Simulator's choice (dop853, restarted at mode changes)
            method = stick_slip.AUTO_METHOD
        if method == AUTO:
            # choose_method reads the model, the MCP range, dt, and the torque's switches and kind
            switches = len(scene.torque.breakpoints(0.0, scene.duration))
            auto_key = None if key is None else (*key, scene.dt, scene.torque.kind, switches, scene.tolerance)
            method = self._auto.get(auto_key) if auto_key is not None else None
            if method is None:
                method, _ = choose_method(scene)
                if auto_key is not None:
                    self._auto[auto_key] = method
        cls = METHODS[method]
        profile = profile_array(scene.torque)
        known, stops = _events(scene, system)
        # auto splits a contact scene's steps near contact (an element's kinks) into substeps (Simulator._step):
        # its Simulator runs it
        substeps = (contact_substeps(scene) if scene.method == AUTO and not cls.implicit
                    and any(has_kinks(e, scene.initial_state()[0]) for e in system.elements) else 1)
        # a drive's mesh modes are events of its Simulator (finger_sim.actuators.stepping): its Simulator runs it
        if model is not None and (profile is None or self._twin(cls) is None or not known or substeps != 1
                                  or scene.drive is not None):
            model = None
        if model is None:  # a per-finger Simulator runs it, and checks its stability
            return _Plan(scene, system, method, None, profile, stops)
        root = self._roots.get(key)
        if root is None:
            root = self._roots[key] = fastest_mode(system, mcp_range(scene))
        stable = self._stable.get((key, method, scene.dt))
        if stable is None:
            stable = self._stable[(key, method, scene.dt)] = stable_at(cls, root, scene.dt)
        if not stable:
            raise StabilityError(cls.name, scene.name, scene.dt, root, largest_stable_dt(cls, root, scene.dt),
                                 f"batch run {index}")
        return _Plan(scene, system, method, model, profile, stops)


def _events(scene: Scene, system: FingerSystem) -> tuple[bool, bool]:
    """(known, stops): whether the loop sees every event of the scene, i.e. its impact gaps are
    exactly the MCP stops (θ1 − lower, upper − θ1) and every other non-smooth element is contact
    (whose gaps `loop` evaluates); and whether it has the stops."""
    from finger_sim.kernel.layout import CONTACT

    impact_gaps = 0
    for element in system.elements:
        if element.smooth:
            continue
        q0, _ = scene.initial_state()
        gaps = element.gaps(q0)
        impacts = [i for i in range(len(gaps)) if element.impact(i) is not None]
        if not impacts:
            if getattr(element, "kernel_code", None) != CONTACT:
                return False, False
            continue
        if scene.mcp_limits is None or len(gaps) != 2 or len(impacts) != 2:
            return False, False
        lower, upper = scene.mcp_limits
        if gaps != (q0[0] - lower, upper - q0[0]) or element.gap_gradient(0, q0) != (1.0, 0.0, 0.0):
            return False, False
        impact_gaps += 2
    return impact_gaps in (0, 2), impact_gaps == 2


def _contact_candidates(model: np.ndarray) -> int:
    """Number of contact candidates (gaps) in a flat model: 0 without contact."""
    from finger_sim.kernel.layout import CONTACT, HEADER

    o, count = HEADER + 1, 0
    for _ in range(int(model[HEADER])):
        code, n = int(model[o]), int(model[o + 1])
        if code == CONTACT:
            count += int(sum(model[o + 2 + 8: o + 2 + 12]))
        o += 2 + n
    return count


def _run_compiled(method: str, plans: list[_Plan], members: list[int], q: np.ndarray, v: np.ndarray,
                  max_res: np.ndarray, handed: np.ndarray, trajs: list[np.ndarray] | None,
                  progress: Callable[[int], None] | None) -> None:
    """Run the fingers of one method in the compiled loop, handing event steps to Simulators."""
    from finger_sim.integrators.explicit import ExplicitRungeKutta
    from finger_sim.kernel import rollout_loop
    from finger_sim.kernel.layout import tableau_array

    ref = METHODS[method]
    # the method's tableau (`CompiledRungeKutta`): the paper's Euler has none
    tab = tableau_array(ref.A, ref.B, ref.C) if issubclass(ref, ExplicitRungeKutta) else np.zeros((3, 0))
    n = len(plans)
    steps_plans = [_step_plan(p.scene.dt, p.model, tab) for p in plans]  # type: ignore[arg-type]
    plan_rows = np.zeros((n, max(len(x) for x in steps_plans)))
    profiles = np.zeros((n, max(len(p.profile) for p in plans)))  # type: ignore[arg-type]
    lasts = np.empty(n, dtype=np.int64)
    stops, limits = np.zeros(n, dtype=np.bool_), np.zeros((n, 2))
    gaps = np.empty(n, dtype=np.int64)
    depths = np.array([min(p.scene.phalanx_radius) for p in plans])  # the loop hands over a step that may reach it
    states = np.empty((n, 6))
    for j, p in enumerate(plans):
        plan_rows[j, : len(steps_plans[j])] = steps_plans[j]
        profiles[j, : len(p.profile)] = p.profile  # type: ignore[arg-type]
        lasts[j] = p.scene.step_count
        if p.stops:
            stops[j], limits[j] = True, p.scene.mcp_limits
        gaps[j] = _contact_candidates(p.model)  # type: ignore[arg-type]
        q0, v0 = p.scene.initial_state()
        states[j] = (*q0, *v0)
    steps = np.zeros(n, dtype=np.int64)
    max_res_local = np.array([kinematics.constraint_norm(p.scene.params, tuple(states[j, :3])) for j, p in enumerate(plans)])
    record = trajs is not None
    if record:
        longest = int(lasts.max())
        paths = np.full((n, longest + 1, 3), np.nan)
        paths[:, 0] = states[:, :3]
    else:
        paths = np.zeros((n, 1, 3))
    finished = _run_lockstep(plans, tab, states, steps, lasts, stops, gaps, max_res_local, paths, record)
    if progress is not None and finished.any():
        progress(int(finished.sum()))
    sims: dict[int, Simulator] = {}
    active = np.flatnonzero(~finished)
    while len(active):
        sub_states, sub_steps, sub_res = states[active], steps[active], max_res_local[active]
        sub_paths = paths[active] if record else paths[np.zeros(len(active), dtype=np.int64)]
        status = rollout_loop.run_rows(plan_rows[active], profiles[active], stops[active], limits[active],
                                       gaps[active], depths[active], sub_states, sub_steps, lasts[active], sub_res,
                                       sub_paths, record)
        states[active], steps[active], max_res_local[active] = sub_states, sub_steps, sub_res
        if record:
            paths[active] = sub_paths
        again = []
        for j in active[status == rollout_loop.EVENT].tolist():
            sim = sims.get(j) or sims.setdefault(j, Simulator(plans[j].scene, kernel="compiled"))
            sim.step_index, sim.q, sim.v = int(steps[j]), tuple(states[j, :3].tolist()), tuple(states[j, 3:].tolist())
            while True:
                s = sim.step()
                handed[members[j]] += 1
                max_res_local[j] = max(max_res_local[j], kinematics.constraint_norm(plans[j].scene.params, s.q))
                if record:
                    paths[j, sim.step_index] = s.q
                # a finger resting on a stop stays with its Simulator, which knows when it leaves
                if sim.step_index >= lasts[j] or sim._resting is None:  # noqa: SLF001 (see the module docstring)
                    break
            steps[j], states[j] = sim.step_index, (*sim.q, *sim.v)
            if sim.step_index < lasts[j]:
                again.append(j)
        if progress is not None:
            progress(len(active) - len(again))
        active = np.array(again, dtype=np.int64)
    for j, i in enumerate(members):
        q[i], v[i], max_res[i] = states[j, :3], states[j, 3:], max_res_local[j]
        if trajs is not None:
            trajs[i] = paths[j, : lasts[j] + 1].copy()


def _step_plan(dt: float, model: np.ndarray, tab: np.ndarray) -> np.ndarray:
    """The step plan `CompiledRungeKutta.step_plan` builds: [dt, len(model), tableau shape, model, tableau]."""
    return np.concatenate(([dt, len(model), *tab.shape], model, tab.ravel()))


def _run_lockstep(plans: list[_Plan], tab: np.ndarray, states: np.ndarray, steps: np.ndarray, lasts: np.ndarray,
                  stops: np.ndarray, gaps: np.ndarray, max_res: np.ndarray, paths: np.ndarray,
                  record: bool) -> np.ndarray:
    """Step the fingers without events under a smooth torque in lock-step (`rollout_loop.run_lockstep`),
    groups of one layout, dt and length, LOCKSTEP_BYTES of paths at a time. Updates states, steps,
    max_res (and paths) in place; returns which fingers reached their end (the others go on in `run_rows`)."""
    from finger_sim.kernel import rollout_loop

    finished = np.zeros(len(plans), dtype=bool)
    groups: dict[tuple, list[int]] = defaultdict(list)
    for j, p in enumerate(plans):
        events = stops[j] or gaps[j]
        layout = None if events else rollout_loop.lockstep_layout(p.model, tab, p.profile)  # type: ignore[arg-type]
        if layout is not None:
            groups[(layout, p.scene.dt, int(lasts[j]))].append(j)
    for (_, dt, nstep), members in groups.items():
        size = max(rollout_loop.TILE, LOCKSTEP_BYTES // (BYTES_PER_STEP * (nstep + 1)))
        for lo in range(0, len(members), size):
            rows = np.array(members[lo: lo + size])
            q, v = np.empty((len(rows), nstep + 1, 3)), np.empty((len(rows), nstep + 1, 3))
            q[:, 0], v[:, 0] = states[rows, :3], states[rows, 3:]
            models = np.column_stack([plans[j].model for j in rows.tolist()])
            inputs = np.column_stack([plans[j].profile for j in rows.tolist()])
            status, reached = np.empty(len(rows), dtype=np.int64), np.empty(len(rows), dtype=np.int64)
            rollout_loop.run_lockstep(dt, tab, models, inputs, np.zeros((len(rows), 0)), q, v, status, reached)
            res = max_res[rows]
            rollout_loop.max_residuals(models, q, reached, res)
            max_res[rows] = res
            at = np.arange(len(rows))
            states[rows, :3], states[rows, 3:] = q[at, reached], v[at, reached]
            steps[rows] = reached
            finished[rows] = status == OK
            if record:
                paths[rows, : nstep + 1] = q
    return finished
