"""Scene YAML as users write it (issue 8.2-8.4): YAML 1.2 numbers, and a one-line ConfigError,
fast, for every hostile file: duplicate keys, anchors and aliases (an alias bomb), tags,
non-UTF-8 bytes, 100k-deep nesting, oversized files and integers.

References: Python's own float() and int() of the literal, and the YAML 1.2.2 spec's core
schema examples (§10.3.2)."""

from __future__ import annotations

import time

import pytest
import yaml

from finger_sim.errors import ConfigError
from finger_sim.scene import Scene, load_scene, scene_from_dict, scene_from_yaml
from finger_sim.scene_yaml import MAX_BYTES, MAX_DEPTH, parse_scene_text

#: A refusal of a hostile file must come at once: well under this, s.
FAST = 2.0


def refusal(tmp_path, content: str | bytes, name: str = "bad.yaml") -> str:
    path = tmp_path / name
    path.write_bytes(content if isinstance(content, bytes) else content.encode())
    start = time.perf_counter()
    with pytest.raises(ConfigError) as info:
        load_scene(path)
    assert time.perf_counter() - start < FAST
    msg = str(info.value)
    assert "\n" not in msg
    return msg.replace(f"{tmp_path}/", "")  # messages name the file by the path given


@pytest.mark.parametrize("literal", ["1e6", "1.0e300", "1e-300", "-2.5E+3", ".5", "3.", "+1e-3"])
def test_yaml_1_2_floats_are_numbers(literal):
    """PyYAML (YAML 1.1) read 1e6 and 1e-300 as strings; the error did not say why."""
    assert parse_scene_text(f"x: {literal}") == {"x": float(literal)}


@pytest.mark.parametrize(
    ("literal", "value"),
    [("010", 10), ("0o17", 15), ("0x1f", 31), ("-7", -7), ("yes", "yes"), ("on", "on"), ("True", True),
     ("~", None), ("2001-12-14", "2001-12-14"), ("1_000", "1_000"), ("1:30", "1:30"), (".inf", float("inf"))],
)
def test_the_rest_of_the_yaml_1_2_core_schema(literal, value):
    """1.1 read 010 as 8, `yes`/`on` as true, 1_000 as 1000, 1:30 as 90 and dates as dates."""
    assert parse_scene_text(f"x: {literal}") == {"x": value}


def test_scene_numbers_as_users_write_them(tmp_path):
    path = tmp_path / "sci.yaml"
    path.write_text("model: {spring_stiffness: 1e-3, damping: 5e-4}\nintegrator: {dt: 5e-4}\nduration: 1e-1\n")
    scene = load_scene(path)
    assert (scene.spring_stiffness, scene.damping, scene.dt, scene.duration) == (1e-3, 5e-4, 5e-4, 0.1)
    # a string where a number belongs says how to write one
    assert refusal(tmp_path, 'model: {damping: "1e-3"}\n') == (
        "bad.yaml: model.damping: expected a finite number (YAML 1.2 float syntax, e.g. 1.0e-3), got '1e-3'"
    )


def test_a_string_that_looks_like_a_number_round_trips_as_a_string(tmp_path):
    scene = scene_from_dict({"name": "yes", "description": "1e6"})
    assert "'1e6'" in scene.to_yaml()
    assert scene_from_yaml(scene.to_yaml()) == scene


@pytest.mark.parametrize(
    ("text", "key", "line"),
    [("model:\n  damping: 0.1\n  damping: 0.2\n", "damping", 3), ("duration: 1\nduration: 2\n", "duration", 2),
     ("input:\n  torque: {type: constant, value: 0, value: 1}\n", "value", 2)],
)
def test_duplicate_keys_are_refused_naming_the_key(tmp_path, text, key, line):
    """PyYAML silently kept the last value."""
    msg = refusal(tmp_path, text)
    assert msg.startswith("scene: expected each key at most once in a mapping, got ")
    assert f"bad.yaml: line {line}, column " in msg and f"duplicate key {key!r}" in msg


