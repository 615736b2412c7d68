"""The schema field by field: contact (its law, the friction law, objects with their own law, strength
and motion), the drive (spec §8), sensors, inputs, geometry, and task files (`finger-sim schema --task`).

The independent validator (`jsonschema`) takes every shipped scene and task file, and refuses what the
loader refuses; the loader's refusal stays one line naming the key path, the allowed range and the value
given (asserted word for word)."""

from __future__ import annotations

import contextlib
import copy
import io
import json
import math
from pathlib import Path
from typing import Any

import jsonschema
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from finger_sim.cli import main
from finger_sim.errors import ConfigError
from finger_sim.scene import scene_from_dict
from finger_sim.scene_yaml import parse_scene_text
from finger_sim.tasks.schema import load_task, task_from_dict

CONFIG = Path(__file__).resolve().parents[2] / "config"
#: Every shipped scene, in config/ and its scene folders (finger_node.yaml holds node parameters).
SCENES = sorted(p for folder in ("", "friction", "hard") for p in (CONFIG / folder).glob("*.yaml")
                if p.name != "finger_node.yaml")
TASKS = sorted((CONFIG / "tasks").glob("*.yaml"))
CUP = {"name": "cup", "type": "circle", "center": [0.065, 0.040], "radius": 0.012}
#: How far beyond a bound (relative) the agreement test steps: well above a float's round-off.
NUDGE = 1e-9


def written_schema(tmp_path_factory: pytest.TempPathFactory, *flags: str) -> jsonschema.Draft202012Validator:
    out = tmp_path_factory.mktemp("schema") / "schema.json"
    with contextlib.redirect_stdout(io.StringIO()):
        assert main(["schema", *flags, "-o", str(out)]) == 0
    schema = json.loads(out.read_text(encoding="utf-8"))
    jsonschema.Draft202012Validator.check_schema(schema)
    return jsonschema.Draft202012Validator(schema)


@pytest.fixture(scope="module")
def scenes(tmp_path_factory: pytest.TempPathFactory) -> jsonschema.Draft202012Validator:
    return written_schema(tmp_path_factory)


@pytest.fixture(scope="module")
def tasks(tmp_path_factory: pytest.TempPathFactory) -> jsonschema.Draft202012Validator:
    return written_schema(tmp_path_factory, "--task")


def refusal(read: Any, data: dict) -> str | None:
    """The loader's one-line refusal of `data`, or None when it takes it."""
    try:
        read(data)
    except ConfigError as exc:
        return str(exc)
    return None


def put(data: dict, path: str, value: Any) -> dict:
    """A copy of `data` with `value` at the dotted `path` (digits index lists)."""
    data = copy.deepcopy(data)
    node = data
    *parents, last = path.split(".")
    for part in parents:
        node = node[int(part)] if part.isdigit() else node.setdefault(part, {})
    node[last] = value
    return data


@pytest.mark.parametrize("path", SCENES, ids=lambda p: f"{p.parent.name}/{p.stem}")
def test_every_shipped_scene_validates_field_by_field(scenes: jsonschema.Draft202012Validator, path: Path) -> None:
    data = parse_scene_text(path.read_text(encoding="utf-8"), str(path))
    assert [e.message for e in scenes.iter_errors(data)] == []


@pytest.mark.parametrize("path", TASKS, ids=lambda p: p.stem)
def test_every_shipped_task_validates(tasks: jsonschema.Draft202012Validator, path: Path) -> None:
    data = parse_scene_text(path.read_text(encoding="utf-8"), str(path))
    assert [e.message for e in tasks.iter_errors(data)] == []
    assert load_task(path).name == path.stem  # and the loader takes it


