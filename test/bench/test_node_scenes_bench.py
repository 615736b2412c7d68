"""`python -m finger_sim.bench.node_scenes_bench --scenes` takes every shipped scene, those of
config/friction/ and config/hard/ too, and hands the node a scene parameter it resolves to that file
(`scene_paths.resolve_scene`, the node's own lookup); an unknown name is one line before any node
starts. No node is started here."""

from __future__ import annotations

import contextlib
import io
import os
from pathlib import Path

import pytest

from finger_sim.bench.node_scenes_bench import main, scene_file
from finger_sim.scene_paths import resolve_scene

CONFIG = Path(__file__).resolve().parents[2] / "config"
#: Every shipped scene by its name under config/ (finger_node.yaml holds node parameters).
NAMES = sorted(str(p.relative_to(CONFIG).with_suffix("")) for folder in ("", "friction", "hard")
               for p in (CONFIG / folder).glob("*.yaml") if p.name != "finger_node.yaml")


def test_the_shipped_scenes_include_the_friction_and_hard_folders() -> None:
    assert any(n.startswith("friction/") for n in NAMES) and any(n.startswith("hard/") for n in NAMES)


@pytest.mark.parametrize("name", NAMES)
def test_the_node_resolves_each_name_to_its_scene_file(name: str) -> None:
    assert resolve_scene(str(scene_file(name))).samefile(CONFIG / f"{name}.yaml")


def test_a_scene_file_path_is_taken_as_it_is(tmp_path: Path) -> None:
    own = tmp_path / "my_scene.yaml"
    own.write_text((CONFIG / "hard" / "grasp_release.yaml").read_text(encoding="utf-8"), encoding="utf-8")
    assert resolve_scene(str(scene_file(str(own)))).samefile(own)


def test_an_unknown_scene_is_one_line_before_any_node_starts(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.delenv("ROS_DOMAIN_ID", raising=False)
    err = io.StringIO()
    with contextlib.redirect_stderr(err), pytest.raises(SystemExit) as exit_:
        main(["--scenes", "paper_flexion", "hard/no_such_scene", "--domain-id", "90"])
    assert exit_.value.code == 2
    last = err.getvalue().strip().splitlines()[-1]
    assert last.startswith("node_scenes_bench: error: --scenes: expected a scene file or a name under config/")
    assert last.endswith("got 'hard/no_such_scene'")
    assert "ROS_DOMAIN_ID" not in os.environ  # refused before the DDS set-up, so before any node
