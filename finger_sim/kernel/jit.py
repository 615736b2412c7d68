"""numba's `njit` for the kernel, with its options and the compilation of a law from its one definition.

Imported before anything else that compiles: it points numba's cache at its keyed folder first
(`finger_sim.kernel.use_writable_cache`). Without numba, `njit` leaves a function as it is (slow, same numbers).
"""

from __future__ import annotations

import types
from collections.abc import Callable
from typing import TYPE_CHECKING

from finger_sim.kernel import use_writable_cache

if TYPE_CHECKING:
    from finger_sim.effects.base import KernelLaw

use_writable_cache()  # before numba reads NUMBA_CACHE_DIR
try:
    from numba import njit
except ImportError:  # no numba: the same functions run as plain Python (slow, same numbers)

    def njit(**_options):  # type: ignore[no-untyped-def]
        return lambda function: function


JIT = {"cache": True, "nogil": True, "error_model": "numpy"}
#: The laws compiled into their callers' own code (numba IR inlining), as the hand-written copies were.
LAW = {**JIT, "inline": "always"}


def compiled(law: Callable, *, options: dict = LAW, **callees: Callable) -> Callable:
    """`law` (a plain function) compiled with numba's `options` (inlined by default), with the plain
    functions it calls by name (`callees`) bound to their compiled forms: the same code object under
    other globals, so nothing is copied."""
    function = types.FunctionType(law.__code__, {**law.__globals__, **callees}, law.__name__, law.__defaults__)
    function.__qualname__, function.__doc__, function.__module__ = law.__qualname__, law.__doc__, law.__module__
    return njit(**options)(function)


def compiled_law(law: KernelLaw) -> Callable:
    """An effect's declared force law (`effects.base.KernelLaw`) compiled, its callees with it."""
    return compiled(law.force, **{f.__name__: njit(**LAW)(f) for f in law.callees})
