"""Scene YAML as users write it: YAML 1.2 scalars, bounded size and depth, one-line errors.

PyYAML implements YAML 1.1, where `1e6` and `1.0e-300` are strings and `yes` is a bool.
`SceneLoader` is PyYAML's safe loader with the YAML 1.2 core schema's resolvers
(yaml.org/spec/1.2.2 §10.3.2) instead, and it refuses what a scene never needs and a
hostile file uses: duplicate keys (1.1 silently keeps the last), anchors and aliases
(a "billion laughs" file expands a few hundred bytes into megabytes), explicit tags, and
nesting deeper than `MAX_DEPTH` (PyYAML's scanner is quadratic in the flow depth and its
composer recursive). `SceneDumper` writes with the same resolvers, so a string that would
read back as a number is quoted.

The value checks (`mapping`, `number`, `pair`, `text`) turn what the loader produced into
the schema's types, refusing anything else with a `ConfigError` naming the key.
"""

from __future__ import annotations

import math
import os
import re
import stat
from pathlib import Path
from typing import Any

import yaml
from yaml.events import AliasEvent, NodeEvent

from finger_sim.errors import ConfigError

#: Largest scene file read, bytes: the shipped scenes are < 1 kB.
MAX_BYTES = 1_000_000
#: Deepest nesting of collections in a scene (the schema needs 4).
MAX_DEPTH = 64

#: What a number is written as in a scene, for messages.
NUMBER_SYNTAX = "a finite number (YAML 1.2 float syntax, e.g. 1.0e-3)"

_NO_ANCHORS = "a scene without anchors or aliases (YAML anchors and aliases are not allowed in scenes)"

# The YAML 1.2 core schema: (tag, pattern, first characters). Ints come before floats: "10" is an int.
_CORE_SCHEMA = [
    ("tag:yaml.org,2002:null", r"^(?:~|null|Null|NULL|)$", ["~", "n", "N", ""]),
    ("tag:yaml.org,2002:bool", r"^(?:true|True|TRUE|false|False|FALSE)$", list("tTfF")),
    ("tag:yaml.org,2002:int", r"^(?:[-+]?[0-9]+|0o[0-7]+|0x[0-9a-fA-F]+)$", list("-+0123456789")),
    (
        "tag:yaml.org,2002:float",
        r"^(?:[-+]?(?:\.[0-9]+|[0-9]+(?:\.[0-9]*)?)(?:[eE][-+]?[0-9]+)?|[-+]?\.(?:inf|Inf|INF)|\.(?:nan|NaN|NAN))$",
        list("-+.0123456789"),
    ),
]


class SceneYamlError(yaml.YAMLError):
    """YAML that parses but a scene refuses: what is allowed, what was found and where."""

    def __init__(self, allowed: str, found: str, mark: yaml.Mark | None) -> None:
        self.allowed, self.found, self.mark = allowed, found, mark
        super().__init__(f"{found}{_where(mark)}")


