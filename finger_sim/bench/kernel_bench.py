"""Side-by-side costs of the compiled and the Python path, against scipy and against MuJoCo.

    python -m finger_sim.bench.kernel_bench [SCENE.yaml]     # kernel table (docs/kernel.md)
    python -m finger_sim.bench.kernel_bench wp               # work-precision against scipy (docs/speed.md)
    python -m finger_sim.bench.kernel_bench e2e              # whole processes against MuJoCo (docs/speed.md)

Prints medians of REPEATS runs in one process (both paths interleaved, so machine load
hits both alike): µs per step in `Simulator.step` and in `simulate`'s whole-run loop for the
fixed-step methods, each one's error against a tight scipy solve, and DOP853 (ours, output
on the 1 ms grid) against scipy's DOP853 with `t_eval` on the same grid at equal rtol.
"""

from __future__ import annotations

import resource
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
from scipy.integrate import solve_ivp

from finger_sim.integrators.dop853 import DormandPrince853
from finger_sim.kernel.runner import advance
from finger_sim.scene import load_scene
from finger_sim.errors import StabilityError
from finger_sim.simulate import Simulator, Trajectory, simulate

REPEATS = 7
METHODS = ("rk4", "rk6", "dop8")  # the fixed-step methods timed
TOLERANCES = (1e-8, 1e-10, 1e-12)
#: The reference's tolerances: its error is far below every figure printed.
REFERENCE_RTOL, REFERENCE_ATOL = 1e-13, 1e-15


def _median(times: list[float]) -> float:
    return statistics.median(times)


def _step_loop(scene, kernel: str) -> float:
    sim = Simulator(scene, kernel=kernel)
    start = time.perf_counter()
    for _ in range(scene.step_count):
        sim.step()
    return (time.perf_counter() - start) / scene.step_count


def kernel_table(path: Path) -> None:
    """µs per step of both kernels per fixed-step method, and our DOP853 against scipy's at equal rtol."""
    base = load_scene(path)
    system = base.build_system()
    q0, v0 = base.initial_state()
    grid = np.arange(base.step_count + 1) * base.dt
    ref = solve_ivp(lambda s, y: system.rhs(s, y, base.torque), (0.0, grid[-1]), [*q0, *v0], method="DOP853",
                    rtol=REFERENCE_RTOL, atol=REFERENCE_ATOL, t_eval=grid).y[:3].T
    print(f"{path.name}: {base.step_count} steps at dt = {base.dt:g} s; µs per step, median of {REPEATS}")
    print("method  kernel     Simulator.step  simulate()  max error (rad)")
    for method in METHODS:
        scene = base.with_overrides(method=method)
        for kernel in ("python", "compiled"):
            simulate(scene, kernel=kernel)  # load the compiled code first
        rows: dict[str, tuple[list[float], list[float]]] = {"python": ([], []), "compiled": ([], [])}
        for _ in range(REPEATS):
            for kernel, (steps, runs) in rows.items():
                steps.append(_step_loop(scene, kernel))
                runs.append(simulate(scene, kernel=kernel).wall_time / scene.step_count)
        for kernel, (steps, runs) in rows.items():
            err = float(np.abs(simulate(scene, kernel=kernel).q - ref).max())
            print(f"{method:7s} {kernel:9s} {_median(steps) * 1e6:14.2f} {_median(runs) * 1e6:11.2f}  {err:.2e}")
    print("\nadaptive at equal rtol (atol = rtol/100), output at every step; wall ms per run, median")
    print("rtol     ours: ms   error      scipy DOP853: ms   error      speed-up")
    for rtol in TOLERANCES:
        ours, theirs, e_ours, e_theirs = [], [], 0.0, 0.0
        for _ in range(REPEATS):
            sim = Simulator(base.with_overrides(method="dop853"))
            sim.integrator = DormandPrince853(sim.system, rtol=rtol, atol=rtol / 100)
            start = time.perf_counter()
            xs = advance(sim, base.step_count)  # what simulate() runs
            ours.append(time.perf_counter() - start)
            e_ours = float(np.abs(xs[:, :3] - ref[1:]).max())
            start = time.perf_counter()
            sol = solve_ivp(lambda s, y: system.rhs(s, y, base.torque), (0.0, grid[-1]), [*q0, *v0],
                            method="DOP853", rtol=rtol, atol=rtol / 100, t_eval=grid)
            theirs.append(time.perf_counter() - start)
            e_theirs = float(np.abs(sol.y[:3].T - ref).max())
        a, b = _median(ours), _median(theirs)
        print(f"{rtol:6.0e} {a * 1e3:10.2f}   {e_ours:.2e}   {b * 1e3:16.2f}   {e_theirs:.2e}   {b / a:6.1f}×")



