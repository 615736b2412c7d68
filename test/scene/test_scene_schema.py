"""`finger-sim schema` writes a JSON Schema that an independent validator (the `jsonschema` package)
accepts every shipped scene with, and that refuses what the loader refuses, with the same bounds:
the effects declare their parameters once (`finger_sim.effects.parameters`)."""

from __future__ import annotations

import contextlib
import copy
import io
import json
import math
from pathlib import Path

import jsonschema
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from finger_sim.cli import main
from finger_sim.effects import EFFECTS, declared_parameters
from finger_sim.errors import ConfigError
from finger_sim.scene import Scene, load_scene, scene_from_dict
from finger_sim.scene_yaml import parse_scene_text

CONFIG = Path(__file__).resolve().parents[2] / "config"
SCENES = sorted(p for p in CONFIG.glob("*.yaml") if p.name != "finger_node.yaml")
#: How far beyond a bound (relative) the agreement test steps: well above a float's round-off.
NUDGE = 1e-9


@pytest.fixture(scope="module")
def validator(tmp_path_factory: pytest.TempPathFactory) -> jsonschema.Draft202012Validator:
    """The validator of the schema file `finger-sim schema -o` writes."""
    out = tmp_path_factory.mktemp("schema") / "scene.schema.json"
    with contextlib.redirect_stdout(io.StringIO()):
        assert main(["schema", "-o", str(out)]) == 0
    schema = json.loads(out.read_text(encoding="utf-8"))
    jsonschema.Draft202012Validator.check_schema(schema)  # a well-formed draft 2020-12 schema
    return jsonschema.Draft202012Validator(schema)


def loader_refuses(data: dict) -> str | None:
    """The loader's one-line refusal of a scene mapping, or None when it takes it."""
    try:
        scene_from_dict(data)
    except ConfigError as exc:
        return str(exc)
    return None


@pytest.mark.parametrize("path", SCENES, ids=lambda p: p.stem)
def test_every_shipped_scene_validates(validator: jsonschema.Draft202012Validator, path: Path) -> None:
    data = parse_scene_text(path.read_text(encoding="utf-8"), str(path))
    assert [e.message for e in validator.iter_errors(data)] == []
    load_scene(path)  # and the loader takes it


def test_the_schema_names_every_declared_parameter_with_its_bounds_and_default(
        validator: jsonschema.Draft202012Validator) -> None:
    model = validator.schema["$defs"]["Model"]["properties"]
    declared = declared_parameters()
    assert set(declared) == {"spring_stiffness", "damping", "gravity", "tip_force", "restitution"}
    assert set(declared) <= set(model)
    for key, parameter in declared.items():
        assert model[key]["default"] == (list(parameter.default) if isinstance(parameter.default, tuple)
                                         else parameter.default)
        assert getattr(Scene(), key) == parameter.default  # the loader's default is the declared one
        if parameter.bound is None:
            assert (model[key].get("minimum"), model[key].get("maximum")) == (parameter.minimum, parameter.maximum)
    assert sum(len(e.parameters) for e in EFFECTS.values()) == len(declared)  # each key owned once


@pytest.mark.parametrize("section, key, value", [
    ("model", "damping", -1.0),
    ("model", "spring_stiffness", 2e6),
    ("model", "restitution", 1.5),
    ("model", "gravity", [0.0, 2e4]),
    ("model", "tip_force", [1.0]),
    ("model", "spring_stifness", 1.0),  # a misspelt key
    ("integrator", "method", "rk5"),
    ("integrator", "dt", 0.0),
    ("initial", "theta1_dot", 1e5),
    (None, "duration", -1.0),
    (None, "name", ".hidden"),
])
def test_a_wrong_value_is_refused_by_both(validator: jsonschema.Draft202012Validator, section: str | None, key: str,
                                          value: object) -> None:
    data = parse_scene_text((CONFIG / "paper_flexion.yaml").read_text(encoding="utf-8"), "paper_flexion.yaml")
    data = copy.deepcopy(data)
    (data.setdefault(section, {}) if section else data)[key] = value
    assert list(validator.iter_errors(data)) != []
    refusal = loader_refuses(data)
    assert refusal is not None and "\n" not in refusal
    assert key in refusal  # the key path (model.gravity[1], integrator.dt, ...) or the unknown key's name


