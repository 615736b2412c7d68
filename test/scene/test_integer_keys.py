"""The schema's "integer" keys and the loader agree on a whole float: JSON Schema counts 3.0 as an
integer (draft 2020-12, §6.1.1 of the validation spec; the `jsonschema` package, an independent
validator, and the editors' YAML language server follow it), so the loader reads 3.0 as 3, and both
refuse 3.5, the loader in one line naming the key and the value given."""

from __future__ import annotations

import contextlib
import copy
import io
import json
from pathlib import Path
from typing import Any, Callable

import jsonschema
import pytest

from finger_sim.cli import main
from finger_sim.errors import ConfigError
from finger_sim.scene import scene_from_dict
from finger_sim.scene_yaml import parse_scene_text
from finger_sim.tasks.schema import task_from_dict

CONFIG = Path(__file__).resolve().parents[2] / "config"
TASK = CONFIG / "tasks" / "hold_cup.yaml"
#: Every integer key of the scene and task schemas: (schema flags, $defs entry, key, dotted path in a file).
INTEGER_KEYS = [
    ((), "DriveSchema", "encoder_counts", "model.drive.encoder_counts"),
    ((), "Sensors", "seed", "sensors.seed"),
    (("--task",), "Controller", "sample_steps", "controller.sample_steps"),
    (("--task",), "Controller", "delay_steps", "controller.delay_steps"),
]


def written(tmp_path_factory: pytest.TempPathFactory, flags: tuple[str, ...]) -> dict:
    out = tmp_path_factory.mktemp("schema") / "schema.json"
    with contextlib.redirect_stdout(io.StringIO()):
        assert main(["schema", *flags, "-o", str(out)]) == 0
    return json.loads(out.read_text(encoding="utf-8"))


@pytest.fixture(scope="module")
def schemas(tmp_path_factory: pytest.TempPathFactory) -> dict[tuple[str, ...], dict]:
    return {flags: written(tmp_path_factory, flags) for flags in ((), ("--task",))}


def integer_keys(schema: dict) -> set[tuple[str, str]]:
    """($defs entry, key) of every property the schema types "integer"."""
    return {(name, key) for name, definition in schema["$defs"].items()
            for key, prop in definition.get("properties", {}).items()
            if "integer" in {p.get("type") for p in prop.get("anyOf", [prop])}}


def test_the_list_covers_every_integer_key(schemas: dict[tuple[str, ...], dict]) -> None:
    for flags, schema in schemas.items():
        assert integer_keys(schema) == {(d, k) for f, d, k, _ in INTEGER_KEYS if f == flags}


def put(data: dict, path: str, value: Any) -> dict:
    data = copy.deepcopy(data)
    node = data
    *parents, last = path.split(".")
    for part in parents:
        node = node.setdefault(part, {})
    node[last] = value
    return data


def reader(flags: tuple[str, ...]) -> tuple[dict, Callable[[dict], Any]]:
    """A valid file's mapping and the loader that reads it."""
    if flags:
        return parse_scene_text(TASK.read_text(encoding="utf-8")), lambda d: task_from_dict(d, base=TASK.parent)
    return {"model": {"drive": {}}}, scene_from_dict


@pytest.mark.parametrize("flags, definition, key, path", INTEGER_KEYS, ids=[k[3] for k in INTEGER_KEYS])
def test_a_whole_float_is_the_integer_for_both(schemas: dict[tuple[str, ...], dict], flags: tuple[str, ...],
                                              definition: str, key: str, path: str) -> None:
    validator = jsonschema.Draft202012Validator(schemas[flags])
    base, read = reader(flags)
    as_float, as_int = put(base, path, 3.0), put(base, path, 3)
    assert [e.message for e in validator.iter_errors(as_float)] == []
    assert read(as_float) == read(as_int)


@pytest.mark.parametrize("flags, definition, key, path", INTEGER_KEYS, ids=[k[3] for k in INTEGER_KEYS])
def test_a_fraction_is_refused_by_both_in_one_line(schemas: dict[tuple[str, ...], dict], flags: tuple[str, ...],
                                                  definition: str, key: str, path: str) -> None:
    validator = jsonschema.Draft202012Validator(schemas[flags])
    base, read = reader(flags)
    data = put(base, path, 3.5)
    assert list(validator.iter_errors(data)) != []
    with pytest.raises(ConfigError) as refused:
        read(data)
    message = str(refused.value)
    assert message.startswith(f"{path}: expected ") and message.endswith("got 3.5") and "\n" not in message
