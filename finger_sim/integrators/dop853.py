"""Our own adaptive method: Dormand-Prince 8(5,3) with error control and dense output, compiled.

Unlike `adaptive` (scipy's solve_ivp restarted at every grid step), this integrator keeps
its own step size across the Simulator's fixed output grid: it takes internal steps as
long as rtol/atol allow, and answers each `step(t, q, v, dt, torque)` from the 7th-order
dense output of the internal step that covers t + dt, projected onto Φ = 0, Φ_q q' = 0.
The internal solution itself is never projected, so the output grid does not change it.

It continues its internal solution only while the caller continues the last output with
the same torque function (same object) under the same modes of the system (`FingerSystem.mode_key`,
whatever element or actuator owns them; their switches are events of the Simulator's step); anything
else (a reset, a torque breakpoint, an event's trial step, a held command) restarts it from the given
state. The step-size control, error norm and dense output are scipy's DOP853 (scipy/integrate/_ivp/rk.py,
after Hairer, Nørsett & Wanner, *Solving ODEs I*, §II.10), with scipy's coefficients.

An attempt is `steps.dop853_attempt`, which the kernel compiles, with the system's right-hand side
(`stepper_slot.StageFunctions`: an actuator in the acceleration solve brings its own). A system with a
force element that has no compiled form (objects with different contact laws, a moving object) runs that same function in
Python on lists, its stages `FingerSystem.accelerations` (`_python_attempt`): slower, the same numbers.
"""

from __future__ import annotations

import bisect
import importlib.util
import math
import sys
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path
from types import ModuleType
from typing import Protocol

import numpy as np

from finger_sim import stepper_slot
from finger_sim.dynamics import FingerSystem
from finger_sim.errors import SimulationDiverged
from finger_sim.inputs import HELD_ARRAY
from finger_sim.integrators.base import Integrator, TorqueFn
from finger_sim.integrators.steps import E3_WEIGHT, StageModel, dop853_attempt, rhs
from finger_sim.kinematics import Vec3

#: scipy's DOP853 tableau module, which imports numpy only.
COEFFICIENTS_MODULE = "scipy.integrate._ivp.dop853_coefficients"


def _scipy_coefficients() -> ModuleType:
    """scipy's DOP853 coefficients, loaded from their file: importing them by name would first
    import the whole of scipy.integrate (≈ 0.3 s), which no fixed-rate run needs."""
    if COEFFICIENTS_MODULE in sys.modules:
        return sys.modules[COEFFICIENTS_MODULE]
    scipy_dir = Path(importlib.util.find_spec("scipy").submodule_search_locations[0])  # type: ignore[union-attr, index]
    spec = importlib.util.spec_from_file_location("finger_sim._dop853_coefficients",
                                                  scipy_dir / "integrate" / "_ivp" / "dop853_coefficients.py")
    module = importlib.util.module_from_spec(spec)  # type: ignore[arg-type]
    spec.loader.exec_module(module)  # type: ignore[union-attr]
    return module


coefficients = _scipy_coefficients()

#: Tolerances when a scene asks for `dop853` without its own: the error per unit time of
#: the internal solution, relative and absolute (rad, rad/s).
DEFAULT_RTOL = 1e-10
DEFAULT_ATOL = 1e-12
#: Attempts allowed for one internal step before the run is declared diverged.
MAX_ATTEMPTS = 60
#: The longest internal step, s: a state exactly at rest (zero error) would otherwise grow it without bound.
MAX_STEP = 0.1
#: `initial_step`: the first internal step is this share of ‖y‖/‖y'‖ (both scaled), or TINY_FIRST_STEP (s)
#: where either scaled norm is below TINY_NORM (a state at rest, or at zero): Hairer's and scipy's constants.
FIRST_STEP_SHARE, TINY_FIRST_STEP, TINY_NORM = 0.01, 1e-6, 1e-5
#: Internal steps per call of the compiled loop (`DormandPrince853._advance_compiled`): rows of history.
COMPILED_CHUNK = 32
#: `error_estimate` remembers this many recent outputs (the states event location tried within
#: a step); older ones are dropped down to KEEP_OUTPUTS.
MAX_OUTPUTS, KEEP_OUTPUTS = 4096, 256
#: An empty block of deferred estimates (`DormandPrince853.defer_estimates`): a single output's.
NO_ROWS = np.empty((0, 4))
#: `straddles` leaves a kink straddled by fewer than this many units in the last place of its time (s): the
#: internal step to it would be too short to take (`_advance`'s floor is 10).
CUT_ULPS = 100

