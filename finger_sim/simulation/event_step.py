"""A Simulator's common step on a scene with events in one compiled call (`kernel.event_step`), where the scene allows.

On a scene with stops or contact, `Simulator.step` runs our DOP853 step by step in Python around
compiled attempts, then checks the step's end gaps (`simulation.gap_screen`). `EventStep.step`
takes a step that holds no crossing in one kernel call on the same numbers: the internal solution
(`DormandPrince853`'s state) is kept in the kernel's arrays while the kernel steps, and written back
to the integrator's attributes before Python takes a step (a possible crossing, a release from a
stop, a switch of a piecewise-constant profile inside the step, a profile without a compiled form),
so that Python's step, its event location included, runs exactly as it always
did. The estimates of `error_estimate` are recorded by the kernel at every step (its estimate rows) and moved
into the integrator when it reads or stores one (`DormandPrince853.estimates_elsewhere`).

A step whose end gaps show a possible contact onset or release is taken whole in the same call where
Python's step would integrate it under the same function (a held command, a constant or smooth profile):
the kernel locates each crossing on its internal steps' dense output and continues or restarts the
solution from it (`kernel.event_step._settle`, `kernel.event_crossing`), on Python's numbers. Where
Python must act (a crossing predicted between two ends on the same side, a phalanx axis in the object, an
impact whose rest test lies within the kernel's margin of its edge), the kernel hands the advanced step over
(`hand_over`) and Python locates it. A stop's impact is applied in the kernel (`kernel.event_step._impact`:
q' → −e q', or the rest on the stop when it holds to the step's end, RESTED), as `simulation.impact` applies it.

A smooth profile (ramp, sine) is evaluated in the kernel (its compiled form, `inputs.profile_array`);
a piecewise-constant one (step, square) is held at its segment's value (`Profile.on_segment`). A step
resting on a stop (the rest mode, `simulation.impact`) is checked in the kernel as
`JointStops.release_time` checks it, by the push into the stop at both ends
(`kernel.event_step.stays_at_rest`), with a margin for the compiled acceleration's round-off; where
the push is near zero, Python decides.

Who stepped last is told by the integrator's last output (`DormandPrince853._last`, a new tuple at
every Python step): the kernel continues only a solution whose last output is still the one it saw
after the Simulator's own last step, or one it started itself: a new integrator (a run's first step,
after `reset`) has its first step, the initial step size included, taken here (`_fresh`). Anything else
(a caller that set the solution, as the task sweep's hand-over does) lets Python take the step, and the
kernel continues from the step after.

Exists when the Simulator runs the compiled gap screen, steps with the compiled DOP853, and has
no drive, no stick–slip friction and no substeps near contact.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

import numpy as np

from finger_sim import stepper_slot
from finger_sim.inputs import BREAK_EPS, HELD, PIECEWISE_CONSTANT, Constant, Profile, profile_array
from finger_sim.integrators.base import HeldTorque
from finger_sim.integrators.dop853 import NO_ROWS, DormandPrince853
from finger_sim.kinematics import ZERO
from finger_sim.simulation import event_locate
from finger_sim.simulation.event_handover import hand_over
from finger_sim.simulation.event_locate import CompiledLocate

if TYPE_CHECKING:
    from finger_sim.simulation.driver import Simulator, State

#: Columns of the kernel's solution rows: (q, q').
WIDTH = 6
#: q' at rest on a stop (as `Simulator._advance` sets it).
#: State(t, q, v) without the NamedTuple's Python-level __new__ (as `Simulator.step`'s lean path).
_new_state = tuple.__new__
#: `EventStep._prepare`'s answer for a step resting on a stop (`EventStep._rest` takes it).
_AT_REST = object()
#: The compiled module → `common_step`'s entry point (its argument types never change: looked up once,
#: ≈ 0.3 ms, not at every Simulator's construction).
_ENTRY_POINTS: dict[Any, Any] = {}


class EventStep:
    """The compiled common step of one Simulator (`step`), holding DOP853's solution between kernel steps."""

    def __init__(self, sim: Simulator, plan: np.ndarray, compiled: Any) -> None:
        from finger_sim.simulation.driver import State  # (the driver imports this module)

        self._state = State
        integ = sim.integrator
        assert isinstance(integ, DormandPrince853)
        self._k, self._ok, self._event = compiled, compiled.OK, compiled.EVENT
        model, gaps = integ._model, int(plan[0])  # noqa: SLF001
        #: the kernel's workspace (`kernel.event_step`): the model and gap plan, then the solution
        self._ws = ws = np.zeros(compiled.workspace_size(len(model), len(plan), gaps))
        ws[:compiled.HEADER] = len(model), len(plan), gaps
        o = compiled.HEADER + len(model) + len(plan)
        ws[compiled.HEADER:o] = np.concatenate([model, plan])
        self._st = ws[o:o + compiled.ST_SIZE]  # views of ws: `kernel.event_step.parts`
        o += compiled.ST_SIZE
        self._arr = ws[o:o + compiled.ROWS * WIDTH].reshape(compiled.ROWS, WIDTH)
        self._log = ws[len(ws) - compiled.internal_steps.HISTORY_SIZE:]  # `kernel.event_step.log_of`
        end = len(ws) - compiled.internal_steps.HISTORY_SIZE
        #: the outputs' (q, estimate) rows the kernel records (`kernel.event_step.common_step`), and their count
        self._estimate_rows = ws[end - compiled.ESTIMATES_SIZE:end].reshape(compiled.ESTIMATE_ROWS,
                                                                            compiled.ESTIMATE_WIDTH)
        self._estimate_count, self._full, self._taken_at = compiled.ESTIMATE_COUNT, compiled.FULL, compiled.TAKEN
        self._st[compiled.RTOL], self._st[compiled.ATOL] = integ.rtol, integ.atol
        self._st[compiled.RESTITUTION] = sim.scene.restitution  # the stops' (`kernel.event_step._impact`)
        self._impacts, self._rest_gap, self._rested = compiled.IMPACTS, compiled.REST_GAP, compiled.RESTED
        self._st[compiled.HELD_AT] = HELD
        self._profile_at = slice(compiled.PROFILE_AT, compiled.PROFILE_AT + compiled.PROFILE_SIZE)
        self._profile_flag = compiled.PROFILE
        self._profile: Profile | None = None  # the smooth profile in the workspace
        #: `common_step(ws, k, dt, command, flags)`, its compiled entry (an int, floats, an int): one per process
        if compiled not in _ENTRY_POINTS:
            _ENTRY_POINTS[compiled] = compiled.entry_point(ws)
        self._call = _ENTRY_POINTS[compiled]
        self._stays = compiled.stays_at_rest
        self._rests = sim._rest_at is not None  # noqa: SLF001  (a stop's rest mode: `_rest` may run)
        self._x = slice(compiled.X, compiled.X + WIDTH)
        self._same, self._at_last = compiled.SAME, compiled.AT_LAST
        self._locate, self._settled, self._ended = compiled.LOCATE, compiled.SETTLED, compiled.ENDED
        #: the flags of the common step: continuing the kernel's last output under the same function, located
        #: while `locates`
        self._continuing = compiled.SAME | compiled.AT_LAST | compiled.LOCATE
        #: the scene's torque when it is a constant (its steps may run here), else None; its value (N·m); both
        self._constant = sim.scene.torque if type(sim.scene.torque) is Constant else None
        self._constant_value = float(self._constant.value) if self._constant is not None else 0.0
        self._scene_torque = (self._constant, self._constant_value)
        self._integ: DormandPrince853 | None = None  # the integrator the Simulator's last step left
        self._token: tuple | None = None  # and its last output then
        self._holds = False  # the arrays hold the solution (the integrator's attributes are behind)
        self._moved = False  # and the kernel has stepped it since it took it over
        #: the (q, q') tuples of the kernel's last output while the arrays hold the solution (else None): the
        #: Simulator's state is still that output where `sim.q is _q`
        self._q: tuple | None = None
        self._v: tuple | None = None
        self._taken = 0  # steps taken here outside `common_step`'s count (`_rest`'s, a stretch's)
        #: the steps of `taken` whose crossings the kernel located, for tests and benchmarks
        self.settled = 0
        #: the compiled location of a crossing (`simulation.event_locate`), or None: Python's
        self.locate: CompiledLocate | None = None

    def compiled_calls(self) -> tuple[stepper_slot.CompiledCall, ...]:
        """The compiled calls of its steps beside the common step (loaded here already): the restore of a declined
        step, the rest test (with a stop's rest mode), and the location's (`locate`), with arguments of their types."""
        k, ws = self._k, self._ws
        rest = ((k.stays_at_rest, (ws, 0.0, 0.0, 0.0, 0, 0.0, 0.0, 0.0, 0.0)),) if self._rests else ()
        return ((k.restore, (ws,)), *rest, *(() if self.locate is None else self.locate.compiled_calls()))

    @property
    def taken(self) -> int:
        """Steps taken here (the rest went to Python), for tests and benchmarks: `common_step`'s count and the
        others."""
        return self._taken + int(self._st[self._taken_at])

    @taken.setter
    def taken(self, value: int) -> None:
        self._taken, self._st[self._taken_at] = value, 0.0

    @property
    def locates(self) -> bool:
        """Whether the kernel locates a step's contact onsets and releases itself (`kernel.event_step._settle`);
        False: it hands every possible crossing to Python (`hand_over`), as the tests of that path set."""
        return bool(self._continuing & self._locate)

    @locates.setter
    def locates(self, value: bool) -> None:
        self._continuing = self._same | self._at_last | (self._locate if value else 0)

    def step(self, sim: Simulator, torque: Profile | float | None) -> State | None:
        """Take `sim.step(torque)` in the kernel: the state after it (the Simulator's state, torque and
        step index set); None: Python must take it (the integrator is then up to date)."""
        # The common step continues the kernel's own last output under the function it stepped under (the
        # scene's constant torque, or the same held value): what `_prepare` would find, decided at once
        # (`_q` is None unless the arrays hold the solution, whose last output has a token then; the flags
        # follow `locates`).
        if torque is None:
            fn, value = self._scene_torque
        elif type(torque) is float and (held := sim._held) is not None and held[0] == torque:  # noqa: SLF001
            fn, value = held[1], torque
        else:
            return self._prepared_step(sim, torque)
        integ = sim.integrator
        if not (fn is not None and sim.q is self._q and sim.v is self._v and integ is self._integ
                and integ._last is self._token and integ._torque is fn  # noqa: SLF001
                and ((at := sim._rest_at) is None or not sim._mode_list[at])):  # noqa: SLF001
            return self._prepared_step(sim, torque)
        k, dt = sim.step_index, sim.dt
        t1 = (k + 1) * dt
        status, q, v, end = self._call(self._ws, k, dt, value, self._continuing)  # (an int, floats, an int)
        if status:  # not OK
            return self._answered(sim, integ, fn, True, k, t1, status, q, v, end)
        sim.q, sim.v, sim.torque, sim.step_index = q, v, end, k + 1
        self._q, self._v = q, v
        return _new_state(self._state, (t1, q, v))

    def _prepared_step(self, sim: Simulator, torque: Profile | float | None) -> State | None:
        """`step` after the full preparation (`_prepare`): any step but the common one."""
        integ = sim.integrator
        k, dt = sim.step_index, sim.dt
        fn, value, flags, continues = self._prepare(sim, integ, torque, k, dt)
        if fn is None:
            return None
        if fn is _AT_REST:
            return self._rest(sim, value, flags, k)
        t1 = (k + 1) * dt
        status, q, v, end = self._call(self._ws, k, dt, value, flags)
        if status:
            return self._answered(sim, integ, fn, continues, k, t1, status, q, v, end)
        return self._took(sim, integ, fn, k, t1, q, v, end, q)

    def _answered(self, sim: Simulator, integ: DormandPrince853, fn: Any, continues: bool, k: int, t1: float,
                  status: int, q: tuple, v: tuple, end: float) -> State | None:
        """`step` after `common_step` answered other than OK (`_prepare`'s `continues`; t1: the step's end, s):
        the estimate rows read where full, crossings located here, or the step left to Python (None)."""
        if status >= self._full:  # the estimate rows are full: into the integrator before the next call
            status -= self._full
            integ.collect_estimates()
        last = q  # the solution's last output, which the next step may continue
        if status != self._ok:
            if status != self._settled and status != self._ended and status != self._rested:
                return self._decline(integ, fn, status == self._event, continues)
            self.settled += 1  # crossings located (and impacts applied) and stepped past here
            self.count_impacts(sim)
            if status == self._ended or status == self._rested:  # its state is not the solution's last output
                last = None
            if status == self._rested:
                sim._resting = sim._gaps[int(self._st[self._rest_gap])]  # noqa: SLF001  (`simulation.impact.impact`)
                v = ZERO
        return self._took(sim, integ, fn, k, t1, q, v, end, last)

    def _took(self, sim: Simulator, integ: DormandPrince853, fn: Any, k: int, t1: float, q: tuple, v: tuple,
              end: float, last: tuple | None) -> State:
        """The Simulator's and the solution's state after a step the kernel took to t1 (s), ending at (q, q')
        under τ = `end` (N·m); `last`: q if it is the solution's last output, else None. After the first step of a
        solution the kernel started, the integrator's last output is set to the kernel's, the token the next step
        checks (`step`); the rest of its attributes are written back only when Python steps (`release`)."""
        self._moved = True
        integ._torque = fn  # noqa: SLF001
        if self._token is None:
            integ._last = self._token = self._last_output()  # noqa: SLF001
        sim.q, sim.v, sim.torque, sim.step_index = q, v, end, k + 1
        self._q, self._v = last, v
        return _new_state(self._state, (t1, q, v))

    def _prepare(self, sim: Simulator, integ: DormandPrince853, torque: Profile | float | None, k: int,
                 dt: float) -> tuple[Any, float, int, bool]:
        """For step k: (the torque function Python's step integrates under, the held command in N·m,
        `common_step`'s flags, whether Python's step would integrate under that function itself rather than a
        new segment's), the solution taken over into the arrays; fn None: Python takes the step; fn _AT_REST:
        the finger rests on a stop (`_rest`)."""
        if not self.claim(integ):
            return None, 0.0, 0, False
        flags = 0
        continues = True  # Python's step integrates under fn itself (not a new segment's function)
        if torque is None and self._constant is not None:
            fn: Any = self._constant
            value = self._constant_value
        elif torque is None or isinstance(torque, Profile):
            fn, value, flags = self._profile_step(sim.scene.torque if torque is None else torque, k * dt, (k + 1) * dt)
            continues = flags != 0  # a smooth profile (a piecewise-constant one's segment is a new function each time)
        else:
            value = float(torque)
            held = sim._held  # noqa: SLF001
            if held is None or held[0] != value:  # `Simulator.step`'s one function object per held value
                held = sim._held = (value, HeldTorque(value))  # noqa: SLF001
            fn = held[1]
        if fn is None:  # a profile's step that Python takes
            self.release()
            return None, 0.0, 0, False
        at = sim._rest_at  # noqa: SLF001  (the stop's rest mode: `Simulator._resting`, read inline)
        if at is not None and sim._mode_list[at]:  # noqa: SLF001
            return _AT_REST, value, flags, continues
        if not self._holds:
            self._take_over(integ)
        if fn is integ._torque:  # noqa: SLF001
            flags |= self._same
        if sim.q is self._q and sim.v is self._v:
            flags |= self._at_last
        else:  # a state the kernel did not produce
            self._st[self._x] = (*sim.q, *sim.v)
        if continues and self.locates:
            flags |= self._locate
        return fn, value, flags, continues

    def count_impacts(self, sim: Simulator) -> None:
        """Add the stop impacts the kernel applied since the last count to `sim.impacts`."""
        count = self._st[self._impacts]
        if count:
            sim.impacts += int(count)
            self._st[self._impacts] = 0.0

    def _decline(self, integ: DormandPrince853, fn: Any, event: bool, continues: bool) -> None:
        """After `common_step` left the step to Python: the integrator made ready for Python's step. On
        EVENT (a possible crossing) under the function Python integrates under, the advanced step is handed
        over (Python locates from it, not integrating again); else the solution as before the step."""
        if event and continues:
            hand_over(self, integ, fn)
            self._holds = self._moved = False
            self._q = None
            return
        if event:  # Python integrates under a new function: the solution as before the step
            self._k.restore(self._ws)
        self.release()

    def claim(self, integ: DormandPrince853) -> bool:
        """Whether the kernel may take `integ`'s next step: it `follows` the solution, or the solution is
        new (a run's first step, a reset's: then taken into the arrays, `_start`), whose initial step is taken
        here too and for which no output of an earlier solution may stand. Otherwise another hand stepped or set
        it: the integrator is the truth, and Python takes the step."""
        if self.follows(integ):
            return True
        self._holds = self._moved = False
        self._q = None
        if not _fresh(integ):
            return False
        self._adopt(integ, None)
        self._start(integ)
        return True

    def follows(self, integ: DormandPrince853) -> bool:
        """Whether the kernel may continue `integ`'s solution: the one it took over, last stepped by the
        Simulator (its last output is the one seen then) or by the kernel since a first step taken here."""
        token = self._token
        if integ is not self._integ or integ._last is not token:  # noqa: SLF001
            return False
        return token is not None or (self._holds and _untouched(integ))

    def _rest(self, sim: Simulator, value: float, flags: int, k: int) -> State | None:
        """A step resting on a stop throughout (`Simulator._advance`'s rest mode, no release inside), checked
        in the kernel (`stays_at_rest`); None: Python takes it (a release may be near)."""
        self.release()  # the integrator is Python's again: the rest does not move it
        gap, q, dt = sim._resting, sim.q, sim.dt  # noqa: SLF001
        stays, end = self._stays(self._ws, k * dt, (k + 1) * dt, value, flags,
                                 gap.element.gap_gradient(gap.index, q)[0], *q)
        if not stays:
            return None
        sim.v, sim.torque, sim.step_index = ZERO, end, k + 1
        self.taken += 1
        return _new_state(self._state, ((k + 1) * dt, q, ZERO))

    def _profile_step(self, profile: Profile, t0: float, t1: float) -> tuple[Any, float, int]:
        """(the torque function `Simulator.step` integrates [t0, t1] under, the held value, flags) for a
        profile's step; (None, 0, 0) where Python must take it (a switch inside, no compiled form)."""
        code = profile.kernel_code
        if code is None:
            return None, 0.0, 0
        if code in PIECEWISE_CONSTANT:  # as `Simulator.step`: split at a switch inside, else held on the segment
            eps = BREAK_EPS * (t1 - t0)
            if any(t0 + eps < b < t1 - eps for b in profile.breakpoints(t0, t1)):
                return None, 0.0, 0
            segment = profile.on_segment(t0, t1)
            return segment, float(segment(t1)), 0
        if profile is not self._profile:  # a smooth profile: the kernel evaluates it at every stage
            self._st[self._profile_at] = 0.0
            array = profile_array(profile)
            self._st[self._profile_at.start:self._profile_at.start + len(array)] = array
            self._profile = profile
        return profile, 0.0, self._profile_flag

    def taken_in_python(self, integ: DormandPrince853) -> None:
        """The Simulator took its last step in Python: the kernel may continue from `integ`'s solution."""
        self._adopt(integ, integ._last)  # noqa: SLF001
        self._holds = self._moved = False
        self._q = None

    def _adopt(self, integ: DormandPrince853, token: tuple | None) -> None:
        """Follow `integ`'s solution, whose last output is `token` (None: a new one). Another integrator
        followed until now keeps the estimate rows recorded for it, copied out of the workspace, and takes them
        in only when it reads or stores an estimate (`KeptEstimates`; a reset's old integrator, which a node
        never reads); `integ` reads its own here (`DormandPrince853.estimates_elsewhere`)."""
        followed = self._integ
        if followed is not integ:
            if followed is not None:
                followed.estimates_elsewhere = KeptEstimates(self._recorded_estimates(followed))
            if integ.estimates_elsewhere is not None:  # rows kept for it elsewhere (followed before): in first
                integ.collect_estimates()
            integ.estimates_elsewhere = self._recorded_estimates
        self._integ, self._token = integ, token

    def _recorded_estimates(self, integ: DormandPrince853) -> np.ndarray:
        """The (q, estimate) rows the kernel recorded for `integ`'s outputs since last asked (n × 4, oldest
        first), forgotten here; none for an integrator not followed now."""
        st, at = self._st, self._estimate_count
        n = int(st[at])
        if not n or integ is not self._integ:
            return NO_ROWS
        st[at] = 0.0
        return self._estimate_rows[:n].copy()

    def release(self) -> None:
        """Write the solution back to the integrator, if the kernel moved it, for Python to step."""
        integ = self._integ
        if self._moved and integ is not None:
            self._write_back(integ)
        self._holds = self._moved = False
        self._q = None

    def _start(self, integ: DormandPrince853) -> None:
        """A new solution (`_fresh`) into the arrays: the integrator's scalars, no last output, no origin. Its
        arrays are not copied: the kernel's restart and first internal step write them before anything reads
        them (y, f at the start; y_old and the dense output after the step)."""
        k, st = self._k, self._st
        st[k.T], st[k.H], st[k.T_OLD], st[k.H_OLD] = integ._t, integ._h, integ._t_old, integ._h_old  # noqa: SLF001
        st[k.ERR], st[k.ERR_OLD] = integ._err, integ._err_old  # noqa: SLF001
        # (the screen's kept gaps and an ended step's output are of another step)
        st[k.HAS_LAST] = st[k.HAS_ORIGIN] = st[k.KNOWN] = st[k.HAS_END] = 0.0
        self._holds, self._moved, self._q = True, False, None

    def _take_over(self, integ: DormandPrince853) -> None:
        """The integrator's solution into the arrays (`kernel.event_step`'s layout)."""
        self._start(integ)
        k, st, arr = self._k, self._st, self._arr
        arr[k.Y], arr[k.F], arr[k.Y_OLD], arr[k.DENSE:k.KK] = integ._y, integ._f, integ._y_old, integ._dense  # noqa: SLF001
        last, origin = integ._last, integ._origin  # noqa: SLF001
        if last is not None:
            st[k.HAS_LAST], st[k.LAST_T] = 1.0, last[0]
            st[k.LAST_Q:k.LAST_Q + 3], st[k.LAST_V:k.LAST_V + 3] = last[1], last[2]
            st[k.LAST_EST] = integ.error_estimate(last[1])  # what a restart from it reads
        if origin is not None:
            st[k.HAS_ORIGIN], st[k.ORIGIN_T] = 1.0, origin[0]
            st[k.ORIGIN_Q:k.ORIGIN_Q + 3], st[k.ORIGIN_V:k.ORIGIN_V + 3] = origin[1], origin[2]

    def _write_back(self, integ: DormandPrince853) -> None:
        """The arrays' solution into the integrator's attributes, as its own steps would have left them
        (the history of internal steps pruned to the one that covers the last output)."""
        k, st, arr = self._k, self._st.tolist(), self._arr
        integ._t, integ._h, integ._t_old, integ._h_old = st[k.T], st[k.H], st[k.T_OLD], st[k.H_OLD]  # noqa: SLF001
        integ._err, integ._err_old = st[k.ERR], st[k.ERR_OLD]  # noqa: SLF001
        integ._y, integ._y_old = arr[k.Y].copy(), arr[k.Y_OLD].copy()  # noqa: SLF001
        integ._f[:], integ._dense[:] = arr[k.F], arr[k.DENSE:k.KK]  # noqa: SLF001
        integ._last = self._last_output()  # noqa: SLF001
        integ._origin = ((st[k.ORIGIN_T], tuple(st[k.ORIGIN_Q:k.ORIGIN_Q + 3]), tuple(st[k.ORIGIN_V:k.ORIGIN_V + 3]))  # noqa: SLF001
                         if st[k.HAS_ORIGIN] else None)
        integ._history[:] = [(integ._t_old, integ._h_old, integ._y_old, integ._dense.copy(), integ._err_old,  # noqa: SLF001
                              integ._err)]  # noqa: SLF001
        integ._history_starts[:] = [integ._t_old]  # noqa: SLF001
        self._token = integ._last  # noqa: SLF001

    def _last_output(self) -> tuple | None:
        """The arrays' solution's last output (t, q, q'), or None (a new solution)."""
        k, st = self._k, self._st
        if not st[k.HAS_LAST]:
            return None
        return float(st[k.LAST_T]), tuple(st[k.LAST_Q:k.LAST_Q + 3].tolist()), tuple(st[k.LAST_V:k.LAST_V + 3].tolist())


