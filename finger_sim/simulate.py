"""Fixed-rate stepping of a scene: the time grid, torque breakpoints, joint stops, checks.

`Simulator` advances exactly dt per step (t = n·dt, never accumulated), whatever the
integrator, so the node and offline runs share one path and the same torques at the
same steps give bit-identical states. `simulate` runs a whole scene offline.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import NamedTuple

import numpy as np
from scipy.optimize import brentq

from finger_sim import kinematics
from finger_sim.errors import SimulationDiverged, StabilityError
from finger_sim.inputs import Profile
from finger_sim.integrators import METHODS, Integrator, TorqueFn
from finger_sim.kinematics import Vec3
from finger_sim.scene import AUTO, Scene
from finger_sim.auto import choose_method
from finger_sim.stability import fastest_mode, largest_stable_dt, stable_at

#: A joint-stop crossing is located to this tolerance on θ1, rad.
STOP_TOLERANCE = 1e-12
#: Regula-falsi iterations allowed to locate one crossing.
MAX_LOCATE_ITERATIONS = 60
#: The release from a stop is located to this fraction of the step.
RELEASE_TOLERANCE = 1e-12
#: Impacts allowed within one step before the run is declared chattering.
MAX_IMPACTS_PER_STEP = 8
#: A constant torque is split nowhere: a break closer than this (relative to dt) to a
#: step's end is taken as lying on it.
BREAK_EPS = 1e-9

ZERO: Vec3 = (0.0, 0.0, 0.0)


class State(NamedTuple):
    """Time (s), q = (θ1, θ2, θ3) (rad) and q' (rad/s)."""

    t: float
    q: Vec3
    v: Vec3


class Simulator:
    """Steps one scene at its fixed dt. Torque is the scene's profile, or a held value per step."""

    def __init__(self, scene: Scene) -> None:
        self.scene = scene
        self.system = scene.build_system()
        self.dt = scene.dt
        self.method_reason = ""
        method = scene.method
        if method == AUTO:
            method, self.method_reason = choose_method(scene)
        self._method_cls = METHODS[method]
        self._check_stability(self._method_cls)
        self.method = method
        self._limits = scene.mcp_limits
        self.reset()

    def reset(self) -> None:
        """Back to the scene's initial state at t = 0."""
        # A fresh integrator: a warm start kept from the last run (adaptive's step size,
        # rattle's Jacobian) would make the rerun differ in the last bits.
        self.integrator: Integrator = self._method_cls(self.system)
        self.step_index = 0
        self.q, self.v = self.scene.initial_state()
        self._contact = 0  # +1 resting on the upper MCP stop, −1 on the lower, 0 free
        #: the motor torque at the end of the last step (N·m): what a JointState effort reports
        self.torque = self.scene.torque(0.0)
        self.impacts = 0

    @property
    def time(self) -> float:
        """Sim time of the current state, s: step_index·dt."""
        return self.step_index * self.dt

    @property
    def state(self) -> State:
        return State(self.time, self.q, self.v)

    def step(self, torque: Profile | float | None = None) -> State:
        """Advance one dt under `torque`: the scene's profile if None, a profile, or a held value (N·m)."""
        profile = self.scene.torque if torque is None else torque
        t0, t1 = self.step_index * self.dt, (self.step_index + 1) * self.dt
        if isinstance(profile, Profile):
            eps = BREAK_EPS * self.dt
            cuts = [b for b in profile.breakpoints(t0, t1) if t0 + eps < b < t1 - eps]
            edges = [t0, *cuts, t1]
            for a, b in zip(edges, edges[1:]):
                segment = profile.on_segment(a, b)
                self._advance(a, b, segment)
            self.torque = segment(t1)
        else:
            value = self.torque = float(profile)
            self._advance(t0, t1, lambda s: value)
        if not all(math.isfinite(c) for c in self.q + self.v):
            raise SimulationDiverged(f"{self.method}: non-finite state at t = {t1:.6f} s (step {self.step_index + 1})")
        self.step_index += 1
        return self.state

    # -- internals ---------------------------------------------------------------------
    def _check_stability(self, cls: type[Integrator]) -> None:
        root = fastest_mode(self.system, self.scene.mcp_limits or kinematics.assembly_range(self.scene.params))
        if not stable_at(cls, root, self.dt):
            safe = largest_stable_dt(cls, root, self.dt)
            raise StabilityError(
                f"integrator.method: {cls.name} is unstable for scene '{self.scene.name}' at dt = {self.dt:g} s "
                f"(fastest mode |s| = {abs(root):.4g} 1/s, |s|·dt = {abs(root) * self.dt:.3g}); "
                f"use an implicit method (radau) or auto, or dt ≤ {safe:.3g} s"
            )

    def _advance(self, t0: float, t1: float, torque: TorqueFn) -> None:
        """Integrate [t0, t1] under a smooth torque, resolving MCP stop impacts on the way."""
        t, q, v = t0, self.q, self.v
        for _ in range(MAX_IMPACTS_PER_STEP):
            if self._contact:
                release = self._release_time(t, t1, q, torque)
                if release is None:  # held on the stop for the whole segment
                    self.q, self.v = q, ZERO
                    return
                t, v, self._contact = release, ZERO, 0
            q1, v1 = self.integrator.step(t, q, v, t1 - t, torque)
            side = self._violated(q1[0])
            if not side:
                self.q, self.v = q1, v1
                return
            t, q, v = self._impact(t, q, v, t1, torque, side)
        raise SimulationDiverged(f"more than {MAX_IMPACTS_PER_STEP} stop impacts in one step at t = {t0:.6f} s")

    def _violated(self, theta1: float) -> int:
        if self._limits is None:
            return 0
        if theta1 > self._limits[1] + STOP_TOLERANCE:
            return +1
        if theta1 < self._limits[0] - STOP_TOLERANCE:
            return -1
        return 0

    def _release_time(self, t: float, t1: float, q: Vec3, torque: TorqueFn) -> float | None:
        """When in [t, t1] the finger resting on the stop leaves it; None if it stays throughout.

        At rest on the stop q is fixed and q' = 0, so the free acceleration is a function of
        time alone: the release is the root of its component into the stop, found by brentq.
        """

        def push(s: float) -> float:
            a, _ = self.system.accelerations(s, q, ZERO, torque(s))
            return a[0] * self._contact

        if push(t) <= 0.0:
            return t
        if push(t1) > 0.0:
            return None
        return brentq(push, t, t1, xtol=RELEASE_TOLERANCE * (t1 - t), rtol=4 * np.finfo(float).eps)

    def _impact(self, t: float, q: Vec3, v: Vec3, t1: float, torque: TorqueFn, side: int) -> tuple[float, Vec3, Vec3]:
        """Locate the crossing in (t, t1], apply the impact there; returns (t*, q*, v⁺)."""
        assert self._limits is not None
        limit = self._limits[1] if side > 0 else self._limits[0]
        step = self.integrator.step

        def gap(s: float) -> tuple[float, Vec3, Vec3]:
            qs, vs = step(t, q, v, s - t, torque)
            return qs[0] - limit, qs, vs

        # Illinois regula falsi on g(s) = θ1(s) − limit; g(t) and g(t1) have opposite signs.
        a, ga = t, q[0] - limit
        b = t1
        gb, qb, vb = gap(b)
        keep = 0
        for _ in range(MAX_LOCATE_ITERATIONS):
            s = b - gb * (b - a) / (gb - ga)
            # A step that starts on the stop (g(t) = 0) crosses at t itself: stepping a
            # zero-length interval would divide by zero in rattle and fail in scipy.
            gs, qs, vs = gap(s) if s > t else (q[0] - limit, q, v)
            if abs(gs) <= STOP_TOLERANCE or s <= a or s >= b:
                break
            if (gs > 0) == (gb > 0):
                b, gb = s, gs
                ga = ga / 2 if keep == 1 else ga  # Illinois: halve the stale end's value
                keep = 1
            else:
                a, ga = s, gs
                gb = gb / 2 if keep == -1 else gb
                keep = -1
        self.impacts += 1
        # One degree of freedom: q' lies on the null space of Φ_q, so the impulse on θ1
        # scales the whole velocity: v⁺ = −e v⁻. Constraints hold; kinetic energy × e².
        e = self.scene.restitution
        v_plus = (-e * vs[0], -e * vs[1], -e * vs[2])
        a_free, _ = self.system.accelerations(s, qs, ZERO, torque(s))
        pushing = a_free[0] * side > 0.0
        if pushing and abs(v_plus[0]) <= abs(a_free[0]) * self.dt:  # would be back within a step: rest
            self._contact = side
            v_plus = ZERO
        return s, qs, v_plus


