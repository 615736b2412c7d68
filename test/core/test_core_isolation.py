"""The core imports nothing from ROS or MCAP (STYLE.md: data flows one way), and the MCAP
library finger_sim.log imports nothing from the core.

Checked twice: in a fresh interpreter after importing every core module *and running*
a scene and the CLI (lazy imports included), and statically over every import statement
of the core's source (function-level imports included).
"""

from __future__ import annotations

import ast
import json
import subprocess
import sys
from pathlib import Path

import finger_sim

import reference as ref

CORE_MODULES = [
    "finger_sim",
    "finger_sim.model",
    "finger_sim.kinematics",
    "finger_sim.effects",
    "finger_sim.dynamics",
    "finger_sim.projection",
    "finger_sim.inputs",
    "finger_sim.stability",
    "finger_sim.auto",
    "finger_sim.integrators",
    "finger_sim.scene",
    "finger_sim.simulate",
    "finger_sim.cli",
]
FORBIDDEN = ("rclpy", "mcap", "mcap_ros2", "rosbags", "finger_sim.ros", "finger_sim.log")
PACKAGE = Path(finger_sim.__file__).parent
#: cli.py is the front-end of every subcommand: its log and bench commands import MCAP
#: lazily, inside their handlers; the fresh-interpreter probe below checks that simulate
#: and kinematics through it load no ROS or MCAP. run_log.py is the bridge between the core
#: and the MCAP library (like ros/ is to ROS), so it is no core file either.
ADAPTERS = ("cli.py", "run_log.py")
CORE_FILES = (sorted(p for p in PACKAGE.glob("*.py") if p.name not in ADAPTERS)
              + sorted((PACKAGE / "integrators").glob("*.py")) + sorted((PACKAGE / "effects").glob("*.py"))
              + sorted((PACKAGE / "actuators").glob("*.py")))
#: The MCAP library under finger_sim/log: it may import itself, never the core or ROS adapters.
LOG_FILES = sorted((PACKAGE / "log").glob("*.py"))

PROBE = f"""
import contextlib, io, json, sys
for name in {CORE_MODULES!r}:
    __import__(name)
from finger_sim.scene import load_scene
from finger_sim.simulate import simulate
from finger_sim.cli import main
traj = simulate(load_scene({str(ref.CONFIG / "bang_bang.yaml")!r}).with_overrides(duration=0.02))
with contextlib.redirect_stdout(io.StringIO()):
    main(["kinematics"])
    main(["simulate", {str(ref.CONFIG / "paper_to_stop.yaml")!r}, "--t-end", "0.01"])
forbidden = {FORBIDDEN!r}
print(json.dumps({{
    "loaded": sorted(m for m in sys.modules if m.startswith(forbidden)),
    "core": all(m in sys.modules for m in {CORE_MODULES!r}),
    "theta1": float(traj.q[-1, 0]),
}}))
"""


def test_fresh_interpreter_loads_no_ros_or_mcap():
    proc = subprocess.run([sys.executable, "-c", PROBE], capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, proc.stderr
    result = json.loads(proc.stdout.splitlines()[-1])
    assert result["core"]
    assert result["loaded"] == []
    assert result["theta1"] > 0.0  # the run did happen: +4 N·mm for the first 10 ms flexes the MCP


def imported_names(path: Path) -> set[str]:
    names = set()
    for node in ast.walk(ast.parse(path.read_text(), filename=str(path))):
        if isinstance(node, ast.Import):
            names.update(alias.name for alias in node.names)
        elif isinstance(node, ast.ImportFrom) and node.module:
            names.add(node.module)
    return names


def test_no_core_source_imports_ros_or_mcap():
    assert len(CORE_FILES) >= 18
    offenders = {
        str(path.relative_to(PACKAGE)): sorted(n for n in imported_names(path) if n.startswith(FORBIDDEN))
        for path in CORE_FILES
    }
    assert {k: v for k, v in offenders.items() if v} == {}


def test_log_library_imports_nothing_from_the_core():
    assert len(LOG_FILES) >= 5
    offenders = {
        str(path.relative_to(PACKAGE)): sorted(n for n in imported_names(path)
                                                 if n.startswith("finger_sim") and not n.startswith("finger_sim.log"))
        for path in LOG_FILES
    }
    assert {k: v for k, v in offenders.items() if v} == {}
    relative = [path.name for path in LOG_FILES
                for node in ast.walk(ast.parse(path.read_text())) if isinstance(node, ast.ImportFrom) and node.level > 1]
    assert relative == []  # no `from .. import` out of the package either
