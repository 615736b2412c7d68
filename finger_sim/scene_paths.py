"""Scenes by name: where installed scenes live, and a name or path → the scene file.

Used by finger_node's `scene` parameter and by the benchmarks; ROS-free (ament_index is
asked only if it is installed).
"""

from __future__ import annotations

import sys
from pathlib import Path

from finger_sim.errors import ConfigError

PACKAGE = "finger_sim"
SCENE_SUFFIXES = (".yaml", ".yml")
#: Files in the scene folders that are not scenes.
NOT_SCENES = frozenset({"finger_node"})


def scene_dirs() -> list[Path]:
    """Where installed scenes are looked for, in order: the ament index (colcon install), the
    venv prefix (pip install), the source tree (editable install)."""
    dirs = []
    try:
        from ament_index_python.packages import get_package_share_directory

        dirs.append(Path(get_package_share_directory(PACKAGE)) / "config")
    except (ImportError, LookupError, OSError):  # no ament_index, package not indexed, no AMENT_PREFIX_PATH
        pass
    dirs.append(Path(sys.prefix) / "share" / PACKAGE / "config")
    dirs.append(Path(__file__).resolve().parents[1] / "config")
    seen: list[Path] = []
    for d in dirs:
        if d.is_dir() and d not in seen:
            seen.append(d)
    return seen


def resolve_scene(value: str) -> Path:
    """A scene parameter → a file: a path if it looks like one, else an installed scene's name.

    Raises ConfigError naming parameter 'scene' and the installed names for an unknown name.
    """
    if "/" in value or value.endswith(SCENE_SUFFIXES):
        return Path(value).expanduser()
    dirs = scene_dirs()
    for d in dirs:
        if (d / f"{value}.yaml").is_file():
            return d / f"{value}.yaml"
    names = sorted({p.stem for d in dirs for p in d.glob("*.yaml")} - NOT_SCENES)
    raise ConfigError("parameter 'scene'", f"a scene file path or an installed scene name {names}", value)
