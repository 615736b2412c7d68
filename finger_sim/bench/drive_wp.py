"""Work-precision of the shipped drive scenes (spec §8): `simulate` (auto) against scipy's best at equal error.

    python -m finger_sim.bench.drive_wp [--scenes drive_grasp ...] [--repeats 3] [--rtols 1e-6 1e-8 ...]

The scipy row is what a solve_ivp script that handles the drive's hybrid modes costs
(test/hybrid_reference.py's scheme): one smooth piece per mesh mode, each ended by a terminal event
on a guard and restarted under the new mode —
- turn (direction·θ1' < 0): the holding test decides, stuck or rolling on (`stepping._turn`);
- flank (τ_g against the flank): drive ↔ back;
- the current limit's kink and every contact onset and release (`reference._kink_events`): restart only;
- stuck: q held, q' = 0, until the holding margin's root (`stepping._release_time`).
It integrates the same equations as every method under test (`DrivenSystem.rhs` in the mode), so the
rows differ in the integration only. The reference is this solve by DOP853 at rtol 1e-13, checked by
Radau at rtol 1e-12 (their largest θ difference on the 1 ms grid is the reference floor).

The error of a run is max |θ − θ_ref| over the 1 ms grid (rad); its cost the median process time of
`--repeats` whole runs (s). scipy's cost at auto's error is log-log interpolated on its Pareto front
(`analysis.cost_at`), as the bench's goal table does.
"""

from __future__ import annotations

import argparse
import math
import statistics
import time
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from scipy.integrate import solve_ivp

from finger_sim.actuators import stepping
from finger_sim.actuators.drive import BACK, DRIVE, STUCK, ZERO, DrivenSystem
from finger_sim.bench.analysis import cost_at
from finger_sim.bench.plan import SPACING, scene_file
from finger_sim.bench.reference import ATOL_PER_RTOL, TIME_EPS, _kink_events
from finger_sim.errors import SimulationDiverged
from finger_sim.scene import Scene, load_scene
from finger_sim.simulate import simulate

#: The shipped drive scenes (config/).
DRIVE_SCENES = ("drive_grasp", "drive_grasp_backdrivable")
#: scipy's methods and rtol grid (the bench's explicit and implicit pair, and LSODA).
METHODS = ("DOP853", "RK45", "LSODA", "Radau")
RTOLS = (1e-4, 1e-6, 1e-8, 1e-10)
#: The reference's and its check's tolerances (DOP853 at its tightest, Radau one decade looser).
REFERENCE_RTOL, CHECK_RTOL = 1e-13, 1e-12
#: After a located event the solve steps this far (s) without events, so that the guard just crossed is
#: not found again at once at the restart (test/effects/test_drive.py's reference does the same).
NUDGE = 1e-9
#: Most pieces (mode changes, kinks, contact events) before the solve gives up.
MAX_PIECES = 100_000


@dataclass(frozen=True)
class Row:
    """One whole run: its label, median process time (s) and error (max |θ − θ_ref| on the grid, rad)."""

    label: str
    cpu: float
    error: float


def _guard_events(system: DrivenSystem, torque: Callable[[float], float]) -> list[Callable[[float, np.ndarray], float]]:
    """Terminal events of the rolling mesh's guards under the mode set now: turn, flank (one-sided, crossing
    downwards) and the current limit (both ways)."""
    drive = system.drive
    s, mode = drive.direction, drive.mode

    def turn(t: float, y: np.ndarray) -> float:
        return s * y[3]

    def flank(t: float, y: np.ndarray) -> float:
        tau_g = system.mesh(t, (y[0], y[1], y[2]), (y[3], y[4], y[5]), torque(t), mode)[0]
        return (s if mode == DRIVE else -s) * tau_g

    def limit(t: float, y: np.ndarray) -> float:
        return drive.params.current_limit - abs(drive.unclamped_current(torque(t), y[3]))

    turn.terminal, turn.direction = True, -1.0  # type: ignore[attr-defined]
    flank.terminal, flank.direction = True, -1.0  # type: ignore[attr-defined]
    limit.terminal = True  # type: ignore[attr-defined]
    return [limit] if drive.params.ideal else [turn, flank, limit]


