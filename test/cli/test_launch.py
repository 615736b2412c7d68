"""finger_node's live default scene (config/finger_default.yaml) and launch/finger.launch.py.

ROS 2's `launch` is not installable here, so the launch file is checked statically: its AST is
read, every executable, package-share path and launch argument it names is checked against
what setup.py installs, and the robot_description command it builds is run with the defaults
its arguments declare (a small evaluator of the substitutions used, below).
"""

from __future__ import annotations

import ast
import configparser
import math
import os
import runpy
import shlex
import subprocess
import sys
import xml.etree.ElementTree as ET
from pathlib import Path
from typing import Any

import pytest
import setuptools

from finger_sim import kinematics
from finger_sim.joints import JOINT_NAMES
from finger_sim.scene import load_scene, scene_from_dict
from finger_sim.scene_paths import resolve_scene
from finger_sim.simulate import Simulator
from finger_sim.stability import modal_roots

ROOT = Path(__file__).resolve().parents[2]
SCENE = ROOT / "config" / "finger_default.yaml"
LAUNCH = ROOT / "launch" / "finger.launch.py"
VENV_BIN = Path(sys.executable).parent
UPPER = math.pi / 2  # rad, the 90° stop
HELD_TORQUE = 0.01  # N·m
FLEXED = 1.2  # rad, the released finger's start
SETTLE_S = 3.0  # s: "settles within a few seconds"
#: robot_state_publisher's executable in its package (ros/robot_state_publisher, CMakeLists.txt).
KNOWN_EXECUTABLES = {"robot_state_publisher": {"robot_state_publisher"}}
COMMAND_TIMEOUT = 60.0  # s


# -- the scene ---------------------------------------------------------------------------

def test_finger_default_is_the_live_scene_it_says():
    scene = load_scene(SCENE)
    assert resolve_scene("finger_default") == SCENE
    assert scene.name == "finger_default" and "paper_flexion" in scene.description
    assert scene.mcp_limits == (0.0, UPPER) and scene.restitution == 0.3
    assert scene.torque.to_dict() == {"type": "constant", "value": 0.0}
    assert (scene.method, scene.dt) == ("auto", 0.001) and scene.duration >= 3600.0
    assert (scene.theta1, scene.theta1_dot) == (0.0, 0.0)


def test_its_damping_ratio_is_the_one_its_description_states():
    """ζ = −Re s / |s| of the 1-DOF linearization over the stop range: 0.43..0.46 (light: underdamped)."""
    scene = load_scene(SCENE)
    system = scene.build_system()
    zetas = []
    for deg in range(91):
        s, _ = modal_roots(system, kinematics.assemble(scene.params, math.radians(deg)))
        zetas.append(-s.real / abs(s))
    assert (round(min(zetas), 2), round(max(zetas), 2)) == (0.43, 0.46)
    assert "modal damping ratio 0.43..0.46" in scene.description


def test_a_held_torque_drives_it_onto_the_90_degree_stop_within_1_s():
    sim = Simulator(load_scene(SCENE))
    theta1 = []
    for _ in range(1000):
        theta1.append(sim.step(HELD_TORQUE).q[0])
    end = sim.state
    assert end.t == pytest.approx(1.0, abs=1e-12)
    assert abs(end.q[0] - UPPER) <= 1e-12 and end.v[0] == 0.0  # resting on the stop
    assert min(theta1) >= 0.0 and max(theta1) <= UPPER + 1e-12


def test_released_from_flexion_it_settles_on_the_0_stop_without_crossing_either():
    scene = scene_from_dict(load_scene(SCENE).to_dict() | {"initial": {"theta1": FLEXED}, "duration": SETTLE_S})
    sim = Simulator(scene)
    energy = [sim.system.energy(sim.state.q, sim.state.v)]
    theta1 = [sim.state.q[0]]
    for _ in range(scene.step_count):
        state = sim.step(0.0)
        energy.append(sim.system.energy(state.q, state.v))
        theta1.append(state.q[0])
    assert min(theta1) >= -1e-12 and max(theta1) == FLEXED  # never past 0°, never further flexed
    rises = [b - a for a, b in zip(energy, energy[1:])]
    assert max(rises) <= 1e-15 * energy[0]  # damping and impacts only take energy away
    assert energy[-1] <= 1e-6 * energy[0] and abs(theta1[-1]) < 1e-3  # at rest on the 0° stop after 3 s


# -- the launch file ---------------------------------------------------------------------

