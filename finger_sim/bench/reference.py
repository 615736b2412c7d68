"""Reference solutions of the bench scenes: scipy at its tightest tolerance, checked by a second method.

A reference integrates the same index-1 equations as every method under test
(`FingerSystem.rhs`), one smooth piece at a time: the solver restarts at each torque switch
(`Profile.breakpoints`) and at each joint-stop impact (located as a solve_ivp event, then
v⁺ = −e v⁻, or rest on the stop while the free acceleration pushes into it and release
where it stops pushing — the rules `finger_sim.simulate.Simulator` applies). Each piece
keeps scipy's dense output, so the reference is evaluated at any sample time.

The check: the same pieces by a second, independent method: scipy's Radau IIA (implicit,
order 5) for smooth scenes, LSODA (Adams/BDF) for stiff ones, where scipy's Radau at a
tight tolerance needs tens of millions of evaluations. Their largest difference on the
sample grid bounds the reference's own error; errors of the methods under test below
about that bound are at the reference floor and are shown as such.

A scene with objects (contact, spec §7) has a force that is not smooth at contact onset and
release (F_n ∝ δ^e). Its reference is the `adaptive` method (scipy DOP853 at rtol 1e-12)
stepped through `finger_sim.simulate.Simulator`, which locates every onset and release inside
the step and restarts the solver there, tabulated on the sample grid (`GridSolution`). Its
check is the piecewise solve above (Radau, LSODA when stiff), which locates each onset and
release as a solve_ivp event on the contact element's gaps and restarts there, as it does at a
stop (test/hybrid_reference.py's scheme): a second method that shares nothing with the first
but the right-hand side and the gap functions. The same `solve` is the bench's scipy row on a
scene with events (`runners.run_scipy`): what a solve_ivp script that handles the events costs.
A drive scene (spec §8) is solved the same way through the mesh's modes (`solve_drive`): one piece per mode,
ended by a terminal event on the turn, the flank, the current limit and every contact onset and release, the
stuck hold by the holding margin's root. Its reference is that solve by DOP853 at REFERENCE_RTOL, its check the
same by Radau.
Where the check still cannot follow the scene (a check difference above MAX_CHECK_DIFFERENCE) it
is reported as such and no reference floor is claimed (`Reference.floor` is NaN); that scene's
reference is then checked only by the tests' independent one (test/hybrid_reference.py,
test/core/test_rest_is_step_independent.py).
"""

from __future__ import annotations

import functools
import math
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from scipy.integrate import solve_ivp
from scipy.optimize import brentq

from finger_sim.actuators import stepping
from finger_sim.actuators.drive import BACK, DRIVE, STUCK, DrivenSystem
from finger_sim.errors import SimulationDiverged
from finger_sim.integrators.adaptive import REFERENCE_RTOL as ADAPTIVE_RTOL
from finger_sim.scene import Scene
from finger_sim.stability import fastest_mode
from finger_sim import kinematics

#: Tolerance of the reference, DOP853 (the `adaptive` method's scheme): scipy warns below
#: rtol = 100·eps ≈ 2.2e-14.
REFERENCE_RTOL = 1e-13
#: On a stiff scene DOP853 at 1e-13 sits at its stability boundary rejecting steps (1e6
#: evaluations, 10 s on stiff_spring); at 1e-11 it takes 1e4 and agrees with LSODA at
#: 1e-12 to 5e-13 rad, so this is the tightest tolerance that is practical there.
STIFF_REFERENCE_RTOL = 1e-11
#: Absolute tolerance per unit rtol: angles are O(1) rad and rates O(1-10) rad/s.
ATOL_PER_RTOL = 1e-2
#: The checking method's tolerance (full run / --quick).
CHECK_RTOL = 1e-12
CHECK_RTOL_QUICK = 1e-10
#: A scene whose fastest mode has |s|·duration above this is stiff for an explicit
#: reference (DOP853 needs at least ~|s|·duration / 3 steps at its stability limit).
STIFF_REFERENCE = 1e3
#: While resting on a stop, the free acceleration is probed at this many times per piece
#: to find where it stops pushing into the stop (then located by brentq): the release.
CONTACT_PROBES = 17
#: A check further from the reference than this (rad, 100× auto's default promise) is not a bound on the
#: reference's error: it follows another path (grasp_release's 86 impacts and rests, 4.7 rad apart
#: before the check located contact events). No floor is claimed there.
MAX_CHECK_DIFFERENCE = 1e-4
#: Times closer than this (s) to a piece's end count as on it.
TIME_EPS = 1e-12
#: A contact gap this close to zero (m) counts as on it when choosing its side at a restart: the side is then
#: the one the gap moves to (its rate), so the event just located is not found again at the restart.
ON_GAP = 1e-13
#: Most restarts at contact onsets and releases before the solve gives up (a chattering contact).
MAX_RESTARTS = 100_000
#: On a drive scene, after a located event the solve steps this far (s) without events, so that the guard just
#: crossed is not found again at once at the restart (test/effects/test_drive.py's reference does the same).
NUDGE = 1e-9

