"""finger_sim.scene_paths: installed scenes by name, paths as given."""

from __future__ import annotations

from pathlib import Path

import pytest

from finger_sim.errors import ConfigError
from finger_sim.scene_paths import resolve_scene, scene_dirs

CONFIG = Path(__file__).resolve().parents[2] / "config"


def test_installed_names_and_paths():
    assert CONFIG in scene_dirs()
    found = resolve_scene("paper_flexion")
    assert found.name == "paper_flexion.yaml" and found.read_bytes() == (CONFIG / "paper_flexion.yaml").read_bytes()
    assert resolve_scene("some/dir/x.yaml") == Path("some/dir/x.yaml")  # a path is taken as given
    assert resolve_scene("x.yml") == Path("x.yml")


def test_unknown_name_lists_the_installed_scenes():
    with pytest.raises(ConfigError) as info:
        resolve_scene("no_such_scene")
    message = str(info.value)
    assert message.startswith("parameter 'scene': expected a scene file path or an installed scene name [")
    assert "'paper_flexion'" in message and "'finger_node'" not in message and message.endswith("got 'no_such_scene'")
