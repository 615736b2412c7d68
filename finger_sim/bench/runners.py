"""Timed runs of one scene by one method: the project's integrators, scipy's solve_ivp and MuJoCo.

Every runner returns a `Run`: the error against the scene's reference (max over the sample
grid of |θ − θ_ref| on the three angles, rad), the largest loop-closure residual |Φ| (m),
the relative energy drift where energy is conserved, and the CPU time of the stepping
alone: `time.process_time`, median of the repeats, with setup (model building, stability
checks, MJCF compiling) outside it. A run whose first repeat takes longer than
LONG_RUN_SECONDS is timed once: its relative timing noise is already small; one whose first repeat takes less
than SHORT_RUN_SECONDS is repeated at least SHORT_RUN_REPEATS times (`repeats_after`), for every runner alike.

On a contact scene (objects) a run also reports the grip force Σ F_n at its end and its
spread over the last GRIP_WINDOW of the run (a run at rest has none; a chattering contact
shows it), and the final θ1.
"""

from __future__ import annotations

import functools
import math
import statistics
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass

import numpy as np
from scipy.integrate import solve_ivp

from finger_sim.effects.contact_outputs import GRIP_FORCE
from finger_sim import kinematics
from finger_sim.bench.reference import Reference, sample_times, solve
from finger_sim.effects.contact import build_contact
from finger_sim.errors import ConfigError, FingerSimError, SimulationDiverged, StabilityError
from finger_sim.inputs import Constant
from finger_sim.scene import Scene
from finger_sim.simulate import Simulator, State
from finger_sim import stepper_slot, stick_slip

#: Runs whose first repeat takes longer than this (s of CPU) are not repeated.
LONG_RUN_SECONDS = 2.0
#: Runs whose first repeat takes less than this (s of CPU) are repeated at least SHORT_RUN_REPEATS times: the median of
#: three sub-millisecond whole runs moved by a third from bench to bench (paper_to_stop's 0.3 ms run read 0.33–0.45 ms).
SHORT_RUN_SECONDS = 0.005
SHORT_RUN_REPEATS = 15
#: A scipy run that asks for more right-hand-side evaluations than this is given up
#: (scipy's Radau at rtol 1e-12 on stiff_spring would take ~2e7 evaluations, 10 minutes).
MAX_SCIPY_EVALUATIONS = 300_000
FAMILY_PROJECT, FAMILY_SCIPY, FAMILY_MUJOCO = "finger_sim", "scipy", "MuJoCo"
#: Fraction of a run, at its end, over which the grip force's spread (max − min) is taken.
GRIP_WINDOW = 0.1
#: The method label that runs `method: auto` itself (the choice and its contact substeps).
AUTO = "auto"
#: Appended to a method's label when its run is timed whole, as `simulate` steps it (`run_method(whole_run=True)`).
WHOLE_RUN_SUFFIX = " (whole run)"
#: The label of `auto`'s whole run: what a user running the scene offline gets, timed as scipy is.
AUTO_WHOLE_RUN = AUTO + WHOLE_RUN_SUFFIX
#: The label of `auto` at dt = 1 ms over a grid of `integrator.tolerance` (knob "tolerance"): on a scene with
#: events, a stiff mode or a drive, the error-controlled dop853 at rtol = atol = 1e-3·tolerance, its
#: work-precision front; on a smooth one, the table's fixed-step method for that tolerance.
AUTO_TOLERANCE = AUTO + " by tolerance"

OK, REFUSED, DIVERGED, GAVE_UP, SKIPPED = "ok", "refused", "diverged", "gave up", "skipped"