@pytest.mark.parametrize("path, value, message", [
    ("model.contact.stiffness", 2e12, "model.contact.stiffness: expected a number ≤ 1e+12, got 2000000000000.0"),
    ("model.contact.stiffness", 0.0, "model.contact.stiffness: expected a finite number > 0, got 0.0"),
    ("model.contact.exponent", 0.5, "model.contact.exponent: expected a finite number ≥ 1, got 0.5"),
    ("model.contact.friction", 11.0, "model.contact.friction: expected a number ≤ 10, got 11.0"),
    ("model.contact.slip_velocity", 1e-10, "model.contact.slip_velocity: expected a number ≥ 1e-09, got 1e-10"),
    ("model.contact.friction_model", "coulomb",
     "model.contact.friction_model: expected one of ['regularized', 'stick_slip'], got 'coulomb'"),
    ("model.contact.static_friction", 0.5, "model.contact.static_friction: expected no value with friction_model: "
                                           "regularized (it belongs to stick_slip), got 0.5"),
    ("model.contact.stribeck_velocity", 0.01, "model.contact.stribeck_velocity: expected no value with friction_model: "
                                              "regularized (it belongs to stick_slip), got 0.01"),
    ("model.drive.resistance", 0.0, "model.drive.resistance: expected a number > 0, got 0.0"),
    ("model.drive.inductance", 2.0, "model.drive.inductance: expected a number ≤ 1, got 2.0"),
    ("model.drive.efficiency", 1.5, "model.drive.efficiency: expected a number ≤ 1, got 1.5"),
    ("model.drive.backward_efficiency", -11.0, "model.drive.backward_efficiency: expected a number ≥ -10, got -11.0"),
    ("model.drive.gear_ratio", 2e5, "model.drive.gear_ratio: expected a number ≤ 100000, got 200000.0"),
    ("model.drive.current_limit", 0.0, "model.drive.current_limit: expected a number > 0, got 0.0"),
    ("model.drive.encoder_counts", -1,
     "model.drive.encoder_counts: expected an integer in [0, 1000000000] (0: no encoder), got -1"),
    ("model.phalanx_radius", [0.008, 11.0], "model.phalanx_radius[1]: expected a number ≤ 10, got 11.0"),
    ("objects.0.radius", 0.0, "objects[0].radius: expected a finite radius > 0 (m), got 0.0"),
    ("objects.0.center", [0.0, 11.0], "objects[0].center[1]: expected a number with magnitude ≤ 10, got 11.0"),
    ("objects.0.stiffness", 0.0, "objects[0].stiffness: expected a finite number > 0, got 0.0"),
    ("objects.0.damping", 2e3, "objects[0].damping: expected a number ≤ 1000, got 2000.0"),
    ("objects.0.break_force", 0.0, "objects[0].break_force: expected a finite number > 0, got 0.0"),
    ("objects.0.type", "sphere", "objects[0].type: expected one of ['circle', 'plane'], got 'sphere'"),
    ("objects.0.motion", {"type": "push", "direction": [0, -1], "distance": 2.0, "start": 0.1, "duration": 0.02},
     "objects[0].motion.distance: expected a finite number in (0, 1], got 2.0"),
    ("objects.0.motion", {"type": "vibration", "direction": [0, -1], "amplitude": 1e-3, "frequency": 2e3, "start": 0.0},
     "objects[0].motion.frequency: expected a finite number in (0, 1000], got 2000.0"),
    ("objects.0.motion", {"type": "push", "direction": [0, -1], "distance": 1e-3, "start": 0.1},
     "objects[0].motion.duration: expected a value (required for a push), got None"),
    ("sensors.seed", -1, "sensors.seed: expected an integer in [0, 9223372036854775807], got -1"),
    ("sensors.fsr_distal", {"noise": -0.1}, "sensors.fsr_distal.noise: expected a number ≥ 0, got -0.1"),
    ("sensors.fsr_distal", {"time_constant": 2e3}, "sensors.fsr_distal.time_constant: expected a number ≤ 1000, got 2000.0"),
    ("sensors.fsr_distal", {"range": [0.0, 2e6]},
     "sensors.fsr_distal.range[1]: expected a number with magnitude ≤ 1e+06, got 2000000.0"),
    ("input.torque", {"type": "sine", "amplitude": 0.1, "frequency": 0.0},
     "input.torque.frequency: expected a number > 0 (Hz), got 0.0"),
    ("input.tip_force", [{"start": 0.0, "end": 0.1, "force": [0.0, 2e3]}],
     "input.tip_force[0].force[1]: expected a number with magnitude ≤ 1000, got 2000.0"),
    ("model.geometry.r9", 1.0,
     "model.geometry: expected only the keys ['L3', 'm1', 'm2', 'm3', 'r1', 'r2', 'r3', 'r4', 'theta4'], got 'r9'"),
    ("model.contact.static_frction", 0.5,  # every key of model.contact is named, the friction law's too
     "model.contact: expected only the keys ['damping', 'exponent', 'friction', 'friction_model', 'slip_velocity', "
     "'static_friction', 'stiffness', 'stribeck_velocity'], got 'static_frction'"),
    ("objects.0.motion", None,
     "objects[0].motion: expected a mapping {type: push|vibration, direction, ...}, got None"),
])
def test_a_wrong_section_value_is_refused_by_both_in_one_line(scenes: jsonschema.Draft202012Validator, path: str,
                                                              value: Any, message: str) -> None:
    data = put({"model": {"drive": {}} if path.startswith("model.drive") else {}, "objects": [CUP]}, path, value)
    assert list(scenes.iter_errors(data)) != []
    assert refusal(scene_from_dict, data) == message


@pytest.mark.parametrize("path", ["model.contact.static_friction", "model.contact.stribeck_velocity",
                                  "objects.0.stiffness", "objects.0.damping", "objects.0.break_force"])
def test_an_explicit_null_the_loader_reads_as_unset_is_taken_by_both(scenes: jsonschema.Draft202012Validator,
                                                                      path: str) -> None:
    unset = {"model": {"contact": {"friction_model": "stick_slip"}}, "objects": [CUP]}
    data = put(unset, path, None)
    assert [e.message for e in scenes.iter_errors(data)] == []
    assert scene_from_dict(data) == scene_from_dict(unset)