def _setup_kwargs() -> dict[str, Any]:
    """The keyword arguments setup.py passes to setuptools.setup (run in the repo, setup() captured)."""
    captured: dict[str, Any] = {}
    original, cwd = setuptools.setup, Path.cwd()
    setuptools.setup = lambda **kw: captured.update(kw)  # type: ignore[assignment]
    try:
        os.chdir(ROOT)
        runpy.run_path(str(ROOT / "setup.py"))
    finally:
        setuptools.setup = original
        os.chdir(cwd)
    return captured


@pytest.fixture(scope="module")
def setup_kwargs() -> dict[str, Any]:
    return _setup_kwargs()


@pytest.fixture(scope="module")
def installed(setup_kwargs) -> dict[str, Path]:
    """Install path (relative to the prefix) → source file, from setup.py's data_files."""
    return {f"{dest}/{Path(src).name}": ROOT / src for dest, files in setup_kwargs["data_files"] for src in files}


@pytest.fixture(scope="module")
def console_scripts(setup_kwargs) -> set[str]:
    """Executables colcon installs to lib/finger_sim (setup.cfg's install_scripts)."""
    cfg = configparser.ConfigParser()
    cfg.read(ROOT / "setup.cfg")
    assert cfg["install"]["install_scripts"] == "$base/lib/finger_sim"
    return {line.split("=")[0].strip() for line in setup_kwargs["entry_points"]["console_scripts"]}


class LaunchFile:
    """The launch file's AST, with an evaluator of the substitutions it uses.

    Substitutions evaluate to strings: FindPackageShare(p) → "share/<p>", ExecutableInPackage(e, p)
    → "lib/<p>/<e>" (both relative to the install prefix), LaunchConfiguration(n) → `configs[n]`,
    Command and PathJoinSubstitution like launch's own, ParameterValue → its value.
    """

    def __init__(self, path: Path) -> None:
        self.tree = ast.parse(path.read_text(), filename=str(path))
        self.constants = {t.id: n.value.value for n in self.tree.body if isinstance(n, ast.Assign)
                          for t in n.targets if isinstance(t, ast.Name) and isinstance(n.value, ast.Constant)}
        self.function = next(n for n in self.tree.body if isinstance(n, ast.FunctionDef) and n.name == "generate_launch_description")
        self.locals = {t.id: n.value for n in ast.walk(self.function) if isinstance(n, ast.Assign)
                       for t in n.targets if isinstance(t, ast.Name)}

    def calls(self, name: str) -> list[ast.Call]:
        return [n for n in ast.walk(self.tree) if isinstance(n, ast.Call) and getattr(n.func, "id", getattr(n.func, "attr", None)) == name]

    @staticmethod
    def argument(call: ast.Call, position: int | None, keyword: str) -> ast.expr | None:
        """The argument given by `keyword`, else the positional one at `position` (None: keyword only)."""
        found = [k.value for k in call.keywords if k.arg == keyword]
        if found:
            return found[0]
        return call.args[position] if position is not None and len(call.args) > position else None

    def literal(self, node: ast.expr | None) -> Any:
        """A constant, or a module-level constant's value."""
        if isinstance(node, ast.Name):
            return self.constants[node.id]
        return ast.literal_eval(node) if node is not None else None

    def declared(self) -> dict[str, ast.expr | None]:
        return {self.literal(self.argument(c, 0, "name")): self.argument(c, 1, "default_value") for c in self.calls("DeclareLaunchArgument")}

    def defaults(self) -> dict[str, str]:
        return {name: self.evaluate(node, {}) for name, node in self.declared().items()}

    def evaluate(self, node: ast.expr, configs: dict[str, str]) -> str:
        if isinstance(node, ast.Constant):
            return str(node.value)
        if isinstance(node, ast.Name):
            return self.evaluate(self.locals[node.id], configs) if node.id in self.locals else self.constants[node.id]
        if isinstance(node, ast.List):
            return "".join(self.evaluate(e, configs) for e in node.elts)
        assert isinstance(node, ast.Call), ast.dump(node)
        kind = getattr(node.func, "id", getattr(node.func, "attr", None))
        arg = lambda i, k: self.argument(node, i, k)  # noqa: E731
        if kind == "LaunchConfiguration":
            return configs[self.literal(arg(0, "variable_name"))]
        if kind == "FindPackageShare":
            return f"share/{self.evaluate(arg(0, 'package'), configs)}"
        if kind == "ExecutableInPackage":
            return f"lib/{self.evaluate(arg(1, 'package'), configs)}/{self.evaluate(arg(0, 'executable'), configs)}"
        if kind == "PathJoinSubstitution":
            return "/".join(self.evaluate(e, configs) for e in arg(0, "substitutions").elts)
        if kind in ("Command", "ParameterValue"):
            return self.evaluate(arg(0, "command" if kind == "Command" else "value"), configs)
        raise AssertionError(f"no evaluator for {kind}")


