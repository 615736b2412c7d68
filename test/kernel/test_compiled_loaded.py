"""A Simulator loads every compiled function its step can call while it is built, none while it steps.

numba loads a compiled function from its on-disk cache at its first call in a process (5–20 ms of CPU each):
before, the compiled event step of chatter_wall handed step 315 to Python's event path, which loaded four
functions then (a 6–45 ms step at 1 kHz). The reference is numba's own record: each compiled function's
overloads (`Dispatcher.overloads`), read in a fresh process per kind of path, after the Simulator is built
and after the whole scene is stepped; and the path is shown to be reached (Python took steps, or the mode
owner's stepping ran).
"""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

pytest.importorskip("numba")

CONFIG = Path(__file__).resolve().parents[2] / "config"

#: Steps the whole scene, as the node does (the scene's profile, or its value held over each step: "held"), and
#: prints the compiled functions that gained an overload after construction, and the steps Python's path took.
CHILD = """
import json, sys
from numba.core.dispatcher import Dispatcher
from finger_sim.scene import load_scene
from finger_sim.simulate import Simulator

def overloads():
    found = {}
    for name, module in list(sys.modules.items()):
        if name.startswith("finger_sim"):
            for d in vars(module).values():
                if isinstance(d, Dispatcher):
                    found[id(d)] = (f"{d.py_func.__module__}.{d.py_func.__name__}", len(d.overloads))
    return found

scene, held = load_scene(sys.argv[1]), sys.argv[2] == "held"
sim = Simulator(scene, kernel="compiled")
built = overloads()
n = scene.step_count
for k in range(n):
    sim.step(float(scene.torque(k * scene.dt)) if held else None)
gained = sorted(name for key, (name, count) in overloads().items() if count > built.get(key, (name, 0))[1])
events = sim._event_step
print(json.dumps({"kernel": sim.kernel, "gained": gained, "steps": n, "owners": len(sim.mode_steppings),
                  "python_steps": None if events is None else n - events.taken}))
"""

#: (scene file, how it is stepped, the path it reaches).
CASES = [
    ("hard/chatter_wall.yaml", "profile", "the compiled event step hands steps to Python's event path"),
    ("hard/grasp_release.yaml", "profile", "contact releases located, a rest on a stop"),
    ("grasp_impact.yaml", "held", "a contact impact under held commands (the node's steps)"),
    ("drive_grasp.yaml", "profile", "the drive's mesh modes"),
    ("friction/hold_table.yaml", "profile", "stick–slip friction's modes"),
    ("paper_flexion.yaml", "held", "the lean compiled step"),
]


@pytest.fixture(scope="module")
def runs() -> dict[str, dict]:
    """Each case in a fresh process of its own (started together)."""
    procs = {}
    for scene, how, _ in CASES:
        procs[scene] = subprocess.Popen([sys.executable, "-c", CHILD, str(CONFIG / scene), how],
                                        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    out = {}
    for scene, proc in procs.items():
        stdout, stderr = proc.communicate()
        assert proc.returncode == 0, stderr
        out[scene] = json.loads(stdout.splitlines()[-1])
    return out


@pytest.mark.parametrize(("scene", "how", "path"), CASES, ids=[c[0] for c in CASES])
def test_stepping_a_whole_scene_loads_no_compiled_code_after_the_simulator_is_built(runs, scene, how, path):
    got = runs[scene]
    assert got["kernel"].startswith("numba-")
    assert got["gained"] == [], f"{path}: loaded while stepping"
    if scene.endswith("chatter_wall.yaml"):  # the path of the defect was reached
        assert got["python_steps"] > 0
    if "drive" in scene or "table" in scene:
        assert got["owners"] >= 1  # the owner's stepping ran
