"""Complete `ros2msg` message definitions, concatenated the way rosbag2 stores them in MCAP schemas.

A schema holds the top-level `.msg` text, then for each dependency (depth first, each type
once, dependencies of one message in sorted order) a newline, a line of 80 `=`, a line
`MSG: pkg/Type` and that type's `.msg` text. This is rosbag2's
`LocalMessageDefinitionSource::get_full_text` (rosbag2_cpp, Jazzy) and the "ros2msg"
encoding of rosbag2's `docs/message_definition_encoding.md`; mcap_ros2, Foxglove and rosbags
parse it. Dependencies are found with rosbag2's own field-type regex so that the text is
byte-for-byte what `ros2 bag record` would write from the same `.msg` files.
"""

from __future__ import annotations

import os
import re
import sys
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from .errors import LogArgumentError, MessageDefinitionNotFoundError

DEFINITION_SEPARATOR = "=" * 80

# rosbag2_cpp MSG_FIELD_TYPE_REGEX: the type at the start of a line ("pkg/Type" in "pkg/Type[] name").
_FIELD_TYPE = re.compile(r"(?:^|\n)\s*([a-zA-Z0-9_/]+)(?:\[[^\]]*\])?\s+")
_PRIMITIVE_TYPES = frozenset(
    ("bool", "byte", "char", "float32", "float64", "int8", "uint8", "int16", "uint16", "int32", "uint32",
     "int64", "uint64", "string")
)
_ROS_NAME = r"[a-zA-Z][a-zA-Z0-9_]*"
_TYPE_NAME = re.compile(rf"^({_ROS_NAME})/(?:msg/)?({_ROS_NAME})$")
# rosbag2 recurses at most this deep before it gives up on a definition (same limit here).
MAX_DEPENDENCY_DEPTH = 50


def type_name_of(message_or_type: Any) -> str:
    """The ROS 2 type name, e.g. 'sensor_msgs/msg/JointState', of an rclpy message or its class."""
    cls = message_or_type if isinstance(message_or_type, type) else type(message_or_type)
    package, _, rest = cls.__module__.partition(".")
    if not rest.startswith("msg"):
        raise LogArgumentError("message type", "a ROS 2 message (module pkg.msg._type)", cls.__module__)
    return f"{package}/msg/{cls.__name__}"


def normalize_type_name(type_name: str) -> str:
    """'pkg/Type' or 'pkg/msg/Type' → 'pkg/msg/Type' (the schema name rosbag2 writes)."""
    match = _TYPE_NAME.match(type_name)
    if match is None:
        raise LogArgumentError("type name", "'pkg/msg/Type' or 'pkg/Type'", type_name)
    return f"{match[1]}/msg/{match[2]}"


def default_search_prefixes() -> list[Path]:
    """Install prefixes searched for `share/<pkg>/msg/<Type>.msg`: AMENT_PREFIX_PATH, then sys.prefix.

    A sourced ROS install sets AMENT_PREFIX_PATH; the ROS 2 wheels install into the
    virtual environment's prefix and leave it unset.
    """
    ament = [Path(p) for p in os.environ.get("AMENT_PREFIX_PATH", "").split(os.pathsep) if p]
    return [*ament, Path(sys.prefix)]


def message_definition(type_name: str, *, prefixes: Sequence[Path] | None = None) -> str:
    """The complete `ros2msg` definition of `type_name` ('pkg/msg/Type' or 'pkg/Type').

    From the installed `.msg` files (byte for byte what rosbag2 writes). Where the default search finds
    none (a machine without ROS 2), from rosbags' ROS 2 Jazzy type store (`jazzy_definition`).
    Raises MessageDefinitionNotFoundError naming every file looked for if a `.msg` is missing and, with
    the default search, rosbags does not know the type either.
    """
    if prefixes is None:
        try:
            return _definition_from_files(type_name, default_search_prefixes())
        except MessageDefinitionNotFoundError:
            fallback = jazzy_definition(type_name)
            if fallback is None:
                raise
            return fallback
    return _definition_from_files(type_name, prefixes)


def jazzy_definition(type_name: str) -> str | None:
    """The `ros2msg` definition rosbags generates from its ROS 2 Jazzy type store, or None if it does
    not know the type: the same fields, types, constants and dependency blocks as rosbag2's text, without
    the `.msg` files' comments, so mcap_ros2, rosbags and Foxglove decode a log written with it alike."""
    from rosbags.typesys import Stores, get_typestore

    store = get_typestore(Stores.ROS2_JAZZY)
    root = normalize_type_name(type_name)
    if root not in store.fielddefs:
        return None
    return store.generate_msgdef(root, ros_version=2)[0]


def _definition_from_files(type_name: str, prefixes: Sequence[Path]) -> str:
    """message_definition from the `.msg` files under `prefixes` only."""
    search = list(prefixes)
    root = normalize_type_name(type_name)
    seen: set[str] = set()

    def full_text(name: str, depth: int) -> str:
        if depth <= 0:
            raise LogArgumentError("type name", f"a type nested at most {MAX_DEPENDENCY_DEPTH} deep", root)
        text = _read_msg(name, search)
        package = name.partition("/")[0]
        result = text
        for dependency in _dependencies(text, package):
            if dependency not in seen:
                seen.add(dependency)
                result += f"\n{DEFINITION_SEPARATOR}\nMSG: {dependency}\n"
                result += full_text(dependency, depth - 1)
        return result

    return full_text(root, MAX_DEPENDENCY_DEPTH)


def _dependencies(text: str, package: str) -> list[str]:
    """Non-primitive field types of one `.msg` text as sorted 'pkg/Type' (rosbag2 uses a std::set)."""
    found = set()
    for match in _FIELD_TYPE.finditer(text):
        field_type = match[1]
        if field_type in _PRIMITIVE_TYPES:
            continue
        found.add(field_type if "/" in field_type else f"{package}/{field_type}")
    return sorted(found)


def _read_msg(type_name: str, prefixes: Sequence[Path]) -> str:
    match = _TYPE_NAME.match(type_name)
    if match is None:
        raise LogArgumentError("field type", "'pkg/Type'", type_name)
    package, name = match[1], match[2]
    candidates = [prefix / "share" / package / "msg" / f"{name}.msg" for prefix in prefixes]
    for candidate in candidates:
        if candidate.is_file():
            # newline="" keeps the file's bytes as they are, as rosbag2's std::ifstream does.
            with candidate.open(encoding="utf-8", newline="") as file:
                return file.read()
    raise MessageDefinitionNotFoundError(f"{package}/msg/{name}", candidates)
