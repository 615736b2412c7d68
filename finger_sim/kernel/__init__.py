"""The compiled stepping kernel (numba): the same numbers as the Python path, cheaper per step (docs/kernel.md).

`finger_sim.simulate.Simulator(scene, kernel=...)` picks the path: "auto" (the default) runs
the compiled kernel whenever numba imports and every force element has a compiled form,
"compiled" insists on it, "python" runs the readable reference. `Simulator.kernel` names the
path that ran ("numba-<version>" or "python"), for a log's metadata and for resim.

The kernel serves the core through `finger_sim.stepper_slot` (the core never imports it): this
module is the `CompiledKernel` there, installed when it is imported.

Compilation is cached on disk (numba's `cache=True`), so the node and the CLI pay it once
per machine. numba checks a cached function against its own source file only, not against the
laws it compiles from other modules (`jit.compiled`, `drive._rebound`, the effects' laws):
an edited law would be served stale. So `use_writable_cache()` points NUMBA_CACHE_DIR at a
folder named by a digest of every source the kernel compiles from (`compiled_sources_digest`):
`kernel/__pycache__/numba/<digest>` beside the modules, or FALLBACK_CACHE_DIR/<digest> where the
package is read-only (a colcon or system install), or <NUMBA_CACHE_DIR>/<digest> when the user
set one. Any change to those sources starts a fresh cache.
"""

from __future__ import annotations

import functools
import hashlib
import importlib
import importlib.metadata
import importlib.util
import os
import sys
import tempfile
from pathlib import Path
from typing import TYPE_CHECKING

from finger_sim import stepper_slot
from finger_sim.errors import ConfigError

if TYPE_CHECKING:
    from collections.abc import Iterable
    from types import ModuleType

    import numpy as np

    from finger_sim.actuators.base import Actuator
    from finger_sim.dynamics import FingerSystem
    from finger_sim.inputs import Profile
    from finger_sim.integrators.base import Integrator
    from finger_sim.kernel.integrators import CompiledRungeKutta, FastStepper
    from finger_sim.scene import Scene
    from finger_sim.simulate import Simulator

PYTHON = "python"
#: The values of `Simulator(kernel=...)`.
KERNELS = ("auto", "compiled", PYTHON)
#: An offline run shorter than this (steps) runs in Python under kernel "auto" when numba is
#: not loaded yet: loading numba and the cached kernel costs ≈ 0.35 s of CPU, which the kernel
#: earns back at ≈ 18 µs of CPU per rk6 step saved (20 µs in Python against 1.8 µs compiled,
#: 2026-11-27, load 0.9–1.3, docs/figures_audit.md) only after some 19 000 steps.
#: Both paths give the same numbers (the tests hold them to 1e-13 rad; in practice bit for bit).
OFFLINE_BREAK_EVEN_STEPS = 20_000
#: What a step of an inductive drive (L > 0) saves on the compiled kernel, in rk6 steps of the rule above:
#: every stage of its electrical substeps runs in Python there, 12.5 ms per step against 0.12 ms compiled
#: (free motion, L = 1 mH, 32 substeps; 2026-11-26, load 4): ≈ 690 × 18 µs; the weight keeps to the safe
#: side of it. So such a run is compiled from some 70 steps on (a 0.2 s grasp took 57 s on the Python path).
INDUCTIVE_STEP_WEIGHT = 300
#: NUMBA_CACHE_DIR used when none is set and the package folder is read-only.
FALLBACK_CACHE_DIR = Path(os.environ.get("XDG_CACHE_HOME", Path.home() / ".cache")) / "finger_sim" / "numba"


#: The kernel module of each actuator whose force enters the acceleration solve (`FingerSystem.actuator`), by
#: the actuator's name: its `STAGES` (`stepper_slot.StageFunctions`) step a system with it (`stage_functions`).
ACTUATOR_STAGES = {"drive": "finger_sim.kernel.drive"}
#: The package's folders whose modules the kernel compiles from (besides the top-level modules).
COMPILED_FOLDERS = ("kernel", "effects", "integrators", "actuators", "simulation")


@functools.cache
def compiled_sources_digest() -> str:
    """A digest (16 hex digits) of the name, size and modification time of every source the
    kernel compiles from: the package's top-level modules and COMPILED_FOLDERS, and a force-law
    dispatch generated for a registry other than the committed one (`force_laws.uncommitted_source`)."""
    from finger_sim.kernel.force_laws import uncommitted_source

    package = Path(__file__).parent.parent
    files = sorted([*package.glob("*.py"), *(f for d in COMPILED_FOLDERS for f in (package / d).glob("*.py"))])
    digest = hashlib.sha256()
    for f in files:
        stat = f.stat()
        digest.update(f"{f.relative_to(package)}:{stat.st_size}:{stat.st_mtime_ns}\n".encode())
    digest.update(uncommitted_source().encode())
    return digest.hexdigest()[:16]