ZERO = (0.0, 0.0, 0.0)


@dataclass(frozen=True)
class _Piece:
    """One smooth piece [t0, t1]: dense scipy output, or a state held on a stop when `sol` is None."""

    t0: float
    t1: float
    sol: Callable[[np.ndarray], np.ndarray] | None
    held: tuple[float, ...]


@dataclass(frozen=True)
class Solution:
    """A piecewise dense solution of one scene by one scipy method."""

    method: str
    rtol: float
    pieces: tuple[_Piece, ...]
    cpu_time: float  # s, process time of the solve
    nfev: int
    steps: int = 0  # accepted steps of every piece

    def states(self, times: Sequence[float]) -> np.ndarray:
        """(N, 6) array of (θ1, θ2, θ3, θ1', θ2', θ3') at `times` (s, within the run)."""
        times = np.asarray(times, dtype=float)
        out = np.empty((times.size, 6))
        starts = np.array([p.t0 for p in self.pieces])
        # a time on a boundary belongs to the later piece (the state after a switch or impact)
        index = np.clip(np.searchsorted(starts, times + TIME_EPS, side="right") - 1, 0, len(self.pieces) - 1)
        for k in np.unique(index):
            piece = self.pieces[k]
            sel = index == k
            if piece.sol is None:
                out[sel] = piece.held
            else:
                out[sel] = piece.sol(np.clip(times[sel], piece.t0, piece.t1)).T
        return out


@dataclass(frozen=True)
class GridSolution:
    """A solution known on a time grid k·spacing only: `Simulator` output of one method.

    method: its row label; rtol: the method's tolerance; nfev: 0 (not counted).
    """

    method: str
    rtol: float
    t: np.ndarray  # (N,) s
    y: np.ndarray  # (N, 6): (θ1, θ2, θ3, θ1', θ2', θ3')
    cpu_time: float  # s, process time of the run
    nfev: int = 0

    def states(self, times: Sequence[float]) -> np.ndarray:
        """(N, 6) states at `times`, each on the grid (ValueError naming the first time that is not)."""
        times = np.asarray(times, dtype=float)
        spacing = self.t[1] - self.t[0]
        index = np.rint(times / spacing).astype(int)
        off = (np.abs(index * spacing - times) > 1e-9 * spacing) | (index < 0) | (index >= self.t.size)
        if np.any(off):
            raise ValueError(f"times: on the reference grid k·{spacing:g} s within the run, got {times[off][0]!r}")
        return self.y[index]


@dataclass(frozen=True)
class Reference:
    """The reference of one scene and its check (max |θ_ref − θ_check| in rad on the sample grid)."""

    scene: str
    solution: Solution | GridSolution
    check: Solution | GridSolution
    check_difference: float

    @property
    def floor(self) -> float:
        """The reference floor, rad: the check difference where the check follows the scene
        (≤ MAX_CHECK_DIFFERENCE); NaN where it cannot, and no floor is claimed."""
        return self.check_difference if self.check_difference <= MAX_CHECK_DIFFERENCE else math.nan

    def theta(self, times: Sequence[float]) -> np.ndarray:
        """(N, 3) reference angles, rad."""
        return self.solution.states(times)[:, :3]


