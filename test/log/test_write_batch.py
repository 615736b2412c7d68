"""McapRecorder.write_batch: one hand-over of a step's messages writes what write() writes for
each of them (records, sequences, times), and drops and counts exactly as write() does."""

from __future__ import annotations

import random
import threading
from pathlib import Path

import pytest
from mcap.reader import make_reader
from rosbags.highlevel import AnyReader

from finger_sim.log import LogArgumentError, McapRecorder
from finger_sim.log.cdr_writer import JointStateCdr, PoseStampedCdr, clock_cdr
from helpers import blocked_recorder

JOINTS = ["mcp_joint", "coupler_joint", "pip_joint"]
FINGERS = 4  # joint_states and fingertip_pose of each, /clock: 9 messages a step
STEPS = 300
DT_NS = 1_000_000
T0_NS = 7_000_000_000
DEADLINE_S = 20.0


def step_messages(k: int, rng: random.Random) -> list[tuple[str, bytes]]:
    """One step of a hand's state as the node publishes it: /clock, then each finger's two messages."""
    stamp = T0_NS + k * DT_NS
    joints, pose = JointStateCdr("f_base", JOINTS), PoseStampedCdr("f_base")
    out = [("/clock", clock_cdr(stamp))]
    for f in range(FINGERS):
        values = [[rng.uniform(-3, 3) for _ in JOINTS] for _ in range(3)]
        out.append((f"/f{f}/joint_states", joints(stamp, *values)))
        out.append((f"/f{f}/fingertip_pose", pose(stamp, [rng.uniform(-1, 1) for _ in range(3)], (0.0, 0.6, 0.0, 0.8))))
    return out


def register(recorder: McapRecorder) -> None:
    recorder.register_channel("/clock", "rosgraph_msgs/msg/Clock")
    for f in range(FINGERS):
        recorder.register_channel(f"/f{f}/joint_states", "sensor_msgs/msg/JointState")
        recorder.register_channel(f"/f{f}/fingertip_pose", "geometry_msgs/msg/PoseStamped")


def record(path: Path, batched: bool) -> McapRecorder:
    rng = random.Random(5)
    with McapRecorder(path, chunk_interval_s=0.05) as recorder:
        register(recorder)
        for k in range(STEPS):
            messages = step_messages(k, rng)
            stamp = T0_NS + k * DT_NS
            if batched:
                assert recorder.write_batch(messages, stamp) == len(messages)
            else:
                assert all(recorder.write(topic, data, stamp) for topic, data in messages)
    return recorder


def messages_of(path: Path) -> list[tuple[str, int, int, int, bytes]]:
    with open(path, "rb") as f:
        return [(c.topic, m.sequence, m.log_time, m.publish_time, m.data)
                for _, c, m in make_reader(f).iter_messages(log_time_order=False)]


def test_a_batch_writes_what_single_writes_write(tmp_path: Path) -> None:
    single, batched = record(tmp_path / "single.mcap", False), record(tmp_path / "batched.mcap", True)
    expected = messages_of(tmp_path / "single.mcap")
    assert len(expected) == STEPS * (1 + 2 * FINGERS)
    assert messages_of(tmp_path / "batched.mcap") == expected
    assert (batched.written, batched.dropped) == (single.written, single.dropped) == (len(expected), 0)
    # sequences count from 1 per channel, as rosbag2 writes them
    assert [s for t, s, *_ in expected if t == "/f2/joint_states"] == list(range(1, STEPS + 1))


def test_rosbags_decodes_the_batched_log(tmp_path: Path) -> None:
    record(tmp_path / "batched.mcap", True)
    rng = random.Random(5)
    sent = [step_messages(k, rng) for k in range(STEPS)]
    with AnyReader([tmp_path / "batched.mcap"]) as reader:
        conns = [c for c in reader.connections if c.topic == "/f3/joint_states"]
        got = [reader.deserialize(raw, c.msgtype) for c, _, raw in reader.messages(connections=conns)]
    assert len(got) == STEPS
    for k, msg in enumerate(got):
        want = sent[k][1 + 2 * 3][1]  # /f3/joint_states of step k
        assert (msg.header.stamp.sec * 1_000_000_000 + msg.header.stamp.nanosec) == T0_NS + k * DT_NS
        assert JointStateCdr("f_base", JOINTS)(T0_NS + k * DT_NS, msg.position.tolist(), msg.velocity.tolist(),
                                               msg.effort.tolist()) == want


