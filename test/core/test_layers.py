"""The package's rooms hold: each module imports only its own room and the rooms below it, so no
import cycle runs between two rooms, and the core imports no kernel, bench, ROS or MCAP.

Read mechanically from the source: every import statement of every module (function-level and
TYPE_CHECKING imports included, which is stricter than what runs), resolved to the module it names.
The package root (`finger_sim/__init__.py`, the one place the compiled kernel is wired into the
core's `stepper_slot`) is the composition root: its implicit import by every module, and
`from finger_sim import __version__`, are no edges.
"""

from __future__ import annotations

import ast
import functools
from pathlib import Path

import finger_sim

PACKAGE = Path(finger_sim.__file__).parent

#: Rooms from low to high. A module not named here is in the core if it sits at the top level or
#: in a core folder; every other folder is a room of its own name.
CORE_FOLDERS = ("effects", "integrators", "actuators", "simulation")
FRONT_ENDS = ("rollouts", "sweep", "sweep_plan", "cluster", "sample", "csv_columns", "streaming")
RECORDS = ("run_log", "run_log_checks")  # the bridge from the core to the MCAP library
#: The one module of runtime/ that records: it assembles the MCAP log, the rest of runtime/ imports no MCAP.
RECORDING = "finger_sim.runtime.recording"
#: Entry points run as `python -m`, which exercise every room: the numba cache's warm-up.
TOOLS = ("finger_sim.kernel.warm",)
#: room → the rooms it may import (besides itself). The MCAP library (log) stands alone.
ALLOWED = {
    "core": set(),
    "kernel": {"core"},
    "front": {"core", "kernel", "batch"},
    "batch": {"core", "kernel"},
    "log": set(),
    "records": {"core", "kernel", "front", "log"},
    "runtime": {"core", "kernel", "front"},  # no MCAP: recording is its own room
    "recording": {"core", "kernel", "front", "log", "records", "runtime"},
    "tasks": {"core", "kernel", "front", "batch", "runtime"},
    "view": {"core", "kernel", "front", "log", "records"},
    "ros": {"core", "kernel", "front", "batch", "log", "records", "runtime", "recording", "tasks"},
    "bench": {"core", "kernel", "front", "batch", "log", "records", "runtime", "recording", "tasks", "view", "ros"},
    "cli": {"core", "kernel", "front", "batch", "log", "records", "runtime", "recording", "tasks", "view", "ros",
            "bench"},
    "package": {"kernel", "front"},  # __init__: wires the kernel; `finger_sim.rollout` on first use
}
#: Third-party packages a room must not import: the core runs without ROS, MCAP and numba.
FORBIDDEN_PACKAGES = {
    "core": ("rclpy", "mcap", "mcap_ros2", "rosbags", "numba"),
    "runtime": ("rclpy", "mcap", "mcap_ros2", "rosbags"),
}
#: Edges that break the rule today (none: the contact law takes its code from effects.base, the
#: drive its compiled guards and lean step from the slot).
PENDING: set[tuple[str, str]] = set()


def module_name(path: Path) -> str:
    parts = list(path.relative_to(PACKAGE.parent).with_suffix("").parts)
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


MODULES = {module_name(p): p for p in PACKAGE.rglob("*.py")}


def room(module: str) -> str:
    parts = module.split(".")
    if len(parts) == 1:
        return "package"
    if module == RECORDING:
        return "recording"
    if parts[1] == "cli" or module in TOOLS:
        return "cli"
    if parts[1] in FRONT_ENDS:
        return "front"
    if parts[1] in RECORDS:
        return "records"
    if len(parts) == 2 and f"{parts[1]}.py" in {p.name for p in PACKAGE.glob("*.py")} or parts[1] in CORE_FOLDERS:
        return "core"
    return parts[1]


