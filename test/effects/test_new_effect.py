"""A new effect is its module, a registry line, its test and its scene: registered here (and removed after),
a torsional MCP spring is read from a scene, bounded with one-line errors, written into the JSON Schema,
dumped and read back, stepped, and its declared output becomes a CSV column, without a line of scene.py,
scene_schema.py or the CSV writers naming it. With its compiled law registered too (`kernel_law`, in a
process of its own: a kernel reads the registry once), the compiled kernel steps it, bit for bit as Python,
without a line of the kernel naming it."""

from __future__ import annotations

import csv
import json
import subprocess
import sys
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import ClassVar

import jsonschema
import numpy as np
import pytest
import reference as ref

from finger_sim.cli import main
from finger_sim.effects import EFFECTS, Output, Smooth
from finger_sim.effects.base import Vec3, effect, kernel_law
from finger_sim.effects.parameters import scalar
from finger_sim.errors import ConfigError
from finger_sim.scene import Scene, scene_from_dict, scene_from_yaml
from finger_sim.scene_schema import scene_schema
from finger_sim.simulate import simulate

KEY = "mcp_spring_stiffness"
TORQUE = Output("mcp_spring_torque", "N·m", "the MCP spring's torque on θ1")
STIFFNESS = 0.02  # N·m/rad
#: A free swing that the spring pulls back towards θ1 = 0.
SCENE = {"model": {KEY: STIFFNESS, "spring_stiffness": 0.0}, "input": {"torque": {"type": "constant", "value": 0.0}},
         "initial": {"theta1": 0.4}, "duration": 0.05, "integrator": {"method": "rk4", "dt": 1e-3}}


def mcp_spring_force(stiffness: float, t1: float) -> Vec3:
    """Q = (−k θ1, 0, 0), N·m: the law, one plain function that the element calls and the kernel compiles."""
    return (-stiffness * t1, 0.0, 0.0)


@dataclass(frozen=True)
class McpSpring(Smooth):
    """V = ½ k θ1², Q = (−k θ1, 0, 0)."""

    stiffness: float
    affine_in_velocity: ClassVar[bool] = True
    kernel_code: ClassVar[int] = 99  # its compiled law's code (`register(compiled=True)`)

    def kernel_params(self) -> tuple[float, ...]:
        return (self.stiffness,)

    def force(self, t: float, q: Vec3, v: Vec3) -> Vec3:
        return mcp_spring_force(self.stiffness, q[0])

    def potential(self, q: Vec3) -> float:
        return 0.5 * self.stiffness * q[0] ** 2

    def modal(self, q: Vec3, n: Vec3) -> tuple[float, float]:
        return (self.stiffness * n[0] ** 2, 0.0)

    def outputs(self, t: float, q: Vec3, v: Vec3) -> dict[str, float]:
        return {TORQUE.name: -self.stiffness * q[0]}


def build(scene: Scene) -> McpSpring | None:
    k = scene.effect_value(KEY)
    return McpSpring(k) if k else None


def register(*, compiled: bool = False) -> None:
    """The registry lines: the effect, and with `compiled` its compiled law (before the kernel first loads)."""
    effect(KEY, "torsional MCP spring, N·m/rad", {KEY: scalar(0.0, "N·m/rad", "MCP spring stiffness", minimum=0.0,
                                                             maximum=1.0)}, outputs=(TORQUE,))(build)
    if compiled:
        kernel_law(mcp_spring_force, ("q0",), code=McpSpring.kernel_code)


@pytest.fixture(autouse=True)
def registered() -> Iterator[None]:
    """The effect's registry line, for this module's tests only (its compiled law: `test_it_is_compiled_...`)."""
    register()
    yield
    del EFFECTS[KEY]


def test_its_key_is_read_bounded_in_one_line_and_dumped_back() -> None:
    scene = scene_from_dict(SCENE)
    assert scene.effect_value(KEY) == STIFFNESS and scene_from_dict({}).effect_value(KEY) == 0.0
    assert scene_from_yaml(scene.to_yaml()) == scene
    with pytest.raises(ConfigError) as refused:
        scene_from_dict({"model": {KEY: 2.0}})
    assert str(refused.value) == f"model.{KEY}: expected a number ≤ 1, got 2.0"


def test_its_key_is_in_the_json_schema_with_its_bounds() -> None:
    validator = jsonschema.Draft202012Validator(scene_schema())
    prop = validator.schema["$defs"]["Model"]["properties"][KEY]
    assert (prop["minimum"], prop["maximum"], prop["default"]) == (0.0, 1.0, 0.0)
    assert list(validator.iter_errors(SCENE)) == []
    assert list(validator.iter_errors({"model": {KEY: 2.0}})) != []