@settings(max_examples=60, deadline=None)
@given(key=st.sampled_from(sorted(k for k, p in declared_parameters().items() if p.bound is None)),
       where=st.sampled_from(["below", "at_min", "inside", "at_max", "above"]),
       fraction=st.floats(0.0, 1.0))
def test_the_schema_and_the_loader_agree_on_every_scalar(validator: jsonschema.Draft202012Validator, key: str,
                                                         where: str, fraction: float) -> None:
    p = declared_parameters()[key]
    lo, hi = p.minimum, p.maximum
    assert lo is not None and hi is not None and math.isfinite(lo) and math.isfinite(hi)
    value = {"below": lo - NUDGE * (1 + abs(lo)) - fraction, "at_min": lo, "inside": lo + fraction * (hi - lo),
             "at_max": hi, "above": hi + NUDGE * (1 + abs(hi)) + fraction}[where]
    data = {"model": {key: value}}
    schema_accepts = not list(validator.iter_errors(data))
    assert schema_accepts == (loader_refuses(data) is None)
    assert schema_accepts == (where not in ("below", "above"))


HANDS = sorted((CONFIG / "hands").glob("*.yaml"))


@pytest.fixture(scope="module")
def hand_validator(tmp_path_factory: pytest.TempPathFactory) -> jsonschema.Draft202012Validator:
    """The validator of the schema file `finger-sim schema --hand -o` writes."""
    out = tmp_path_factory.mktemp("schema") / "hand.schema.json"
    with contextlib.redirect_stdout(io.StringIO()):
        assert main(["schema", "--hand", "-o", str(out)]) == 0
    schema = json.loads(out.read_text(encoding="utf-8"))
    jsonschema.Draft202012Validator.check_schema(schema)
    return jsonschema.Draft202012Validator(schema)


@pytest.mark.parametrize("path", HANDS, ids=lambda p: p.stem)
def test_every_shipped_hand_validates(hand_validator: jsonschema.Draft202012Validator, path: Path) -> None:
    from finger_sim.runtime.hand_config import load_hand

    data = parse_scene_text(path.read_text(encoding="utf-8"), str(path))
    assert [e.message for e in hand_validator.iter_errors(data)] == []
    assert len(load_hand(path)) == len(data["fingers"])


@pytest.mark.parametrize("change, key", [
    (lambda f: f.__setitem__("pose", [0.0, 0.0, 0.0, 0.0, 10.5, 0.0]), "pose[4]"),
    (lambda f: f.__setitem__("pose", [2.0, 0.0, 0.0, 0.0, 0.0, 0.0]), "pose[0]"),
    (lambda f: f.__setitem__("name", "1st"), "name"),
    (lambda f: f.__setitem__("frame_prefix", "a b"), "frame_prefix"),
    (lambda f: f.__setitem__("colour", "red"), "colour"),
])
def test_a_wrong_hand_value_is_refused_by_both(hand_validator: jsonschema.Draft202012Validator, tmp_path: Path,
                                                change, key: str) -> None:
    from finger_sim.runtime.hand_config import load_hand

    data = {"fingers": [{"name": "index", "scene": "finger_default"}]}
    change(data["fingers"][0])
    assert list(hand_validator.iter_errors(data)) != []
    path = tmp_path / "hand.yaml"
    path.write_text(json.dumps(data), encoding="utf-8")  # JSON is YAML 1.2
    with pytest.raises(ConfigError) as refusal:
        load_hand(path)
    assert key in str(refusal.value) and "\n" not in str(refusal.value)
