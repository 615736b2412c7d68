"""ros.state_output: a finger_hand's state leaves in one hand-over to the log per step, and every
message of every step is still in the log (counts equal steps, sequences unbroken), each finger's
joint_states equal to its part of the merged /joint_states (decoded by rosbags, an independent reader)."""

from __future__ import annotations

import subprocess
import sys
import textwrap
from pathlib import Path

import pytest
import yaml

pytest.importorskip("rclpy")

from conftest import allocate_domain_id, ros_environment  # noqa: E402
from rosbags.highlevel import AnyReader  # noqa: E402
from ros_helpers import stamp  # noqa: E402

FINGERS = ("a", "b", "c")
STEPS = 300  # after the first state: paper_flexion lasts 0.3 s
TIMEOUT_S = 300.0

#: Builds the hand in a process of its own (its own rclpy context), steps it as the stepping
#: thread does (`_advance`, realtime_factor 0, publishing every step) and closes the log.
SCRIPT = textwrap.dedent("""
    import sys
    import rclpy
    from rclpy.parameter import Parameter
    from finger_sim.ros.hand import FingerHand
    hand_file, folder, steps = sys.argv[1], sys.argv[2], int(sys.argv[3])
    rclpy.init()
    params = dict(hand=hand_file, torque_source="scene", physics_rate_hz=1000.0, publish_rate_hz=0.0,
                  realtime_factor=0.0, record=True, record_dir=folder, marker_rate_hz=0.0)
    node = FingerHand(parameter_overrides=[Parameter(k, value=v) for k, v in params.items()])
    node._publish_state(force=True)
    for _ in range(steps):
        node._advance()  # False after the last: the scene ends there
    node.close_log()
    print(node.recorder.path, node.recorder.written, node.recorder.dropped)
    node.destroy_node()
    rclpy.shutdown()
""")


def test_every_message_of_every_step_is_logged_once(tmp_path: Path) -> None:
    hand = tmp_path / "hand.yaml"
    hand.write_text(yaml.safe_dump({"fingers": [dict(name=n, scene="paper_flexion", pose=[0.0, 0.02 * i, 0.0, 0.0, 0.0, 0.0])
                                                for i, n in enumerate(FINGERS)]}))
    done = subprocess.run([sys.executable, "-c", SCRIPT, str(hand), str(tmp_path / "bags"), str(STEPS)],
                          env=ros_environment(allocate_domain_id()), capture_output=True, text=True, timeout=TIMEOUT_S)
    assert done.returncode == 0, done.stderr[-2000:]
    path, written, dropped = done.stdout.split()[-3:]
    states = STEPS + 1
    per_step = ["/clock", "/joint_states", *(f"/{n}/{t}" for n in FINGERS for t in ("joint_states", "fingertip_pose"))]
    assert int(dropped) == 0

    stamps: dict[str, list[int]] = {}
    values: dict[str, list[tuple[list[float], ...]]] = {}
    with AnyReader([Path(path)]) as reader:
        conns = [c for c in reader.connections if c.topic in per_step]
        for c, log_time, raw in reader.messages(connections=conns):
            msg = reader.deserialize(raw, c.msgtype)
            stamps.setdefault(c.topic, []).append(stamp(msg))
            if c.msgtype == "sensor_msgs/msg/JointState":
                values.setdefault(c.topic, []).append((list(msg.position), list(msg.velocity), list(msg.effort)))
    assert sorted(stamps) == sorted(per_step)
    for topic in per_step:  # one message of each topic per state, in step order
        assert stamps[topic] == [k * 1_000_000 for k in range(states)], topic
    assert int(written) >= states * len(per_step)
    for k in range(states):  # the merged /joint_states holds each finger's three joints, in the hand's order
        merged = values["/joint_states"][k]
        for i, n in enumerate(FINGERS):
            own = values[f"/{n}/joint_states"][k]
            assert all(merged[j][3 * i:3 * i + 3] == own[j] for j in range(3)), (k, n)
    # the fingers really moved (the scene's torque profile): the comparison is not of zeros
    assert values["/a/joint_states"][-1][0][0] != values["/a/joint_states"][0][0][0]