class SceneLoader(yaml.SafeLoader):
    """PyYAML's safe loader with the YAML 1.2 core schema and a scene's refusals (see the module)."""

    yaml_implicit_resolvers: dict[str, list[tuple[str, re.Pattern[str]]]] = {}

    # -- scanner: bound the depth before the quadratic flow-key bookkeeping can run away --
    def fetch_flow_collection_start(self, TokenClass: type) -> None:  # noqa: N803 (PyYAML's name)
        self._check_depth(self.flow_level + 1)
        super().fetch_flow_collection_start(TokenClass)

    def add_indent(self, column: int) -> bool:
        added = super().add_indent(column)
        if added:
            self._check_depth(self.flow_level)
        return added

    def _check_depth(self, flow_level: int) -> None:
        depth = flow_level + len(self.indents)
        if depth > MAX_DEPTH:
            raise SceneYamlError(f"collections nested at most {MAX_DEPTH} deep", f"nesting deeper than {MAX_DEPTH}", self.get_mark())

    # -- composer: no anchors, aliases or tags ------------------------------------------
    def compose_node(self, parent: yaml.Node | None, index: Any) -> yaml.Node:
        event = self.peek_event()
        if isinstance(event, AliasEvent):
            raise SceneYamlError(_NO_ANCHORS, f"alias *{event.anchor}", event.start_mark)
        if isinstance(event, NodeEvent) and event.anchor is not None:
            raise SceneYamlError(_NO_ANCHORS, f"anchor &{event.anchor}", event.start_mark)
        tag = getattr(event, "tag", None)
        if tag is not None:
            raise SceneYamlError("a scene without explicit YAML tags", f"tag {tag}", event.start_mark)
        return super().compose_node(parent, index)

    # -- constructor: duplicate keys, YAML 1.2 ints ------------------------------------
    def construct_mapping(self, node: yaml.MappingNode, deep: bool = False) -> dict[Any, Any]:
        mapping = super().construct_mapping(node, deep=deep)
        if len(mapping) < len(node.value):
            seen: set[Any] = set()
            for key_node, _ in node.value:
                key = self.construct_object(key_node, deep=deep)
                if key in seen:
                    raise SceneYamlError("each key at most once in a mapping", f"duplicate key {key!r}", key_node.start_mark)
                seen.add(key)
        return mapping

    def construct_yaml_int(self, node: yaml.ScalarNode) -> int:
        value = self.construct_scalar(node)
        body = value.lstrip("+-")
        try:  # 1.2: "010" is ten (1.1 read it as octal); 0o17 and 0x1f are prefixed
            return int(value, 0) if body[:2] in ("0o", "0x") else int(value, 10)
        except ValueError:  # more digits than Python converts (sys.get_int_max_str_digits)
            raise SceneYamlError("an integer of at most 4300 digits", f"an integer of {len(body)} digits", node.start_mark) from None


for _tag, _pattern, _first in _CORE_SCHEMA:
    SceneLoader.add_implicit_resolver(_tag, re.compile(_pattern), _first)
SceneLoader.add_constructor("tag:yaml.org,2002:int", SceneLoader.construct_yaml_int)


class SceneDumper(yaml.SafeDumper):
    """Writes scenes that `SceneLoader` reads back: strings that look like 1.2 numbers are quoted."""

    yaml_implicit_resolvers: dict[str, list[tuple[str, re.Pattern[str]]]] = {}


for _tag, _pattern, _first in _CORE_SCHEMA:
    SceneDumper.add_implicit_resolver(_tag, re.compile(_pattern), _first)


def parse_scene_text(text: str, source: str = "scene") -> Any:
    """The data of one YAML scene document; ConfigError (key "scene") on anything refused.

    `source` (a path, or e.g. "log metadata") prefixes the position in messages.
    """
    if len(text) > MAX_BYTES:
        raise ConfigError("scene", f"a scene of at most {MAX_BYTES} characters", f"{source} ({len(text)} characters)")
    try:
        return yaml.load(text, Loader=SceneLoader)  # noqa: S506 (a safe loader)
    except SceneYamlError as exc:
        raise ConfigError("scene", exc.allowed, f"{source}{_where(exc.mark)}: {exc.found}") from None
    except yaml.MarkedYAMLError as exc:
        problem = " ".join(str(exc.problem or exc.context or "invalid").split())
        raise ConfigError("scene", "valid YAML", f"{source}{_where(exc.problem_mark or exc.context_mark)}: {problem}") from None
    except yaml.YAMLError as exc:
        raise ConfigError("scene", "valid YAML", f"{source}: {' '.join(str(exc).split())}") from None


