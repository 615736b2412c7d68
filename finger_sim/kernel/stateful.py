"""An actuator with its own state in the compiled kernel: `integrators.stateful.StatefulRungeKutta`, compiled.

The step is the projected explicit Runge–Kutta step (`numerics.rk_step`) on the flat state
x = (q, q', the actuator's slots, `state_layout`): q'' under the actuator's torque and the rates of its
slots come from its declared law (`actuators.base.ActuatorLaw`), compiled from its one definition
(`jit.compiled`). `stateful_rk_step` and `stateful_advance` below are plain functions whose globals
`actuator_torque` and `actuator_rates` are bound to an actuator's compiled law when they are compiled
for it (`for_law`, as `kernel.drive` binds the drive's law into numerics' steps): one compiled step per
law, cached on disk under a name keyed by the law's source. Same numbers as the Python path.
"""

from __future__ import annotations

import functools
import hashlib
import inspect
import types
from collections.abc import Callable
from typing import Any

import numpy as np

from finger_sim.actuators.base import Actuator, ActuatorLaw
from finger_sim.dynamics import FingerSystem
from finger_sim.integrators.base import TorqueFn
from finger_sim.integrators.stateful import StatefulRungeKutta
from finger_sim.kernel.integrators import WARM_UP_STATE, check_status
from finger_sim.kernel.jit import JIT, LAW, compiled, njit
from finger_sim.kernel.layout import OK, distinct_nodes, model_array, tableau_array
from finger_sim.kernel.numerics import accelerations, project
from finger_sim.kinematics import Vec3
from finger_sim.state_layout import LINKAGE_SIZE

#: Length of the digest of a law's source in its compiled step's name (hex digits).
NAME_DIGEST = 16


def stateful_rk_step(m, p, tab, t, x, h, taus, k, y, held):  # type: ignore[no-untyped-def]
    """One explicit Runge–Kutta step of x = (q, q', own) in place, then the projection of (q, q'):
    `StatefulRungeKutta._substep`. held: the linkage held at q with q' = 0 (on a stop, locked by friction;
    `advance_held`'s substep): no acceleration, the rates at (q, 0), no projection. Returns the status.

    m: the flat model; p: the actuator's parameters; tab, taus: as `numerics.rk_step` (the input u at each
    distinct node); k: s × len(x) stage rates; y: len(x) work. Zero tableau entries are skipped and the
    weights combined as a stage is, as in Python (`explicit.rk_stage_loop`)."""
    s = tab.shape[1]
    n = x.shape[0]
    for r in range(s + 1):  # the stages, then the weights' row (tab[s]): the step's end, combined as a stage is
        for c in range(n):
            y[c] = x[c]
        for j in range(r):
            a = tab[r, j]
            if a != 0.0:
                ha = h * a
                for c in range(n):
                    y[c] += ha * k[j, c]
        if r == s:
            break
        ts = t + tab[s + 1, r] * h
        u = taus[int(tab[s + 2, r])]
        own = y[LINKAGE_SIZE:]
        k[r, 0], k[r, 1], k[r, 2] = y[3], y[4], y[5]
        if held:
            k[r, 3], k[r, 4], k[r, 5] = 0.0, 0.0, 0.0
            rates = actuator_rates(p, ts, x[0], x[1], x[2], 0.0, 0.0, 0.0, u, own)  # noqa: F821  (bound by `for_law`)
        else:
            tau = actuator_torque(p, ts, y[0], y[1], y[2], y[3], y[4], y[5], u, own)  # noqa: F821
            k[r, 3], k[r, 4], k[r, 5] = accelerations(m, ts, y[0], y[1], y[2], y[3], y[4], y[5], tau)
            rates = actuator_rates(p, ts, y[0], y[1], y[2], y[3], y[4], y[5], u, own)  # noqa: F821
        for c in range(n - LINKAGE_SIZE):
            k[r, LINKAGE_SIZE + c] = rates[c]
    for c in range(n):
        x[c] = y[c]
    return OK if held else project(m, x)


def stateful_advance(m, p, tab, t, x, h, n, taus, held):  # type: ignore[no-untyped-def]
    """n substeps of h/n of `stateful_rk_step` on x in place from t (s); taus[j]: the input at the distinct
    nodes of substep j (n × nodes). Returns the status of the first substep that fails, else OK."""
    k = np.empty((tab.shape[1], x.shape[0]))
    y = np.empty(x.shape[0])
    sub = h / n
    for j in range(n):
        status = stateful_rk_step(m, p, tab, t + j * sub, x, sub, taus[j], k, y, held)
        if status != OK:
            return status
    return OK


def _law_digest(law: ActuatorLaw) -> str | None:
    """A digest of the law's source (its functions and callees, with their modules and names); None when a
    source cannot be read (a function defined at a prompt): its step is then not cached on disk."""
    digest = hashlib.sha256()
    for function in (law.torque, law.rates, *law.callees):
        try:
            source = inspect.getsource(function)
        except (OSError, TypeError):
            return None
        digest.update(f"{function.__module__}.{function.__qualname__}\n{source}\n".encode())
    return digest.hexdigest()[:NAME_DIGEST]