@pytest.mark.parametrize("key, value, message", [
    ("duration", 700.0, "duration: expected a number ≤ 600, got 700.0"),
    ("controller", {"sample_steps": 0},
     "controller.sample_steps: expected a whole number of steps in [1, 1000000], got 0"),
    ("controller", {"input": "current"}, "controller.input: expected one of ['torque', 'voltage'] (the scene input the "
                                         "controller commands), got 'current'"),
    ("setpoints", [], "setpoints: expected at least one {t, value}, the first at t = 0, got []"),
    ("setpoints", [{"t": 0.0, "value": 2e3}], "setpoints[0].value: expected a number ≤ 1000, got 2000.0"),
    ("disturbances", [{"type": "push", "start": 0.5, "force": [0, 0]}],
     "disturbances[0].type: expected tip_force (a pull on the fingertip), got 'push'"),
    ("hold_after", -0.1, "hold_after: expected a number ≥ 0, got -0.1"),
    ("limits", {"overshoot": -1.0}, "limits.overshoot: expected a number ≥ 0, got -1.0"),
    ("limits", {"crushed": "no"}, "limits.crushed: expected true or false (the value that passes), got 'no'"),
    ("objects", [{**CUP, "radius": -0.012}], "objects[0].radius: expected a finite radius > 0 (m), got -0.012"),
])
def test_a_wrong_task_value_is_refused_by_both_in_one_line(tasks: jsonschema.Draft202012Validator, key: str,
                                                           value: Any, message: str) -> None:
    data = put(parse_scene_text((CONFIG / "tasks" / "hold_cup.yaml").read_text(encoding="utf-8")), key, value)
    assert list(tasks.iter_errors(data)) != []
    assert refusal(lambda d: task_from_dict(d, base=CONFIG / "tasks"), data) == message


def bounded_fields(schema: dict) -> list[tuple[str, str, dict]]:
    """(section path in a scene, key, its JSON Schema) of every bounded number of the contact law, the
    drive and a sensor, read from the written schema itself."""
    defs = schema["$defs"]
    out = []
    for definition, section in (("ContactLaw", "model.contact"), ("DriveSchema", "model.drive"),
                                    ("SensorSchema", "sensors.fsr_distal")):
        for key, prop in defs[definition]["properties"].items():
            prop = next((p for p in prop.get("anyOf", [prop]) if p.get("type") in ("number", "integer")), None)
            if prop is not None and ("minimum" in prop or "exclusiveMinimum" in prop):
                out.append((section, key, prop))
    return out


@pytest.fixture(scope="module")
def fields(scenes: jsonschema.Draft202012Validator) -> list[tuple[str, str, dict]]:
    found = bounded_fields(scenes.schema)
    assert {k for s, k, _ in found if s == "model.drive"} >= {"resistance", "inductance", "current_limit", "gear_ratio",
                                                               "efficiency", "backward_efficiency", "encoder_counts"}
    assert {k for s, k, _ in found if s == "model.contact"} >= {"stiffness", "static_friction", "stribeck_velocity"}
    return found


@settings(max_examples=120, deadline=None)
@given(pick=st.integers(0, 10**6), where=st.sampled_from(["below", "at_min", "inside", "at_max", "above"]),
       fraction=st.floats(0.0, 1.0))
def test_the_schema_and_the_loader_agree_on_every_bounded_section_number(
        scenes: jsonschema.Draft202012Validator, fields: list, pick: int, where: str, fraction: float) -> None:
    section, key, prop = fields[pick % len(fields)]
    exclusive = "exclusiveMinimum" in prop
    lo = prop.get("exclusiveMinimum", prop.get("minimum"))
    hi = prop.get("maximum", lo + 1e3)  # no upper bound: probe above the lower one
    integer = prop["type"] == "integer"
    if where in ("at_max", "above") and "maximum" not in prop:
        where = "inside"
    value: float = {"below": lo - NUDGE * (1 + abs(lo)) - fraction, "at_min": lo,
                    "inside": lo + (0.5 + fraction) / 2 * (hi - lo), "at_max": hi,
                    "above": hi + NUDGE * (1 + abs(hi)) + fraction}[where]
    if integer:
        value = int(math.floor(value) if where in ("below", "at_min") else math.ceil(value))
    data = {"model": {"drive": {}} if section == "model.drive" else {}, "objects": [CUP]}
    if key in ("static_friction", "stribeck_velocity"):
        data["model"]["contact"] = {"friction_model": "stick_slip"}
    data = put(data, f"{section}.{key}", value)
    schema_accepts = not list(scenes.iter_errors(data))
    loader_says = refusal(scene_from_dict, data)
    assert schema_accepts == (loader_says is None), (section, key, value, loader_says)
    assert schema_accepts == (where == "inside" or (where == "at_max") or (where == "at_min" and not exclusive))
    if loader_says is not None:
        assert loader_says.startswith(f"{section}.{key}: expected ") and "\n" not in loader_says