_N_STAGES = coefficients.N_STAGES
#: Stage nodes of one attempt: the 12 stages, t + h, then the 3 extra dense-output stages.
_NODES = tuple(float(c) for c in (*coefficients.C[:_N_STAGES], 1.0, *coefficients.C[_N_STAGES + 1:]))
_A = np.ascontiguousarray(coefficients.A, dtype=np.float64)
_B = np.ascontiguousarray(coefficients.B, dtype=np.float64)
_C = np.ascontiguousarray(coefficients.C, dtype=np.float64)
_E3 = np.ascontiguousarray(coefficients.E3, dtype=np.float64)
_E5 = np.ascontiguousarray(coefficients.E5, dtype=np.float64)
_D = np.ascontiguousarray(coefficients.D, dtype=np.float64)
_E53 = np.vstack([_E5, _E3])  # both error estimates in one product
#: The coefficients as nested lists, for the attempt in Python (`_python_attempt`)
_LISTS = tuple(x.tolist() for x in (_A, _B, _C, _E3, _E5, _D))


class Watch(Protocol):
    """What a watched `DormandPrince853.step` watches (`simulation.crossings.GapWatch`): the gaps at an internal
    step's end against the step's start."""

    def crossed(self, t: float, q: Vec3, s: float, y: np.ndarray) -> bool:
        """Whether the internal state y = (q, q') at s (s) shows a gap on its other side than the step's start
        (t, q)."""

    def compiled(self) -> tuple[np.ndarray, np.ndarray] | None:
        """The same test for the compiled chunk (`kernel.internal_steps.advance_to`): the gap plan
        (`kernel.gap_screen`) and a 4 × n_gaps work array; None: Python's test only."""


