"""Fixed-rate stepping of a scene: the time grid, torque breakpoints, events, checks.

`Simulator` advances exactly dt per step (t = n·dt, never accumulated), whatever the
integrator, so the node and offline runs share one path and the same torques at the
same steps give bit-identical states. Events of the non-smooth force elements (a stop
impact, a contact onset) are located inside the step and the step is split there.
`simulate` runs a whole scene offline.
"""

from __future__ import annotations

import functools
import math
import time
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import NamedTuple

import numpy as np

from finger_sim import stick_slip
from finger_sim.actuators import stepping as drive_stepping
from finger_sim.sensors import SensorBank
from finger_sim.auto import (ERROR_CONTROLLED, PYTHON_STAGES_NOTE, choose_method, contact_substeps,
                             integrator_options, warn_unresolved_contact)
from finger_sim.depth_guard import DepthLimit, depth_limit
from finger_sim.dynamics import FingerSystem
from finger_sim.effects import EFFECTS, Effect, ForceElement
from finger_sim.errors import SimulationDiverged, StabilityError
from finger_sim.inputs import BREAK_EPS, HELD_ARRAY, Profile
from finger_sim.integrators import METHODS, HeldTorque, Integrator, TorqueFn
from finger_sim import stepper_slot
from finger_sim.projection import OK as FAST_OK
from finger_sim.stepper_slot import BREAKPOINT
from finger_sim.kinematics import Vec3
from finger_sim.scene import AUTO, Scene
from finger_sim.tip_force_profile import refuse_profile
from finger_sim.stability import CONTACT_RESOLUTION, fastest_mode, has_contact, largest_stable_dt, mcp_range, stable_at

#: A gap crossing (a stop) is located to this tolerance on the gap (rad for the MCP stops);
#: a gap counts as closed below −EVENT_TOLERANCE.
EVENT_TOLERANCE = 1e-12
#: Regula-falsi iterations allowed to locate one crossing.
MAX_LOCATE_ITERATIONS = 60
#: The release from a stop is located to this fraction of the step.
RELEASE_TOLERANCE = 1e-12
#: Events (impacts, kinks) allowed within one step before the run is declared chattering.
MAX_EVENTS_PER_STEP = 8
#: A step is split into substeps (auto on a contact scene) when a contact gap, moving at its
#: start rate, would close within this many step lengths: margin for the acceleration towards it.
NEAR_CONTACT = 2.0
#: How deep `Simulator._bracket` refines a predicted crossing inside a step that its check
#: did not confirm (each level probes both halves: at most 2^depth − 1 extra integrator steps).
BRACKET_DEPTH = 3
ZERO: Vec3 = (0.0, 0.0, 0.0)


class State(NamedTuple):
    """Time (s), q = (θ1, θ2, θ3) (rad) and q' (rad/s)."""

    t: float
    q: Vec3
    v: Vec3


#: State(t, q, v) without the NamedTuple's Python-level __new__ (0.3 µs of a 2 µs step).
_new_state = tuple.__new__


class _Gap(NamedTuple):
    """One event function of a non-smooth element: gap `index` of `element`, and the restitution
    of its impact (None: crossing it is a kink only)."""

    element: ForceElement
    index: int
    restitution: float | None


class _Crossing(NamedTuple):
    """A located crossing: where the sub-step ends (t, q, q') and the gap that crossed."""

    t: float
    q: Vec3
    v: Vec3
    gap: _Gap


