"""The Simulator: fixed-rate stepping of a scene on its time grid, split at breakpoints and events.

`Simulator` advances exactly dt per step (t = n·dt, never accumulated), whatever the integrator,
so the node and offline runs share one path and the same torques at the same steps give
bit-identical states. A torque profile's breakpoints cut the step into smooth segments; the
events of the non-smooth force elements (a stop impact, a contact onset) are located inside a
segment (`simulation.crossings`) and the segment is split there; a stop's impact may start its
rest mode (`simulation.impact`). An owner that steps its own modes (`simulation.mode_stepping`,
listed in `simulation.mode_owners`) steps the segment instead, with the same pieces. The values of the
declared modes live in one home per run (`mode_values`, `state_layout.ModeValues`), each owner's at its
own entries.
"""

from __future__ import annotations

import math
from typing import NamedTuple

from finger_sim import stepper_slot
from finger_sim.actuators.base import Actuator
from finger_sim.effects import EFFECTS
from finger_sim.errors import SimulationDiverged
from finger_sim.inputs import BREAK_EPS, HELD_ARRAY, Profile
from finger_sim.integrators import HeldTorque, Integrator, TorqueFn
from finger_sim.kinematics import ZERO, Vec3
from finger_sim.projection import OK as FAST_OK
from finger_sim.scene import Scene
from finger_sim.simulation import actuated, crossings, event_step, gap_screen, impact, mode_owners
from finger_sim.simulation.crossings import Crossing, Gap
from finger_sim.simulation.impact import FREE, REST_MODE, RESTING
from finger_sim.simulation.locate import ON_GAP
from finger_sim.simulation.mode_stepping import ModeStepping, leader
from finger_sim.simulation.setup import for_simulator
from finger_sim.state_layout import ModeValues, StateLayout, layout_of
from finger_sim.stepper_slot import BREAKPOINT
from finger_sim.tip_force_profile import refuse_profile

#: Events (impacts, kinks) allowed within one step before the run is declared chattering: room for
#: a stop's Zeno series down to its rest (`effects.stops.REST_HEIGHT`; e = 0.3 from 1e-2 rad: 10 impacts).
MAX_EVENTS_PER_STEP = 64
#: A step is split into substeps (auto on a contact scene) when a contact gap, moving at its
#: start rate, would close within this many step lengths: margin for the acceleration towards it.
NEAR_CONTACT = 2.0


class State(NamedTuple):
    """Time (s), q = (θ1, θ2, θ3) (rad) and q' (rad/s)."""

    t: float
    q: Vec3
    v: Vec3


#: State(t, q, v) without the NamedTuple's Python-level __new__ (0.3 µs of a 2 µs step).
_new_state = tuple.__new__