class DormandPrince853(Integrator):
    """DOP853 with error control and dense output at the fixed output grid, compiled; projected outputs.

    Cost: 12 acceleration solves per accepted internal step + 3 for its dense output, the
    internal step set by rtol/atol (often many output steps long on a smooth scene), plus
    one dense evaluation and one projection per output step.
    """

    name = "dop853"
    order = 8
    keeps_constraints = True

    def __init__(self, system: FingerSystem, *, rtol: float = DEFAULT_RTOL, atol: float = DEFAULT_ATOL) -> None:
        compiled = stepper_slot.kernel()
        super().__init__(system)
        model = compiled.model_array(system)
        #: whether the stages run compiled; else in Python (a force element without a compiled form)
        self.compiled = model is not None
        if model is None:  # the geometry alone (no elements) for the compiled dense output and projection
            model = compiled.model_array(FingerSystem(system.params))
        self._numerics, self._model = compiled.compiled_numerics(), model
        self._stages = StageModel(system)  # the model of an attempt in Python
        #: the system's compiled right-hand side, attempt and internal-step loop (`stepper_slot.StageFunctions`)
        stages = compiled.stage_functions(system)
        self._rhs, self._attempt = stages.rhs, stages.dop853_attempt
        #: the compiled model the stages run on, whose mode slots follow the system's modes, for an actuator's
        #: compiled guards (`actuators.stepping.start`); None with stages in Python
        self.guard_model = model if self.compiled else None
        #: `system.mode_key` when it has modes, else None; and the key the internal solution is under
        self._mode_key_now = system.mode_key if system.mode_owners else None
        self._mode_key: list | None = None
        self.rtol, self.atol = rtol, atol
        self._torque: TorqueFn | None = None
        self._last: tuple[float, Vec3, Vec3] | None = None  # the last output (t, q, q')
        self._t = 0.0  # internal time, s
        self._y = np.empty(6)  # internal state at _t
        self._f = np.empty(6)  # y' at _t
        self._h = 0.0  # next internal step, s
        self._t_old = self._h_old = 0.0  # the last accepted step: its start and length
        self._y_old = np.empty(6)
        self._dense = np.zeros((7, 6))
        self._kk = np.empty((16, 6))
        self._out = np.empty(6)
        self._taus = np.empty(len(_NODES))  # τ at the stage times of a held torque
        #: accepted and rejected internal steps so far (for benchmarks)
        self.accepted = self.rejected = 0
        self._err = 0.0  # Σ local θ error estimates of the internal solution since its start, rad
        self._err_old = 0.0  # `_err` at the start of the last accepted step
        self._settled: dict[Vec3, float] = {}  # output q → estimated θ error there (`_estimates`)
        #: blocks of estimates not yet in it (`defer_estimates`), oldest first, and their row count
        self._deferred: list[tuple[np.ndarray, Vec3, float]] = []
        self._deferred_rows = 0
        #: where estimates of this integrator's outputs are recorded outside it (the compiled common step's rows,
        #: `simulation.event_step`), or None: called with the integrator before any estimate is read or stored
        #: here, it hands them over, oldest first (n × 4: q, estimate in rad), and forgets them
        self.estimates_elsewhere: Callable[[DormandPrince853], np.ndarray] | None = None
        #: (t, q, q') the internal solution started from at its last restart, or continued from
        self._origin: tuple[float, Vec3, Vec3] | None = None
        #: accepted internal steps since then, (t_old, h_old, y_old, dense, err_old, err), and their starts
        self._history: list[tuple[float, float, np.ndarray, np.ndarray, float, float]] = []
        self._history_starts: list[float] = []
        self._keep_history = True
        #: the end (s) of the internal step a compiled watched step stopped at (`simulation.event_handover`): the
        #: next watched `step` stops there too, as its own watch would have
        self._hit: float | None = None
        #: the compiled loop of internal steps under a held torque (`kernel.internal_steps`), or None
        #: (stages in Python, a system without one), and its scalars and scratch arrays
        self._steps = stages.internal_steps() if self.compiled else None
        self._step_scalars = np.empty(self._steps.ST_SIZE) if self._steps is not None else None
        self._y_next, self._f_next = np.empty(6), np.empty(6)
        self._y_scratch, self._y_new = np.empty(6), np.empty(6)

    def compiled_calls(self) -> tuple[stepper_slot.CompiledCall, ...]:
        """The compiled functions of its Python steps (`step`, `cut_at`, `_advance`, `_advance_compiled`), with
        arguments of the types those pass (its own arrays, floats; the watch's gap plan and work are arrays as
        NO_PLAN and NO_WORK are)."""
        num, m, y, kk, dense = self._numerics, self._model, self._y, self._kk, self._dense
        calls: list[stepper_slot.CompiledCall] = [
            (num.dop853_output, (m, 0.0, 0.0, self._y_old, dense, 0.0, self._out)),
            (num.dop853_theta_error, (_E53, kk, 0.0, E3_WEIGHT)),
            (num.crossing_retry, (m, y, self._y_new, 0.0, 0.0)),
        ]
        if self.compiled:
            calls += [(self._rhs, (m, 0.0, y, 0.0, self._f)),
                      (self._attempt, (m, _A, _B, _C, _E3, _E5, _D, 0.0, y, self._f, 0.0, self._taus, self.rtol,
                                       self.atol, kk, self._y_new, dense))]
        k = self._steps
        if k is not None:
            rows = np.empty((0, k.ROW_SIZE))
            calls.append((k.advance_to, (m, self.rtol, self.atol, self._step_scalars, self._y_next, self._f_next,
                                         self._y_scratch, dense, kk, self._y_new, self._taus, HELD_ARRAY, 0.0, rows,
                                         False, k.NO_PLAN, k.NO_WORK, k.NO_PLAN)))
        return tuple(calls)

    def error_estimate(self, q: Vec3) -> float:
        """The estimated θ error (rad) of an output q of this integrator (0 for a state it did not
        produce): the sum of the local error estimates of the accepted internal steps on the path that
        led to it, each bounded as √6·norm·(atol + rtol·|θ|), carried through restarts from an
        earlier output (an impact keeps q). Linear accumulation: error growth or decay along the
        flow is not modelled."""
        if self.estimates_elsewhere is not None:
            self.collect_estimates()
        for block, last_q, estimate in reversed(self._deferred):  # the newest entry for q wins, as in the dict
            if last_q == q:
                return estimate
            hits = np.flatnonzero((block[:, 0] == q[0]) & (block[:, 1] == q[1]) & (block[:, 2] == q[2]))
            if len(hits):
                return float(block[hits[-1], 3])
        return self._settled.get(q, 0.0)

    @property
    def _estimates(self) -> dict[Vec3, float]:
        """Output q → estimated θ error there (rad), insertion-ordered, at most MAX_OUTPUTS: the deferred
        blocks settled into it first."""
        if self.estimates_elsewhere is not None:
            self.collect_estimates()
        if self._deferred:
            self._settle()
        return self._settled

    @_estimates.setter
    def _estimates(self, value: dict[Vec3, float]) -> None:
        self._settled, self._deferred, self._deferred_rows = value, [], 0

    def defer_estimates(self, rows: np.ndarray, q: Vec3, estimate: float) -> bool:
        """Record the estimates of consecutive outputs later, when `_estimates` is read (`error_estimate`
        reads them as they are): rows (n × 4: q, estimate in rad) then the last output q with `estimate`,
        the same entries as n + 1 calls of `store_estimate`. False (nothing recorded): they would reach
        MAX_OUTPUTS, whose drops the caller applies to the dict."""
        if self.estimates_elsewhere is not None:
            self.collect_estimates()
        return self._defer(rows, q, estimate)

    def _defer(self, rows: np.ndarray, q: Vec3, estimate: float) -> bool:
        """`defer_estimates` without collecting the estimates recorded elsewhere first."""
        count = len(rows) + 1
        if len(self._settled) + self._deferred_rows + count > MAX_OUTPUTS:
            return False
        self._deferred.append((rows, q, estimate))
        self._deferred_rows += count
        return True

    def collect_estimates(self) -> None:
        """The estimates recorded elsewhere (`estimates_elsewhere`) into this integrator's, as one `store_estimate`
        per output in their order: deferred as a block where no drop is due, else stored one by one."""
        rows = self.estimates_elsewhere(self)  # type: ignore[misc]
        if len(rows) > 1 and self._defer(rows[:-1], tuple(rows[-1, :3].tolist()), float(rows[-1, 3])):
            return
        for a, b, c, estimate in rows.tolist():
            self._store((a, b, c), estimate)

    def _settle(self) -> None:
        """The deferred blocks into the dict, oldest first (none reaches MAX_OUTPUTS: `defer_estimates`)."""
        settled = self._settled
        for block, q, estimate in self._deferred:
            settled.update(zip(map(tuple, block[:, :3].tolist()), block[:, 3].tolist()))
            settled[q] = estimate
        self._deferred, self._deferred_rows = [], 0

    def carry(self, q_from: Vec3, q_to: Vec3, error: float) -> None:
        """Give q_to, a state another solver reached from q_from (a ride with a moving object,
        `finger_sim.stick_slip_moving`), q_from's estimate plus that solver's own `error` (rad)."""
        if len(self._estimates) >= MAX_OUTPUTS:
            self._estimates = dict(list(self._estimates.items())[-KEEP_OUTPUTS:])
        self._estimates[q_to] = self._estimates.get(q_from, 0.0) + error

    def step(self, t: float, q: Vec3, v: Vec3, dt: float, torque: TorqueFn,
             watch: Watch | None = None) -> tuple[Vec3, Vec3]:
        """The output at t + dt (s) of the internal solution from (t, q, q') under `torque`. With `watch`
        (`simulation.crossings.step_to_crossing`), the internal steps stop one step past the first that ends
        before t + dt where `watch.crossed` (t, q, its end time, its end state y) is True (a gap on its other side),
        if that one ends before t + dt too: the output is there, at the time `_last` holds."""
        target = t + dt
        last = self._last
        if not self.under_current_modes():
            self._torque = None  # a mode changed: the internal solution is another mode's
        if torque is self._torque and self._origin == (t, q, v) and target >= t:
            pass  # a trial from the internal solution's start (event location): answered from it
        elif torque is self._torque and last is not None and last[1] == q and last[2] == v \
                and abs(last[0] - t) <= 1e-9 * dt and target >= self._t_old:
            self._origin = (t, q, v)  # continuing the last output: later trials start here
            self._prune(t)
        else:
            self._restart(t, q, v, dt, torque)
        if watch is not None:
            target = self._watched(t, q, v, target, torque, watch)
        else:
            held = getattr(torque, "value", None)  # a held or constant torque (`HeldTorque`, `inputs.Constant`)
            if held is not None and self._steps is not None and self._t < target:
                self._advance_compiled(target, held)
            while self._t < target:
                self._advance(torque)
        t_old, h_old, y_old, dense, err_old, err = self._segment(target)
        status, q1, v1 = self._numerics.dop853_output(self._model, t_old, h_old, y_old, dense, target, self._out)
        if status != self._numerics.OK:
            raise SimulationDiverged("non-finite or unprojectable state", method=self.name, t=target, dt=dt)
        self._last = (target, q1, v1)
        self._remember(q1, target, t_old, h_old, err_old, err)
        return q1, v1

    def _watched(self, t: float, q: Vec3, v: Vec3, target: float, torque: TorqueFn, watch: Watch) -> float:
        """`step`'s internal steps from (t, q, q') to `target` (s) under `watch`: the time of its output
        (`simulation.crossings.step_to_crossing`: they stop one internal step past the first whose end shows a
        gap crossed). Under a held torque in compiled chunks that watch on the gap plan (`watch.compiled`), else
        (and to retry a step the chunk could not take) in Python's loop; a pass the kernel's event step stopped
        (`_hit`) stops there again."""
        hit, self._hit = self._hit, None
        if hit is not None and hit == self._t and t < hit < target:
            return hit
        seen = False  # an internal step ended with a gap on its other side: one more, then stop
        held = getattr(torque, "value", None)  # a held or constant torque, as in `step`
        if held is not None and self._steps is not None and self._t < target:
            gaps = watch.compiled()
            if gaps is not None:
                state = self._advance_compiled(target, held, gaps=(*gaps, np.array((*q, *v))))
                if state == self._steps.STOPPED:
                    return self._t
                seen = state == self._steps.SEEN
        while self._t < target:
            self._advance(torque)
            if self._t < target and (seen or watch.crossed(t, q, self._t, self._y)):
                if seen:
                    return self._t
                seen = True
        return target

    @contextmanager
    def aside(self) -> Iterator[None]:
        """Steps inside are trials from the internal solution that leave its continuation as it was
        (an energy quadrature between two steps): the next step continues as without them."""
        last = self._last
        try:
            yield
        finally:
            self._last = last

    def _segment(self, target: float) -> tuple[float, float, np.ndarray, np.ndarray, float, float]:
        """The accepted internal step whose dense output covers `target` (s): the last one, or an
        earlier one kept in the history since the last restart."""
        if target >= self._t_old or not self._history:
            return self._t_old, self._h_old, self._y_old, self._dense, self._err_old, self._err
        i = max(0, bisect.bisect_right(self._history_starts, target) - 1)
        return self._history[i]

    def _prune(self, t: float) -> None:
        """Drop the history of internal steps that end before t (s): no trial starts before it again."""
        keep = bisect.bisect_right(self._history_starts, t) - 1
        if keep > 0:
            del self._history[:keep], self._history_starts[:keep]

    def _remember(self, q: Vec3, target: float, t_old: float, h_old: float, err_old: float, err: float) -> None:
        """Record the estimate at an output q at time `target` (s), interpolated linearly over the
        internal step (t_old, h_old) that covers it, whose estimates at its ends are err_old and err."""
        self.store_estimate(q, interpolated_estimate(target, t_old, h_old, err_old, err))

    def store_estimate(self, q: Vec3, estimate: float) -> None:
        """Record the estimate (rad) at an output q; at MAX_OUTPUTS the oldest are dropped down to KEEP_OUTPUTS."""
        if self.estimates_elsewhere is not None:
            self.collect_estimates()
        self._store(q, estimate)

    def _store(self, q: Vec3, estimate: float) -> None:
        """`store_estimate` without collecting the estimates recorded elsewhere first."""
        if self._deferred and self._defer(NO_ROWS, q, estimate):  # after the deferred ones, in order
            return
        if self._deferred:
            self._settle()
        if len(self._settled) >= MAX_OUTPUTS:
            self._estimates = dict(list(self._settled.items())[-KEEP_OUTPUTS:])
        self._settled[q] = estimate

    def run_grid(self, times: np.ndarray, q: Vec3, v: Vec3, torque: TorqueFn) -> np.ndarray:
        """Outputs at times[1:] from (q, q') at times[0], all under one smooth `torque`: the (n, 6)
        projected states (q, q'), the same numbers as n calls of `step` on that grid."""
        n = len(times) - 1
        out = np.empty((n, 6))
        self._keep_history = False  # one pass over the grid: no trial goes back
        self._restart(float(times[0]), q, v, float(times[1] - times[0]), torque)
        done = 0
        while done < n:
            self._advance(torque)
            end = done + int(np.searchsorted(times[done + 1:], self._t, side="right"))
            if end > done:
                status = self._numerics.dop853_outputs(self._model, self._t_old, self._h_old, self._y_old, self._dense,
                                                       times[done + 1: end + 1], out[done:end])
                if status != self._numerics.OK:
                    raise SimulationDiverged("non-finite or unprojectable state", method=self.name, t=float(times[end]))
                done = end
        a, b, c, d, e, f = out[-1].tolist()
        self._last = (float(times[-1]), (a, b, c), (d, e, f))
        self._origin = None
        self._keep_history = True
        self._remember((a, b, c), float(times[-1]), self._t_old, self._h_old, self._err_old, self._err)
        return out

    def _restart(self, t: float, q: Vec3, v: Vec3, dt: float, torque: TorqueFn) -> None:
        self._torque = torque
        self._origin = (t, q, v)
        self._hit = None
        self._history.clear()
        self._history_starts.clear()
        self._err = self._err_old = self.error_estimate(q)  # (the deferred estimates left as they are)
        self._t = self._t_old = t
        self._y[:3], self._y[3:] = q, v
        self.adopt_modes()
        self._slope(t, torque)
        if self._h <= 0.0:
            self._h = initial_step(self._y, self._f, self.rtol, self.atol, dt)

    def adopt_modes(self) -> None:
        """Take the system's current modes as those the internal solution is under (at a restart, or for a
        solution continued elsewhere under them, by a compiled batch)."""
        if self._mode_key_now is not None:
            self._mode_key = self._mode_key_now()

    def under_current_modes(self) -> bool:
        """Whether the internal solution was computed under the system's current modes."""
        return self._mode_key_now is None or self._mode_key_now() == self._mode_key

    def _slope(self, t: float, torque: TorqueFn) -> None:
        """_f = y' at (t, _y) under `torque`."""
        if self.compiled:
            self._rhs(self._model, t, self._y, torque(t), self._f)
        else:
            f = [0.0] * 6
            rhs(self._stages, t, self._y.tolist(), torque(t), f)
            self._f[:] = f

    def cut_at(self, s: float, t: float, q: Vec3, v: Vec3, torque: TorqueFn,
               onset: bool) -> tuple[Vec3, Vec3] | None:
        """The output at s (s) of the internal solution started (or continued) at (t, q, q') under `torque`,
        retaken so that an internal step ends exactly at s: a located kink (a contact onset or release),
        which the accepted internal step across it straddles. The force is not smooth there (δ^1.5), so
        that step's local error estimate misses its error; the steps up to s, and those after it (which
        continue from this output), each lie on one side. The next internal step from s (`restart_step`):
        on an `onset` (the gap open at t) the one the error control took just past the kink before the cut.
        None (nothing changed): the solution is not the one from (t, q, q'), or no internal step straddles
        s (`straddles`)."""
        if torque is not self._torque or self._origin != (t, q, v) or not t < s <= self._t:
            return None
        i = bisect.bisect_left(self._history_starts, s) - 1  # the step with t_old < s ≤ t_old + h_old
        if i < 0:
            return None
        t_old, h_old, y_old, _, err_old, _ = self._history[i]
        if not straddles(s, t_old, h_old):
            return None
        past = self._history[i + 1][1] if i + 1 < len(self._history) else h_old  # (t_old, h_old, …)
        proposed = self._h
        del self._history[i:], self._history_starts[i:]
        self._hit = None
        self._t, self._y, self._err, self._h = t_old, y_old, err_old, h_old
        self._slope(t_old, torque)
        held = getattr(torque, "value", None)  # as `step`: a held torque's internal steps compiled
        if held is not None and self._steps is not None:
            self._advance_compiled(s, held, bounded=True)
        while self._t < s:
            self._advance(torque, s)
        self._h = restart_step(onset, past, self._h, proposed)
        status, q1, v1 = self._numerics.dop853_output(self._model, self._t_old, self._h_old, self._y_old,
                                                      self._dense, s, self._out)
        if status != self._numerics.OK:
            raise SimulationDiverged("non-finite or unprojectable state", method=self.name, t=s)
        self._last = (s, q1, v1)
        self._remember(q1, s, self._t_old, self._h_old, self._err_old, self._err)
        return q1, v1

    def _advance_compiled(self, target: float, held: float, bounded: bool = False,
                          gaps: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None) -> float:
        """`while _t < target: _advance(torque)` under the held torque `held` (N·m) in compiled chunks of
        COMPILED_CHUNK internal steps (`kernel.internal_steps.advance_to`, the same numbers), each step
        kept in the history as `_advance` keeps it; it stops before a step that fails, which the Python
        loop then retries and reports. The rejected attempts are not counted here. `bounded` (`cut_at`):
        the last step ends exactly at target, as `_advance(torque, target)` ends it. `gaps` (`Watch.compiled`'s,
        and the step's start q, q'): the steps watched as `_watched` watches them. The watch's state at the end
        (`kernel.internal_steps`: STOPPED where the watch ended the pass before target)."""
        k = self._steps
        st, y, f = self._step_scalars, self._y_next, self._f_next
        plan, work, start = (k.NO_PLAN, k.NO_WORK, k.NO_PLAN) if gaps is None else gaps
        st[k.WATCH] = k.START
        self._taus.fill(held)
        while self._t < target:
            st[:k.WATCH] = (self._t, self._h, self._t_old, self._h_old, self._err, self._err_old)
            y[:], f[:] = self._y, self._f
            rows = np.empty((COMPILED_CHUNK, k.ROW_SIZE))  # the history keeps views of its rows
            n = k.advance_to(self._model, self.rtol, self.atol, st, y, f, self._y_scratch, self._dense, self._kk,
                             self._y_new, self._taus, HELD_ARRAY, target, rows, bounded, plan, work, start)
            done = n if n >= 0 else -n - 1
            if done:
                self._t, self._h, self._t_old, self._h_old, self._err, self._err_old = st[:k.WATCH].tolist()
                self._y, self._f[:] = y.copy(), f  # a new array for y, as `_advance` makes one per step
                self.accepted += done
                y_olds, denses = rows[:done, k.ROW_Y_OLD:k.ROW_DENSE], rows[:done, k.ROW_DENSE:].reshape(done, 7, 6)
                for (t_old, h_old, err_old, err), y_old, dense in zip(rows[:done, :4].tolist(), y_olds, denses):
                    self._y_old = y_old
                    if self._keep_history:
                        self._history.append((t_old, h_old, y_old, dense, err_old, err))
                        self._history_starts.append(t_old)
            if n < 0 or st[k.WATCH] == k.STOPPED:
                break
        return float(st[k.WATCH])

    def _advance(self, torque: TorqueFn, bound: float = math.inf) -> None:
        """One accepted internal step from _t (scipy's `RungeKutta._step_impl`), ending at `bound` (s) at
        the latest (scipy's t_bound: `cut_at`)."""
        num = self._numerics
        t, h = self._t, min(self._h, bound - self._t)
        y_new = np.empty(6)
        rejected = False
        for _ in range(MAX_ATTEMPTS):
            if h < 10.0 * abs(math.nextafter(t, math.inf) - t):
                break
            held = getattr(torque, "value", None)  # a held or constant torque (`HeldTorque`, `inputs.Constant`)
            if held is not None:
                taus = self._taus
                taus.fill(held)
            else:
                taus = np.array([torque(t + c * h) for c in _NODES])
            if self.compiled:
                norm = self._attempt(self._model, _A, _B, _C, _E3, _E5, _D, t, self._y, self._f, h, taus,
                                     self.rtol, self.atol, self._kk, y_new, self._dense)
            else:
                norm = self._python_attempt(t, h, taus, y_new)
            if norm < 1.0:
                self._err_old = self._err
                self._err += num.dop853_theta_error(_E53, self._kk, h, E3_WEIGHT)
                factor = num.MAX_FACTOR if norm == 0.0 else min(num.MAX_FACTOR, num.SAFETY * norm**num.ERROR_EXPONENT)
                self._t_old, self._h_old = t, h
                # y_new is this attempt's own array: the state moves on without copies (no array is
                # written again once it is y_old, so the history keeps it as it is)
                self._y_old, self._y = self._y, y_new
                self._f[:] = self._kk[_N_STAGES]
                self._t = bound if h == bound - t else t + h
                self._h = min(MAX_STEP, h * (min(1.0, factor) if rejected else factor))
                self.accepted += 1
                if self._keep_history:
                    self._history.append((t, h, self._y_old, self._dense.copy(), self._err_old, self._err))
                    self._history_starts.append(t)
                return
            # a non-finite trial (e.g. a contact state far outside its law) is rejected like a large
            # error, as scipy does: the step shrinks by MIN_FACTOR; a trial that lands inside a contact is
            # retried up to the contact's interpolated onset (`crossing_retry`)
            shrunk = h * (max(num.MIN_FACTOR, num.SAFETY * norm**num.ERROR_EXPONENT) if math.isfinite(norm) else num.MIN_FACTOR)
            h = num.crossing_retry(self._model, self._y, y_new, h, shrunk)
            rejected = True
            self.rejected += 1
        raise SimulationDiverged(f"internal step fell to {h:.3g} s (rtol {self.rtol:g})", method=self.name, t=t)

    def _python_attempt(self, t: float, h: float, taus: np.ndarray, y_new: np.ndarray) -> float:
        """`steps.dop853_attempt` from (t, y) with step h (s) in Python, on lists, its stages the system's
        own (`steps.rhs`); the stages, y_new and the dense coefficients then into the arrays the
        compiled dense output and error estimate read. The error norm (accepted when < 1)."""
        kk, new, dense = [[0.0] * 6 for _ in range(16)], [0.0] * 6, self._dense.tolist()
        norm = dop853_attempt(self._stages, *_LISTS, t, self._y.tolist(), self._f.tolist(), h, taus.tolist(),
                              self.rtol, self.atol, kk, new, dense)
        self._kk[:], y_new[:], self._dense[:] = kk, new, dense
        return norm

    @classmethod
    def is_stable(cls, z: complex) -> bool:
        return True  # error control shrinks the internal step as needed


