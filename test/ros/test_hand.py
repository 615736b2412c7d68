"""finger_hand: three fingers in one process, in lock-step on one /clock, into one log.

References: each finger's own offline run (a Simulator of its scene fed the torque it was
sent, from the step it took effect), the /clock publisher count of the ROS graph, the URDF of
finger_sim.urdf.hand_urdf, and the log read back by rosbags (an independent MCAP reader).
"""

from __future__ import annotations

from pathlib import Path

import pytest

rclpy = pytest.importorskip("rclpy")

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus  # noqa: E402
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy  # noqa: E402
from rosgraph_msgs.msg import Clock  # noqa: E402
from sensor_msgs.msg import JointState  # noqa: E402
from std_msgs.msg import Float64, String  # noqa: E402
from std_srvs.srv import Trigger  # noqa: E402

from finger_sim import joints, kinematics  # noqa: E402
from finger_sim.ros import conversions  # noqa: E402
from finger_sim.runtime.hand_config import load_hand, resolve_hand  # noqa: E402
from finger_sim.scene import load_scene  # noqa: E402
from finger_sim.simulate import Simulator  # noqa: E402
from finger_sim.urdf import hand_urdf  # noqa: E402
from ros_helpers import stamp  # noqa: E402

HAND = "finger_sim.ros.hand"
RATE = 1000.0
DT_NS = 1_000_000
STEPS = 300
#: What each finger is sent while paused at step 0 (topic, message), and the torque it means, N·m.
COMMANDS = {
    "index": ("motor_torque", Float64(data=0.003), 0.003),
    "middle": ("joint_command", JointState(name=["middle_mcp_joint"], effort=[-0.002]), -0.002),  # on its 0° stop
    "ring": ("joint_command", JointState(name=["ring_mcp_joint"], effort=[0.01]), 0.01),
}
RELIABLE = QoSProfile(depth=100, reliability=ReliabilityPolicy.RELIABLE)


def offline(scene_path: Path, torque: float) -> list:
    """States 0..STEPS of the finger's own Simulator at the hand's rate, `torque` held from step 0."""
    sim = Simulator(load_scene(scene_path).with_overrides(dt=1.0 / RATE))
    return [sim.state] + [sim.step(torque) for _ in range(STEPS)]


def reset_until_heard(client, received: list[list]) -> int:
    """~/reset the paused hand until a state of every finger reaches us (a reset publishes the
    initial states; those at start may go before the subscriptions match); the stamp (ns) of
    step 0 of the episode it then waits in."""
    clock: list[int] = []

    def heard():
        if clock and all(received):
            return True
        answer = client.call(Trigger, "/finger_hand/reset").message
        clock[:] = [round(float(answer.split("clock=")[1].split()[0]) * 1e9)]
        return False

    client.wait_for(heard, "every finger's initial state")
    return clock[0]