def test_a_full_queue_drops_the_rest_of_a_batch_as_write_would(tmp_path: Path) -> None:
    with blocked_recorder(tmp_path, queue_size=12) as (recorder, problems):
        register(recorder)
        first, second = step_messages(0, random.Random(1)), step_messages(1, random.Random(2))
        assert recorder.write_batch(first, T0_NS) == 9
        assert recorder.write_batch(second, T0_NS + DT_NS) == 3  # 12 - 9 fit, 6 dropped
        assert recorder.dropped == 6
        assert len(problems) == 1 and "12 messages wait for the writer" in problems[0]


def test_a_batch_with_an_unregistered_topic_raises(tmp_path: Path) -> None:
    with McapRecorder(tmp_path / "x.mcap") as recorder:
        recorder.register_channel("/clock", "rosgraph_msgs/msg/Clock")
        with pytest.raises(LogArgumentError, match="/nowhere"):
            recorder.write_batch([("/clock", clock_cdr(0)), ("/nowhere", clock_cdr(0))], 0)


def test_back_pressure_keeps_every_message_of_batches_larger_than_the_room(tmp_path: Path) -> None:
    """A batch that does not fit waits message by message, without holding the lock the sender
    needs to hand the buffer over (it deadlocked so before)."""
    path = tmp_path / "pressed.mcap"
    recorder = McapRecorder(path, queue_size=4, back_pressure=True).open()
    register(recorder)
    rng = random.Random(3)
    counts: list[int] = []
    worker = threading.Thread(target=lambda: counts.extend(
        recorder.write_batch(step_messages(k, rng), T0_NS + k * DT_NS) for k in range(50)), daemon=True)
    worker.start()
    worker.join(DEADLINE_S)
    assert not worker.is_alive(), "write_batch blocked under back-pressure"
    recorder.close(timeout_s=DEADLINE_S)
    assert counts == [1 + 2 * FINGERS] * 50
    assert (recorder.written, recorder.dropped) == (50 * (1 + 2 * FINGERS), 0)
    assert len(messages_of(path)) == 50 * (1 + 2 * FINGERS)


def changing_steps() -> list[list[tuple[str, bytes]]]:
    """Each step's (topic, CDR) messages, seeded: every third step leaves out the fingertip poses
    and every fifth reverses the order."""
    rng = random.Random(5)
    steps = []
    for k in range(STEPS):
        messages = step_messages(k, rng)
        if k % 3 == 1:
            messages = [m for m in messages if not m[0].endswith("fingertip_pose")]
        if k % 5 == 2:
            messages.reverse()
        steps.append(messages)
    return steps


def record_reusing_lists(path: Path) -> McapRecorder:
    """`changing_steps()`, handed over as StateOutput does: two lists cleared and refilled in
    place every step, so the recorder's remembered topic list must notice each change."""
    topics: list[str] = []
    datas: list[bytes] = []
    with McapRecorder(path, chunk_interval_s=0.05) as recorder:
        register(recorder)
        for k, messages in enumerate(changing_steps()):
            topics.clear()
            datas.clear()
            for topic, data in messages:
                topics.append(topic)
                datas.append(data)
            assert recorder.write_records(topics, datas, T0_NS + k * DT_NS) == len(messages)
    return recorder


def test_records_from_lists_reused_in_place_write_what_single_writes_write(tmp_path: Path) -> None:
    with McapRecorder(tmp_path / "single.mcap", chunk_interval_s=0.05) as single:
        register(single)
        for k, messages in enumerate(changing_steps()):
            assert all(single.write(topic, data, T0_NS + k * DT_NS) for topic, data in messages)
    reused = record_reusing_lists(tmp_path / "reused.mcap")
    expected = messages_of(tmp_path / "single.mcap")
    assert len(expected) == STEPS * (1 + 2 * FINGERS) - len(range(1, STEPS, 3)) * FINGERS
    assert messages_of(tmp_path / "reused.mcap") == expected
    assert (reused.written, reused.dropped) == (len(expected), 0)


def test_records_other_than_bytes_go_the_way_of_write(tmp_path: Path) -> None:
    """A bytearray is copied (write()'s path), so changing it afterwards changes nothing logged."""
    with McapRecorder(tmp_path / "x.mcap") as recorder:
        recorder.register_channel("/clock", "rosgraph_msgs/msg/Clock")
        data = bytearray(clock_cdr(T0_NS))
        assert recorder.write_records(["/clock"], [data], T0_NS) == 1
        data[:] = clock_cdr(0)
    assert [m[4] for m in messages_of(tmp_path / "x.mcap")] == [clock_cdr(T0_NS)]


def test_records_need_one_message_per_topic(tmp_path: Path) -> None:
    with McapRecorder(tmp_path / "x.mcap") as recorder:
        recorder.register_channel("/clock", "rosgraph_msgs/msg/Clock")
        with pytest.raises(LogArgumentError, match="one CDR message per topic"):
            recorder.write_records(["/clock", "/clock"], [clock_cdr(0)], 0)