class Simulator:
    """Steps one scene at its fixed dt. Torque is the scene's profile, or a held value per step."""

    def __init__(self, scene: Scene, *, kernel: str = "auto") -> None:
        """kernel: "auto" (compiled where numba and the scene allow), "compiled", "python", or a
        kernel name recorded by an earlier run; `self.kernel` names the one that runs. The set-up
        (system, method choice, stability check, compiled plan) is kept per scene (`_setup`)."""
        refuse_profile(scene, "simulate or rollout")
        self.scene = scene
        # the registered effects are part of the key: a plug-in registered later builds another system
        effects = tuple(EFFECTS.values())
        # a drive holds its mesh mode: each Simulator of a drive scene builds its own system
        cached = _hashable(scene) and scene.drive is None and not stick_slip.in_scene(scene)  # nor a friction mode
        setup = _setup(scene, kernel, effects) if cached else _setup.__wrapped__(scene, kernel, effects)
        self.system, self.dt, self.method, self.method_reason = setup.system, scene.dt, setup.method, setup.reason
        #: steps in contact (or closing a contact within the step) are split in this many (auto only)
        self.substeps = setup.substeps
        #: keyword options of the integrator (auto's error-controlled method: its tolerances)
        self._options = setup.options
        #: the drive (spec §8) whose mesh modes this Simulator steps, or None (an ideal torque source)
        self._drive = getattr(self.system, "drive", None)
        #: the stick–slip contact (spec §7) whose friction modes this Simulator steps, or None
        self._friction = stick_slip.element(self.system)
        self._method_cls, self._integrator_cls, self.kernel = setup.method_cls, setup.integrator_cls, setup.kernel
        self._gaps, self._kinks, self._gap_elements = setup.gaps, setup.kinks, setup.gap_elements
        #: the depth gaps (`DepthLimit`, last in `_gaps`): (position of the contact gap in `_gaps`, ρ) each
        self._depth_sources = setup.depth_sources
        #: elements whose gaps move with time too (contact with a moving object): asked at (t, q)
        self._timed = frozenset(g.element for g in self._gaps if getattr(g.element, "time_varying", False))
        self.reset()
        #: the lean compiled path of `step` (a compiled fixed-step method on a smooth scene), else None
        self.fast_stepper = setup.fast_stepper
        #: what `step`'s lean path calls: the fast stepper, or a drive scene's (`actuators.stepping.fast_stepper`)
        self._lean = self.fast_stepper if self._drive is None else drive_stepping.fast_stepper(self)

    def reset(self) -> None:
        """Back to the scene's initial state at t = 0."""
        # A fresh integrator: a warm start kept from the last run (adaptive's step size,
        # rattle's Jacobian) would make the rerun differ in the last bits.
        self.integrator: Integrator = self._integrator_cls(self.system, **self._options)
        self.step_index = 0
        self.q, self.v = self.scene.initial_state()
        self._resting: _Gap | None = None  # the closed impact gap the finger rests on (a stop)
        self._gap_cache: tuple[Vec3, Vec3, list[tuple[float, float]], float] | None = None  # `_gap_states`' last
        #: the motor torque at the end of the last step (N·m): what a JointState effort reports
        #: (with a drive: the voltage command, V)
        self.torque = self.scene.torque(0.0)
        if self._drive is not None:
            drive_stepping.start(self)
        if self._friction is not None:
            stick_slip.start(self)
        self.impacts = 0
        self._held: tuple[float, TorqueFn] | None = None  # the held torque (N·m) and its function

    @property
    def time(self) -> float:
        """Sim time of the current state, s: step_index·dt."""
        return self.step_index * self.dt

    @property
    def state(self) -> State:
        return State(self.time, self.q, self.v)

    @property
    def error_estimate(self) -> float:
        """The integrator's estimate of the global θ error at the current state (rad): an
        error-controlled method's sum of local error estimates (`DormandPrince853.error_estimate`);
        NaN for a fixed-step method, which does not estimate its error."""
        estimate = getattr(self.integrator, "error_estimate", None)
        return math.nan if estimate is None else estimate(self.q)

    def step(self, torque: Profile | float | None = None) -> State:
        """Advance one dt under `torque`: the scene's profile if None, a profile, or a held value (N·m)."""
        fast = self._lean
        if fast is not None and not isinstance(torque, Profile):
            # one kernel call: the compiled profile (or the held value) and the step, same numbers
            prof, held = (fast.profile, 0.0) if torque is None else (HELD_ARRAY, float(torque))
            if prof is not None:
                k = self.step_index
                status, q, v, end = fast.call(fast.plan, prof, held, k, self.q, self.v)
                if status == FAST_OK:
                    self.q, self.v, self.torque, self.step_index = q, v, end, k + 1
                    return _new_state(State, ((k + 1) * self.dt, q, v))
                if status != BREAKPOINT:  # else a switch inside the step: split it below
                    fast.fail(status, k, self.q)
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
            if self._held is None or self._held[0] != value:
                # one function object per held value: an error-controlled method continues its internal
                # solution from step to step while the value is held (it restarts for a new function);
                # a HeldTorque, whose `value` tells it that τ is the same at every stage
                self._held = (value, HeldTorque(value))
            self._advance(t0, t1, self._held[1])
        if not math.isfinite(sum(self.q) + sum(self.v)):  # a NaN or inf anywhere makes the sum non-finite
            raise SimulationDiverged(f"non-finite state (step {self.step_index + 1})", method=self.method, t=t1, dt=self.dt)
        self.step_index += 1
        return self.state

    # -- internals ---------------------------------------------------------------------
    def _advance(self, t0: float, t1: float, torque: TorqueFn) -> None:
        """Integrate [t0, t1] under a smooth torque, splitting it at every event on the way."""
        if self._friction is not None:  # with a drive too: the mesh and the friction share one lock
            stick_slip.advance(self, t0, t1, torque)
            return
        if self._drive is not None:
            drive_stepping.advance(self, t0, t1, torque)
            return
        if not self._gaps:
            self.q, self.v = self.integrator.step(t0, self.q, self.v, t1 - t0, torque)
            return
        t, q, v = t0, self.q, self.v
        for _ in range(MAX_EVENTS_PER_STEP):
            if self._resting is not None:
                release = self._release_time(self._resting, t, t1, q, torque)
                if release is None:  # held on the stop for the whole segment
                    self.q, self.v = q, ZERO
                    return
                t, v, self._resting = release, ZERO, None
            q1, v1 = self._step(t, q, v, t1 - t, torque)
            crossing = self._first_crossing(t, q, v, t1, q1, v1, torque)
            if crossing is None:
                self.q, self.v = q1, v1
                return
            t, q, v = crossing.t, crossing.q, crossing.v
            if crossing.gap.restitution is not None:
                v = self._impact(crossing, torque)
            if t >= t1:  # the crossing ends the segment: a zero-length step would divide by zero (rattle)
                self.q, self.v = q, v
                return
        raise SimulationDiverged(f"more than {MAX_EVENTS_PER_STEP} events (stop impacts, contact changes) in one step",
                                 method=self.method, t=t0, dt=self.dt)

    def _step(self, t: float, q: Vec3, v: Vec3, h: float, torque: TorqueFn) -> tuple[Vec3, Vec3]:
        """One integrator step of length h, split in `substeps` equal ones when a contact gap is
        closed at its start or closes within it (gap + NEAR_CONTACT·h·gap' < 0)."""
        for gap in self._kinks:
            if gap.element in self._timed:
                g, rate = gap.element.gaps_at(t, q)[gap.index], gap.element.gap_rates(t, q, v)[gap.index]
            else:
                g = gap.element.gaps(q)[gap.index]
                n = gap.element.gap_gradient(gap.index, q)
                rate = n[0] * v[0] + n[1] * v[1] + n[2] * v[2]
            if g + NEAR_CONTACT * h * min(0.0, rate) < 0.0:
                m = self.substeps
                for k in range(m):
                    q, v = self.integrator.step(t + h * k / m, q, v, h / m, torque)
                return q, v
        return self.integrator.step(t, q, v, h, torque)

    def _first_crossing(self, t: float, q: Vec3, v: Vec3, t1: float, q1: Vec3, v1: Vec3,
                        torque: TorqueFn) -> _Crossing | None:
        """The earliest gap crossing in (t, t1] of the step (t, q, q') → (t1, q1, q1'), or None.

        A gap crosses when it is closed at one end of the step and open at the other (an impact
        gap, a stop, counts as open at the start: the step starts off it), or when it closes and
        opens again inside the step, which the ends alone do not show (a contact shorter than
        a step): `_bracket` looks for that between the ends.
        """
        first: _Crossing | None = None
        start, end = self._gap_states(t, q, v), self._gap_states(t1, q1, v1)
        h = t1 - t
        for gap, (g0, r0), (g1, r1) in zip(self._gaps, start, end):
            if gap.restitution is not None:
                g0 = max(g0, 0.0)  # an impact gap: the step starts on the open side
            if min(g0, g1) > h * (abs(r0) + abs(r1)):
                continue  # open at both ends, and too far for `_predicted_crossing` to see a crossing between
            found = self._bracket(gap, t, q, v, torque, (t, g0, r0), (t1, g1, r1, q1, v1), BRACKET_DEPTH)
            if found is not None:
                crossing = self._locate(gap, t, q, v, (t, g0), found, torque)
                if first is None or crossing.t < first.t:
                    first = crossing
        if first is not None and isinstance(first.gap.element, DepthLimit):  # a phalanx axis reached an object
            raise first.gap.element.crossed(first.gap.index, first.t, first.q, first.v, self.method)
        return first

    def _gap_states(self, t: float, q: Vec3, v: Vec3) -> list[tuple[float, float]]:
        """(gap, gap') of every gap at (t, q, q') in `_gaps` order: gap' = ∂gap/∂q · q' (+ ∂gap/∂t
        for a moving object). The last state asked is kept: a step's end is the next one's start."""
        cached = self._gap_cache
        if cached is not None and cached[0] is q and cached[1] is v and (not self._timed or cached[3] == t):
            return cached[2]
        out = []
        for element, indices in self._gap_elements:
            if element in self._timed:
                values, rates = element.gaps_at(t, q), element.gap_rates(t, q, v)
                out.extend((values[i], rates[i]) for i in indices)
                continue
            values = element.gaps(q)
            for i in indices:
                n = element.gap_gradient(i, q)
                out.append((values[i], n[0] * v[0] + n[1] * v[1] + n[2] * v[2]))
        out.extend((out[p][0] + rho, out[p][1]) for p, rho in self._depth_sources)  # ρ − δ, at the rate of −δ
        self._gap_cache = (q, v, out, t)
        return out

    def _bracket(self, gap: _Gap, t: float, q: Vec3, v: Vec3, torque: TorqueFn,
                 lo: tuple[float, float, float], hi: tuple[float, float, float, Vec3, Vec3],
                 depth: int) -> tuple[float, float, Vec3, Vec3] | None:
        """(s, gap, q, q') at a time s in (lo, hi] where the gap is on the other side than at lo,
        or None. lo = (s, gap, gap'), hi = (s, gap, gap', q, q'): states of the step from
        (t, q, q'), so the state at s is one step from t.

        Either hi is across already, or the gap crosses and comes back inside: predicted by
        `_predicted_crossing` from the ends' values and rates, then checked by stepping to the
        predicted time; a check that finds no crossing checks the cubic's extremum too (the start's
        rate falls short of a convex gap's crossing, e.g. an axis passing a circle), then refines on
        both halves, `depth` deep.
        """
        sa, ga, ra = lo
        sb, gb, rb, qb, vb = hi
        closed = ga < -EVENT_TOLERANCE
        if (gb < -EVENT_TOLERANCE) != closed:
            return sb, gb, qb, vb
        x = _predicted_crossing(ga, ra, gb, rb, sb - sa, closed)
        if x is None or depth == 0:
            return None
        s = sa + x * (sb - sa)
        qs, vs = self._step(t, q, v, s - t, torque)
        gs, rs = self._gap_states(s, qs, vs)[self._gaps.index(gap)]
        mid = (s, gs, rs, qs, vs)
        if (gs < -EVENT_TOLERANCE) != closed:
            return s, gs, qs, vs
        extremum = _predicted_crossing(ga, ra, gb, rb, sb - sa, closed, False)
        if extremum is not None and extremum > x:
            s2 = sa + extremum * (sb - sa)
            q2, v2 = self._step(t, q, v, s2 - t, torque)
            g2, _ = self._gap_states(s2, q2, v2)[self._gaps.index(gap)]
            if (g2 < -EVENT_TOLERANCE) != closed:
                return s2, g2, q2, v2
        return (self._bracket(gap, t, q, v, torque, lo, mid, depth - 1)
                or self._bracket(gap, t, q, v, torque, (s, gs, rs), hi, depth - 1))

    def _locate(self, gap: _Gap, t: float, q: Vec3, v: Vec3, lo: tuple[float, float],
                hi: tuple[float, float, Vec3, Vec3], torque: TorqueFn) -> _Crossing:
        """Where in (lo, hi] the gap crosses zero: Illinois regula falsi on g(s) = gap(q(s)),
        q(s) the step from (t, q, q') to s. lo = (s, gap), hi = (s, gap, q, q') (`_bracket`).

        An impact is applied at the located point (|g| ≤ EVENT_TOLERANCE); a kink's step ends
        on its far side, so that the rest of the step does not see the crossing again.
        """
        step, element, index = self._step, gap.element, gap.index
        timed = element in self._timed

        def gap_at(s: float, qs: Vec3) -> float:
            return element.gaps_at(s, qs)[index] if timed else element.gaps(qs)[index]

        def at(s: float) -> tuple[float, Vec3, Vec3]:
            qs, vs = step(t, q, v, s - t, torque)
            return gap_at(s, qs), qs, vs

        # g(a) and g(b) lie on opposite sides.
        a, ga = lo
        b, gb, qb, vb = hi
        s, gs, qs, vs = b, gb, qb, vb
        keep = 0
        for _ in range(MAX_LOCATE_ITERATIONS):
            s = b - gb * (b - a) / (gb - ga)
            # A step that starts on the gap (g(t) = 0) crosses at t itself: stepping a
            # zero-length interval would divide by zero in rattle and fail in scipy.
            gs, qs, vs = at(s) if s > t else (gap_at(t, q), q, v)
            if abs(gs) <= EVENT_TOLERANCE or s <= a or s >= b:
                break
            if (gs > 0) == (gb > 0):
                b, gb, qb, vb = s, gs, qs, vs
                ga = ga / 2 if keep == 1 else ga  # Illinois: halve the stale end's value
                keep = 1
            else:
                a, ga = s, gs
                gb = gb / 2 if keep == -1 else gb
                keep = -1
        if gap.restitution is None and (gs < -EVENT_TOLERANCE) != (gap_at(b, qb) < -EVENT_TOLERANCE):
            return _Crossing(b, qb, vb, gap)  # the kink's far side
        return _Crossing(s, qs, vs, gap)

    def _impact(self, crossing: _Crossing, torque: TorqueFn) -> Vec3:
        """q' just after the impact of a located crossing: −e q', or rest (zero) on the closed gap.

        One degree of freedom: q' lies on the null space of Φ_q, so the impulse along the gap
        scales the whole velocity: v⁺ = −e v⁻. Constraints hold; kinetic energy × e².
        """
        s, qs, vs, gap = crossing
        assert gap.restitution is not None
        self.impacts += 1
        e = gap.restitution
        v_plus = (-e * vs[0], -e * vs[1], -e * vs[2])
        a_free, _ = self.system.accelerations(s, qs, ZERO, torque(s))
        n = gap.element.gap_gradient(gap.index, qs)
        closing = n[0] * a_free[0] + n[1] * a_free[1] + n[2] * a_free[2]  # d²gap/dt² at rest
        rate = n[0] * v_plus[0] + n[1] * v_plus[1] + n[2] * v_plus[2]
        if closing < 0.0 and abs(rate) <= abs(closing) * self.dt:  # would be back within a step: rest
            self._resting = gap
            return ZERO
        return v_plus

    def _release_time(self, gap: _Gap, t: float, t1: float, q: Vec3, torque: TorqueFn) -> float | None:
        """When in [t, t1] the finger resting on a closed gap leaves it; None if it stays throughout.

        At rest q is fixed and q' = 0, so the free acceleration is a function of time alone:
        the release is the root of its component into the gap, found by brentq.
        """
        n = gap.element.gap_gradient(gap.index, q)

        def push(s: float) -> float:
            a, _ = self.system.accelerations(s, q, ZERO, torque(s))
            return -(n[0] * a[0] + n[1] * a[1] + n[2] * a[2])

        if push(t) <= 0.0:
            return t
        if push(t1) > 0.0:
            return None
        from scipy.optimize import brentq  # here: a release from a stop is rare, scipy.optimize costs ≈ 0.15 s to import

        return brentq(push, t, t1, xtol=RELEASE_TOLERANCE * (t1 - t), rtol=4 * np.finfo(float).eps)