def test_three_fingers_one_clock_their_own_runs_one_log(launcher, ros_client, tmp_path):
    fingers = load_hand(resolve_hand("three_fingers"))
    assert [f.name for f in fingers] == list(COMMANDS)
    hand = launcher.node(HAND, dict(hand="three_fingers", realtime_factor=0.0, start_paused=True, command_timeout=0.0,
                                    command_qos="reliable", steps_per_trigger=STEPS, marker_rate_hz=0.0))
    clocks = ros_client.collect(Clock, "/clock", QoSProfile(depth=10_000, reliability=ReliabilityPolicy.BEST_EFFORT))
    diagnostics = ros_client.collect(DiagnosticArray, "/diagnostics")
    states = {name: ros_client.collect(JointState, f"/{name}/joint_states") for name in COMMANDS}
    logs = {name: ros_client.collect(DiagnosticStatus, f"/{name}/command_log") for name in COMMANDS}
    publishers = {name: ros_client.publisher(type(msg), f"/{name}/{topic}", RELIABLE) for name, (topic, msg, _) in COMMANDS.items()}
    graph = ros_client.node
    ros_client.wait_for(lambda: all(p.get_subscription_count() for p in publishers.values())
                        and all(graph.count_publishers(f"/{n}/joint_states") for n in COMMANDS), "the hand's topics")

    def received(name: str) -> int:
        counts = [int(conversions.parse_values(s)["commands_received"]) for d in diagnostics for s in d.status
                  if s.name == f"/finger_hand: {name} simulation"]
        return max(counts, default=-1)

    offset = reset_until_heard(ros_client, list(states.values()))  # the hand waits at step 0 of an episode
    for name, (_, msg, _) in COMMANDS.items():
        publishers[name].publish(msg)
    ros_client.wait_for(lambda: all(received(n) == 1 for n in COMMANDS), "every finger's command counted (about 1 Hz)")
    answer = ros_client.call(Trigger, "/finger_hand/step")
    assert answer.success and f"step={STEPS}" in answer.message, answer.message
    end = offset + STEPS * DT_NS
    ros_client.wait_for(lambda: all(any(stamp(m) == end for m in s) for s in states.values()), "every finger at the last step")
    ros_client.wait_for(lambda: any(stamp(c) == end for c in clocks), "/clock at the last step")

    # one /clock, never going back, carrying the states' sim time; best effort (ClockQoS), so a
    # burst of ticks may reach us in part: the paused hand repeats the last one, the log has all
    assert graph.count_publishers("/clock") == 1
    ticks = [stamp(c) for c in clocks]
    assert all(b >= a for a, b in zip(ticks, ticks[1:])) and ticks[-1] == end
    assert {t for t in ticks if t >= offset} <= set(range(offset, end + 1, DT_NS))

    # robot_description: every finger under hand_base at its pose
    description = ros_client.collect(String, "/robot_description",
                                     QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE,
                                                durability=DurabilityPolicy.TRANSIENT_LOCAL))
    ros_client.wait_for(lambda: description, "robot_description")
    expected = hand_urdf([(f.frame_prefix, load_scene(f.scene_path).params, f.pose, load_scene(f.scene_path).mcp_limits)
                          for f in fingers], mcp_effort=0.05)
    assert description[0].data == expected

    # one log holding all three fingers' topics, read by rosbags
    assert hand.stop() == 0, hand.log_path.read_text()
    assert "Traceback" not in hand.log_path.read_text()
    from rosbags.highlevel import AnyReader

    (path,) = (tmp_path / "bags").glob("three_fingers_*.mcap")
    with AnyReader([path]) as reader:
        topics = {c.topic for c in reader.connections}
        logged, logged_ticks = {}, []
        for c, _, raw in reader.messages(connections=[c for c in reader.connections if c.topic.endswith("/joint_states")]):
            m = reader.deserialize(raw, c.msgtype)
            logged.setdefault(c.topic, {})[stamp(m)] = \
                (list(m.name), m.header.frame_id, list(m.position), list(m.velocity), list(m.effort))
        for c, _, raw in reader.messages(connections=[c for c in reader.connections if c.topic == "/clock"]):
            m = reader.deserialize(raw, c.msgtype)
            logged_ticks.append(m.clock.sec * 10**9 + m.clock.nanosec)
    for name in COMMANDS:
        assert {f"/{name}/joint_states", f"/{name}/fingertip_pose", f"/{name}/command_log", f"/{name}/motor_torque",
                f"/{name}/joint_command"} <= topics
    assert {"/clock", "/diagnostics", "/robot_description"} <= topics
    assert all(b >= a for a, b in zip(logged_ticks, logged_ticks[1:]))
    assert {t for t in logged_ticks if t >= offset} == set(range(offset, end + 1, DT_NS))  # every state's tick

    # each finger: its own offline run, state for state at the same sim times, every state in the
    # log; what reached us is the log's (joint_states is reliable keep-last 10: a subscriber more
    # than 10 states behind a burst of 300 loses the oldest, and the last always arrives)
    for spec in fingers:
        topic, _, torque = COMMANDS[spec.name]
        ref = offline(spec.scene_path, torque)
        p = load_scene(spec.scene_path).params
        q_ext, alpha = kinematics.extended_pose(p), kinematics.distal_offset(p)
        log_states = logged[f"/{spec.name}/joint_states"]
        got = {(t - offset) // DT_NS: state for t, state in log_states.items() if t >= offset}
        assert sorted(got) == list(range(STEPS + 1)), spec.name
        for n, (names, frame, position, velocity, effort) in got.items():
            assert names == [spec.frame_prefix + j for j in joints.JOINT_NAMES]
            assert frame == spec.frame_prefix + "finger_base"
            assert position == list(joints.joint_positions(ref[n].q, q_ext, alpha)), (spec.name, n)
            assert velocity == list(joints.joint_velocities(ref[n].v)), (spec.name, n)
            assert effort[0] == (torque if n > 0 else 0.0)
        received = {stamp(m): (list(m.name), m.header.frame_id, list(m.position), list(m.velocity), list(m.effort))
                    for m in states[spec.name] if stamp(m) >= offset}
        assert end in received and received == {t: log_states[t] for t in received}, spec.name
        # command_log is a topic of its own: its event may reach us after the states did
        ros_client.wait_for(lambda: any(conversions.parse_values(m)["event"] == "accepted" for m in logs[spec.name]),
                            f"{spec.name}'s accepted command in its command_log")
        event = conversions.parse_values(logs[spec.name][-1])
        assert (event["event"], event["step"], event["source"]) == ("accepted", "0", f"/{spec.name}/{topic}")
    assert got[STEPS][2][0] > 0.1  # the ring finger flexed; index and middle differ from it
    assert {states[n][-1].position[0] for n in COMMANDS}.__len__() == 3