# -- end to end: `finger-sim simulate --csv` against a MuJoCo RK4 loop writing the same CSV ---------
#: MuJoCo's step for the end-to-end peer, s: the scene's 1 kHz, as the node and `simulate` step.
PEER_TIMESTEP = 1e-3


def mujoco_csv(scene_path: Path, t_end: float, path: Path) -> None:
    """The peer process: the MJCF finger (bench.mujoco_peer, its stiffest stable loop constraint) stepped
    with RK4 at 1 ms in a tight Python `mj_step` loop, τ((k + ½) dt) held per step, then the same
    columns as `finger-sim simulate --csv` (θ, θ', energy, |Φ|) written block-wise with the same writer."""
    import mujoco

    from finger_sim.bench import mujoco_peer as mp
    from finger_sim.simulate import state_columns
    from finger_sim.streaming import VALUE_FORMAT

    scene = load_scene(scene_path).with_overrides(duration=t_end)
    finger = mp.MujocoFinger(scene.params, timestep=PEER_TIMESTEP, integrator="RK4",
                             equality=mp.tight_equality(PEER_TIMESTEP), spring_stiffness=scene.spring_stiffness)
    model, n = finger.model, scene.step_count
    data = finger.make_data(*scene.initial_state())
    qpos, qvel = np.empty((n + 1, model.nq)), np.empty((n + 1, model.nv))
    qpos[0], qvel[0] = data.qpos, data.qvel
    ctrl, motor, step, torque = data.ctrl, finger.motor_id, mujoco.mj_step, scene.torque
    for k in range(n):
        ctrl[motor] = torque((k + 0.5) * PEER_TIMESTEP)
        step(model, data)
        qpos[k + 1], qvel[k + 1] = data.qpos, data.qvel
    theta = finger.to_paper(qpos)
    w = qvel[:, finger.dof_index]
    x = np.column_stack([theta, w[:, 0], w[:, 1], w[:, 0] + w[:, 2]])
    t = np.arange(n + 1) * PEER_TIMESTEP
    system = scene.build_system()
    row = ",".join([VALUE_FORMAT] * 9) + "\n"
    with open(path, "w") as file:
        file.write(Trajectory.CSV_HEADER + "\n")
        for a in range(0, n + 1, 200):
            energy, residual, _ = state_columns(system, t[a: a + 200], x[a: a + 200])
            rows = np.column_stack([t[a: a + 200], x[a: a + 200], energy, residual]).tolist()
            file.writelines(map(row.__mod__, map(tuple, rows)))


def _child_cpu() -> float:
    usage = resource.getrusage(resource.RUSAGE_CHILDREN)
    return usage.ru_utime + usage.ru_stime


def _process(command: list[str]) -> tuple[float, float]:
    """(wall s, CPU s) of one child process."""
    cpu, start = _child_cpu(), time.perf_counter()
    subprocess.run(command, check=True, stdout=subprocess.DEVNULL)
    return time.perf_counter() - start, _child_cpu() - cpu