#: Scenes whose Simulator set-up is kept (`_setup`): a node's resets, a rollout's rows, a test's reruns.
SETUP_CACHE_SIZE = 256


class _Setup(NamedTuple):
    """What a Simulator of one scene needs before its first step; immutable, shared by its Simulators."""

    system: FingerSystem
    method: str
    reason: str
    substeps: int
    options: dict[str, float]
    method_cls: type[Integrator]
    integrator_cls: type[Integrator]
    kernel: str
    gaps: tuple[_Gap, ...]
    kinks: tuple[_Gap, ...]
    gap_elements: tuple[tuple[ForceElement, tuple[int, ...]], ...]
    depth_sources: tuple[tuple[int, float], ...]
    fast_stepper: object  # kernel.integrators.FastStepper | None


def _hashable(scene: Scene) -> bool:
    try:
        hash(scene)
    except TypeError:
        return False
    return True


@functools.lru_cache(maxsize=SETUP_CACHE_SIZE)
def _setup(scene: Scene, kernel: str, effects: tuple[Effect, ...]) -> _Setup:
    """The set-up of a Simulator of `scene` on `kernel`: method (auto resolved), stability check,
    integrator class, the non-smooth elements' gaps and the compiled fast path. Kept per scene
    (a frozen value) and registry of effects (`effects.EFFECTS`, what builds the system), so a
    scene seen before costs a dictionary look-up."""
    system = scene.build_system()
    reason = ""
    method = scene.method
    substeps = 1
    options: dict[str, float] = {}
    if method == AUTO and not stick_slip.in_scene(scene):  # stick–slip: see below
        method, reason = choose_method(scene)
        if (method == ERROR_CONTROLLED and getattr(system, "drive", None) is None
                and stepper_slot.kernel().model_array(system) is None):
            reason += PYTHON_STAGES_NOTE
    if getattr(system, "drive", None) is not None:
        method, reason = drive_stepping.drive_method(method, reason, scene.method == AUTO,
                                                     lambda name: _stable_under_auto(scene, system, name),
                                                     system.drive.inductive)
    if scene.method == AUTO and stick_slip.in_scene(scene):  # dop853, restarted at every friction mode change
        method, reason, options, substeps = stick_slip.auto_method(scene)
    elif scene.method == AUTO:
        options = integrator_options(scene, method)
        if method != ERROR_CONTROLLED:  # its error control resolves the contact mode itself
            substeps = contact_substeps(scene, METHODS[method].implicit)
    method_cls = METHODS[method]
    _check_stability(scene, system, method_cls, substeps)
    depth = depth_limit(system.elements, scene.phalanx_radius)
    if depth is not None and scene.method != AUTO and method_cls.implicit:
        warn_unresolved_contact(scene, method_cls)
    integrator_cls, kernel_name = stepper_slot.kernel().select(method_cls, system, kernel)
    if getattr(system, "drive", None) is not None and system.drive.inductive:  # L > 0: the current is a state
        from finger_sim.actuators import inductive

        integrator_cls = inductive.integrator_class(
            integrator_cls, inductive.electrical_substeps(scene, system, method_cls, scene.method == AUTO))
    q0, _ = scene.initial_state()
    # every gap of every non-smooth element; empty on a smooth scene, which then pays nothing
    gaps = tuple(_Gap(e, i, e.impact(i)) for e in system.elements if not e.smooth for i in range(len(e.gaps(q0))))
    kinks = tuple(gap for gap in gaps if gap.restitution is None) if substeps > 1 else ()
    # the gaps grouped by element, in `gaps` order: each element's gaps are evaluated once per state
    gap_elements = tuple((e, tuple(g.index for g in gaps if g.element is e))
                         for e in dict.fromkeys(g.element for g in gaps))
    depth_sources: tuple[tuple[int, float], ...] = ()
    if depth is not None:  # a depth gap ρ − δ per contact candidate, after every other gap
        depth_sources = tuple((next(p for p, g in enumerate(gaps) if g.element is depth.contact and g.index == i), rho)
                              for i, rho in enumerate(depth.offsets))
        gaps += tuple(_Gap(depth, i, None) for i in range(len(depth.offsets)))  # type: ignore[arg-type]
    fast_stepper = None
    if hasattr(integrator_cls, "step_plan") and not gaps and getattr(system, "drive", None) is None:
        fast_stepper = stepper_slot.kernel().fast_stepper(integrator_cls(system), scene.dt, scene.torque)
    return _Setup(system, method, reason, substeps, options, method_cls, integrator_cls, kernel_name, gaps, kinks,
                  gap_elements, depth_sources, fast_stepper)