class Simulator:
    """Steps one scene at its fixed dt. Torque is the scene's profile, or a held value per step."""

    def __init__(self, scene: Scene, *, kernel: str = "auto", actuator: Actuator | None = None) -> None:
        """kernel: "auto" (compiled where numba and the scene allow), "compiled", "python", or a
        kernel name recorded by an earlier run; `self.kernel` names the one that runs. The set-up
        (system, method choice, stability check, compiled plan) is kept per scene (`setup_for`).
        actuator: an actuator with its own state in the slot (`actuators.base`), which takes the scene's
        input; None: the ideal torque source (or the scene's own actuator, `system.actuator`)."""
        refuse_profile(scene, "simulate or rollout")
        self.scene = scene
        # the registered effects are part of the key: a plug-in registered later builds another system
        effects = tuple(EFFECTS.values())
        if actuator is not None:  # its integrator and kernel are chosen below (`simulation.actuated`)
            requested, kernel = kernel, "python"
        # an owner of modes holds run state: its system is this Simulator's own
        setup = for_simulator(scene, kernel, effects)
        self.system, self.dt, self.method, self.method_reason = setup.system, scene.dt, setup.method, setup.reason
        #: steps in contact (or closing a contact within the step) are split in this many (auto only)
        self.substeps = setup.substeps
        #: keyword options of the integrator (auto's error-controlled method: its tolerances)
        self._options = setup.options
        self._method_cls, self._integrator_cls, self.kernel = setup.method_cls, setup.integrator_cls, setup.kernel
        #: the kernel asked for: "python" keeps an owner's mode guards in Python under our DOP853 too
        #: (whose stages are compiled by construction, `self.kernel` naming the compiled kernel)
        self.requested_kernel = kernel
        if actuator is not None:
            self._integrator_cls, self.substeps, self.kernel, note = actuated.integrator_class(scene, setup, actuator,
                                                                                              requested)
            self.method, self._options, self.method_reason = self._integrator_cls.name, {}, self.method_reason + note
        #: the actuator with its own state in the slot, or None
        self._actuator = actuator
        owners = (*self.system.elements, actuator or self.system.actuator)
        #: the declared state: (q, q', then the actuator's own slots), and the owners' modes
        self.layout: StateLayout = layout_of(self.system.elements, owners[-1])
        self._gaps, self._kinks, self._gap_elements = setup.gaps, setup.kinks, setup.gap_elements
        #: the gaps declared to the guard loop (`crossings.first_crossing`): all ON_GAP, and which are impact gaps
        self._gap_kinds = (ON_GAP,) * len(self._gaps)
        self._gap_impacts = tuple(gap.restitution is not None for gap in self._gaps)
        #: the start's findings at the initial state, shared by the scene's Simulators (`Setup.kept_start`)
        self.kept_start = setup.kept_start
        #: the run's discrete state: each declared mode's value, in `layout.modes` order
        self.mode_values = ModeValues(self.layout, owners)
        self._mode_list = self.mode_values.values
        #: the owners that step their own modes (`simulation.mode_stepping`), in owner order
        self.mode_steppings: tuple[ModeStepping, ...] = mode_owners.steppings(owners)
        #: the one of them that steps the segment (it carries the others' modes), or None: the gap loop here
        self._stepping = leader(self.mode_steppings)
        self._after_step = None if self._stepping is None else self._stepping.after_step
        #: where the rest mode of the impact gaps' owner (the stops' `rest`) is in `mode_values`, or None
        rest_owner = next((gap.element for gap in self._gaps if gap.restitution is not None), None)
        self._rest_at = None if rest_owner is None else self.mode_values.position(rest_owner, REST_MODE)
        if actuator is not None and self.substeps > setup.substeps:  # auto's rk6 for the actuator: its contact substeps
            self._kinks = tuple(gap for gap in self._gaps if gap.restitution is None)
        #: the depth gaps (`DepthLimit`, last in `_gaps`): (position of the contact gap in `_gaps`, ρ) each
        self._depth_sources = setup.depth_sources
        #: elements whose gaps move with time too (contact with a moving object): asked at (t, q)
        self._timed = frozenset(g.element for g in self._gaps if getattr(g.element, "time_varying", False))
        #: the compiled check of a step's end gaps (`simulation.gap_screen`), or None: the Python check alone
        self._gap_screen = gap_screen.for_simulator(self)
        #: what DOP853 watches in the gap loop's steps (`crossings.step_to_crossing`), or None: they are not watched
        self._watch = crossings.watch_for(self)
        self.reset()
        #: the compiled common step of a scene with events (`simulation.event_step`), or None
        self._event_step = event_step.for_simulator(self)
        #: the lean compiled path of `step` (a compiled fixed-step method on a smooth scene), else None
        self.fast_stepper = setup.fast_stepper
        #: what `step`'s lean path calls: the fast stepper, or the one the stepping owner allows
        self._lean = self.fast_stepper if self._stepping is None else self._stepping.fast_stepper(self)
        # every compiled function its step may call from Python, loaded now: numba loads one at its first call
        # in a process (5–20 ms), a stall of the paced step that first reaches that path (Python's event path)
        stepper_slot.kernel().load(call for owner in (self.integrator, self._gap_screen, self._event_step)
                                   if owner is not None for call in owner.compiled_calls())

    def reset(self) -> None:
        """Back to the scene's initial state at t = 0."""
        # A fresh integrator: a warm start kept from the last run (adaptive's step size,
        # rattle's Jacobian) would make the rerun differ in the last bits.
        self.mode_values.reset()  # before the integrator: a compiled model takes the modes it is built in
        self.integrator: Integrator = self._integrator_cls(self.system, **self._options)
        self.step_index = 0
        self.q, self.v = self.scene.initial_state()
        #: the impact gap rested on while the rest mode is `resting` (its release is located on it)
        self._rest_gap: Gap | None = None
        #: `crossings.gap_states`' last (q, q', gaps and rates, t)
        self._gap_cache: tuple[Vec3, Vec3, list[tuple[float, float]], float] | None = None
        if self._gap_screen is not None:
            self._gap_screen.reset()
        #: the motor torque at the end of the last step (N·m): what a JointState effort reports
        #: (with a voltage input: the command, V)
        self.torque = self.scene.torque(0.0)
        if self._stepping is not None:  # the owners' modes at the initial state
            self._stepping.start(self)
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
    def state_vector(self) -> tuple[float, ...]:
        """The continuous state at the current step, flat, in `layout` order: each owner's own slots
        as its stepping reads them (`ModeStepping.own_slots`)."""
        own: tuple[float, ...] = ()
        for stepping in self.mode_steppings:
            own += stepping.own_slots(self)
        return self.layout.pack(self.q, self.v, own)

    @property
    def modes(self) -> tuple[str, ...]:
        """The value of each declared mode (`layout.modes`) at the current step, read from `mode_values`."""
        return self.mode_values.names

    @property
    def _resting(self) -> Gap | None:
        """The rest mode (its owner's entry in `mode_values`) as the closed impact gap rested on, or None: free."""
        at = self._rest_at
        return None if at is None or not self._mode_list[at] else self._rest_gap

    @_resting.setter
    def _resting(self, gap: Gap | None) -> None:
        """Enter the rest on `gap` (an impact that `rests`), or leave it (None: its release)."""
        self._mode_list[self._rest_at] = FREE if gap is None else RESTING  # type: ignore[index]
        self._rest_gap = gap

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
        events = self._event_step
        if events is not None:  # a step with no gap crossing, in one kernel call
            state = events.step(self, torque)
            if state is not None:
                return state
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
        if self._after_step is not None:  # the stepping owner's (`ModeStepping.after_step`)
            self._after_step(self)
        if events is not None:
            events.taken_in_python(self.integrator)
        return self.state

    # -- internals ---------------------------------------------------------------------
    def _advance(self, t0: float, t1: float, torque: TorqueFn) -> None:
        """Integrate [t0, t1] under a smooth torque, splitting it at every event on the way."""
        if self._stepping is not None:  # an owner steps its modes' events with the gaps' (`ModeStepping.advance`)
            self._stepping.advance(self, t0, t1, torque)
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
            if self._watch is not None:
                end, q1, v1 = crossings.step_to_crossing(self, t, q, v, t1, torque)
            else:
                end = t1
                q1, v1 = self._step(t, q, v, t1 - t, torque)
            crossing = self._first_crossing(t, q, v, end, q1, v1, torque)
            if crossing is None:
                if end < t + (t1 - t):  # stopped where a gap showed its other side, which no crossing confirmed
                    t, q, v = end, q1, v1
                    continue
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

    # -- events (`simulation.crossings`, `simulation.impact`), also taken by the owners' steppings
    def _first_crossing(self, t: float, q: Vec3, v: Vec3, t1: float, q1: Vec3, v1: Vec3,
                        torque: TorqueFn) -> Crossing | None:
        """The earliest gap crossing of the step (t, q, q') → (t1, q1, q1'), located; None if none."""
        return crossings.first_crossing(self, t, q, v, t1, q1, v1, torque)

    def _locate(self, gap: Gap, t: float, q: Vec3, v: Vec3, lo: tuple[float, float],
                hi: tuple[float, float, Vec3, Vec3], torque: TorqueFn) -> Crossing:
        """Where in (lo, hi] of the step from (t, q, q') the gap crosses (`crossings.locate_gap`)."""
        return crossings.locate_gap(self, gap, t, q, v, lo, hi, torque)

    def _impact(self, crossing: Crossing, torque: TorqueFn) -> Vec3:
        """q' just after the impact of a located crossing; zero when it starts the rest on the stop."""
        return impact.impact(self, crossing, torque)

    def _release_time(self, gap: Gap, t: float, t1: float, q: Vec3, torque: TorqueFn) -> float | None:
        """When in [t, t1] the finger resting on a closed gap leaves it; None if it stays throughout."""
        return impact.release_time(self, gap, t, t1, q, torque)
