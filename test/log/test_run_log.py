"""finger_sim.run_log without ROS: the stamp rule, the metadata record and the command-log events."""

from __future__ import annotations

import pytest

from finger_sim.log.recorder import MAX_METADATA_BYTES
from finger_sim.run_log import CommandEvent, RunLogError, RunMetadata, run_metadata, stamp_ns
from finger_sim.scene import load_scene

import reference as ref


def test_stamp_rule_is_offset_plus_rounded_step_time() -> None:
    assert stamp_ns(0, 0, 1e-3) == 0
    assert stamp_ns(5, 3, 1e-3) == 3_000_005
    # round(n·dt·1e9), not n·round(dt·1e9): 0.1 ms steps accumulate no drift
    assert stamp_ns(0, 10**7, 1e-4) == 10**12


def test_metadata_round_trips_and_keeps_unknown_keys() -> None:
    scene = load_scene(ref.CONFIG / "paper_flexion.yaml")
    record = run_metadata(scene, method="rk6", method_reason="", torque_source="scene", parameters={"rate": 1000.0})
    parsed = RunMetadata.from_dict({**record, "kernel": "numba"})
    assert parsed.scene == scene and parsed.torque_source == "scene" and parsed.parameters == {"rate": 1000.0}
    assert parsed.to_dict() == {**record, "kernel": "numba"}


@pytest.mark.parametrize(("change", "problem"), [
    ({"scene": "[unclosed"}, "key 'scene' does not parse as a scene"),
    ({"scene": "duration: -1"}, "key 'scene' does not parse as a scene: duration"),
    ({"torque_source": "joystick"}, "key 'torque_source': expected one of ['topic', 'scene'], got 'joystick'"),
    ({"parameters": "- a list"}, "key 'parameters': expected a mapping"),
])
def test_metadata_that_does_not_parse_is_one_line(change: dict[str, str], problem: str) -> None:
    record = run_metadata(load_scene(ref.CONFIG / "paper_flexion.yaml"), method="rk6", method_reason="",
                          torque_source="topic", parameters={})
    with pytest.raises(RunLogError) as err:
        RunMetadata.from_dict({**record, **change}, "run.mcap")
    assert problem in str(err.value) and "\n" not in str(err.value)
    assert str(err.value).startswith("run.mcap: metadata record 'finger_sim'")


def test_metadata_is_bounded() -> None:
    scene = load_scene(ref.CONFIG / "paper_flexion.yaml")
    with pytest.raises(RunLogError, match=r"would take \d+ bytes, more than the 65536 bytes a log stores"):
        run_metadata(scene, method="rk4", method_reason="", torque_source="topic",
                     parameters={"note": "x" * MAX_METADATA_BYTES})


def test_command_event_round_trips_and_names_bad_keys() -> None:
    event = CommandEvent("accepted", step=12, episode=1, stamp_ns=1_012_000_000, torque=0.1 + 0.2,
                         requested="0.30000000000000004", source="/motor_torque", saturated=True)
    assert CommandEvent.from_values(event.to_values()) == event
    with pytest.raises(RunLogError, match=r"command log key 'step': expected an int, got 'twelve'"):
        CommandEvent.from_values({**event.to_values(), "step": "twelve"})
    with pytest.raises(RunLogError, match=r"command log key 'event': expected one of"):
        CommandEvent.from_values({**event.to_values(), "event": "teleport"})