def _stable_under_auto(scene: Scene, system: FingerSystem, name: str) -> bool:
    """Whether method `name` is stable on the scene's fastest mode at auto's (sub)step for it."""
    cls = METHODS[name]
    return stable_at(cls, fastest_mode(system, mcp_range(scene)), scene.dt / contact_substeps(scene, cls.implicit), False)


def _check_stability(scene: Scene, system: FingerSystem, cls: type[Integrator], substeps: int) -> None:
    """StabilityError unless `cls` is stable on the scene's fastest mode at its (sub)step; a named
    method on a scene with contact must also resolve that mode (`stability.stable_at`). auto
    resolves the contact mode by its substeps (auto.CONTACT_SUBSTEP_MODE_DT)."""
    root = fastest_mode(system, mcp_range(scene))
    contact = scene.method != AUTO and has_contact(system, scene.initial_state()[0])
    if not stable_at(cls, root, scene.dt / substeps, contact):
        raise StabilityError(cls.name, scene.name, scene.dt, root, largest_stable_dt(cls, root, scene.dt, contact),
                             f"a method with a bounded stability region must resolve the contact mode, |s|·dt ≤ {CONTACT_RESOLUTION:g}"
                             if contact and stable_at(cls, root, scene.dt) else "")


def _predicted_crossing(ga: float, ra: float, gb: float, rb: float, h: float, closed: bool,
                        start_rate: bool = True) -> float | None:
    """Where (a fraction x of h, in (0, 1)) a gap that is on the same side at both ends of an
    interval of length h (s) may cross and come back inside it; None if nothing suggests so.

    ga, gb: the gap at the ends; ra, rb: its rates (gap units/s); closed: the side at both
    ends (below −EVENT_TOLERANCE). Two predictions, the earlier one counts (start_rate False:
    the second only):
    - the start's rate: ga + x h ra reaches zero at x < 1 (the start state is the trustworthy
      one: a step straddling a whole contact bounces in its stages and ends on the open side);
    - the cubic Hermite interpolant of (gap, rate) at both ends has an extremum across the
      side's bound at x (the contact, or the release, lies wholly inside the interval).
    """
    sign = 1.0 if closed else -1.0  # the direction that crosses
    best = None
    if start_rate and sign * ra > 0.0 and sign * (ga + h * ra) > -sign * EVENT_TOLERANCE:
        best = min(1.0, max(0.0, -ga / (h * ra)))
    # H(x) = ((a x + b) x + c) x + ga; H'(x) = 3a x² + 2b x + c
    a = 2.0 * (ga - gb) + h * (ra + rb)
    b = 3.0 * (gb - ga) - h * (2.0 * ra + rb)
    c = h * ra
    disc = b * b - 3.0 * a * c
    if disc >= 0.0:
        root = -(b + math.copysign(math.sqrt(disc), b))  # the stable quadratic formula
        for x in ((root / (3.0 * a)) if a != 0.0 else 2.0, (c / root) if root != 0.0 else 2.0):
            if 0.0 < x < 1.0 and ((((a * x + b) * x + c) * x + ga) < -EVENT_TOLERANCE) != closed:
                best = x if best is None else min(best, x)
    return best if best is not None and 0.0 < best < 1.0 else None