class KeptEstimates:
    """The estimate rows (n × 4: q, estimate in rad, oldest first) the kernel recorded for an integrator it no longer
    follows: its `estimates_elsewhere`, handing them over once, when it first reads or stores an estimate."""

    __slots__ = ("_rows",)

    def __init__(self, rows: np.ndarray) -> None:
        self._rows = rows

    def __call__(self, integ: DormandPrince853) -> np.ndarray:
        rows, self._rows = self._rows, NO_ROWS
        return rows


def _untouched(integ: DormandPrince853) -> bool:
    """Whether `integ`'s own solution attributes are as built: no output, no origin, no step size, no history
    (nobody stepped it or set it; the kernel's steps leave them so)."""
    return integ._last is None and integ._origin is None and integ._h <= 0.0 and not integ._history  # noqa: SLF001


def _fresh(integ: DormandPrince853) -> bool:
    """Whether `integ` has not stepped yet (untouched, no estimates): its first step, the initial step size
    included, may be taken by the kernel from its start."""
    return _untouched(integ) and not integ._estimates  # noqa: SLF001


def for_simulator(sim: Simulator) -> EventStep | None:
    """The compiled common step of `sim`, or None (no compiled gap screen, another method, an owner that
    steps its own modes, `Simulator.mode_steppings`, substeps near contact)."""
    screen = sim._gap_screen  # noqa: SLF001
    integ = sim.integrator
    if screen is None or sim.mode_steppings:
        return None
    if type(integ) is not DormandPrince853 or not integ.compiled or (sim.substeps != 1 and sim._kinks):  # noqa: SLF001
        return None
    step = EventStep(sim, screen._plan, stepper_slot.kernel().compiled_event_step())  # noqa: SLF001
    step.locate = event_locate.for_simulator(sim)
    return step