def test_it_is_stepped_and_its_declared_output_is_a_csv_column(tmp_path: Path) -> None:
    traj = simulate(scene_from_dict(SCENE))
    assert np.array_equal(traj.outputs[TORQUE.name], -STIFFNESS * traj.q[:, 0])  # its law on the state
    assert abs(traj.energy[-1] - traj.energy[0]) < 1e-9 * abs(traj.energy[0])  # conservative: ½ k θ1² counted
    free = simulate(scene_from_dict({**SCENE, "model": {"spring_stiffness": 0.0}}))
    assert traj.q[-1, 0] < free.q[-1, 0] - 1e-4  # it pulls θ1 back
    path = tmp_path / "spring.yaml"
    path.write_text(scene_from_dict(SCENE).to_yaml(), encoding="utf-8")
    out = tmp_path / "run.csv"
    assert main(["simulate", str(path), "--csv", str(out), "--kernel", "python"]) == 0
    with out.open(encoding="utf-8") as f:
        rows = list(csv.DictReader(f))
    assert list(rows[0])[-1] == TORQUE.name
    assert [float(r[TORQUE.name]) for r in rows] == pytest.approx([-STIFFNESS * float(r["theta1"]) for r in rows],
                                                                   rel=1e-12, abs=1e-15)


#: rk4 at 1 ms over 50 ms against the tight solve, rad (measured 6.5e-11; without the spring the two part by 0.15)
REFERENCE_TOLERANCE = 1e-8


@dataclass(frozen=True)
class McpSpringReference(ref.Effects):
    """The reference's force elements plus the MCP spring, written again: Q1 −= k θ1, V += ½ k θ1²."""

    mcp: float = 0.0  # N·m/rad

    def force(self, q, v, tau):  # type: ignore[no-untyped-def]
        return super().force(q, v, tau) - np.array([self.mcp * q[0], 0.0, 0.0])

    def potential(self, q):  # type: ignore[no-untyped-def]
        return super().potential(q) + 0.5 * self.mcp * q[0] ** 2


#: Run in a process of its own: the effect and its compiled law registered before the kernel loads, the
#: scene stepped on the compiled kernel and in Python, and the compiled force against the element's.
COMPILED_RUN = """
import json, sys
import numpy as np
sys.path[:0] = sys.argv[1:3]  # this folder, and test/ (reference.py)
import test_new_effect as new
new.register(compiled=True)
from finger_sim.dynamics import FingerSystem
from finger_sim.kernel import numerics
from finger_sim.kernel.layout import model_array
from finger_sim.scene import scene_from_dict
from finger_sim.simulate import Simulator, simulate
scene = scene_from_dict(new.SCENE)
element = new.build(scene)
model = model_array(FingerSystem(scene.params, (element,)))
rng = np.random.default_rng(4)
states = rng.uniform(-1.0, 1.0, (50, 6)).tolist()
forces = [[x[0], list(element.force(0.0, x[:3], x[3:])), list(numerics.generalized_force(model, 0.0, *x, 0.0))]
          for x in states]
print(json.dumps({"kernel": Simulator(scene, kernel="compiled").kernel,
                  "compiled": simulate(scene, kernel="compiled").q.tolist(),
                  "python": simulate(scene, kernel="python").q.tolist(), "forces": forces}))
"""


def test_it_is_compiled_with_its_law_registered_and_steps_bit_for_bit() -> None:
    pytest.importorskip("numba")
    run = subprocess.run([sys.executable, "-c", COMPILED_RUN, str(Path(__file__).parent), str(Path(__file__).parents[1])],
                         capture_output=True, text=True, check=False)
    assert run.returncode == 0, run.stderr
    got = json.loads(run.stdout.splitlines()[-1])
    assert got["kernel"].startswith("numba-")  # the compiled kernel ran it, not the Python fallback
    compiled, python = np.array(got["compiled"]), np.array(got["python"])
    assert np.array_equal(compiled, python)  # bit for bit, as every shipped law
    assert abs(python[-1, 0] - python[0, 0]) > 1e-3  # and the run moved
    for theta1, python_q, kernel_q in got["forces"]:
        assert kernel_q == python_q == [-STIFFNESS * theta1, 0.0, 0.0]  # the element's law, and the closed form
    # the independent reference: the spec's equations in numpy (test/reference.py) with the spring added there
    reference = ref.solve(lambda a, b: ref.constant(0.0), [], [*ref.assemble(SCENE["initial"]["theta1"]), 0, 0, 0],
                          SCENE["duration"], McpSpringReference(k=0.0, mcp=STIFFNESS))
    t = np.arange(len(compiled)) * SCENE["integrator"]["dt"]
    assert np.max(np.abs(compiled - reference.y(t)[:3].T)) < REFERENCE_TOLERANCE


def test_without_its_compiled_law_it_runs_in_python() -> None:
    """In this process the law is not registered: no compiled form, so "auto" steps it in Python."""
    from finger_sim.simulate import Simulator

    assert Simulator(scene_from_dict(SCENE), kernel="auto").kernel == "python"