@dataclass
class Trajectory:
    """A run sampled at every step, t = 0 included. Angles rad, rates rad/s, energy J, |Φ| m."""

    t: np.ndarray
    q: np.ndarray  # (N, 3)
    v: np.ndarray  # (N, 3)
    energy: np.ndarray
    residual: np.ndarray
    method: str
    method_reason: str
    wall_time: float  # s, stepping only

    CSV_HEADER = "t,theta1,theta2,theta3,theta1_dot,theta2_dot,theta3_dot,energy,constraint_residual"

    def write_csv(self, path: str | Path) -> None:
        data = np.column_stack([self.t, self.q, self.v, self.energy, self.residual])
        np.savetxt(path, data, delimiter=",", header=self.CSV_HEADER, comments="", fmt="%.17g")

    def summary(self) -> str:
        deg = np.degrees(self.q[-1])
        return (
            f"t = {self.t[-1]:.4g} s  θ = ({deg[0]:.2f}°, {deg[1]:.2f}°, {deg[2]:.2f}°)  "
            f"max|Φ| = {self.residual.max():.2e} m  ΔE = {self.energy[-1] - self.energy[0]:+.3e} J  "
            f"method = {self.method}  steps = {len(self.t) - 1}"
            + (f"  wall = {self.wall_time:.3f} s" if math.isfinite(self.wall_time) else "")
        )


def simulate(scene: Scene, *, on_step: Callable[[State], None] | None = None) -> Trajectory:
    """Run `scene` from t = 0 to its duration (rounded up to whole steps) and record every step."""
    sim = Simulator(scene)
    n = math.ceil(scene.duration / scene.dt - BREAK_EPS)
    states = [sim.state]
    start = time.perf_counter()
    for _ in range(n):
        state = sim.step()
        states.append(state)
        if on_step is not None:
            on_step(state)
    wall = time.perf_counter() - start
    system, p = sim.system, scene.params
    return Trajectory(
        t=np.array([s.t for s in states]),
        q=np.array([s.q for s in states]),
        v=np.array([s.v for s in states]),
        energy=np.array([system.energy(s.q, s.v) for s in states]),
        residual=np.array([kinematics.constraint_norm(p, s.q) for s in states]),
        method=sim.method,
        method_reason=sim.method_reason,
        wall_time=wall,
    )
