"""The scene key `input.tip_force` (a tip-force profile): its schema, and the paths that refuse it.

References: the switch steps written out by hand from the spans and dt; the YAML round trip.
"""

from __future__ import annotations

from pathlib import Path

import pytest
import yaml

from finger_sim.errors import ConfigError
from finger_sim.rollouts import rollout
from finger_sim.scene import load_scene, scene_from_dict
from finger_sim.scene_changes import SceneChanges
from finger_sim.simulate import simulate
from finger_sim.batch import run_batch
from finger_sim.tip_force_profile import static_scene, tip_force_switches

CONFIG = Path(__file__).resolve().parents[2] / "config"


def cup_with(spans) -> dict:
    data = yaml.safe_load((CONFIG / "grasp_cylinder.yaml").read_text())
    data["model"] = {**data["model"], "tip_force": [0.01, 0.0]}
    data["input"]["tip_force"] = spans
    return data


def test_profile_switches_at_the_first_step_at_or_after_each_end_and_round_trips():
    scene = scene_from_dict(cup_with([{"start": 0.1005, "end": 0.2, "force": [0.0, -0.2]},
                                      {"start": 0.2, "end": 0.3, "force": [0.1, 0.0]},
                                      {"start": 0.0, "end": 0.05, "force": [0.0, 0.3]}]))
    # dt = 1 ms: 0.1005 s → step 101; 0.2 s ends one span and starts the next (the start wins)
    assert tip_force_switches(scene) == {0: (0.0, 0.3), 50: (0.01, 0.0), 101: (0.0, -0.2), 200: (0.1, 0.0),
                                         300: (0.01, 0.0)}
    assert scene_from_dict(scene.to_dict()) == scene
    fixed = static_scene(scene)
    assert fixed.tip_force == (0.0, 0.3) and fixed.tip_force_profile == ()
    changes = SceneChanges(scene, kernel="python")
    seen = {}
    for _ in range(310):
        changes.before_step()
        seen.setdefault(changes.sim.scene.tip_force, changes.sim.step_index)
        changes.sim.step(0.02)
    assert seen == {(0.0, 0.3): 0, (0.01, 0.0): 50, (0.0, -0.2): 101, (0.1, 0.0): 200}


@pytest.mark.parametrize("spans, key", [
    ([{"start": 0.1, "end": 0.3, "force": [0, 1]}, {"start": 0.2, "end": 0.4, "force": [0, 1]}], "input.tip_force"),
    ([{"start": 0.1, "end": 0.05, "force": [0, 1]}], "input.tip_force[0].end"),
    ([{"start": 0.1, "force": [0, 1], "torque": 1}], "input.tip_force[0]"),
    ([{"start": 0.1, "force": [0, 1e9]}], "input.tip_force[0].force[1]"),
    ({"start": 0.1}, "input.tip_force"),
])
def test_bad_profiles_are_refused_naming_the_key(spans, key):
    with pytest.raises(ConfigError) as err:
        scene_from_dict(cup_with(spans))
    assert err.value.key == key and "\n" not in str(err.value)


def test_paths_that_run_one_fixed_system_refuse_a_profile_rather_than_ignore_it():
    scene = scene_from_dict(cup_with([{"start": 0.1, "end": 0.2, "force": [0.0, -0.2]}]))
    for run in (lambda: simulate(scene), lambda: rollout(scene, nstep=10),
                lambda: run_batch([scene])):
        with pytest.raises(ConfigError, match="no tip-force profile") as err:
            run()
        assert err.value.key == "input.tip_force"
    assert simulate(load_scene(CONFIG / "grasp_cylinder.yaml")).t.size  # without a profile: as before
