"""The inductive drive (L > 0) in the compiled kernel: its Runge–Kutta step (`kernel.drive.inductive_step_tuple`,
`actuators.inductive.InductiveRungeKutta` with its substeps in one call) and the Simulator's lean step
(`InductiveFastStepper`: the input, the substeps and the guards in one call), same numbers."""

from __future__ import annotations

import numpy as np

from finger_sim.actuators.drive import Drive, DrivenSystem
from finger_sim.actuators.inductive import InductiveRungeKutta
from finger_sim.inputs import HELD_ARRAY, Profile, profile_array
from finger_sim.integrators.base import TorqueFn
from finger_sim.kernel import drive as kernel_drive
from finger_sim.kernel.integrators import WARM_UP_STATE, FastStepper, _entry_point, check_status
from finger_sim.kernel.layout import BREAKPOINT, OK, model_array, tableau_array
from finger_sim.kinematics import Vec3


class CompiledInductiveRungeKutta(InductiveRungeKutta):
    """`InductiveRungeKutta` in the compiled kernel (`kernel.drive.inductive_step_tuple`), same numbers."""

    def __init__(self, system: DrivenSystem) -> None:  # type: ignore[override]
        super().__init__(system)
        ref = self.reference
        self.model = model_array(system)
        self.tableau = tableau_array(ref.A, ref.B, ref.C)
        self.nodes = tuple(dict.fromkeys(float(x) for x in ref.C))
        self._kernel = kernel_drive.inductive_step_tuple
        self._profile_kernel = kernel_drive.inductive_profile_step
        self._numerics = kernel_drive.numerics
        #: the flat encodings of the profiles stepped under (`profile_array`; None: no compiled form)
        self._profiles: dict[Profile, np.ndarray | None] = {}

    def _compiled_input(self, torque: TorqueFn) -> tuple[np.ndarray | None, float]:
        """(flat encoding, held value) of the input `torque` for `kernel.drive.substep_inputs`: a held value
        (a command, a piecewise-constant segment's level) as HELD_ARRAY and the value, a profile with a
        compiled form as its encoding; (None, 0.0): evaluate it in Python."""
        value = getattr(torque, "value", None)
        if type(value) is float:
            return HELD_ARRAY, value
        if isinstance(torque, Profile):
            prof = self._profiles.get(torque, HELD_ARRAY)
            if prof is HELD_ARRAY:
                prof = self._profiles[torque] = profile_array(torque)
            return prof, 0.0
        return None, 0.0

    def advance_state(self, t: float, q: Vec3, v: Vec3, own: tuple[float, ...], dt: float, torque: TorqueFn,
                      n: int) -> tuple[Vec3, Vec3, tuple[float, ...]]:
        prof, held = self._compiled_input(torque)
        if prof is not None:  # the input at the substep nodes evaluated in the same call
            status, q1, v1, i1 = self._profile_kernel(self.model, self.tableau, t, q, v, own[0], dt, n, prof, held)
        else:
            h = dt / n
            nodes = self.nodes
            taus = np.array([torque(tk + c * h) for tk in [t + k * h for k in range(n)]
                             for c in nodes]).reshape(n, len(nodes))
            status, q1, v1, i1 = self._kernel(self.model, self.tableau, t, q, v, own[0], dt, n, taus)
        if status != self._numerics.OK:
            check_status(status, self.name, t, q)
        return q1, v1, (i1,)


class InductiveFastStepper:
    """The Simulator's lean path for an inductive drive scene without gaps (no stops, no contact): one
    kernel call per step (`kernel.drive.inductive_fast_step`) while the mesh rolls; a step with a mode
    change or a current-limit event, a stuck mesh or an energy ledger to fill goes through
    `actuators.inductive_stepping` as before. Same numbers, bit for bit.

    The interface `Simulator.step` calls: `call(plan, profile, held, k, q, v)`, `plan`, `profile`, `fail`."""

    fail = FastStepper.fail

    def __init__(self, integrator: CompiledInductiveRungeKutta, dt: float, profile: Profile, drive: Drive) -> None:
        self.method, self.dt, self._drive, self._integrator = integrator.name, dt, drive, integrator
        model = integrator.model
        rows, cols = integrator.tableau.shape
        self.plan = np.concatenate(([dt, len(model), rows, cols], model, integrator.tableau.ravel()))
        #: the plan's model, a view: the drive keeps its mode slot current (`Drive.mirror`)
        self._model = self.plan[4: 4 + len(model)]
        drive.mirror(self._model)
        self._substeps = integrator.substeps
        #: the scene profile's compiled form; None: it has none, steps under it go through Python
        self.profile = profile_array(profile)
        args = (self.plan, HELD_ARRAY, 0.0, 0, WARM_UP_STATE, WARM_UP_STATE, 0.0, 1.0, self._substeps)
        kernel_drive.inductive_fast_step(*args)  # load (or compile) it now, not in the first paced step
        self._entry = _entry_point(kernel_drive.inductive_fast_step, args)

    def call(self, plan: np.ndarray, prof: np.ndarray, held: float, k: int, q: Vec3, v: Vec3):  # type: ignore[no-untyped-def]
        """`inductive_fast_step` from the drive's current and direction; on success the drive and the
        integrator take the current reached (`inductive_stepping._commit`). BREAKPOINT while a ledger is kept."""
        drive = self._drive
        if drive.ledger is not None:
            return BREAKPOINT, q, v, 0.0
        status, q1, v1, i1, end = self._entry(plan, prof, held, k, q, v, drive.i, drive.direction, self._substeps)
        if status == OK:
            drive.i = i1
            self._integrator.begin(q1, v1, (i1,))
        return status, q1, v1, end
