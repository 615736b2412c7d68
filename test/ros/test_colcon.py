"""The colcon install path: `colcon build` of a copy of the package in a temporary workspace puts
the executables where `ros2 run` looks (<prefix>/lib/finger_sim/<exe>, the prefix found through
the ament index), the scenes under share/finger_sim/config, and the built node runs a scene
from that share directory and exits 0.

Uses the venv's colcon (colcon-common-extensions). `ros2 run` itself is not installed here;
its lookup is ament_index_python.get_package_prefix + lib/<package>/<executable>, done below.
"""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

pytest.importorskip("rclpy")  # the executables it builds are ROS nodes

ROOT = Path(__file__).resolve().parents[2]
VENV_BIN = Path(sys.executable).parent
COLCON = shutil.which("colcon", path=f"{VENV_BIN}{os.pathsep}{os.environ.get('PATH', '')}")
BUILD_TIMEOUT = 240.0  # s
RUN_TIMEOUT = 60.0  # s
#: What the package is built from: setup.py's inputs, nothing else of the working tree.
PACKAGE_FILES = ("setup.py", "setup.cfg", "package.xml", "README.md")
PACKAGE_DIRS = ("resource", "config", "finger_sim", "urdf", "launch")
EXECUTABLES = ("finger_node", "finger_pd_controller", "finger_replay", "finger-sim")

pytestmark = pytest.mark.skipif(COLCON is None, reason="colcon is not installed")


@pytest.fixture(scope="module")
def workspace(tmp_path_factory) -> Path:
    ws = tmp_path_factory.mktemp("colcon_ws")
    src = ws / "src" / "finger_sim"
    src.mkdir(parents=True)
    for name in PACKAGE_FILES:
        shutil.copy2(ROOT / name, src / name)
    for name in PACKAGE_DIRS:
        shutil.copytree(ROOT / name, src / name, ignore=shutil.ignore_patterns("__pycache__", "*.pyc", "*.egg-info"))
    env = dict(os.environ, PATH=f"{VENV_BIN}{os.pathsep}{os.environ.get('PATH', '')}")
    for key in ("AMENT_PREFIX_PATH", "COLCON_PREFIX_PATH", "PYTHONPATH"):
        env.pop(key, None)
    proc = subprocess.run([COLCON, "build", "--base-paths", "src", "--event-handlers", "console_cohesion+"],
                          cwd=ws, env=env, capture_output=True, text=True, timeout=BUILD_TIMEOUT)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    return ws


def installed_env(ws: Path, domain_id: int) -> dict[str, str]:
    """What `source install/setup.bash` sets for this package, plus the test's ROS isolation."""
    from conftest import ros_environment

    prefix = ws / "install" / "finger_sim"
    site = prefix / "lib" / f"python{sys.version_info.major}.{sys.version_info.minor}" / "site-packages"
    env = ros_environment(domain_id)
    env.update(AMENT_PREFIX_PATH=str(prefix), PYTHONPATH=str(site), PATH=f"{VENV_BIN}{os.pathsep}{env.get('PATH', '')}")
    return env


def test_executables_are_where_ros2_run_looks(workspace, monkeypatch):
    from ament_index_python.packages import get_package_prefix, get_package_share_directory

    monkeypatch.setenv("AMENT_PREFIX_PATH", str(workspace / "install" / "finger_sim"))
    prefix = Path(get_package_prefix("finger_sim"))
    assert prefix == workspace / "install" / "finger_sim"
    for exe in EXECUTABLES:
        path = prefix / "lib" / "finger_sim" / exe
        assert path.is_file() and os.access(path, os.X_OK), path
        shebang = path.read_text().splitlines()[0]
        assert shebang.startswith("#!") and "python" in shebang, shebang
    share = Path(get_package_share_directory("finger_sim"))
    assert (share / "package.xml").is_file()
    assert {"paper_flexion.yaml", "finger_default.yaml", "finger_node.yaml"} <= {p.name for p in (share / "config").iterdir()}
    assert (share / "urdf" / "finger.urdf").read_text() == (ROOT / "urdf" / "finger.urdf").read_text()
    assert (share / "launch" / "finger.launch.py").read_text() == (ROOT / "launch" / "finger.launch.py").read_text()


def test_the_built_node_runs_a_scene_from_its_share_directory(workspace, ros_domain, tmp_path):
    env = installed_env(workspace, ros_domain)
    prefix = workspace / "install" / "finger_sim"
    # the installed package is the one imported, not the source tree
    where = subprocess.run([sys.executable, "-c", "import finger_sim.ros.node as m; print(m.__file__)"],
                           env=env, capture_output=True, text=True, timeout=RUN_TIMEOUT, cwd=tmp_path)
    assert Path(where.stdout.strip()).is_relative_to(prefix), where.stdout + where.stderr
    node = prefix / "lib" / "finger_sim" / "finger_node"
    proc = subprocess.run(
        [str(node), "--ros-args", "--params-file", str(prefix / "share" / "finger_sim" / "config" / "finger_node.yaml"),
         "-p", "torque_source:=scene", "-p", "realtime_factor:=0.0"],
        env=env, capture_output=True, text=True, timeout=RUN_TIMEOUT, cwd=tmp_path, start_new_session=True)
    out = proc.stdout + proc.stderr
    assert proc.returncode == 0, out
    assert f"from {prefix / 'share' / 'finger_sim' / 'config' / 'paper_flexion.yaml'}" in out, out
    assert "ended at t = 0.3 s after 300 steps" in out, out
