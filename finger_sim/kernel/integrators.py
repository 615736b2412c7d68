"""Compiled integrators behind the shared `Integrator.step` interface.

`CompiledRungeKutta` runs any fixed-step explicit method of `finger_sim.integrators`
(euler, rk4, rk6, dop8: their tableaux as data) in the compiled kernel; the Simulator's
time grid, breakpoints and events are unchanged. Through `step` the motor torque stays a
Python callable: an explicit step's stage times are known before it starts, so τ is
evaluated there in Python and handed to the kernel as an array.

`FastStepper` is the Simulator's lean path for a smooth scene: one kernel call per step
(or per run) that evaluates a compiled torque profile (`inputs.profile_array`) itself.
"""

from __future__ import annotations

from typing import ClassVar

import numpy as np

from finger_sim.dynamics import FingerSystem
from finger_sim.errors import SimulationDiverged
from finger_sim.integrators.base import Integrator, TorqueFn
from finger_sim.integrators.explicit import ExplicitRungeKutta, PaperEuler
from finger_sim.inputs import HELD_ARRAY, Profile, profile_array
from finger_sim.kernel import numerics, stage_functions
from finger_sim.kernel.layout import distinct_nodes, model_array, tableau_array
from finger_sim.kinematics import Vec3

#: The state of the throw-away step that loads the compiled code at construction.
WARM_UP_STATE: Vec3 = (0.0, 0.0, 0.0)


def check_status(status: int, method: str, t: float, q: Vec3) -> None:
    """Raise the Python path's SimulationDiverged for a kernel status other than OK."""
    if status == numerics.NON_FINITE:
        raise SimulationDiverged(f"state became non-finite: q = {q}", method=method, t=t)
    if status == numerics.NOT_CONVERGED:
        raise SimulationDiverged(f"projection did not converge at q = {q}", method=method, t=t)
    if status == numerics.STEP_TOO_SMALL:
        raise SimulationDiverged("the adaptive step fell below its floor", method=method, t=t)


class CompiledRungeKutta(Integrator):
    """A fixed-step explicit method (`PaperEuler` or an `ExplicitRungeKutta` tableau), compiled.

    Same numbers as the Python class it mirrors (to round-off), same class constants, so
    stability checks and `auto` read it unchanged. Build with `CompiledRungeKutta.of(cls, system)`.
    """

    reference: ClassVar[type[Integrator]]

    def __init__(self, system: FingerSystem, model: np.ndarray | None = None) -> None:
        super().__init__(system)
        self.model = model_array(system) if model is None else model
        if self.model is None:
            raise ValueError("a force element of this system has no compiled form (kernel_code)")
        ref = self.reference
        if issubclass(ref, ExplicitRungeKutta):
            self.tableau = tableau_array(ref.A, ref.B, ref.C)
        else:  # the paper's Euler: an empty tableau, one stage at c = 0
            self.tableau = np.zeros((3, 0))
        #: the distinct stage nodes c: τ is evaluated at t + c·dt for each
        self.nodes = distinct_nodes(ref.C) if issubclass(ref, ExplicitRungeKutta) else (0.0,)
        #: the system's compiled single step (`stepper_slot.StageFunctions`: an actuator's own where it has one)
        self._single_step = stage_functions(system).rk_step_tuple
        # Load the compiled step now (from numba's disk cache: ~0.3-1 s the first time in a
        # process), not inside the first paced step of the node.
        self._single_step(self.model, self.tableau, 0.0, WARM_UP_STATE, WARM_UP_STATE, 0.0,
                          tuple(0.0 for _ in self.nodes))

    def step_plan(self, dt: float) -> np.ndarray:
        """This method on this system at step dt as one array for `numerics.fast_step` and
        `fast_run`: [dt, len(model), tableau rows, tableau columns, model..., tableau...]."""
        rows, cols = self.tableau.shape
        return np.concatenate(([dt, len(self.model), rows, cols], self.model, self.tableau.ravel()))

    @classmethod
    def of(cls, method: type[Integrator]) -> type[CompiledRungeKutta]:
        """The compiled twin of a fixed-step explicit method class."""
        return type(f"Compiled{method.__name__}", (cls,), {
            "reference": method, "name": method.name, "order": method.order,
            "keeps_constraints": method.keeps_constraints, "implicit": method.implicit,
            "__doc__": f"{method.name}, compiled: {(method.__doc__ or '').splitlines()[0]}",
        })

    def step(self, t: float, q: Vec3, v: Vec3, dt: float, torque: TorqueFn) -> tuple[Vec3, Vec3]:
        taus = tuple([torque(t + c * dt) for c in self.nodes])
        status, q1, v1 = self._single_step(self.model, self.tableau, t, q, v, dt, taus)
        if status != numerics.OK:
            check_status(status, self.name, t, q)
        return q1, v1

    @classmethod
    def is_stable(cls, z: complex) -> bool:
        return cls.reference.is_stable(z)


_TWINS: dict[type[Integrator], type[CompiledRungeKutta]] = {}


def compiled_twin(method: type[Integrator]) -> type[CompiledRungeKutta] | None:
    """The compiled class of a fixed-step explicit method (euler and every RK tableau), else None."""
    if not (method is PaperEuler or issubclass(method, ExplicitRungeKutta)):
        return None
    if method not in _TWINS:
        _TWINS[method] = CompiledRungeKutta.of(method)
    return _TWINS[method]


class FastStepper:
    """One compiled call per `Simulator.step` on a smooth scene (no events): `numerics.fast_step`
    with the method, the system and dt as one plan array, and the scene's compiled profile.

    `call` is the compiled function's entry point for exactly the argument types the
    Simulator passes (float64 arrays, a float, an int, two 3-tuples of floats), which skips
    numba's type dispatch (≈ 1 µs of a ≈ 3 µs step); `numerics.fast_step` itself otherwise.
    """

    def __init__(self, integrator: CompiledRungeKutta, dt: float, profile: Profile) -> None:
        self.method, self.dt = integrator.name, dt
        self.plan = integrator.step_plan(dt)
        #: the scene profile's compiled form; None: it has none, steps under it go through Python
        self.profile = profile_array(profile)
        args = (self.plan, HELD_ARRAY, 0.0, 0, WARM_UP_STATE, WARM_UP_STATE)
        numerics.fast_step(*args)  # load (or compile) it now, not in the first paced step
        self.call = _entry_point(numerics.fast_step, args)

    def run(self, k0: int, xs: np.ndarray) -> tuple[int, int, float]:
        """Steps k0, k0 + 1, … under the scene's profile from xs[0] into xs[1:] (`numerics.fast_run`):
        (status, steps done, τ at the end of the last step done)."""
        return numerics.fast_run(self.plan, self.profile, k0, xs)

    def fail(self, status: int, k: int, q: Vec3) -> None:
        """Raise what the Python path raises for step k failed with `status` from state q."""
        if status == numerics.STATE_NON_FINITE:
            raise SimulationDiverged(f"non-finite state (step {k + 1})", method=self.method, t=(k + 1) * self.dt,
                                     dt=self.dt)
        check_status(status, self.method, k * self.dt, q)


def _entry_point(dispatcher, args: tuple):  # type: ignore[no-untyped-def]
    """The compiled entry of `dispatcher` for the types of `args` (the dispatcher when absent)."""
    try:
        import numba
    except ImportError:
        return dispatcher
    overloads = getattr(dispatcher, "overloads", {})
    compiled = overloads.get(tuple(numba.typeof(a) for a in args))
    return dispatcher if compiled is None else compiled.entry_point