@dataclass
class Run:
    """One timed run. Times in s, error in rad, |Φ| in m; NaN where a figure does not apply."""

    scene: str
    family: str
    method: str  # row label, e.g. "rk4", "scipy DOP853", "MuJoCo RK4 tight"
    knob: str  # "dt", "rtol" or "timestep"
    value: float  # the knob's value
    duration: float  # simulated s
    status: str = OK
    note: str = ""
    error: float = math.nan
    final_error: float = math.nan  # rad, |θ − θ_ref| at the run's end
    max_phi: float = math.nan
    energy_drift: float = math.nan
    penetration: float = math.nan
    grip_force: float = math.nan  # N, Σ F_n at the run's end (contact scenes)
    grip_spread: float = math.nan  # N, max − min of Σ F_n over the last GRIP_WINDOW of the run
    final_theta1: float = math.nan  # rad
    cpu: float = math.nan  # median CPU s of the stepping
    repeats: int = 0
    steps: int = 0
    nfev: int = 0

    @property
    def ok(self) -> bool:
        return self.status == OK

    @property
    def us_per_step(self) -> float:
        return 1e6 * self.cpu / self.steps if self.ok and self.steps else math.nan

    @property
    def cpu_per_second(self) -> float:
        """CPU s per simulated s."""
        return self.cpu / self.duration if self.ok else math.nan

    @property
    def realtime_factor(self) -> float:
        """Simulated s per CPU s."""
        return self.duration / self.cpu if self.ok and self.cpu > 0 else math.nan


def conserves_energy(scene: Scene) -> bool:
    """τ ≡ 0 (no drive), no damping, and no stops or contacts that could absorb energy: T + V (+ V_c) is a constant of motion."""
    no_torque = scene.drive is None and isinstance(scene.torque, Constant) and scene.torque.value == 0.0
    elastic = scene.mcp_limits is None or scene.restitution == 1.0
    lossless_contact = not scene.objects or (scene.contact.damping == 0.0 and scene.contact.friction == 0.0)
    return no_torque and scene.damping == 0.0 and elastic and lossless_contact


def repeats_after(first_cpu: float, repeats: int) -> int:
    """How many repeats a run gets in all, given its first one's CPU s: one after a long first run, at least
    SHORT_RUN_REPEATS after a short one, else `repeats`."""
    if first_cpu > LONG_RUN_SECONDS:
        return 1
    return max(repeats, SHORT_RUN_REPEATS) if first_cpu < SHORT_RUN_SECONDS else repeats


def _timed(fn: Callable[[], object], repeats: int) -> tuple[object, float, int]:
    """(first result, median CPU s, repeats done) of fn(); repeated as `repeats_after` its first run says."""
    results, cpus, count = None, [], repeats
    while len(cpus) < count:
        start = time.process_time()
        out = fn()
        cpus.append(time.process_time() - start)
        if len(cpus) == 1:
            results, count = out, repeats_after(cpus[0], repeats)
    return results, statistics.median(cpus), len(cpus)


def _fill_accuracy(run: Run, scene: Scene, reference: Reference, times: np.ndarray, q: np.ndarray, v: np.ndarray | None) -> None:
    """Error, |Φ|, energy drift and stop penetration from states q (N, 3), v (N, 3) at `times`."""
    if not (np.all(np.isfinite(q)) and (v is None or np.all(np.isfinite(v)))):
        run.status, run.note = DIVERGED, "non-finite state"
        return
    deviation = np.abs(q - reference.theta(times))
    run.error = float(np.max(deviation))
    run.final_error = float(np.max(deviation[-1]))
    run.max_phi = max(kinematics.constraint_norm(scene.params, tuple(row)) for row in q)
    if v is not None and conserves_energy(scene):
        system = scene.build_system()
        energy = np.array([system.energy(tuple(a), tuple(b)) for a, b in zip(q, v)])
        run.energy_drift = float(np.max(np.abs(energy - energy[0])) / abs(energy[0]))
    if scene.mcp_limits is not None:
        lo, hi = scene.mcp_limits
        run.penetration = float(max(0.0, np.max(q[:, 0] - hi), np.max(lo - q[:, 0])))
    run.final_theta1 = float(q[-1, 0])