def sample_times(duration: float, spacing: float) -> np.ndarray:
    """k·spacing for k = 0..round(duration / spacing), s: the grid errors are measured on."""
    n = round(duration / spacing)
    return np.arange(n + 1) * spacing


def _kink_events(system, t: float, y: Sequence[float]) -> list[Callable[[float, np.ndarray], float]]:  # type: ignore[no-untyped-def]
    """Terminal solve_ivp events at the contact onsets and releases (the gaps of every element whose crossing is
    a kink, `impact(i)` None) of a piece starting at (t, y): side·gap, crossing from the side the gap is on now
    (or moves to, when it is within ON_GAP of zero), as test/hybrid_reference.py does."""
    q, v = (y[0], y[1], y[2]), (y[3], y[4], y[5])
    events = []
    for element in system.elements:
        if element.smooth:
            continue
        gaps_at = getattr(element, "gaps_at", None)
        gap_of = (lambda s, z, g=gaps_at: g(s, (z[0], z[1], z[2]))) if gaps_at else \
            (lambda s, z, e=element: e.gaps((z[0], z[1], z[2])))
        now = gap_of(t, y)
        rates = element.gap_rates(t, q, v) if hasattr(element, "gap_rates") else (1.0,) * len(now)
        for i, gap in enumerate(now):
            if element.impact(i) is not None:
                continue  # a stop: an impact, handled by the stop events
            side = math.copysign(1.0, gap if abs(gap) > ON_GAP else (rates[i] or 1.0))
            event = (lambda s, z, i=i, side=side, g=gap_of: side * g(s, z)[i])
            event.terminal, event.direction = True, -1.0  # type: ignore[attr-defined]
            events.append(event)
    return events


def _smooth_piece(scene: Scene, rhs: Callable[..., list[float]], t: float, end: float, y: Sequence[float], method: str,
                  rtol: float, events: list[Callable[[float, np.ndarray], float]], pieces: list[_Piece]) -> Any:
    """solve_ivp's result on one smooth piece [t, end] from y (dense output, stopped by a terminal one of `events`),
    its `_Piece` appended to `pieces`; SimulationDiverged where scipy fails."""
    sol = solve_ivp(rhs, (t, end), y, method=method, rtol=rtol, atol=ATOL_PER_RTOL * rtol, dense_output=True,
                    events=events or None)
    if not sol.success:
        raise SimulationDiverged(f"reference {method} on {scene.name}: {sol.message} at t = {sol.t[-1]:.6f} s")
    pieces.append(_Piece(t, float(sol.t[-1]), sol.sol, ()))
    return sol