def imports(path: Path) -> tuple[set[str], set[str]]:
    """(modules of finger_sim, top-level third-party packages) imported anywhere in the file."""
    ours, theirs = set(), set()
    for node in ast.walk(ast.parse(path.read_text(), filename=str(path))):
        if isinstance(node, ast.Import):
            names = [alias.name for alias in node.names]
        elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            # `from pkg import sub` names the submodule; `from pkg import name` the module pkg
            subs = [f"{node.module}.{alias.name}" for alias in node.names]
            names = [s for s in subs if s in MODULES] or [node.module]
            if len(names) < len(subs) and names != [node.module]:
                names.append(node.module)
        else:
            continue
        for name in names:
            if name.split(".")[0] != "finger_sim":
                theirs.add(name.split(".")[0])
                continue
            while name not in MODULES and "." in name:
                name = name.rsplit(".", 1)[0]
            ours.add(name)
    return ours, theirs


@functools.cache
def edges() -> frozenset[tuple[str, str]]:
    """Every import of one module by another; the package root (`__version__`) is no room's."""
    return frozenset((m, n) for m, path in MODULES.items() for n in imports(path)[0] if n not in (m, "finger_sim"))


def test_the_rooms_are_what_the_rules_name():
    rooms = {room(m) for m in MODULES}
    assert rooms == set(ALLOWED)
    core = {m for m in MODULES if room(m) == "core"}
    assert {"finger_sim.simulate", "finger_sim.scene", "finger_sim.dynamics", "finger_sim.stepper_slot",
            "finger_sim.effects.spring", "finger_sim.integrators.dop853", "finger_sim.actuators.drive"} <= core
    assert room("finger_sim.kernel.numerics") == "kernel" and room("finger_sim.ros.node") == "ros"


def test_each_room_imports_only_the_rooms_below_it():
    offenders = sorted((m, n) for m, n in edges() - PENDING
                       if room(n) != room(m) and room(n) not in ALLOWED[room(m)])
    assert offenders == []


def test_the_core_imports_no_kernel_bench_ros_or_mcap():
    forbidden_rooms = {"kernel", "bench", "ros", "log", "records", "runtime", "batch", "front"}
    offenders = sorted((m, n) for m, n in edges() - PENDING if room(m) == "core" and room(n) in forbidden_rooms)
    assert offenders == []
    packages = {m: sorted(set(imports(path)[1]) & set(FORBIDDEN_PACKAGES[room(m)]))
                for m, path in MODULES.items() if room(m) in FORBIDDEN_PACKAGES}
    assert {m: p for m, p in packages.items() if p} == {}


def test_no_import_cycle_between_rooms():
    graph: dict[str, set[str]] = {r: set() for r in ALLOWED}
    for m, n in edges() - PENDING:
        if room(m) != room(n):
            graph[room(m)].add(room(n))
    # depth-first search for a back edge: a cycle through two or more rooms
    state: dict[str, int] = {}
    cycle: list[str] = []

    def visit(node: str, path: list[str]) -> bool:
        state[node] = 1
        for nxt in sorted(graph[node]):
            if state.get(nxt) == 1:
                cycle.extend([*path[path.index(nxt):], nxt] if nxt in path else [node, nxt])
                return True
            if nxt not in state and visit(nxt, [*path, nxt]):
                return True
        state[node] = 2
        return False

    assert not any(visit(r, [r]) for r in sorted(graph) if r not in state), cycle


def test_the_checks_see_a_violation():
    """The rules fire on a planted core → kernel import and on a planted cycle (not vacuous)."""
    planted = {("finger_sim.simulate", "finger_sim.kernel.runner"), ("finger_sim.kernel.runner", "finger_sim.simulate")}
    bad = [(m, n) for m, n in planted if room(n) != room(m) and room(n) not in ALLOWED[room(m)]]
    assert bad == [("finger_sim.simulate", "finger_sim.kernel.runner")]
    # the edge the kernel loop really has (runner → simulate, for its type) is allowed only one way
    assert ("finger_sim.kernel.runner", "finger_sim.simulate") in edges()
    assert not any(m == "finger_sim.simulate" and room(n) == "kernel" for m, n in edges())
