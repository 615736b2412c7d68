"""The slot through which the core receives its compiled stepper: the core never imports the kernel.

The kernel (`finger_sim.kernel`) sits above the core: it compiles the core's laws. The Simulator,
the stability check and DOP853 still need what it builds (a compiled integrator class, the flat
model, a whole-run loop), so the kernel hands them in here: importing `finger_sim.kernel` installs
it (`install`), and importing the package does that (`finger_sim/__init__.py`, the one place where
the rooms are wired). Dependency inversion, as a plug-in registry: data flows core → kernel only.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable
from types import ModuleType
from typing import TYPE_CHECKING, Any, NamedTuple, Protocol

if TYPE_CHECKING:
    import numpy as np

    from finger_sim.dynamics import FingerSystem
    from finger_sim.inputs import Profile
    from finger_sim.integrators.base import Integrator

#: Status codes of a compiled call beyond the projection's OK, NON_FINITE, NOT_CONVERGED (0, 1, 2).
STEP_TOO_SMALL = 3  # DOP853's step fell below its floor
BREAKPOINT = 4  # a torque switch lies inside the step: the caller splits it (state unchanged)
STATE_NON_FINITE = 5  # the step ended in a non-finite state (the Simulator's own check)

#: A compiled function that a Python path of the step calls, and arguments of the types it calls it with (their
#: values unused): what an owner of such a path declares (`compiled_calls`) for `CompiledKernel.load`.
CompiledCall = tuple[Callable[..., Any], tuple[Any, ...]]


class StageFunctions(NamedTuple):
    """The compiled functions that step one system's first-order form y = (q, q'): its right-hand side
    `rhs(m, t, y, u, out)`, one DOP853 attempt (`integrators.steps.dop853_attempt`), one step of an explicit
    Runge–Kutta tableau (`rk_step_tuple`, `kernel.integrators.CompiledRungeKutta`), and the loop of DOP853's
    internal steps under a held input (`internal_steps()`: `kernel.internal_steps`, loaded on first call;
    None: the system has none, its internal steps go one by one). An actuator whose force enters the
    acceleration solve (the drive's mesh) registers its own with the kernel; the integrators ask for a
    system's, never for an actuator by name."""

    rhs: Callable[..., None]
    dop853_attempt: Callable[..., float]
    rk_step_tuple: Callable[..., tuple]
    internal_steps: Callable[[], ModuleType | None]


class CompiledKernel(Protocol):
    """What the core asks of the compiled kernel (`finger_sim.kernel` implements it)."""

    def select(self, method: type[Integrator], system: FingerSystem, kernel: str) -> tuple[type[Integrator], str]:
        """The integrator class that steps `system` with `method` on the requested kernel, and the kernel's name."""
        ...

    def select_stateful(self, integrator_cls: type[Integrator], system: FingerSystem,
                        kernel: str) -> tuple[type[Integrator], str, str]:
        """The class stepping an actuator with its own state (a `StatefulRungeKutta` class, its actuator
        bound) on the requested kernel, the kernel's name, and why it runs in Python ('' when compiled)."""
        ...

    def offline_kernel(self, kernel: str, steps: int, scene: Any = None) -> str:
        """The kernel for an offline run of `steps` steps of `scene` ("auto" may become "python" for a short one)."""
        ...

    def model_array(self, system: FingerSystem) -> np.ndarray | None:
        """The system as the kernel's flat model; None when an element has no compiled form."""
        ...

    def fast_stepper(self, integrator: Integrator, dt: float, profile: Profile) -> Any:
        """A one-call-per-step stepper of a smooth scene (`kernel.integrators.FastStepper`), or None
        when `integrator` has no step plan."""
        ...

    def advance(self, sim: Any, n: int) -> np.ndarray:
        """Step a Simulator n times under its scene's profile; the (n, 6) states after each step."""
        ...

    def load(self, calls: Iterable[CompiledCall]) -> None:
        """Load (or compile) each compiled function for its arguments' types now, not at its first call."""
        ...

    def compiled_numerics(self) -> ModuleType:
        """The compiled numerics (DOP853's attempt, dense output and right-hand side)."""
        ...

    def stage_functions(self, system: FingerSystem) -> StageFunctions:
        """The compiled stepping functions of `system`: the plain ones, or its actuator's (`system.actuator`)."""
        ...

    def compiled_gap_screen(self) -> ModuleType:
        """The compiled step-end gap check (`screen`: whether a step may hold a gap crossing)."""
        ...

    def compiled_event_step(self) -> ModuleType:
        """The compiled common step of a scene with events (`common_step`: DOP853 and the gap check)."""
        ...

    def compiled_internal_steps(self) -> ModuleType | None:
        """DOP853's internal steps up to an output time in one call (`advance_to`, under a held torque);
        None without numba."""
        ...

    def compiled_locate_event(self) -> ModuleType:
        """A located gap crossing on the step's dense output in one call (`locate`: the Illinois loop)."""
        ...

    def compiled_inductive(self) -> type:
        """The compiled Runge–Kutta class of an inductive drive (`actuators.inductive`'s twin)."""
        ...

    def inductive_fast_stepper(self, integrator: Integrator, dt: float, profile: Profile, drive: Any) -> Any:
        """The lean step of an inductive drive scene without gaps: input, substeps and guards in one call."""
        ...

    def compiled_drive(self) -> ModuleType:
        """The compiled drive (spec §8): its guards and lean steps (`actuators.stepping`)."""
        ...


_installed: list[CompiledKernel] = []


def install(kernel: CompiledKernel) -> None:
    """Put the compiled kernel in the slot (the kernel does this when imported)."""
    _installed[:] = [kernel]


def kernel() -> CompiledKernel:
    """The installed compiled kernel."""
    if not _installed:
        raise RuntimeError("no compiled kernel installed: import finger_sim (it installs finger_sim.kernel)")
    return _installed[0]