def end_to_end(scene_path: Path, durations: tuple[float, ...] = (30.0, 300.0), repeats: int = 5) -> None:
    """Whole-process wall and CPU, medians of `repeats` alternating runs, per duration; the slope
    between the two durations is the cost per step; accuracy of each CSV against a tight solve."""
    cli = str(Path(sys.executable).with_name("finger-sim"))
    out = Path(tempfile.mkdtemp())
    commands = {
        "finger-sim simulate": lambda d, p: [cli, "simulate", str(scene_path), "--t-end", f"{d:g}", "--csv", str(p)],
        "MuJoCo RK4 loop": lambda d, p: [sys.executable, "-m", "finger_sim.bench.kernel_bench", "mujoco-csv",
                                         str(scene_path), f"{d:g}", str(p)],
    }
    medians: dict[tuple[str, float], tuple[float, float]] = {}
    for d in durations:
        runs: dict[str, list[tuple[float, float]]] = {name: [] for name in commands}
        for _ in range(repeats):
            for name, make in commands.items():
                runs[name].append(_process(make(d, out / f"{name[:4]}_{d:g}.csv")))
        for name, got in runs.items():
            medians[name, d] = (statistics.median(w for w, _ in got), statistics.median(c for _, c in got))
    print(f"{scene_path.name}: whole process, medians of {repeats} alternating runs (wall s / CPU s)")
    short, long = durations[0], durations[-1]
    steps = round((long - short) / PEER_TIMESTEP)
    for name in commands:
        cells = "  ".join(f"t_end {d:g}: {medians[name, d][0]:.2f} / {medians[name, d][1]:.2f}" for d in durations)
        slope = (medians[name, long][1] - medians[name, short][1]) / steps * 1e6
        err = _csv_error(scene_path, out / f"{name[:4]}_{short:g}.csv", ACCURACY_WINDOW)
        print(f"  {name:20s} {cells}  CPU per step {slope:.2f} µs  "
              f"max|θ error| over {ACCURACY_WINDOW:g} s {err:.2e} rad")


#: The accuracy of the end-to-end CSVs is measured over the paper's run (a tight reference over
#: 30 s of an ever-growing ramp torque, spinning the finger at hundreds of rad/s, is not tight).
ACCURACY_WINDOW = 0.3


def _csv_error(scene_path: Path, csv: Path, window: float) -> float:
    data = np.loadtxt(csv, delimiter=",", skiprows=1, max_rows=round(window / PEER_TIMESTEP) + 1)
    scene = load_scene(scene_path).with_overrides(duration=window)
    return float(np.abs(data[:, 1:4] - _reference(scene)).max())


def _reference(scene) -> np.ndarray:  # type: ignore[no-untyped-def]
    """θ on the 1 ms grid of a tight scipy DOP853 solve of the project's right-hand side."""
    system = scene.build_system()
    q0, v0 = scene.initial_state()
    grid = np.arange(scene.step_count + 1) * scene.dt
    return solve_ivp(lambda s, y: system.rhs(s, y, scene.torque), (0.0, grid[-1]), [*q0, *v0], method="DOP853",
                     rtol=REFERENCE_RTOL, atol=REFERENCE_ATOL, t_eval=grid).y[:3].T


# -- work-precision against scipy at equal error, output at every 1 ms --------------------------------
PEER_SCENES = ("paper_flexion", "toggle_passage", "free_swing")
SCIPY_METHODS = ("DOP853", "Radau", "LSODA")
SCIPY_RTOLS = (1e-6, 1e-8, 1e-10, 1e-12)
OUR_RTOLS = (1e-6, 1e-8, 1e-10, 1e-12)
WP_REPEATS = 3


def _cpu(fn) -> tuple[float, object]:  # type: ignore[no-untyped-def]
    """Median CPU s of WP_REPEATS calls of fn, and its result."""
    times, result = [], None
    for _ in range(WP_REPEATS):
        start = time.process_time()
        result = fn()
        times.append(time.process_time() - start)
    return statistics.median(times), result