def output_names(elements: Sequence[ForceElement], q: Vec3) -> tuple[str, ...]:
    """The names of every element's `outputs` (e.g. contact's grip_force, N), in element order:
    the extra columns of a run's CSV. Asked at a pose q; an element reports the same names at every state."""
    return tuple(name for e in elements for name in e.outputs(0.0, q, ZERO))


def output_values(elements: Sequence[ForceElement], t: float, q: Vec3, v: Vec3) -> tuple[float, ...]:
    """Every element's `outputs` at (t, q, q'), in the order of `output_names`."""
    return tuple(value for e in elements for value in e.outputs(t, q, v).values())


def state_columns(system: FingerSystem, t: np.ndarray, x: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A block of states' checks and outputs: energy (J), |Φ| (m), and the elements' outputs
    (one column per `output_names`), for states x = (q, q') (n × 6) at times t (s).

    The kinetic energy and Φ are evaluated over the block with numpy in the same order of
    operations as `FingerSystem.kinetic_energy` and `kinematics.constraint` (|Φ| by math.hypot);
    the elements' potentials and outputs row by row. Used by `simulate` and `stream_csv` alike,
    so both write the same bytes.
    """
    p, alpha = system.params, system.alpha
    q0, q1, q2, v0, v1, v2 = x.T
    # FingerSystem's mass-matrix entries, the same expressions
    m11, m22, m33 = p.inertia_A + p.m3 * p.r1**2, p.inertia_D, p.inertia_G3 + p.m3 * p.L3**2 / 4.0
    b = p.m3 * p.r1 * p.L3 / 2.0 * np.cos(q0 - q2 - alpha)
    energy = 0.5 * (m11 * v0**2 + m22 * v1**2 + m33 * v2**2) + b * v0 * v2
    rows = x.tolist()
    elements = system.elements
    if elements:
        # an element that moves with time (a moving object's contact) stores V at (t, q)
        energy = energy + np.array([sum(e.potential_at(s, (r[0], r[1], r[2])) if getattr(e, "time_varying", False)
                                        else e.potential((r[0], r[1], r[2])) for e in elements)
                                    for s, r in zip(t.tolist(), rows)])
    k1, k2 = p.r4 * math.cos(p.theta4), p.r4 * math.sin(p.theta4)
    f1 = p.r1 * np.cos(q0) + k1 - p.r2 * np.cos(q1) - p.r3 * np.cos(q2)
    f2 = p.r1 * np.sin(q0) + k2 - p.r2 * np.sin(q1) - p.r3 * np.sin(q2)
    residual = np.array(list(map(math.hypot, f1.tolist(), f2.tolist())))
    names = output_names(elements, (0.0, 0.0, 0.0))
    outputs = np.array([output_values(elements, s, (r[0], r[1], r[2]), (r[3], r[4], r[5]))
                        for s, r in zip(t.tolist(), rows)] if names else np.empty((len(rows), 0)))
    return energy, residual, outputs.reshape(len(rows), len(names))


@dataclass
class Trajectory:
    """A run sampled at every step, t = 0 included. Angles rad, rates rad/s, energy J, |Φ| m;
    `outputs`: what the force elements report (name → one value per sample, e.g. grip_force, N)."""

    t: np.ndarray
    q: np.ndarray  # (N, 3)
    v: np.ndarray  # (N, 3)
    energy: np.ndarray
    residual: np.ndarray
    method: str
    method_reason: str
    wall_time: float  # s, stepping only
    outputs: dict[str, np.ndarray] = field(default_factory=dict)
    #: the integrator's estimate of the θ error at the end (rad; NaN: a fixed-step method, none)
    error_estimate: float = math.nan
    #: a drive scene's energy balance, J (`finger_sim.actuators.stepping.EnergyLedger.report`); else empty
    energy_report: dict[str, float] = field(default_factory=dict)

    #: The columns every run has; the elements' outputs follow them (`csv_header`).
    CSV_HEADER = "t,theta1,theta2,theta3,theta1_dot,theta2_dot,theta3_dot,energy,constraint_residual"

    @staticmethod
    def csv_header(output_columns: Sequence[str] = ()) -> str:
        """The CSV header: CSV_HEADER, then the elements' output names."""
        return ",".join([Trajectory.CSV_HEADER, *output_columns])

    def write_csv(self, path: str | Path) -> None:
        data = np.column_stack([self.t, self.q, self.v, self.energy, self.residual, *self.outputs.values()])
        np.savetxt(path, data, delimiter=",", header=self.csv_header(list(self.outputs)), comments="", fmt="%.17g")

    def summary(self) -> str:
        line = summary_line(self.t[-1], self.q[-1], float(self.residual.max()), self.energy[-1] - self.energy[0],
                            self.method, len(self.t) - 1, self.wall_time, self.error_estimate)
        if self.energy_report:
            from finger_sim.actuators.report import energy_line

            line += "\n" + energy_line(self.energy_report)
        return line


def summary_line(t_end: float, q_end: Sequence[float], max_residual: float, energy_change: float, method: str,
                 steps: int, wall_time: float, error_estimate: float = math.nan) -> str:
    """The one-line run summary `finger-sim simulate` prints (s, rad, m, J; wall s, NaN for none;
    error_estimate: the integrator's estimated θ error, rad, NaN for none)."""
    deg = np.degrees(q_end)
    return (
        f"t = {t_end:.4g} s  θ = ({deg[0]:.2f}°, {deg[1]:.2f}°, {deg[2]:.2f}°)  "
        f"max|Φ| = {max_residual:.2e} m  ΔE = {energy_change:+.3e} J  "
        f"method = {method}  steps = {steps}"
        + (f"  est. error = {error_estimate:.1e} rad" if math.isfinite(error_estimate) else "")
        + (f"  wall = {wall_time:.3f} s" if math.isfinite(wall_time) else "")
    )


def simulate(scene: Scene, *, kernel: str = "auto") -> Trajectory:
    """Run `scene` from t = 0 to its duration (rounded up to whole steps) and record every step.

    On the compiled kernel a smooth scene's steps run in one kernel loop (`kernel.runner`);
    "auto" runs a short scene in Python (`kernel.offline_kernel`: loading numba costs more).
    """
    n = scene.step_count
    sim = Simulator(scene, kernel=stepper_slot.kernel().offline_kernel(kernel, n))
    x0 = (*sim.q, *sim.v)
    start = time.perf_counter()
    drive_outputs: dict[str, np.ndarray] = {}
    report: dict[str, float] = {}
    if sim._friction is not None:  # its holding torques are read back after the run: keep every row's
        sim._friction.memory = n + 1
    if sim._drive is not None:  # the mesh mode is discrete state: its outputs are taken as the run goes
        from finger_sim.actuators import record

        xs, drive_outputs, report = record.run(sim, n)
    else:
        xs = stepper_slot.kernel().advance(sim, n)  # in the kernel where it can, else step by step
    wall = time.perf_counter() - start
    x = np.vstack([x0, xs])
    t = np.arange(n + 1) * sim.dt  # k·dt, as Simulator.time
    energy, residual, values = state_columns(sim.system, t, x)
    names = output_names(sim.system.elements, sim.q)
    outputs = {**{name: values[:, i] for i, name in enumerate(names)}, **drive_outputs}
    if scene.sensors is not None:  # read from the outputs after the run: the dynamics never see them
        outputs.update(SensorBank(scene.sensors, sim.dt).measure(outputs))
    return Trajectory(
        t=t,
        q=np.ascontiguousarray(x[:, :3]),
        v=np.ascontiguousarray(x[:, 3:]),
        energy=energy,
        residual=residual,
        method=sim.method,
        method_reason=sim.method_reason,
        wall_time=wall,
        outputs=outputs,
        error_estimate=sim.error_estimate,
        energy_report=report,
    )