def grip_forces(scene: Scene, times: np.ndarray, q: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Σ F_n (N) of the scene's contact element at each sampled state (spec §7)."""
    contact = build_contact(scene)
    if contact is None:
        return np.zeros(len(times))
    return np.array([contact.outputs(t, tuple(a), tuple(b))[GRIP_FORCE.name] for t, a, b in zip(times, q, v)])


def fill_grip(run: Run, times: np.ndarray, grip: np.ndarray) -> None:
    """The run's grip force at its end and its spread over the last GRIP_WINDOW of the run."""
    tail = grip[times >= times[-1] - GRIP_WINDOW * run.duration - 1e-12]
    run.grip_force, run.grip_spread = float(grip[-1]), float(np.max(tail) - np.min(tail))


# -- the project's integrators ---------------------------------------------------------------


def run_method(
    scene: Scene, method: str, dt: float, reference: Reference, *, spacing: float, repeats: int, kernel: str = "auto",
    whole_run: bool = False, tolerance: float | None = None,
) -> Run:
    """`scene` stepped by the project's `method` at `dt` through `Simulator` (the node's path).

    method AUTO runs `method: auto` (its choice and, in contact, its substeps); the note says what ran.
    kernel: Simulator's kernel ("auto": compiled where it can, "python": CPython, "compiled").
    whole_run: the run to its end as `simulate` steps it (`kernel.advance`: stretches of steps in one
    kernel call where the scene allows), not one `Simulator.step` per step; the same states (`run_states`).
    Its label is the method's with WHOLE_RUN_SUFFIX.
    tolerance: the scene's `integrator.tolerance` (rad) instead of its own; the run's knob is then
    "tolerance" with this value, and method AUTO is labelled AUTO_TOLERANCE.
    """
    label = AUTO_TOLERANCE if tolerance is not None and method == AUTO else method
    knob, value = ("dt", dt) if tolerance is None else ("tolerance", tolerance)
    run = Run(scene.name, FAMILY_PROJECT, label + WHOLE_RUN_SUFFIX if whole_run else label, knob, value, scene.duration)
    n = round(scene.duration / dt)
    try:
        resolved = scene.with_overrides(method=method, dt=dt, tolerance=tolerance)
        probe = Simulator(resolved, kernel=kernel)  # the stability check, outside the timing
        if method == AUTO:
            run.note = f"{probe.method}" + (f", {probe.substeps} substeps in contact" if probe.substeps > 1 else "")
    except StabilityError as exc:
        run.status, run.note = REFUSED, str(exc).split(";")[0].split(": ", 1)[-1]
        return run
    except ConfigError as exc:  # a method that cannot step the scene (rattle on a drive scene)
        run.status, run.note = REFUSED, str(exc)
        return run

    cpus: list[float] = []
    states: list[State] = []
    try:
        if whole_run:  # an untimed run first: the whole run's compiled loops load (or compile) lazily, outside the timing
            run_states(Simulator(resolved, kernel=kernel), n, whole_run=True)
        count = repeats
        while len(cpus) < count:
            out, cpu = run_states(Simulator(resolved, kernel=kernel), n, whole_run=whole_run)
            cpus.append(cpu)
            if len(cpus) == 1:
                states, count = out, repeats_after(cpu, repeats)
    except (SimulationDiverged, ZeroDivisionError, OverflowError, ValueError, np.linalg.LinAlgError) as exc:
        run.status, run.note = DIVERGED, f"{type(exc).__name__}: {exc}"[:160]
        return run
    run.cpu, run.repeats, run.steps, run.nfev = statistics.median(cpus), len(cpus), n, 0
    stride = max(1, round(spacing / dt))
    picked = states[::stride]
    times = np.array([s.t for s in picked])
    q = np.array([s.q for s in picked])
    v = np.array([s.v for s in picked])
    _fill_accuracy(run, scene, reference, times, q, v)
    # |Φ| and stop penetration over every step, not only the samples
    if run.ok:
        run.max_phi = max(kinematics.constraint_norm(scene.params, s.q) for s in states)
        if scene.mcp_limits is not None:
            lo, hi = scene.mcp_limits
            run.penetration = max(0.0, max(max(s.q[0] - hi, lo - s.q[0]) for s in states))
        if scene.objects:
            fill_grip(run, times, grip_forces(scene, times, q, v))
    return run


def run_states(sim: Simulator, n: int, *, whole_run: bool) -> tuple[list[State], float]:
    """(the states at the start and after each of n steps of a fresh `sim`, CPU s of the stepping alone).

    whole_run: as `simulate` steps the scene (`kernel.advance`), else one `Simulator.step` per step (the node's path).
    """
    states = [sim.state]
    if whole_run:
        start = time.process_time()
        xs = stepper_slot.kernel().advance(sim, n)
        cpu = time.process_time() - start
        states += [State((k + 1) * sim.dt, tuple(r[:3]), tuple(r[3:])) for k, r in enumerate(xs.tolist())]
        return states, cpu
    step, append = sim.step, states.append
    start = time.process_time()
    for _ in range(n):
        append(step())
    return states, time.process_time() - start


# -- scipy ------------------------------------------------------------------------------------


class _GaveUp(Exception):
    pass


def scalar_rhs(scene: Scene) -> Callable[[Callable[[float], float]], Callable[[float, np.ndarray], list[float]]]:
    """y' = f(t, y) on y = (q, q'): the project's own `FingerSystem.rhs` (scalar), per torque piece."""
    rhs = scene.build_system().rhs

    def make(torque: Callable[[float], float]) -> Callable[[float, np.ndarray], list[float]]:
        return functools.partial(rhs, torque=torque)

    return make


def numpy_rhs(scene: Scene) -> Callable[[Callable[[float], float]], Callable[[float, np.ndarray], np.ndarray]]:
    """The same equations as a user would first write them: numpy arrays and a 5×5 `np.linalg.solve`."""
    system = scene.build_system()
    p = scene.params
    r = np.array([p.r1, p.r2, p.r3])
    forces = [e.force for e in system.elements]

    def make(torque: Callable[[float], float]) -> Callable[[float, np.ndarray], np.ndarray]:
        def rhs(t: float, y: np.ndarray) -> np.ndarray:
            q, v = y[:3], y[3:]
            m = np.array(system.mass_matrix(tuple(q)))
            u = q[0] - q[2] - system.alpha
            h = system._c * np.sin(u) * np.array([v[2] ** 2, 0.0, -v[0] ** 2])
            f = np.array([torque(t), 0.0, 0.0]) + sum(np.array(fn(t, tuple(q), tuple(v))) for fn in forces)
            s, c = np.sin(q), np.cos(q)
            jac = np.array([[-r[0] * s[0], r[1] * s[1], r[2] * s[2]], [r[0] * c[0], -r[1] * c[1], -r[2] * c[2]]])
            gamma = np.array([r[0] * c[0], -r[1] * c[1], -r[2] * c[2]]) @ v**2, np.array([r[0] * s[0], -r[1] * s[1], -r[2] * s[2]]) @ v**2
            kkt = np.zeros((5, 5))
            kkt[:3, :3], kkt[:3, 3:], kkt[3:, :3] = m, -jac.T, jac
            x = np.linalg.solve(kkt, np.concatenate([f - h, gamma]))
            return np.concatenate([v, x[:3]])

        return rhs

    return make


def run_scipy(
    scene: Scene, method: str, rtol: float, reference: Reference, *, spacing: float, repeats: int, rhs: str = "scalar"
) -> Run:
    """solve_ivp(method, rtol, atol = 1e-2·rtol) on the index-1 equations, output on the sample grid.

    Restarted at each torque switch, as `Simulator` and the reference are. rhs "scalar" is
    the project's `FingerSystem.rhs` (integrator against integrator on the same
    equations); "numpy" is the naive numpy right-hand side.
    """
    label = f"scipy {method}" + (" (numpy RHS)" if rhs == "numpy" else "")
    run = Run(scene.name, FAMILY_SCIPY, label, "rtol", rtol, scene.duration)
    if scene.mcp_limits is not None or scene.objects or scene.drive is not None:
        return _run_scipy_events(run, scene, method, rtol, reference, spacing=spacing, repeats=repeats)
    make = (scalar_rhs if rhs == "scalar" else numpy_rhs)(scene)
    profile = scene.torque
    edges = [0.0, *profile.breakpoints(0.0, scene.duration), scene.duration]
    grid = sample_times(scene.duration, spacing)
    q0, v0 = scene.initial_state()
    pieces = []
    for a, b in zip(edges, edges[1:]):
        inside = grid[(grid >= a - 1e-12) & (grid <= b + 1e-12)]
        pieces.append((a, b, make(profile.on_segment(a, b)), inside))
    count, counted = _counted()

    def solve_all(t_eval: bool) -> tuple[np.ndarray, np.ndarray, int]:
        count[0] = 0
        y = [*q0, *v0]
        ts, ys, steps = [], [], 0
        for a, b, fn, inside in pieces:
            # the piece's end is always evaluated, to carry the state on; off the grid it is dropped
            ends_on_grid = bool(inside.size) and abs(inside[-1] - b) < 1e-12
            wanted = (inside if ends_on_grid else np.append(inside, b)) if t_eval else None
            sol = solve_ivp(counted(fn), (a, b), y, method=method, rtol=rtol, atol=1e-2 * rtol, t_eval=wanted)
            if not sol.success:
                raise SimulationDiverged(sol.message)
            y = sol.y[:, -1]
            if t_eval:
                keep = slice(None) if ends_on_grid else slice(0, -1)
                ts.append(sol.t[keep])
                ys.append(sol.y[:, keep])
            else:
                steps += sol.t.size - 1
        if t_eval:
            t_all = np.concatenate(ts)
            y_all = np.concatenate(ys, axis=1)
            keep = np.concatenate([[True], np.diff(t_all) > 1e-12])  # a switch on the grid is sampled twice
            return t_all[keep], y_all[:, keep], count[0]
        return np.array([]), np.array([]), steps

    try:
        _, _, steps = solve_all(False)  # untimed: the step count (t_eval does not change the steps)
        (times, y, nfev), cpu, done = _timed(lambda: solve_all(True), repeats)  # type: ignore[misc]
    except _GaveUp:
        run.status, run.note = GAVE_UP, f"more than {MAX_SCIPY_EVALUATIONS:,} evaluations"
        return run
    except (SimulationDiverged, ZeroDivisionError, OverflowError, ValueError, np.linalg.LinAlgError) as exc:
        run.status, run.note = DIVERGED, f"{type(exc).__name__}: {exc}"[:160]
        return run
    run.cpu, run.repeats, run.steps, run.nfev = cpu, done, steps, nfev
    _fill_accuracy(run, scene, reference, times, y[:3].T, y[3:].T)
    return run


def _counted() -> tuple[list[int], Callable]:  # type: ignore[type-arg]
    """(counter, wrap): wrap(fn) counts fn's calls in counter[0] and gives the run up past MAX_SCIPY_EVALUATIONS."""
    count = [0]

    def wrap(fn):  # type: ignore[no-untyped-def]
        def wrapped(t, y):  # type: ignore[no-untyped-def]
            count[0] += 1
            if count[0] > MAX_SCIPY_EVALUATIONS:
                raise _GaveUp
            return fn(t, y)

        return wrapped

    return count, wrap


def _run_scipy_events(run: Run, scene: Scene, method: str, rtol: float, reference: Reference, *, spacing: float,
                      repeats: int) -> Run:
    """A scene with events (stops, contact, a drive's mesh modes): solve_ivp restarted at every located stop impact,
    contact onset and release and mode change (`reference.solve`, the bench's own piecewise solver), its dense
    output sampled on the grid."""
    if stick_slip.in_scene(scene):
        run.status, run.note = SKIPPED, "stick–slip friction's locked mode is not in the piecewise solve"
        return run
    grid = sample_times(scene.duration, spacing)
    count, wrap = _counted()

    def solve_all() -> tuple[np.ndarray, int, int]:
        count[0] = 0
        sol = solve(scene, method=method, rtol=rtol, wrap=wrap)
        return sol.states(grid), sol.steps, count[0]

    try:
        (y, steps, nfev), cpu, done = _timed(solve_all, repeats)  # type: ignore[misc]
    except _GaveUp:
        run.status, run.note = GAVE_UP, f"more than {MAX_SCIPY_EVALUATIONS:,} evaluations"
        return run
    except (SimulationDiverged, ZeroDivisionError, OverflowError, ValueError, np.linalg.LinAlgError) as exc:
        run.status, run.note = DIVERGED, f"{type(exc).__name__}: {exc}"[:160]
        return run
    run.cpu, run.repeats, run.steps, run.nfev = cpu, done, steps, nfev
    run.note = "restarted at every located event"
    _fill_accuracy(run, scene, reference, grid, y[:, :3], y[:, 3:])
    if run.ok and scene.objects:
        fill_grip(run, grid, grip_forces(scene, grid, y[:, :3], y[:, 3:]))
    return run


# -- MuJoCo -------------------------------------------------------------------------------


def mujoco_available() -> tuple[bool, str]:
    """(available, note): whether `mujoco` and the peer model import."""
    try:
        import mujoco  # noqa: F401

        from finger_sim.bench import mujoco_peer  # noqa: F401
    except ImportError as exc:
        return False, f"MuJoCo rows skipped: {exc} (install with `pip install .[bench]` or `pip install mujoco`)"
    return True, ""


@contextmanager
def _mujoco_warnings(sink: list[str]) -> Iterator[None]:
    """Collect MuJoCo's warnings in `sink` instead of stderr and MUJOCO_LOG.TXT in the cwd.

    A diverging run still raises (the peer checks MuJoCo's warning counters); the text
    goes into the run's note.
    """
    import mujoco

    previous = mujoco.get_mju_user_warning()
    mujoco.set_mju_user_warning(sink.append)
    try:
        yield
    finally:
        mujoco.set_mju_user_warning(previous)


def run_mujoco_peer(
    scene: Scene, integrator: str, timestep: float, setting: str, reference: Reference, *, spacing: float, repeats: int
) -> Run:
    """The MJCF peer (finger_sim.bench.mujoco_peer) with MuJoCo's `integrator` at `timestep`.

    setting "default": MuJoCo's default solref/solimp on the loop-closing connect (and on the
    contacts of a scene with objects); "tight": the peer's `tight_equality(timestep)` (the
    stiffest stable loop) and `tight_contact(timestep)`.
    """
    label = f"MuJoCo {integrator} {setting}"
    run = Run(scene.name, FAMILY_MUJOCO, label, "timestep", timestep, scene.duration)
    available, note = mujoco_available()
    if not available:
        run.status, run.note = SKIPPED, note
        return run
    from finger_sim.bench import mujoco_peer as mp

    if scene.mcp_limits is not None or any(scene.gravity) or any(scene.tip_force):
        run.status, run.note = SKIPPED, "the MJCF peer models neither joint stops, gravity nor tip forces"
        return run
    equality = mp.DEFAULT_EQUALITY if setting == "default" else mp.tight_equality(timestep)
    contact = mp.DEFAULT_CONTACT if setting == "default" else mp.tight_contact(timestep)
    times = sample_times(scene.duration, max(spacing, timestep))
    q0, v0 = scene.initial_state()
    plain = scene.theta1 == 0.0 and scene.theta1_dot == 0.0 and scene.damping == 0.0 and not scene.objects

    def once() -> tuple[np.ndarray, np.ndarray | None, float, int, np.ndarray | None]:
        if plain:  # the peer's own runner
            res = mp.run_mujoco(
                scene.params, torque=scene.torque, t_end=scene.duration, timestep=timestep, integrator=integrator,
                equality=equality, spring_stiffness=scene.spring_stiffness, sample_times=times,
            )
            return res.theta, None, res.cpu_time, res.n_steps, None
        return _mujoco_general(mp, scene, integrator, timestep, equality, contact, times, q0, v0)

    warnings: list[str] = []
    try:
        cpus = []
        first = None
        with _mujoco_warnings(warnings):
            count = repeats
            while len(cpus) < count:
                out = once()
                cpus.append(out[2])
                if len(cpus) == 1:
                    first, count = out, repeats_after(out[2], repeats)
    except (SimulationDiverged, FingerSimError, ValueError) as exc:
        said = f" (MuJoCo: {warnings[0]})" if warnings else ""
        run.status, run.note = DIVERGED, (str(exc).split(":", 1)[-1].strip() + said)[:200]
        return run
    assert first is not None
    theta, theta_dot, _, n_steps, grip = first
    run.cpu, run.repeats, run.steps = statistics.median(cpus), len(cpus), n_steps
    _fill_accuracy(run, scene, reference, times, theta, theta_dot)
    if run.ok and grip is not None:
        fill_grip(run, times, grip)
    return run


def _mujoco_general(mp, scene, integrator, timestep, equality, contact, times, q0, v0):  # type: ignore[no-untyped-def]
    """run_mujoco's loop for what it does not take (an initial rate, joint damping, objects): same timing, same checks.

    Joint damping c on MuJoCo's hinges (mcp, coupler, pip) is the spec's Rayleigh damping
    R = ½ c (θ1'² + θ2'² + β'²) exactly, since the pip hinge turns by β. With objects, the
    grip force (`MujocoFinger.grip_force`) is read at each sample, outside the timing; else None.
    """
    import mujoco

    finger = mp.MujocoFinger(
        scene.params, timestep=timestep, integrator=integrator, equality=equality, spring_stiffness=scene.spring_stiffness,
        objects=scene.objects, radii=scene.phalanx_radius, contact=contact, friction=scene.contact.friction,
    )
    model = finger.model
    model.dof_damping[finger.dof_index] = scene.damping
    data = finger.make_data(q0, v0)
    n_steps = round(scene.duration / timestep)
    samples = np.rint(times / timestep).astype(int)
    offset = mp.TORQUE_TIME_IN_STEP[integrator]
    taus = [float(scene.torque((k + offset) * timestep)) for k in range(n_steps)]
    chunks = [taus[a:b] for a, b in zip([0, *samples[1:-1].tolist()], samples[1:].tolist())]
    qpos = np.empty((samples.size, model.nq))
    qvel = np.empty((samples.size, model.nv))
    qpos[0], qvel[0] = data.qpos, data.qvel
    grip = np.zeros(samples.size) if scene.objects else None
    ctrl, motor, step = data.ctrl, finger.motor_id, mujoco.mj_step
    cpu = 0.0
    for j, chunk in enumerate(chunks, start=1):
        start = time.process_time()
        for tau in chunk:
            ctrl[motor] = tau
            step(model, data)
        qpos[j], qvel[j] = data.qpos, data.qvel
        cpu += time.process_time() - start
        if grip is not None:
            grip[j] = finger.grip_force(data)
    theta = finger.to_paper(qpos)
    w = qvel[:, finger.dof_index]
    theta_dot = np.column_stack([w[:, 0], w[:, 1], w[:, 0] + w[:, 2]])
    loop = finger.loop_violation(theta) if np.all(np.isfinite(theta)) else np.array([math.inf])
    bad = data.warning[mujoco.mjtWarning.mjWARN_BADQACC]
    if bad.number > 0 or not np.all(np.isfinite(theta)) or loop.max() > mp.DIVERGED_LOOP_FRACTION * scene.params.r3:
        raise SimulationDiverged(
            f"MuJoCo {integrator}: {bad.number} bad-acceleration reset(s), largest loop violation {loop.max():.3g} m"
        )
    return theta, theta_dot, cpu, n_steps, grip