@pytest.fixture(scope="module")
def launch_file() -> LaunchFile:
    return LaunchFile(LAUNCH)


def test_it_defines_generate_launch_description_and_is_installed(launch_file, installed):
    assert launch_file.function.args.args == []
    assert installed["share/finger_sim/launch/finger.launch.py"] == LAUNCH


def test_every_launch_configuration_is_a_declared_argument_and_every_argument_is_used(launch_file):
    declared = launch_file.declared()
    used = {launch_file.literal(launch_file.argument(c, 0, "variable_name")) for c in launch_file.calls("LaunchConfiguration")}
    assert used == set(declared) == {"params_file", "namespace", "frame_prefix", "use_rsp", "description_scene", "use_sim_time"}
    assert all(default is not None for default in declared.values())


def test_every_executable_it_starts_is_installed_where_ros2_run_looks(launch_file, console_scripts):
    nodes = launch_file.calls("Node")
    started = {(launch_file.literal(launch_file.argument(n, None, "package")), launch_file.literal(launch_file.argument(n, None, "executable")))
               for n in nodes}
    assert started == {("finger_sim", "finger_node"), ("robot_state_publisher", "robot_state_publisher")}
    known = KNOWN_EXECUTABLES | {"finger_sim": console_scripts}
    assert all(exe in known[package] for package, exe in started)
    for call in launch_file.calls("ExecutableInPackage"):
        path = launch_file.evaluate(call, {})
        assert path.startswith("lib/finger_sim/") and path.removeprefix("lib/finger_sim/") in console_scripts, path


def test_every_share_file_it_names_is_installed_from_the_repo(launch_file, installed):
    defaults = launch_file.defaults()
    shared = {value for value in defaults.values() if value.startswith("share/")}
    assert shared == {"share/finger_sim/config/finger_node.yaml", "share/finger_sim/config/finger_default.yaml"}
    for path in shared:
        assert path in installed and installed[path].is_file(), path
    assert load_scene(installed[defaults["description_scene"]]).name == "finger_default"


def _robot_description(launch_file: LaunchFile, installed: dict[str, Path], **overrides: str) -> str:
    """Run robot_state_publisher's robot_description command as launch would (split like a shell's
    command line), with installed paths mapped to the repo's sources and the venv's scripts."""
    rsp = next(n for n in launch_file.calls("Node") if launch_file.literal(launch_file.argument(n, None, "package")) == "robot_state_publisher")
    params = launch_file.argument(rsp, None, "parameters").elts[0]
    value = params.values[[launch_file.literal(k) for k in params.keys].index("robot_description")]
    command = shlex.split(launch_file.evaluate(value, launch_file.defaults() | overrides))
    command = [str(VENV_BIN / Path(a).name) if a.startswith("lib/finger_sim/") else str(installed.get(a, a)) for a in command]
    proc = subprocess.run(command, capture_output=True, text=True, timeout=COMMAND_TIMEOUT, cwd=ROOT)
    assert proc.returncode == 0 and proc.stderr == "", proc.stderr  # launch's Command fails on stderr output
    return proc.stdout


def test_robot_description_by_default_is_the_installed_urdf(launch_file, installed):
    text = _robot_description(launch_file, installed)
    assert text == installed["share/finger_sim/urdf/finger.urdf"].read_text()


def test_robot_description_with_a_frame_prefix_names_the_nodes_prefixed_joints(launch_file, installed):
    robot = ET.fromstring(_robot_description(launch_file, installed, frame_prefix="index_"))
    links = {e.get("name") for e in robot.iter("link")}
    joints = {e.get("name"): e.get("type") for e in robot.iter("joint")}
    assert links and all(name.startswith("index_") for name in links | set(joints))
    assert "index_finger_base" in links
    assert {name for name, kind in joints.items() if kind != "fixed"} == {f"index_{n}" for n in JOINT_NAMES}


def test_package_xml_exec_depends_on_what_the_launch_file_uses():
    """issue 19, item 11: every ROS package the launch file imports or starts a node from is an
    exec_depend, so that rosdep installs it (read from the launch file's source, not listed here)."""
    tree = ast.parse(LAUNCH.read_text())
    imported = {node.module.split(".")[0] for node in ast.walk(tree) if isinstance(node, ast.ImportFrom) and node.module}
    started = {kw.value.value for node in ast.walk(tree) if isinstance(node, ast.Call)
               for kw in node.keywords if kw.arg == "package" and isinstance(kw.value, ast.Constant)}
    assert {"launch", "launch_ros", "robot_state_publisher"} <= imported | started
    depends = {e.text for e in ET.parse(ROOT / "package.xml").getroot().iter("exec_depend")}
    assert (imported | started) - {"__future__"} <= depends