def read_scene_file(path: Path) -> Any:
    """The data of a scene file: at most MAX_BYTES of UTF-8 YAML (see `parse_scene_text`)."""
    try:  # non-blocking open: a FIFO without a writer would block here forever
        with os.fdopen(os.open(path, os.O_RDONLY | os.O_NONBLOCK), "rb") as f:
            if not stat.S_ISREG(os.fstat(f.fileno()).st_mode):
                raise ConfigError("scene", "a regular file", f"{path} (a FIFO, socket, device or folder)")
            raw = f.read(MAX_BYTES + 1)
    except OSError as exc:
        raise ConfigError("scene", "a readable scene file", f"{path} ({exc.strerror})") from None
    if len(raw) > MAX_BYTES:
        raise ConfigError("scene", f"a scene file of at most {MAX_BYTES} bytes", f"{path} (larger)")
    try:
        text = raw.decode("utf-8-sig")
    except UnicodeDecodeError as exc:
        raise ConfigError("scene", "a UTF-8 text file", f"{path}: byte 0x{raw[exc.start]:02x} at offset {exc.start} is not UTF-8") from None
    return parse_scene_text(text, str(path))


def dump_scene(data: dict[str, Any]) -> str:
    """YAML text of a scene mapping that `parse_scene_text` reads back equal."""
    return yaml.dump(data, Dumper=SceneDumper, sort_keys=False, allow_unicode=True)


# -- value checks ----------------------------------------------------------------------
def mapping(value: Any, key: str, allowed: set[str]) -> dict[str, Any]:
    """`value` as a mapping whose keys are all in `allowed`."""
    if not isinstance(value, dict):
        raise ConfigError(key, "a mapping", value)
    unknown = sorted((k for k in value if k not in allowed), key=str)
    if unknown:
        raise ConfigError(key, f"only the keys {sorted(allowed)}", unknown[0])
    return value


def number(value: Any, key: str, *, minimum: float | None = None, maximum: float | None = None, strict: bool = False) -> float:
    """A finite float in [minimum, maximum] ((minimum, maximum] if strict); bools are not numbers.
    A refusal states the bound that was crossed."""
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise ConfigError(key, NUMBER_SYNTAX if isinstance(value, str) else "a finite number", value)
    try:
        x = float(value)
    except OverflowError:  # an int beyond the float range
        x = math.inf
    if not math.isfinite(x):
        raise ConfigError(key, "a finite number", value)
    if minimum is not None and (x < minimum or (strict and x == minimum)):
        raise ConfigError(key, f"a number {'>' if strict else '≥'} {minimum:g}", value)
    if maximum is not None and x > maximum:
        raise ConfigError(key, f"a number ≤ {maximum:g}", value)
    return x


def whole(value: Any, key: str, minimum: int, maximum: int, expected: str) -> int:
    """An integer in [minimum, maximum]; bools are not numbers. A float with no fractional part
    (3.0) reads as that integer, as JSON Schema's "integer" (the editors' check) takes it too.
    A refusal says `expected` and the value as given."""
    given = value
    if isinstance(value, float) and value.is_integer():
        value = int(value)
    if isinstance(value, bool) or not isinstance(value, int) or not minimum <= value <= maximum:
        raise ConfigError(key, expected, given)
    return value


def magnitude(value: Any, key: str, limit: float) -> float:
    """A finite float with |value| ≤ limit."""
    x = number(value, key)
    if abs(x) > limit:
        raise ConfigError(key, f"a number with magnitude ≤ {limit:g}", value)
    return x


def pair(value: Any, key: str, limit: float = math.inf) -> tuple[float, float]:
    """A list of two finite floats, each of magnitude ≤ limit."""
    if not isinstance(value, (list, tuple)) or len(value) != 2:
        raise ConfigError(key, "a list of two numbers", value)
    return (magnitude(value[0], f"{key}[0]", limit), magnitude(value[1], f"{key}[1]", limit))


def text(value: Any, key: str, max_length: int) -> str:
    """A string of at most max_length characters."""
    if not isinstance(value, str):
        raise ConfigError(key, "a string", value)
    if len(value) > max_length:
        raise ConfigError(key, f"a string of at most {max_length} characters", f"{len(value)} characters")
    return value


def _where(mark: yaml.Mark | None) -> str:
    return "" if mark is None else f": line {mark.line + 1}, column {mark.column + 1}"