@functools.cache
def cache_folder() -> Path:
    """The writable folder, keyed by `compiled_sources_digest`, that numba caches the kernel in (module docstring)."""
    user = os.environ.get("NUMBA_CACHE_DIR")
    own = Path(__file__).parent / "__pycache__" / "numba"
    candidates = [Path(user)] if user else [own, FALLBACK_CACHE_DIR, Path(tempfile.gettempdir()) / "finger_sim_numba"]
    for base in candidates:
        target = base / compiled_sources_digest()
        try:
            target.mkdir(parents=True, exist_ok=True)
        except OSError:
            continue
        if os.access(target, os.W_OK):
            break
    return target


@functools.cache
def use_writable_cache() -> None:
    """Point numba's cache at `cache_folder()`."""
    target = cache_folder()
    # numba's config, not the environment: child processes (a node, Dask workers) key their own
    try:
        import numba
    except ImportError:  # the Python path only: nothing is compiled, nothing cached
        return
    numba.config.CACHE_DIR = str(target)


@functools.cache
def compiled_name() -> str | None:
    """"numba-<version>" when numba is installed, else None (the Python path only).

    Read from the package metadata once per process (≈ 3 ms): numba itself (about 0.3 s to
    import) is imported only when a compiled kernel is built.
    """
    if importlib.util.find_spec("numba") is None:
        return None
    try:
        return f"numba-{importlib.metadata.version('numba')}"
    except importlib.metadata.PackageNotFoundError:
        return None


def offline_kernel(kernel: str, steps: int, scene: "Scene | None" = None) -> str:
    """The kernel for an offline run of `steps` steps of `scene`: "auto" becomes "python" for a short run
    while numba is not loaded yet (see OFFLINE_BREAK_EVEN_STEPS; a step of an inductive drive counts
    INDUCTIVE_STEP_WEIGHT steps); anything else is kept."""
    drive = getattr(scene, "drive", None)
    weight = INDUCTIVE_STEP_WEIGHT if drive is not None and drive.inductance > 0.0 else 1
    if kernel == "auto" and steps * weight < OFFLINE_BREAK_EVEN_STEPS and "numba" not in sys.modules:
        return PYTHON
    return kernel


def select(method: type["Integrator"], system: "FingerSystem", kernel: str = "auto") -> tuple[type["Integrator"], str]:
    """The integrator class to step `system` with `method` on the requested kernel, and the kernel's name.

    kernel: "auto" (compiled when numba imports, the method has a compiled form and every force
    element has one; else Python), "compiled" (refused when it cannot run), "python", or a name
    recorded by an earlier run ("numba-…", taken as "compiled", or "python").
    """
    _check_kernel(kernel)
    if method.name == "dop853":  # compiled by construction (plain Python without numba), its stages where they can be
        from finger_sim.kernel.layout import model_array

        return method, (compiled_name() or PYTHON) if model_array(system) is not None else PYTHON
    if kernel == PYTHON:
        return method, PYTHON
    name = compiled_name()
    reason = _why_not_compiled(method, system, name)
    if reason is None:
        from finger_sim.kernel.integrators import compiled_twin

        return compiled_twin(method), name  # type: ignore[return-value]
    if kernel == "auto":
        return method, PYTHON
    raise ConfigError("kernel", f"a kernel that can run here ({reason})", kernel)


def select_stateful(integrator_cls: type["Integrator"], system: "FingerSystem",
                    kernel: str = "auto") -> tuple[type["Integrator"], str, str]:
    """The class stepping an actuator with its own state (`integrator_cls`, a `StatefulRungeKutta` class
    with its actuator bound) on the requested kernel, the kernel's name, and why it runs on the Python
    path ('' when compiled). kernel: as `select`; "compiled" is refused (ConfigError) when it cannot run."""
    _check_kernel(kernel)
    if kernel == PYTHON:
        return integrator_cls, PYTHON, ""
    actuator = integrator_cls.bound  # type: ignore[attr-defined]
    reason = _why_not_stateful(actuator)
    if reason is None:
        reason = _why_not_compiled(integrator_cls.reference, system, compiled_name())  # type: ignore[attr-defined]
    if reason is None:
        from finger_sim.kernel.stateful import CompiledStatefulRungeKutta

        return CompiledStatefulRungeKutta.of(integrator_cls), compiled_name(), ""  # type: ignore[arg-type,return-value]
    if kernel == "auto":
        return integrator_cls, PYTHON, reason
    raise ConfigError("kernel", f"a kernel that can run here ({reason})", kernel)


def _check_kernel(kernel: object) -> None:
    """ConfigError unless `kernel` is one of KERNELS or a recorded "numba-<version>"."""
    if not isinstance(kernel, str) or not (kernel in KERNELS or kernel.startswith("numba-")):
        raise ConfigError("kernel", f"one of {list(KERNELS)} or a recorded 'numba-<version>'", kernel)


def _why_not_stateful(actuator: "Actuator") -> str | None:
    """Why the actuator has no compiled form (no declared law, no own slots, its own accelerations), or None."""
    from finger_sim.actuators.base import Actuator

    if getattr(actuator, "law", None) is None:
        why = "has no compiled form"
    elif not actuator.slots:
        why = "has no own slots"
    elif type(actuator).accelerations is not Actuator.accelerations:
        why = "writes its own accelerations"
    else:
        return None
    return f"the actuator {actuator.name!r} {why}"