def solve_drive(scene: Scene, *, method: str, rtol: float, times: np.ndarray) -> np.ndarray:
    """θ (len(times), 3) of a drive scene by scipy `method` at `rtol` (atol = ATOL_PER_RTOL·rtol), piece by
    piece through the mesh's modes (module docstring). ValueError for a scene this script does not cover
    (joint stops, L > 0)."""
    if scene.mcp_limits is not None or scene.drive is None or scene.drive.inductance > 0.0:
        raise ValueError(f"{scene.name}: drive_wp covers drive scenes with L = 0 and without joint stops")
    system: DrivenSystem = scene.build_system()  # type: ignore[assignment]
    drive = system.drive
    profile = scene.torque
    q, v = scene.initial_state()
    cuts = sorted(profile.breakpoints(0.0, scene.duration)) + [scene.duration]
    if v[0] == 0.0:
        v = stepping._turn(system, 0.0, q, profile(0.0))
    else:
        stepping._roll(system, 0.0, q, v, profile(0.0), math.copysign(1.0, v[0]))
    out = np.full((times.size, 3), np.nan)
    t, y = 0.0, np.array([*q, *v])
    for _ in range(MAX_PIECES):
        if t >= scene.duration - TIME_EPS:
            break
        end = next(b for b in cuts if b > t + TIME_EPS)
        u = profile.on_segment(t, end)
        if drive.mode == STUCK:
            qs = (y[0], y[1], y[2])
            release = stepping._release_time(system, t, end, qs, u)
            held = (times >= t - TIME_EPS) & (times <= (end if release is None else release) + TIME_EPS)
            out[held] = qs
            if release is None:
                t = end
                continue
            t = release
            stepping._roll(system, t, qs, ZERO, u(t), stepping._break_direction(system, t, qs, u(t)))
            continue
        rhs = lambda s, z: system.rhs(s, z, u)  # noqa: E731  (the mode is read at each call)
        guards = _guard_events(system, u)
        events = guards + _kink_events(system, t, y)
        sol = solve_ivp(rhs, (t, end), y, method=method, rtol=rtol, atol=ATOL_PER_RTOL * rtol, dense_output=True,
                        events=events)
        if not sol.success:
            raise SimulationDiverged(f"drive_wp {method} on {scene.name}: {sol.message} at t = {sol.t[-1]:.6f} s")
        t1 = float(sol.t[-1])
        inside = (times >= t - TIME_EPS) & (times <= t1 + TIME_EPS)
        out[inside] = sol.sol(np.clip(times[inside], t, t1))[:3].T
        t, y = t1, sol.y[:, -1].copy()
        if sol.status != 1:
            continue
        qs, us = (y[0], y[1], y[2]), u(t)
        if len(guards) == 3 and sol.t_events[0].size:  # the turn: stick, or roll on
            y[3:] = stepping._turn(system, t, qs, us)
            continue
        if len(guards) == 3 and sol.t_events[1].size:
            drive.mode = BACK if drive.mode == DRIVE else DRIVE
        # a kink (limit, contact) or a flank change: step just past it, then restart
        nxt = min(end, t + NUDGE)
        y = solve_ivp(rhs, (t, nxt), y, method=method, rtol=rtol, atol=ATOL_PER_RTOL * rtol).y[:, -1]
        t = nxt
    else:
        raise SimulationDiverged(f"drive_wp {method} on {scene.name}: more than {MAX_PIECES} pieces")
    return out


def median_cpu(fn: Callable[[], object], repeats: int) -> tuple[object, float]:
    """(first result, median process time s) of `repeats` calls."""
    result, cpus = None, []
    for k in range(repeats):
        start = time.process_time()
        out = fn()
        cpus.append(time.process_time() - start)
        result = out if k == 0 else result
    return result, statistics.median(cpus)


def measure(name: str, *, repeats: int, rtols: tuple[float, ...]) -> tuple[float, list[Row], Row]:
    """(reference floor rad, scipy rows, auto's row) of one drive scene."""
    scene = load_scene(scene_file(name))
    times = np.arange(scene.step_count + 1) * SPACING
    ref = solve_drive(scene, method="DOP853", rtol=REFERENCE_RTOL, times=times)
    floor = float(np.max(np.abs(ref - solve_drive(scene, method="Radau", rtol=CHECK_RTOL, times=times))))
    simulate(scene)  # the numba cache loaded once, as every later run finds it
    rows = []
    for method in METHODS:
        for rtol in rtols:
            theta, cpu = median_cpu(lambda m=method, r=rtol: solve_drive(scene, method=m, rtol=r, times=times), repeats)
            rows.append(Row(f"scipy {method} rtol={rtol:g}", cpu, float(np.max(np.abs(theta - ref)))))
    traj, cpu = median_cpu(lambda: simulate(scene), repeats)
    auto = Row(f"simulate auto ({traj.method})", cpu, float(np.max(np.abs(traj.q - ref))))  # type: ignore[attr-defined]
    return floor, rows, auto


def scipy_best_at(rows: list[Row], target: float) -> tuple[float, str]:
    """(CPU s, method) of scipy's cheapest method at error ≤ target (interpolated on its own front)."""
    best = (math.inf, "none")
    for method in METHODS:
        front: list[tuple[float, float]] = []
        for cpu, err in sorted((r.cpu, r.error) for r in rows if r.label.split()[1] == method and math.isfinite(r.error)):
            if not front or err < front[-1][1]:
                front.append((cpu, err))
        best = min(best, (cost_at(front, target), method))
    return best


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scenes", nargs="+", choices=DRIVE_SCENES, default=list(DRIVE_SCENES))
    parser.add_argument("--repeats", type=int, default=3, help="whole runs per row (median)")
    parser.add_argument("--rtols", type=float, nargs="+", default=list(RTOLS), help="scipy's rtol grid")
    args = parser.parse_args(argv)
    for name in args.scenes:
        floor, rows, auto = measure(name, repeats=args.repeats, rtols=tuple(args.rtols))
        cost, method = scipy_best_at(rows, auto.error)
        print(f"## {name} (reference floor {floor:.1e} rad)\n\n| run | CPU ms, median | error rad |\n|---|---|---|")
        for row in [*rows, auto]:
            print(f"| {row.label} | {row.cpu * 1e3:.1f} | {row.error:.2e} |")
        print(f"\nat auto's error {auto.error:.2e} rad: scipy's best {method} {cost * 1e3:.1f} ms, auto "
              f"{auto.cpu * 1e3:.1f} ms: **{cost / auto.cpu:.1f}×**\n", flush=True)


if __name__ == "__main__":
    main()