def straddles(s: float, t_old: float, h_old: float) -> bool:
    """Whether the accepted internal step (t_old, h_old) (s) straddles a located kink at s, t_old < s ≤
    t_old + h_old, so that it is retaken to end there (`DormandPrince853.cut_at`): not when it ends at s
    already, nor when fewer than CUT_ULPS units in the last place of s lie before s (too short a step to
    take). A plain function: the kernel compiles it (`kernel.event_step`), on the same numbers."""
    return t_old + h_old != s and s - t_old >= CUT_ULPS * (math.nextafter(s, math.inf) - s)


def restart_step(onset: bool, past: float, bounded: float, proposed: float) -> float:
    """The next internal step (s) after `DormandPrince853.cut_at` ended one at a kink. On an `onset`: `past`,
    the step the error control took just past the kink before the cut, or the straddling step's own where it
    was the last. On a release: the larger of the bounded step's next one and the one `proposed` at the end of
    the internal steps before the cut (the clipped step's own is too short; error control shrinks it where
    needed). After an onset the contact's transient needs short steps, which the larger one
    overshoots and retries 5-6 times; after a release the free flight takes the large one at once (the steps
    past it before the cut were held back by the growth limit, not by the error). A plain function: the
    kernel compiles it (`kernel.event_step._cut_at`), on the same numbers."""
    if onset:
        return past
    return max(bounded, proposed)


