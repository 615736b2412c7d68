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

The same module holds each law written out for the rollout's lock-step tiles (`tile_element_force`, a loop
over the fingers of a tile around the law's own statements, `tile_statements`): the tile form is generated
from the law's source as the dispatch is, so no law is written again for the tiles; a law that cannot be
written so (it calls functions of its own, reads t, branches) leaves its rows to the row-by-row loop.

The registry is read once per process, when the kernel first needs it (`compiled_laws`): a law registered
later has no compiled form in that process (its scenes run on the Python path).
"""

from __future__ import annotations

import ast
import functools
import importlib.util
import inspect
import sys
import textwrap
from pathlib import Path
from types import ModuleType
from typing import TYPE_CHECKING

from finger_sim.effects.base import KERNEL_ARGUMENTS, KERNEL_RESIDENT

if TYPE_CHECKING:
    from finger_sim.effects.base import KernelLaw

#: The committed dispatch of the shipped registry.
COMMITTED = Path(__file__).with_name("element_forces.py")
#: The module name of a dispatch generated at run time (suffixed with its source's digest).
GENERATED_MODULE = "finger_sim_element_forces"
PACKAGE = Path(__file__).resolve().parents[1]
#: The row of a lock-step tile's stage state (6 × fingers, `rollout_loop._tile`) that each kernel argument reads.
TILE_ROWS = {name: row for row, name in enumerate(KERNEL_ARGUMENTS[1:])}
#: The names the tile form binds around a law's statements: a law that uses one of them is not tiled.
TILE_NAMES = frozenset({"code", "m", "o", "y", "force", "n", "f"})


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
        "import math",
        "",
        "from finger_sim.kernel.force_laws import compiled_laws",
        "from finger_sim.kernel.jit import JIT, LAW, compiled_law, njit",
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
    tiled = [(law, body) for law in laws if (body := tile_statements(law)) is not None]
    lines += [
        "",
        "#: The laws `tile_element_force` writes out for the rollout's lock-step tiles (`rollout_loop.run_lockstep`).",
        f"TILE_CODES = {tuple(law.code for law, _ in tiled)!r}",
        "",
        "",
        "@njit(**JIT)",  # a call per element and stage: inlined, the tiles measured ≈ 4 % slower
        "def tile_element_force(code, m, o, y, force, n):",
        '    """Adds Q (N·m) of an element whose law is `code` to force (3 × n) for each of n fingers, its',
        "    parameters at m[o:] (a column a finger), the stage state y (q, q': 6 × n): the law's own statements",
        "    over one finger at a time, written into the loop (`tile_statements`); (0, 0, 0) for any other code,",
        '    added as `numerics.generalized_force` adds it."""',
    ]
    for law, body in tiled:
        lines += [f"    if code == {law.code}:", "        for f in range(n):",
                  *(f"            {line}" for line in body), "        return"]
    lines += ["    for f in range(n):", *(f"        force[{c}, f] += 0.0" for c in range(3)), ""]
    return "\n".join(lines)


@functools.cache  # read from the law's source once per process
def tile_statements(law: KernelLaw) -> tuple[str, ...] | None:
    """The statements of `law` for finger f of a lock-step tile: its parameters and state read from the tile's
    columns (m[o + i, f], y[row, f]), its own statements as written, then its Q added to force[:, f]. None when
    it cannot be written so: it calls functions of its own (callees), reads t (the tiles carry none), is not
    assignments to names ending in `return (Q1, Q2, Q3)`, uses a name the tile binds (TILE_NAMES) or a global
    other than `math`, or has no source to read."""
    if law.callees or "t" in law.state:
        return None
    try:
        function = ast.parse(textwrap.dedent(inspect.getsource(law.force))).body[0]
    except (OSError, TypeError):
        return None
    assert isinstance(function, ast.FunctionDef)
    body = function.body[1:] if ast.get_docstring(function) is not None else function.body
    *statements, result = body
    if not (isinstance(result, ast.Return) and isinstance(result.value, ast.Tuple) and len(result.value.elts) == 3
            and all(isinstance(s, ast.Assign) and all(_names_only(t) for t in s.targets) for s in statements)):
        return None
    arguments = [a.arg for a in function.args.args]
    used = {node.id for s in body for node in ast.walk(s) if isinstance(node, ast.Name)} | set(arguments)
    bound = set(arguments) | {node.id for s in statements for t in s.targets for node in ast.walk(t)
                              if isinstance(node, ast.Name)}
    if used & TILE_NAMES or used - bound - {"math"}:
        return None
    reads = [(name, f"m[o + {i}, f]" if i else "m[o, f]") for i, name in enumerate(arguments[:law.parameters])]
    reads += [(name, f"y[{TILE_ROWS[kernel_name]}, f]") for name, kernel_name in zip(arguments[law.parameters:],
                                                                                      law.state)]
    lines = [f"{', '.join(n for n, _ in group)} = {', '.join(r for _, r in group)}"
             for group in (reads[:law.parameters], reads[law.parameters:]) if group]
    lines += [ast.unparse(s) for s in statements]
    lines += [f"force[{c}, f] += {ast.unparse(e)}" for c, e in enumerate(result.value.elts)]
    return tuple(lines)


def _names_only(target: ast.expr) -> bool:
    """An assignment's target that binds names only (a name, or a tuple of them)."""
    return isinstance(target, ast.Name) or (isinstance(target, ast.Tuple)
                                            and all(isinstance(e, ast.Name) for e in target.elts))


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