def test_an_alias_bomb_is_refused_at_once(tmp_path):
    """A 266-byte file of nested aliases became a 9 MB log metadata record."""
    bomb = 'description: &a ["lol","lol","lol","lol","lol","lol","lol","lol","lol"]\n'
    for i in range(8):
        previous = "a" if i == 0 else f"b{i - 1}"
        bomb += f"x{i}: &b{i} [{', '.join([f'*{previous}'] * 9)}]\n"
    msg = refusal(tmp_path, bomb)
    assert msg == (
        "scene: expected a scene without anchors or aliases (YAML anchors and aliases are not allowed in scenes), "
        "got 'bad.yaml: line 1, column 14: anchor &a'"
    )
    assert "not allowed in scenes" in refusal(tmp_path, "duration: *x\n")  # an alias alone, too


def test_explicit_tags_are_refused(tmp_path):
    """`!!float abc` raised a bare ValueError inside PyYAML's constructor."""
    assert refusal(tmp_path, "duration: !!float abc\n") == (
        "scene: expected a scene without explicit YAML tags, got 'bad.yaml: line 1, column 11: tag tag:yaml.org,2002:float'"
    )
    assert "tag" in refusal(tmp_path, "!!python/object:os.system {}\n")


def test_non_utf8_bytes_give_one_line(tmp_path):
    """read_text raised UnicodeDecodeError with a traceback."""
    assert refusal(tmp_path, b"duration: 0.3\ndescription: caf\xe9\n") == (
        "scene: expected a UTF-8 text file, got 'bad.yaml: byte 0xe9 at offset 30 is not UTF-8'"
    )


@pytest.mark.parametrize(
    "text",
    ["[" * 100_000 + "]" * 100_000, "{a: " * 100_000 + "}" * 100_000, "- " * 100_000 + "x\n",
     "".join(" " * i + "a:\n" for i in range(200))],
    ids=["flow-sequences", "flow-mappings", "block-sequences", "block-mappings"],
)
def test_deep_nesting_is_refused_without_recursion(tmp_path, text):
    """100k-deep nesting raised RecursionError (and PyYAML's scanner is quadratic in flow depth)."""
    msg = refusal(tmp_path, text)
    assert msg.startswith(f"scene: expected collections nested at most {MAX_DEPTH} deep, got 'bad.yaml: line ")
    assert msg.endswith(f": nesting deeper than {MAX_DEPTH}'")


def test_nesting_within_the_bound_still_parses():
    assert parse_scene_text("[" * 30 + "]" * 30) is not None


def test_oversized_file_and_integer_are_refused(tmp_path):
    msg = refusal(tmp_path, "description: " + "x" * MAX_BYTES + "\n")
    assert msg == f"scene: expected a scene file of at most {MAX_BYTES} bytes, got 'bad.yaml (larger)'"
    # 5000 digits: more than Python converts (a ValueError from int())
    msg = refusal(tmp_path, "duration: 1" + "0" * 5000 + "\n")
    assert msg == "scene: expected an integer of at most 4300 digits, got 'bad.yaml: line 1, column 11: an integer of 5001 digits'"


def test_non_string_keys_are_named():
    """sorted() of a mix of int and str keys raised TypeError."""
    with pytest.raises(ConfigError, match=r"^scene: expected only the keys \[.*\], got 1$"):
        scene_from_yaml("1: 2\nname: x\n")
    with pytest.raises(ConfigError, match=r"^scene: expected valid YAML, got .*unhashable"):
        scene_from_yaml("? [1]\n: 2\n")


def test_the_log_metadata_record_is_bounded():
    """The record a log stores is Scene.to_yaml(): its only free text is bounded."""
    scene = scene_from_dict({"name": "n" * 64, "description": "d" * 4096})
    assert len(scene.to_yaml()) < 6000
    with pytest.raises(ConfigError, match=r"^description: expected a string of at most 4096 characters, got '4097 characters'$"):
        scene_from_dict({"description": "d" * 4097})
    assert yaml.safe_load(Scene().to_yaml()) == Scene().to_dict()  # a YAML 1.1 reader agrees on it