def interpolated_estimate(target: float, t_old: float, h_old: float, err_old: float, err: float) -> float:
    """The θ error estimate (rad) at an output at time `target` (s), interpolated linearly over the
    internal step (t_old, h_old) that covers it, whose estimates at its ends are err_old and err."""
    x = (target - t_old) / h_old if h_old > 0.0 else 1.0
    return err_old + min(1.0, max(0.0, x)) * (err - err_old)


def initial_step(y: np.ndarray, f: np.ndarray, rtol: float, atol: float, dt: float) -> float:
    """A first internal step (s) from the state y = (q, q') with y' = f: Hairer's d0/d1 rule (scipy's
    `select_initial_step` without its second-derivative estimate), h = 0.01·‖y/sc‖/‖f/sc‖ with
    sc = atol + |y|·rtol (1e-6 s where either norm is tiny), capped at the output step dt (s). A plain
    function: `_restart` calls it and the kernel compiles it (`kernel.event_step`), on the same numbers."""
    s0 = s1 = 0.0
    for i in range(6):
        scale = atol + abs(y[i]) * rtol
        a, b = y[i] / scale, f[i] / scale
        s0 += a * a
        s1 += b * b
    d0, d1 = math.sqrt(s0), math.sqrt(s1)
    h = TINY_FIRST_STEP if d0 < TINY_NORM or d1 < TINY_NORM else FIRST_STEP_SHARE * d0 / d1
    return min(h, dt)
