"""A hand file: the fingers finger_hand steps on one clock, each with its scene and base pose.

    fingers:
      - name: index                      # namespace of its topics: /index/joint_states, /index/motor_torque …
        scene: finger_default            # an installed scene's name, or a path (relative: to the hand file)
        pose: [0.0, 0.02, 0.0, 0.0, 0.0, 0.0]   # in hand_base: x y z (m), roll pitch yaw (rad), as URDF
        frame_prefix: index_             # of its links, joints and frames; default "<name>_"

Hand files live in `config/hands/` (installed to share/finger_sim/config/hands), apart from the
scenes. Read with the scenes' strict YAML 1.2 loader; every problem is a ConfigError naming
the parameter, the file and the key.
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from pathlib import Path

from finger_sim.errors import ConfigError
from finger_sim.scene_paths import SCENE_SUFFIXES, resolve_scene, scene_dirs
from finger_sim.scene_yaml import MAX_BYTES, mapping, number, parse_scene_text

#: Folder of the hand files inside each scene folder.
HANDS_DIR = "hands"
#: A finger's name: one ROS name token (it becomes a namespace).
NAME = re.compile(r"[A-Za-z][A-Za-z0-9_]*")
MAX_FINGERS = 10
#: Largest base-pose offset, m (a hand is ~0.2 m), and angle, rad (a few turns either way).
MAX_OFFSET = 1.0
MAX_ANGLE = 10.0
_KEYS = {"name", "scene", "pose", "frame_prefix"}

Pose = tuple[float, float, float, float, float, float]


@dataclass(frozen=True)
class FingerSpec:
    """One finger to simulate: name (the namespace of its topics; "" for finger_node's one
    finger), scene file, frame prefix, base pose in hand_base (x, y, z m, roll, pitch, yaw rad)."""

    name: str
    scene_path: Path
    frame_prefix: str = ""
    pose: Pose = (0.0, 0.0, 0.0, 0.0, 0.0, 0.0)


def resolve_hand(value: str) -> Path:
    """The `hand` parameter → a file: a path if it looks like one, else an installed hand's name."""
    if "/" in value or value.endswith(SCENE_SUFFIXES):
        return Path(value).expanduser()
    folders = [d / HANDS_DIR for d in scene_dirs()]
    for folder in folders:
        if (folder / f"{value}.yaml").is_file():
            return folder / f"{value}.yaml"
    names = sorted({p.stem for d in folders for p in d.glob("*.yaml")})
    raise ConfigError("parameter 'hand'", f"a hand file path or an installed hand ({', '.join(names) or 'none installed'})", value)


def load_hand(path: Path) -> list[FingerSpec]:
    """The fingers of the hand file at `path`; ConfigError names the file and the key."""
    where = f"parameter 'hand' ({path})"
    try:
        raw = path.read_bytes()[: MAX_BYTES + 1]
        text = raw.decode("utf-8-sig")
    except (OSError, UnicodeDecodeError) as exc:
        raise ConfigError(where, "a readable UTF-8 hand file", str(exc)) from None
    if len(raw) > MAX_BYTES:
        raise ConfigError(where, f"a hand file of at most {MAX_BYTES} bytes", "a larger file")
    try:
        data = mapping(parse_scene_text(text, str(path)), "hand", {"fingers"})
        entries = data.get("fingers")
        if not isinstance(entries, list) or not 1 <= len(entries) <= MAX_FINGERS:
            raise ConfigError("fingers", f"a list of 1 to {MAX_FINGERS} fingers", entries)
        fingers = [_finger(entry, i, path.parent) for i, entry in enumerate(entries)]
    except ConfigError as exc:
        raise exc.within(where) from None
    for key in ("name", "frame_prefix"):
        seen = [getattr(f, key) for f in fingers]
        twice = next((v for v in seen if seen.count(v) > 1), None)
        if twice is not None:
            raise ConfigError(f"{where}: fingers.{key}", "a different one for every finger", twice)
    return fingers


def _finger(entry: object, i: int, folder: Path) -> FingerSpec:
    key = f"fingers[{i}]"
    m = mapping(entry, key, _KEYS)
    missing = sorted({"name", "scene"} - m.keys())
    if missing:
        raise ConfigError(f"{key}.{missing[0]}", "a value (name and scene are required)", None)
    name = m["name"]
    if not isinstance(name, str) or not NAME.fullmatch(name):
        raise ConfigError(f"{key}.name", "a name of letters, digits and '_' that starts with a letter", name)
    scene = m["scene"]
    if not isinstance(scene, str) or not scene:
        raise ConfigError(f"{key}.scene", "a scene name or file path", scene)
    path = resolve_scene(scene)
    if not path.is_absolute() and ("/" in scene or scene.endswith(SCENE_SUFFIXES)):
        path = folder / path
    pose = m.get("pose", [0.0] * 6)
    if not isinstance(pose, list) or len(pose) != 6:
        raise ConfigError(f"{key}.pose", "[x, y, z, roll, pitch, yaw] (m, rad)", pose)
    values = tuple(number(v, f"{key}.pose[{j}]", minimum=-MAX_OFFSET if j < 3 else -MAX_ANGLE,
                          maximum=MAX_OFFSET if j < 3 else MAX_ANGLE) for j, v in enumerate(pose))
    prefix = m.get("frame_prefix", f"{name}_")
    if not isinstance(prefix, str) or any(c.isspace() for c in prefix):
        raise ConfigError(f"{key}.frame_prefix", "a prefix without white space", prefix)
    return FingerSpec(name, path, prefix, values)  # type: ignore[arg-type]