def _why_not_compiled(method: type["Integrator"], system: "FingerSystem", name: str | None) -> str | None:
    if name is None:
        return "numba is not installed"
    try:
        import numba  # noqa: F401
    except ImportError as exc:
        return f"numba does not import: {exc}"
    from finger_sim.kernel.integrators import compiled_twin
    from finger_sim.kernel.layout import model_array

    if compiled_twin(method) is None:
        return f"method '{method.name}' has no compiled form"
    if model_array(system) is None:
        return "a force element has no compiled form"
    return None


# -- the rest of `stepper_slot.CompiledKernel`: each loads its module on first use (numba with it) ----------
def model_array(system: "FingerSystem") -> "np.ndarray | None":
    """`layout.model_array`: the system as the kernel's flat model, or None."""
    from finger_sim.kernel.layout import model_array as flat_model

    return flat_model(system)


def fast_stepper(integrator: "CompiledRungeKutta", dt: float, profile: "Profile") -> "FastStepper":
    """`integrators.FastStepper`: one compiled call per step of a smooth scene."""
    from finger_sim.kernel.integrators import FastStepper

    return FastStepper(integrator, dt, profile)


def advance(sim: "Simulator", n: int) -> "np.ndarray":
    """`runner.advance`: n steps of `sim` in one kernel loop where it can."""
    from finger_sim.kernel.runner import advance as run

    return run(sim, n)


#: (function, its arguments' Python types) that `load` has loaded in this process. Each function is called from
#: Python with one signature (an array's rank and layout, which Python's types do not tell apart, fixed by its caller).
_LOADED: set[tuple[object, tuple[type, ...]]] = set()


def load(calls: "Iterable[stepper_slot.CompiledCall]") -> None:
    """Load each compiled function's machine code for the types of its arguments (`Dispatcher.compile`) now.

    numba loads a function from its on-disk cache lazily, at its first call in a process (5–20 ms of CPU each):
    in a paced step, the first that reaches a path (Python's event path after hundreds of kernel steps), that
    is a stall. A plain function (numba absent, or not imported: nothing was compiled) is left as it is.
    """
    numba = sys.modules.get("numba")
    if numba is None:
        return
    from numba.core.dispatcher import Dispatcher

    for function, args in calls:
        key = (function, tuple(map(type, args)))  # numba's typing costs ~10 µs an argument: once per process
        if key not in _LOADED and isinstance(function, Dispatcher):
            function.compile(tuple(numba.typeof(a) for a in args))
            _LOADED.add(key)


def compiled_numerics() -> "ModuleType":
    """The compiled numerics module."""
    from finger_sim.kernel import numerics as compiled

    return compiled


def stage_functions(system: "FingerSystem") -> stepper_slot.StageFunctions:
    """The compiled stepping functions of `system`: numerics' own, or those its actuator's kernel module
    registers (`ACTUATOR_STAGES`)."""
    if system.actuator is None:
        numerics = compiled_numerics()
        return stepper_slot.StageFunctions(numerics._rhs, numerics.dop853_attempt, numerics.rk_step_tuple,
                                           compiled_internal_steps)
    return importlib.import_module(ACTUATOR_STAGES[system.actuator.name]).STAGES


def compiled_drive() -> "ModuleType":
    """The compiled drive module (spec §8): its guards and lean steps."""
    from finger_sim.kernel import drive as compiled

    return compiled


def compiled_gap_screen() -> "ModuleType":
    """The compiled step-end gap check (`kernel.gap_screen`)."""
    from finger_sim.kernel import gap_screen as compiled

    return compiled


def compiled_event_step() -> "ModuleType":
    """The compiled common step of a scene with events (`kernel.event_step`)."""
    from finger_sim.kernel import event_step as compiled

    return compiled


def compiled_internal_steps() -> "ModuleType | None":
    """DOP853's internal steps up to an output time in one call (`kernel.internal_steps`); None without numba."""
    if compiled_name() is None:
        return None
    from finger_sim.kernel import internal_steps as compiled

    return compiled


def compiled_locate_event() -> "ModuleType":
    """A located gap crossing on the step's dense output in one call (`kernel.locate_event`)."""
    from finger_sim.kernel import locate_event as compiled

    return compiled


def compiled_inductive() -> type:
    """The inductive drive's compiled Runge–Kutta class (`kernel.inductive`)."""
    from finger_sim.kernel.inductive import CompiledInductiveRungeKutta

    return CompiledInductiveRungeKutta


def inductive_fast_stepper(integrator: "Integrator", dt: float, profile: "Profile", drive: object) -> object:
    """`inductive.InductiveFastStepper`: one compiled call per rolling step of an inductive drive scene."""
    from finger_sim.kernel.inductive import InductiveFastStepper

    return InductiveFastStepper(integrator, dt, profile, drive)  # type: ignore[arg-type]


stepper_slot.install(sys.modules[__name__])  # type: ignore[arg-type]
