"""Our own adaptive method: Dormand-Prince 8(5,3) with error control and dense output, compiled.

Unlike `adaptive` (scipy's solve_ivp restarted at every grid step), this integrator keeps
its own step size across the Simulator's fixed output grid: it takes internal steps as
long as rtol/atol allow, and answers each `step(t, q, v, dt, torque)` from the 7th-order
dense output of the internal step that covers t + dt, projected onto Φ = 0, Φ_q q' = 0.
The internal solution itself is never projected, so the output grid does not change it.

It continues its internal solution only while the caller continues the last output with
the same torque function (same object); anything else (a reset, a torque breakpoint, an
event's trial step, a held command) restarts it from the given state. The step-size
control, error norm and dense output are scipy's DOP853 (scipy/integrate/_ivp/rk.py,
after Hairer, Nørsett & Wanner, *Solving ODEs I*, §II.10), with scipy's coefficients.
"""

from __future__ import annotations

import importlib.util
import math
import sys
from pathlib import Path
from types import ModuleType

import numpy as np

from finger_sim.dynamics import FingerSystem
from finger_sim.errors import ConfigError, SimulationDiverged
from finger_sim.integrators.base import Integrator, TorqueFn
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

_N_STAGES = coefficients.N_STAGES
#: Stage nodes of one attempt: the 12 stages, t + h, then the 3 extra dense-output stages.
_NODES = tuple(float(c) for c in (*coefficients.C[:_N_STAGES], 1.0, *coefficients.C[_N_STAGES + 1:]))
_A = np.ascontiguousarray(coefficients.A, dtype=np.float64)
_B = np.ascontiguousarray(coefficients.B, dtype=np.float64)
_C = np.ascontiguousarray(coefficients.C, dtype=np.float64)
_E3 = np.ascontiguousarray(coefficients.E3, dtype=np.float64)
_E5 = np.ascontiguousarray(coefficients.E5, dtype=np.float64)
_D = np.ascontiguousarray(coefficients.D, dtype=np.float64)


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
        from finger_sim.kernel import numerics
        from finger_sim.kernel.layout import model_array

        super().__init__(system)
        model = model_array(system)
        if model is None:
            raise ConfigError("integrator.method", "a method other than dop853 for a force element without a compiled "
                              "form (kernel_code)", self.name)
        self._numerics, self._model = numerics, model
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
        #: accepted and rejected internal steps so far (for benchmarks)
        self.accepted = self.rejected = 0

    def step(self, t: float, q: Vec3, v: Vec3, dt: float, torque: TorqueFn) -> tuple[Vec3, Vec3]:
        target = t + dt
        last = self._last
        if not (torque is self._torque and last is not None and last[1] == q and last[2] == v
                and abs(last[0] - t) <= 1e-9 * dt and target >= self._t_old):
            self._restart(t, q, v, dt, torque)
        while self._t < target:
            self._advance(torque)
        status, q1, v1 = self._numerics.dop853_output(self._model, self._t_old, self._h_old, self._y_old, self._dense,
                                                      target, self._out)
        if status != self._numerics.OK:
            raise SimulationDiverged("non-finite or unprojectable state", method=self.name, t=target, dt=dt)
        self._last = (target, q1, v1)
        return q1, v1

    def run_grid(self, times: np.ndarray, q: Vec3, v: Vec3, torque: TorqueFn) -> np.ndarray:
        """Outputs at times[1:] from (q, q') at times[0], all under one smooth `torque`: the (n, 6)
        projected states (q, q'), the same numbers as n calls of `step` on that grid."""
        n = len(times) - 1
        out = np.empty((n, 6))
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
        return out

    def _restart(self, t: float, q: Vec3, v: Vec3, dt: float, torque: TorqueFn) -> None:
        self._torque = torque
        self._t = self._t_old = t
        self._y[:3], self._y[3:] = q, v
        self._numerics._rhs(self._model, t, self._y, torque(t), self._f)
        if self._h <= 0.0:
            self._h = _initial_step(self._y, self._f, self.rtol, self.atol, dt)

    def _advance(self, torque: TorqueFn) -> None:
        """One accepted internal step from _t (scipy's `RungeKutta._step_impl` without t_bound)."""
        num = self._numerics
        t, h = self._t, self._h
        y_new = np.empty(6)
        rejected = False
        for _ in range(MAX_ATTEMPTS):
            if h < 10.0 * abs(math.nextafter(t, math.inf) - t):
                break
            taus = np.array([torque(t + c * h) for c in _NODES])
            norm = num.dop853_attempt(self._model, _A, _B, _C, _E3, _E5, _D, t, self._y, self._f, h, taus,
                                      self.rtol, self.atol, self._kk, y_new, self._dense)
            if norm < 1.0:
                factor = num.MAX_FACTOR if norm == 0.0 else min(num.MAX_FACTOR, num.SAFETY * norm**num.ERROR_EXPONENT)
                self._t_old, self._h_old = t, h
                self._y_old[:] = self._y
                self._y[:] = y_new
                self._f[:] = self._kk[_N_STAGES]
                self._t = t + h
                self._h = h * (min(1.0, factor) if rejected else factor)
                self.accepted += 1
                return
            if not math.isfinite(norm):
                break
            h *= max(num.MIN_FACTOR, num.SAFETY * norm**num.ERROR_EXPONENT)
            rejected = True
            self.rejected += 1
        raise SimulationDiverged(f"internal step fell to {h:.3g} s (rtol {self.rtol:g})", method=self.name, t=t)

    @classmethod
    def is_stable(cls, z: complex) -> bool:
        return True  # error control shrinks the internal step as needed


def _initial_step(y: np.ndarray, f: np.ndarray, rtol: float, atol: float, dt: float) -> float:
    """A first internal step: Hairer's d0/d1 rule without the second derivative, capped at dt."""
    scale = atol + np.abs(y) * rtol
    d0, d1 = float(np.linalg.norm(y / scale)), float(np.linalg.norm(f / scale))
    h = 1e-6 if d0 < 1e-5 or d1 < 1e-5 else 0.01 * d0 / d1
    return min(h, dt)
