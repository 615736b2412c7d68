"""A log is written on a machine without ROS 2: where no `.msg` file is installed, the message definitions
come from rosbags' Jazzy type store, and two independent readers (rosbags, mcap_ros2) decode what was written.

The missing files are made so here (the search prefixes point at an empty folder), so that these tests
fail without the fallback whether or not ROS is installed on the machine that runs them."""

from __future__ import annotations

from pathlib import Path

import pytest
from mcap.reader import make_reader
from mcap_ros2.decoder import DecoderFactory
from rosbags.highlevel import AnyReader

from finger_sim.log import McapRecorder, MessageDefinitionNotFoundError, definitions, message_definition

JOINT_STATE = {"header": {"stamp": {"sec": 1, "nanosec": 500}, "frame_id": "finger"},
               "name": ["mcp", "coupler", "pip"], "position": [0.1, -0.2, 0.3], "velocity": [1.0, 2.0, 3.0],
               "effort": [0.0, 0.01, -0.02]}
#: Nested types of its own package written unqualified in the .msg files (DiagnosticStatus, KeyValue).
DIAGNOSTICS = {"header": {"stamp": {"sec": 2, "nanosec": 0}, "frame_id": ""},
               "status": [{"level": 1, "name": "finger_node: simulation", "message": "ok", "hardware_id": "sim",
                           "values": [{"key": "realtime_factor", "value": "1.0"}]}]}


@pytest.fixture
def no_msg_files(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """The default search finds no `.msg` file, as on a machine without ROS 2."""
    empty = tmp_path / "no_ros"
    empty.mkdir()
    monkeypatch.setattr(definitions, "default_search_prefixes", lambda: [empty])


@pytest.mark.usefixtures("no_msg_files")
def test_a_log_is_written_and_read_back_without_ros_message_files(tmp_path: Path) -> None:
    path = tmp_path / "run.mcap"
    with McapRecorder(path) as recorder:
        recorder.register_channel("/joint_states", "sensor_msgs/msg/JointState")
        recorder.register_channel("/diagnostics", "diagnostic_msgs/msg/DiagnosticArray")
        assert recorder.write("/joint_states", JOINT_STATE, 1_000_000)
        assert recorder.write("/diagnostics", DIAGNOSTICS, 2_000_000)
    with AnyReader([path]) as reader:
        by_rosbags = {c.topic: reader.deserialize(raw, c.msgtype) for c, _, raw in reader.messages()}
    with path.open("rb") as file:
        by_mcap_ros2 = {c.topic: m for _, c, _, m in make_reader(file, decoder_factories=[DecoderFactory()])
                        .iter_decoded_messages()}
    for decoded in (by_rosbags, by_mcap_ros2):
        js = decoded["/joint_states"]
        assert (js.header.stamp.sec, js.header.stamp.nanosec, js.header.frame_id) == (1, 500, "finger")
        assert list(js.name) == JOINT_STATE["name"]
        for key in ("position", "velocity", "effort"):
            assert list(getattr(js, key)) == JOINT_STATE[key]
        (status,) = decoded["/diagnostics"].status
        assert (status.name, status.message, status.hardware_id) == ("finger_node: simulation", "ok", "sim")
        assert [(kv.key, kv.value) for kv in status.values] == [("realtime_factor", "1.0")]


@pytest.mark.usefixtures("no_msg_files")
def test_an_unknown_type_still_names_the_files_looked_for() -> None:
    with pytest.raises(MessageDefinitionNotFoundError, match=r"no message definition for nosuch_msgs/msg/Thing: "
                       r"looked for .*no_ros/share/nosuch_msgs/msg/Thing\.msg"):
        message_definition("nosuch_msgs/Thing")


def test_installed_msg_files_are_preferred_byte_for_byte() -> None:
    """With ROS's .msg files installed, the definition is their text (comments kept), not rosbags'."""
    files = [p / "share" / "sensor_msgs" / "msg" / "JointState.msg" for p in definitions.default_search_prefixes()]
    found = [f for f in files if f.is_file()]
    if not found:
        pytest.skip("no sensor_msgs .msg files installed (the ROS 2 message packages)")
    text = message_definition("sensor_msgs/msg/JointState")
    assert text.startswith(found[0].read_text(encoding="utf-8"))
    assert text != definitions.jazzy_definition("sensor_msgs/msg/JointState")