def _bound(function: Callable[..., Any], suffix: str, cache: bool, **names: Any) -> Any:
    """`function` compiled under the name `<its name>_<suffix>` with the globals `names` bound (numba's
    disk cache keys a function by its name and its own source file, not by the functions it calls)."""
    name = f"{function.__name__}_{suffix}"
    code = function.__code__.replace(co_name=name, co_qualname=name)
    bound = types.FunctionType(code, {**function.__globals__, **names}, name, function.__defaults__)
    bound.__qualname__, bound.__doc__, bound.__module__ = name, function.__doc__, function.__module__
    return njit(**{**JIT, "cache": cache})(bound)


@functools.cache
def for_law(law: ActuatorLaw) -> Any:
    """`stateful_advance` compiled with the actuator law `law` bound (its torque and rates, their callees)."""
    digest = _law_digest(law)
    callees = {f.__name__: njit(**LAW)(f) for f in law.callees}
    laws = {"actuator_torque": compiled(law.torque, **callees), "actuator_rates": compiled(law.rates, **callees)}
    suffix, cache = (digest, True) if digest is not None else (f"{id(law):x}", False)
    step = _bound(stateful_rk_step, suffix, cache, **laws)
    return _bound(stateful_advance, suffix, cache, stateful_rk_step=step)


class CompiledStatefulRungeKutta(StatefulRungeKutta):
    """`StatefulRungeKutta` in the compiled kernel (`stateful_advance` with the actuator's law bound), same
    numbers. The input is evaluated in Python at each substep's distinct stage nodes, as `CompiledRungeKutta`
    does; build with `of(<a StatefulRungeKutta class>)`."""

    def __init__(self, system: FingerSystem, actuator: Actuator | None = None) -> None:
        super().__init__(system, actuator)
        model = model_array(system)
        if model is None:
            raise ValueError("a force element of this system has no compiled form (kernel_code)")
        ref = self.reference
        self.model, self.tableau, self.nodes = model, tableau_array(ref.A, ref.B, ref.C), distinct_nodes(ref.C)
        self.params = np.array(self.actuator.kernel_params(), dtype=np.float64)  # type: ignore[attr-defined]
        self._advance = for_law(self.actuator.law)  # type: ignore[attr-defined]
        # load (or compile) it now, not in the first paced step
        x = np.array((*WARM_UP_STATE, *WARM_UP_STATE, *self.own), dtype=np.float64)
        self._advance(self.model, self.params, self.tableau, 0.0, x, 0.0, 1, np.zeros((1, len(self.nodes))), False)

    @classmethod
    def of(cls, python: type[StatefulRungeKutta]) -> type[CompiledStatefulRungeKutta]:  # type: ignore[override]
        """The compiled twin of a class made by `StatefulRungeKutta.of` (its tableau, substeps and actuator)."""
        return type(f"Compiled{python.__name__}", (cls, python), {
            "__doc__": f"{python.name} on the flat state, compiled: {(python.__doc__ or '').splitlines()[0]}"})

    def _inputs(self, t: float, dt: float, n: int, torque: TorqueFn) -> np.ndarray:
        """The input at the distinct nodes of each of n substeps of dt/n from t: n × nodes, at the times the
        Python stage loop evaluates it (the substep's start + c h)."""
        h = dt / n
        nodes = self.nodes
        value = getattr(torque, "value", None)
        if type(value) is float:  # a held input: the same value at every node
            return np.full((n, len(nodes)), value)
        return np.array([[torque(tk + c * h) for c in nodes] for tk in [t + j * h for j in range(n)]])

    def advance_state(self, t: float, q: Vec3, v: Vec3, own: tuple[float, ...], dt: float, torque: TorqueFn,
                      n: int) -> tuple[Vec3, Vec3, tuple[float, ...]]:
        x = np.array((*q, *v, *own), dtype=np.float64)
        status = self._advance(self.model, self.params, self.tableau, t, x, dt, n, self._inputs(t, dt, n, torque), False)
        if status != OK:
            check_status(status, self.name, t, q)
        s = x.tolist()
        return (s[0], s[1], s[2]), (s[3], s[4], s[5]), tuple(s[LINKAGE_SIZE:])

    def advance_held(self, t: float, q: Vec3, own: tuple[float, ...], dt: float,
                     torque: TorqueFn) -> tuple[float, ...]:
        n = self.substeps
        x = np.array((*q, 0.0, 0.0, 0.0, *own), dtype=np.float64)
        self._advance(self.model, self.params, self.tableau, t, x, dt, n, self._inputs(t, dt, n, torque), True)
        return tuple(x.tolist()[LINKAGE_SIZE:])
