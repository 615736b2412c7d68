"""A new effect is its module, a registry line, its test and its scene: registered here (and removed after),
a torsional MCP spring is read from a scene, bounded with one-line errors, written into the JSON Schema,
dumped and read back, stepped, and its declared output becomes a CSV column, without a line of scene.py,
scene_schema.py or the CSV writers naming it."""

from __future__ import annotations

import csv
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import ClassVar

import jsonschema
import numpy as np
import pytest

from finger_sim.cli import main
from finger_sim.effects import EFFECTS, Output, Smooth
from finger_sim.effects.base import Vec3, effect
from finger_sim.effects.parameters import scalar
from finger_sim.errors import ConfigError
from finger_sim.scene import Scene, scene_from_dict, scene_from_yaml
from finger_sim.scene_schema import scene_schema
from finger_sim.simulate import simulate

KEY = "mcp_spring_stiffness"
TORQUE = Output("mcp_spring_torque", "N·m", "the MCP spring's torque on θ1")
STIFFNESS = 0.02  # N·m/rad
#: A free swing that the spring pulls back towards θ1 = 0 (Python stepping: no compiled law is named).
SCENE = {"model": {KEY: STIFFNESS, "spring_stiffness": 0.0}, "input": {"torque": {"type": "constant", "value": 0.0}},
         "initial": {"theta1": 0.4}, "duration": 0.05, "integrator": {"method": "rk4", "dt": 1e-3}}


@dataclass(frozen=True)
class McpSpring(Smooth):
    """V = ½ k θ1², Q = (−k θ1, 0, 0)."""

    stiffness: float
    affine_in_velocity: ClassVar[bool] = True

    def force(self, t: float, q: Vec3, v: Vec3) -> Vec3:
        return (-self.stiffness * q[0], 0.0, 0.0)

    def potential(self, q: Vec3) -> float:
        return 0.5 * self.stiffness * q[0] ** 2

    def modal(self, q: Vec3, n: Vec3) -> tuple[float, float]:
        return (self.stiffness * n[0] ** 2, 0.0)

    def outputs(self, t: float, q: Vec3, v: Vec3) -> dict[str, float]:
        return {TORQUE.name: -self.stiffness * q[0]}


@pytest.fixture(autouse=True)
def registered() -> Iterator[None]:
    """The registry line, for this module's tests only."""

    def build(scene: Scene) -> McpSpring | None:
        k = scene.effect_value(KEY)
        return McpSpring(k) if k else None

    effect(KEY, "torsional MCP spring, N·m/rad", {KEY: scalar(0.0, "N·m/rad", "MCP spring stiffness", minimum=0.0,
                                                             maximum=1.0)}, outputs=(TORQUE,))(build)
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
