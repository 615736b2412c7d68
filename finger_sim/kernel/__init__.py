"""The compiled stepping kernel (numba): the same numbers as the Python path, 5-10× cheaper per step.

`finger_sim.simulate.Simulator(scene, kernel=...)` picks the path: "auto" (the default) runs
the compiled kernel whenever numba imports and every force element has a compiled form,
"compiled" insists on it, "python" runs the readable reference. `Simulator.kernel` names the
path that ran ("numba-<version>" or "python"), for a log's metadata and for resim.

Compilation is cached on disk (numba's `cache=True`), so the node and the CLI pay it once
per machine. numba writes the cache into `__pycache__` next to the modules; where that is
read-only (a colcon or system install) `use_writable_cache()` points NUMBA_CACHE_DIR at
FALLBACK_CACHE_DIR, unless the user has set NUMBA_CACHE_DIR.
"""

from __future__ import annotations

import functools
import importlib.metadata
import importlib.util
import os
import sys
import tempfile
from pathlib import Path
from typing import TYPE_CHECKING

from finger_sim.errors import ConfigError

if TYPE_CHECKING:
    from finger_sim.dynamics import FingerSystem
    from finger_sim.integrators.base import Integrator

PYTHON = "python"
#: The values of `Simulator(kernel=...)`.
KERNELS = ("auto", "compiled", PYTHON)
#: An offline run shorter than this (steps) runs in Python under kernel "auto" when numba is
#: not loaded yet: loading numba and the cached kernel costs ≈ 0.5 s of CPU, which the kernel
#: earns back at ≈ 25 µs per rk6 step saved (≈ 14 µs per rk4 step) only after some 20 000 steps.
#: Both paths give the same numbers (the tests hold them to 1e-13 rad; in practice bit for bit).
OFFLINE_BREAK_EVEN_STEPS = 20_000
#: NUMBA_CACHE_DIR used when none is set and the package folder is read-only.
FALLBACK_CACHE_DIR = Path(os.environ.get("XDG_CACHE_HOME", Path.home() / ".cache")) / "finger_sim" / "numba"


def use_writable_cache() -> None:
    """Point numba's cache at a writable folder when the package's own folder is not writable."""
    if "NUMBA_CACHE_DIR" in os.environ or os.access(Path(__file__).parent, os.W_OK):
        return
    target = FALLBACK_CACHE_DIR
    try:
        target.mkdir(parents=True, exist_ok=True)
    except OSError:
        target = Path(tempfile.gettempdir()) / "finger_sim_numba"
        target.mkdir(parents=True, exist_ok=True)
    os.environ["NUMBA_CACHE_DIR"] = str(target)


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


def offline_kernel(kernel: str, steps: int) -> str:
    """The kernel for an offline run of `steps` steps: "auto" becomes "python" for a short run
    while numba is not loaded yet (see OFFLINE_BREAK_EVEN_STEPS); anything else is kept."""
    if kernel == "auto" and steps < OFFLINE_BREAK_EVEN_STEPS and "numba" not in sys.modules:
        return PYTHON
    return kernel


def select(method: type["Integrator"], system: "FingerSystem", kernel: str = "auto") -> tuple[type["Integrator"], str]:
    """The integrator class to step `system` with `method` on the requested kernel, and the kernel's name.

    kernel: "auto" (compiled when numba imports, the method has a compiled form and every force
    element has one; else Python), "compiled" (refused when it cannot run), "python", or a name
    recorded by an earlier run ("numba-…", taken as "compiled", or "python").
    """
    if not isinstance(kernel, str) or not (kernel in KERNELS or kernel.startswith("numba-")):
        raise ConfigError("kernel", f"one of {list(KERNELS)} or a recorded 'numba-<version>'", kernel)
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
