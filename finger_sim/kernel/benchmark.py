"""Side-by-side costs of the compiled and the Python path, and of our DOP853 against scipy's.

    python -m finger_sim.kernel.benchmark [SCENE.yaml]

Prints medians of REPEATS runs in one process (both paths interleaved, so machine load
hits both alike): µs per step in `Simulator.step` and in `simulate`'s whole-run loop for the
fixed-step methods, each one's error against a tight scipy solve, and DOP853 (ours, output
on the 1 ms grid) against scipy's DOP853 with `t_eval` on the same grid at equal rtol.
"""

from __future__ import annotations

import statistics
import sys
import time
from pathlib import Path

import numpy as np
from scipy.integrate import solve_ivp

from finger_sim.integrators.dop853 import DormandPrince853
from finger_sim.kernel.runner import advance
from finger_sim.scene import load_scene
from finger_sim.simulate import Simulator, simulate

REPEATS = 7
METHODS = ("rk4", "rk6", "dop8")
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


def main(argv: list[str] | None = None) -> int:
    args = sys.argv[1:] if argv is None else argv
    path = Path(args[0]) if args else Path(__file__).resolve().parents[2] / "config" / "paper_flexion.yaml"
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
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