def solve(scene: Scene, *, method: str, rtol: float,
          wrap: Callable[[Callable[..., list[float]]], Callable[..., list[float]]] = lambda f: f) -> Solution:
    """`scene` by scipy `method` at `rtol` (atol = ATOL_PER_RTOL·rtol), piece by piece: restarted at every
    torque switch, stop impact, contact onset and release, and on a drive scene at every mesh mode change
    (`solve_drive`). `wrap` wraps each piece's right-hand side (the bench's evaluation counter)."""
    if scene.drive is not None:
        return solve_drive(scene, method=method, rtol=rtol, wrap=wrap)
    system = scene.build_system()
    acc = system.accelerations
    profile = scene.torque
    duration = scene.duration
    q, v = scene.initial_state()
    y = [*q, *v]
    t = 0.0
    cuts = sorted(profile.breakpoints(0.0, duration))
    limits = scene.mcp_limits
    contact = 0
    pieces: list[_Piece] = []
    nfev = steps = restarts = 0
    start = time.process_time()
    while t < duration - TIME_EPS:
        end = next((b for b in cuts if b > t + TIME_EPS), duration)
        torque = profile.on_segment(t, end)
        if contact:  # resting on a stop: held until the free acceleration stops pushing into it
            qs = (y[0], y[1], y[2])

            def push(s: float, qs=qs, torque=torque) -> float:  # type: ignore[no-untyped-def]
                return acc(s, qs, ZERO, torque(s))[0][0] * contact

            probes = np.linspace(t, end, CONTACT_PROBES)
            pushing = [push(s) > 0.0 for s in probes]
            if all(pushing):
                pieces.append(_Piece(t, end, None, tuple(y)))
                t = end
                continue
            k = pushing.index(False)
            release = t if k == 0 else brentq(push, probes[k - 1], probes[k], xtol=TIME_EPS, rtol=4e-16)
            if release > t:
                pieces.append(_Piece(t, release, None, tuple(y)))
            t, contact = release, 0

        rhs = wrap(functools.partial(system.rhs, torque=torque))
        events = []
        if limits is not None:
            upper = lambda s, z: z[0] - limits[1]  # noqa: E731
            lower = lambda s, z: z[0] - limits[0]  # noqa: E731
            upper.terminal, upper.direction = True, 1.0  # type: ignore[attr-defined]
            lower.terminal, lower.direction = True, -1.0  # type: ignore[attr-defined]
            events = [upper, lower]
        stops = len(events)
        events += _kink_events(system, t, y)
        sol = _smooth_piece(scene, rhs, t, end, y, method, rtol, events, pieces)
        nfev += sol.nfev
        steps += sol.t.size - 1
        t_hit = float(sol.t[-1])
        y = sol.y[:, -1].tolist()
        t = t_hit
        restarts += sol.status == 1
        if restarts > MAX_RESTARTS:
            raise SimulationDiverged(f"reference {method} on {scene.name}: more than {MAX_RESTARTS} contact events")
        if sol.status == 1 and any(sol.t_events[k].size for k in range(stops)):
            # a stop was reached: the impact rule of simulation.impact.impact (a contact event: restart only)
            side = +1 if sol.t_events[0].size else -1
            qs = (y[0], y[1], y[2])
            e = scene.restitution
            v_plus = [-e * w for w in y[3:]]
            a_free = acc(t, qs, ZERO, torque(t))[0][0]
            if a_free * side > 0.0 and v_plus[0] == 0.0:
                contact = side
            y = [*qs, *v_plus]
    return Solution(method, rtol, tuple(pieces), time.process_time() - start, nfev, steps)


def _drive_guard_events(system: DrivenSystem, torque: Callable[[float], float]) -> list[Callable[[float, np.ndarray], float]]:
    """Terminal events of the rolling mesh's guards under the mode set now (`actuators.stepping._guards`): turn
    and flank (one-sided, crossing downwards) and the current limit (both ways); an ideal gear has the limit only."""
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


def solve_drive(scene: Scene, *, method: str, rtol: float,
                wrap: Callable[[Callable[..., list[float]]], Callable[..., list[float]]] = lambda f: f) -> Solution:
    """A drive scene (spec §8, L = 0, no joint stops) by scipy `method` at `rtol`, one smooth piece per mesh mode
    (test/hybrid_reference.py's scheme), each ended by a terminal event and restarted under the new mode:
    - turn (direction·θ1' < 0): the holding test decides, stuck or rolling on (`stepping._turn`);
    - flank (τ_g against the flank): drive ↔ back;
    - the current limit's kink and every contact onset and release (`_kink_events`): restart only;
    - stuck: q held, q' = 0, until the holding margin's root (`stepping._release_time`).
    The same equations as every method under test (`DrivenSystem.rhs` in the mode). ValueError for a scene this
    does not cover (joint stops, L > 0)."""
    if scene.mcp_limits is not None or scene.drive is None or scene.drive.inductance > 0.0:
        raise ValueError(f"{scene.name}: the reference covers drive scenes with L = 0 and without joint stops")
    system: DrivenSystem = scene.build_system()  # type: ignore[assignment]
    drive = system.drive
    profile = scene.torque
    duration = scene.duration
    q, v = scene.initial_state()
    cuts = sorted(profile.breakpoints(0.0, duration)) + [duration]
    if v[0] == 0.0:
        v = stepping._turn(system, 0.0, q, profile(0.0))
    else:
        stepping._roll(system, 0.0, q, v, profile(0.0), math.copysign(1.0, v[0]))
    pieces: list[_Piece] = []
    nfev = steps = 0
    start = time.process_time()
    t, y = 0.0, np.array([*q, *v])
    for _ in range(MAX_RESTARTS):
        if t >= duration - TIME_EPS:
            break
        end = next(b for b in cuts if b > t + TIME_EPS)
        u = profile.on_segment(t, end)
        if drive.mode == STUCK:
            qs = (y[0], y[1], y[2])
            release = stepping._release_time(system, t, end, qs, u)
            held_to = end if release is None else release
            if held_to > t:
                pieces.append(_Piece(t, held_to, None, (*qs, *ZERO)))
            t, y = held_to, np.array([*qs, *ZERO])
            if release is not None:
                stepping._roll(system, t, qs, ZERO, u(t), stepping._break_direction(system, t, qs, u(t)))
            continue
        rhs = wrap(lambda s, z, u=u: system.rhs(s, z, u))  # the mode is read at each call
        guards = _drive_guard_events(system, u)
        sol = _smooth_piece(scene, rhs, t, end, y, method, rtol, guards + _kink_events(system, t, y), pieces)
        nfev += sol.nfev
        steps += sol.t.size - 1
        t, y = float(sol.t[-1]), sol.y[:, -1].copy()
        if sol.status != 1:
            continue
        qs, us = (y[0], y[1], y[2]), u(t)
        if len(guards) == 3 and sol.t_events[0].size:  # the turn: stick, or roll on
            y[3:] = stepping._turn(system, t, qs, us)
            continue
        if len(guards) == 3 and sol.t_events[1].size:
            drive.mode = BACK if drive.mode == DRIVE else DRIVE
        # a kink (limit, contact) or a flank change: step just past it without events, then restart
        nxt = min(end, t + NUDGE)
        sol = _smooth_piece(scene, rhs, t, nxt, y, method, rtol, [], pieces)
        nfev += sol.nfev
        steps += sol.t.size - 1
        t, y = nxt, sol.y[:, -1].copy()
    else:
        raise SimulationDiverged(f"reference {method} on {scene.name}: more than {MAX_RESTARTS} pieces")
    return Solution(method, rtol, tuple(pieces), time.process_time() - start, nfev, steps)