def work_precision(config: Path) -> None:
    """Each of ours (dop853 at OUR_RTOLS, whole-run path; rk4, rk6, dop8 at 1 ms) against the
    cheapest scipy run (DOP853, Radau, LSODA at SCIPY_RTOLS, atol = rtol/100, t_eval on the
    1 ms grid) whose error is at most ours: the speed-up at equal error."""
    print("| scene | ours | error (rad) | CPU ms | scipy's cheapest at ≤ that error | error (rad) | CPU ms "
          "| speed-up |")
    print("|---|---|---|---|---|---|---|---|")
    for name in PEER_SCENES:
        scene = load_scene(config / f"{name}.yaml")
        ref = _reference(scene)
        system = scene.build_system()
        q0, v0 = scene.initial_state()
        grid = np.arange(scene.step_count + 1) * scene.dt
        theirs = []
        for method in SCIPY_METHODS:
            for rtol in SCIPY_RTOLS:
                def solve(method=method, rtol=rtol):  # type: ignore[no-untyped-def]
                    return solve_ivp(lambda s, y: system.rhs(s, y, scene.torque), (0.0, grid[-1]), [*q0, *v0],
                                     method=method, rtol=rtol, atol=rtol / 100, t_eval=grid)
                cpu, sol = _cpu(solve)
                if sol.success:  # type: ignore[attr-defined]
                    err = float(np.abs(sol.y[:3].T - ref).max())  # type: ignore[attr-defined]
                    theirs.append((err, cpu, f"{method} rtol {rtol:g}"))
        ours = []
        for rtol in OUR_RTOLS:
            def run(rtol=rtol):  # type: ignore[no-untyped-def]
                sim = Simulator(scene.with_overrides(method="dop853"))
                sim.integrator = DormandPrince853(sim.system, rtol=rtol, atol=rtol / 100)
                return advance(sim, scene.step_count)
            cpu, xs = _cpu(run)
            ours.append((float(np.abs(xs[:, :3] - ref[1:]).max()), cpu, f"dop853 rtol {rtol:g}"))  # type: ignore[index]
        for method in METHODS:
            sc = scene.with_overrides(method=method)
            try:
                cpu, traj = _cpu(lambda sc=sc: simulate(sc, kernel="compiled"))
            except StabilityError:
                continue
            ours.append((float(np.abs(traj.q - ref).max()), cpu, f"{method} dt 1 ms"))  # type: ignore[attr-defined]
        for err, cpu, label in ours:
            match = min((t for t in theirs if t[0] <= err), key=lambda t: t[1], default=None)
            if match is None:
                print(f"| {name} | {label} | {err:.1e} | {cpu * 1e3:.2f} | none reaches it | | | |")
            else:
                print(f"| {name} | {label} | {err:.1e} | {cpu * 1e3:.2f} | {match[2]} | {match[0]:.1e} | "
                      f"{match[1] * 1e3:.1f} | {match[1] / cpu:.0f}× |")


def main(argv: list[str] | None = None) -> int:
    """`[SCENE.yaml]`: the kernel table; `wp [CONFIG]`: against scipy at equal error; `e2e [SCENE.yaml]`:
    whole processes against MuJoCo; `mujoco-csv SCENE T_END CSV`: the MuJoCo peer process itself."""
    args = sys.argv[1:] if argv is None else argv
    config = Path(__file__).resolve().parents[2] / "config"
    if args[:1] == ["mujoco-csv"]:
        mujoco_csv(Path(args[1]), float(args[2]), Path(args[3]))
    elif args[:1] == ["wp"]:
        work_precision(Path(args[1]) if len(args) > 1 else config)
    elif args[:1] == ["e2e"]:
        end_to_end(Path(args[1]) if len(args) > 1 else config / "paper_flexion.yaml")
    else:
        kernel_table(Path(args[0]) if args else config / "paper_flexion.yaml")
    return 0

if __name__ == "__main__":
    raise SystemExit(main())
