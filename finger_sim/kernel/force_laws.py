"""The kernel's dispatch over the force laws the effects declare (`effects.base.kernel_law`), generated.

numba compiles a call only to a function it can see when it compiles, so the force sum cannot look a
law up at run time for free; and it caches compiled code only for functions defined in a source file.
So the dispatch is source, generated from the registry: `element_force(code, m, o, t, q, q')` calls each
registered law with its parameters m[o:] and the state it names, one branch per law, compiled into the
force sum (`numerics.generalized_force`) as the hand-written branches were.

The shipped registry's dispatch is committed beside this module (`element_forces.py`, so that the install
step warms its cache, and a read-only install needs no writing); `python -m finger_sim.kernel.force_laws`
rewrites it, and a test holds it equal to the registry. A process whose registry differs when the kernel
first compiles (an effect registered outside the package) gets its dispatch written into the numba cache
folder, which is then keyed by that source too (`finger_sim.kernel.compiled_sources_digest`).

The registry is read once per process, when the kernel first needs it (`compiled_laws`): a law registered
later has no compiled form in that process (its scenes run on the Python path).
"""

from __future__ import annotations

import functools
import importlib.util
import inspect
import sys
from pathlib import Path
from types import ModuleType
from typing import TYPE_CHECKING

from finger_sim.effects.base import KERNEL_RESIDENT

if TYPE_CHECKING:
    from finger_sim.effects.base import KernelLaw

#: The committed dispatch of the shipped registry.
COMMITTED = Path(__file__).with_name("element_forces.py")
#: The module name of a dispatch generated at run time (suffixed with its source's digest).
GENERATED_MODULE = "finger_sim_element_forces"
PACKAGE = Path(__file__).resolve().parents[1]


@functools.cache
def compiled_laws() -> tuple[KernelLaw, ...]:
    """The registered compiled force laws, as this process's kernel compiles them (read once)."""
    import finger_sim.effects  # noqa: F401  (registers every shipped effect)
    from finger_sim.effects.base import KERNEL_LAWS

    return tuple(KERNEL_LAWS.values())


def compiled_codes() -> tuple[int, ...]:
    """Every `kernel_code` this process's kernel computes: the kernel's own laws and the declared ones."""
    return (*KERNEL_RESIDENT, *(law.code for law in compiled_laws()))


def dispatch_source(laws: tuple[KernelLaw, ...]) -> str:
    """The source of the dispatch module over `laws`."""
    lines = [
        '"""The force sum\'s dispatch over the compiled force laws the effects declare (`effects.base.kernel_law`).',
        "",
        "Generated from the registry by `python -m finger_sim.kernel.force_laws`: do not edit.",
        '"""',
        "",
        "from finger_sim.kernel.force_laws import compiled_laws",
        "from finger_sim.kernel.jit import LAW, compiled_law, njit",
        "",
        "_LAWS = {law.code: law for law in compiled_laws()}",
    ]
    lines += [f"law_{law.code} = compiled_law(_LAWS[{law.code}])  # {law.force.__module__}.{law.force.__qualname__}"
              for law in laws]
    lines += [
        "",
        "",
        "@njit(**LAW)",
        "def element_force(code, m, o, t, q0, q1, q2, v0, v1, v2):",
        '    """Q (N·m) of an element whose law is `code`, its parameters at m[o:]; (0, 0, 0) for any other code."""',
    ]
    for law in laws:
        arguments = [f"m[o + {i}]" if i else "m[o]" for i in range(law.parameters)] + list(law.state)
        lines += [f"    if code == {law.code}:", f"        return law_{law.code}({', '.join(arguments)})"]
    lines += ["    return 0.0, 0.0, 0.0", ""]
    return "\n".join(lines)


def uncommitted_source() -> str:
    """"" when this process's registry is the committed dispatch's; else the dispatch's source and the source
    of every law defined outside the package (what numba's cache must be keyed by)."""
    laws = compiled_laws()
    source = dispatch_source(laws)
    if COMMITTED.read_text(encoding="utf-8") == source:
        return ""
    outside = [inspect.getsource(f) for law in laws for f in (law.force, *law.callees)
               if not Path(inspect.getfile(f)).resolve().is_relative_to(PACKAGE)]
    return "\n".join([source, *outside])


@functools.cache
def element_forces() -> ModuleType:
    """The dispatch module of this process's registry: the committed one, or one written into numba's
    cache folder (keyed by its source) and imported from there."""
    if not uncommitted_source():
        from finger_sim.kernel import element_forces as committed

        return committed
    from finger_sim.kernel import cache_folder

    path = cache_folder() / f"{GENERATED_MODULE}.py"
    source = dispatch_source(compiled_laws())
    if not path.exists() or path.read_text(encoding="utf-8") != source:
        path.write_text(source, encoding="utf-8")
    spec = importlib.util.spec_from_file_location(GENERATED_MODULE, path)
    assert spec is not None and spec.loader is not None
    module = sys.modules[GENERATED_MODULE] = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


if __name__ == "__main__":
    COMMITTED.write_text(dispatch_source(compiled_laws()), encoding="utf-8")