def is_stiff(scene: Scene) -> bool:
    """Whether an explicit reference would crawl: |s|·duration of the fastest mode above STIFF_REFERENCE."""
    system = scene.build_system()
    root = fastest_mode(system, scene.mcp_limits or kinematics.assembly_range(scene.params))
    return abs(root) * scene.duration > STIFF_REFERENCE


def solve_with_events(scene: Scene, *, spacing: float) -> GridSolution:
    """`scene` by the `adaptive` method through `Simulator` at output step `spacing` s: every
    contact onset and release located inside its step (the Simulator's event location)."""
    from finger_sim.simulate import Simulator  # the stepping path; imported late, it imports auto

    sim = Simulator(scene.with_overrides(method="adaptive", dt=spacing), kernel="python")
    n = round(scene.duration / spacing)
    start = time.process_time()
    states = [sim.state] + [sim.step() for _ in range(n)]
    cpu = time.process_time() - start
    y = np.array([[*s.q, *s.v] for s in states])
    return GridSolution("adaptive (Simulator, contact events located)", ADAPTIVE_RTOL, np.array([s.t for s in states]), y, cpu)


def build_reference(scene: Scene, *, quick: bool, spacing: float) -> Reference:
    """DOP853 at its tightest practical tolerance, checked by Radau (LSODA on a stiff scene).

    A contact scene (objects): `solve_with_events` on the sample grid, checked the same way; a drive scene, with
    or without objects, is solved piece by piece through the mesh's modes (`solve_drive`) both times.
    """
    stiff = is_stiff(scene)
    if scene.objects and scene.drive is None:
        solution: Solution | GridSolution = solve_with_events(scene, spacing=spacing)
    else:
        solution = solve(scene, method="DOP853", rtol=STIFF_REFERENCE_RTOL if stiff else REFERENCE_RTOL)
    check_rtol = CHECK_RTOL_QUICK if quick else CHECK_RTOL
    check = solve(scene, method="LSODA" if stiff else "Radau", rtol=check_rtol)
    times = sample_times(scene.duration, spacing)
    diff = float(np.max(np.abs(solution.states(times)[:, :3] - check.states(times)[:, :3])))
    if not math.isfinite(diff):
        raise SimulationDiverged(f"reference of {scene.name}: non-finite check difference")
    return Reference(scene.name, solution, check, diff)
