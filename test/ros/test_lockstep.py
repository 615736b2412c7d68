"""Lockstep (`lockstep:=true`): the node steps k+1 only when the command answering state k has come.

References: the PD law (finger_sim.ros.pd_controller.pd_torque) evaluated in the test on each
logged state, which must be the torque applied over the next step, bit for bit; a second run of
the same closed loop at the same time, whose logged states must equal the first's bit for bit
although the machine is loaded by a busy process and by the other run; the commands this test
sends itself and the events and diagnostics the node reports about them. Logs are read by
rosbags (an independent reader).
"""

from __future__ import annotations

import os
import sys
from pathlib import Path

import pytest

rclpy = pytest.importorskip("rclpy")

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus  # noqa: E402
from rclpy.qos import QoSProfile  # noqa: E402
from sensor_msgs.msg import JointState  # noqa: E402

from finger_sim.ros import conversions  # noqa: E402
from finger_sim.ros.controller_main import AnswerPublisher  # noqa: E402
from finger_sim.ros.pd_controller import KD, KP, MAX_TORQUE, pd_torque  # noqa: E402
from ros_helpers import stamp  # noqa: E402

NODE = "finger_sim.ros.node"
PD = "finger_sim.ros.pd_controller"
DT_NS = 1_000_000
SETPOINT = 0.8  # rad: a step from rest, so the loop moves the finger
STEPS = 600  # states compared between the two runs
#: Generous: a loaded machine must never make the controller miss it (the runs would differ).
LOCKSTEP_TIMEOUT_S = 30.0
#: A busy process that competes for the cores during the runs.
BURN = "import time\nend = time.monotonic() + 300\nwhile time.monotonic() < end: pass\n"
RELIABLE = QoSProfile(depth=1000)
#: lockstep_timeout of the silent-controller test, wall s: this test's own answers (a Python callback in a
#: process spun only while it waits) must come within it, also on a loaded machine (0.1 s did not, always)
SILENCE_TIMEOUT_S = 2.0


def namespace(tag: str) -> str:
    return f"/lockstep_{os.getpid()}_{tag}"


def read_log(folder: Path) -> list[tuple[str, object]]:
    """(topic, message) of the one log in `folder`, by rosbags."""
    from rosbags.highlevel import AnyReader

    (path,) = folder.glob("*.mcap")
    with AnyReader([path]) as reader:
        return [(c.topic, reader.deserialize(raw, c.msgtype)) for c, _, raw in reader.messages()]


def states_of(log: list[tuple[str, object]], ns: str) -> list[tuple[int, tuple, tuple, tuple]]:
    return [(stamp(m), tuple(m.position), tuple(m.velocity), tuple(m.effort)) for t, m in log
            if t == f"{ns}/joint_states"]


def last_values(log: list[tuple[str, object]]) -> dict[str, str]:
    (status,) = [m for t, m in log if t == "/diagnostics"][-1].status
    return {kv.key: kv.value for kv in status.values}


def start_closed_loop(launcher, ros_client, tag: str) -> tuple:
    """The PD controller and a lockstep node, started; (the node, the /diagnostics this client gets).

    Both run in a namespace of their own (this test process's id and `tag`), so that no other
    node on the DDS domain (another checkout's run, the other run here) can answer or be counted."""
    ns = namespace(tag)
    remap = ["-r", f"__ns:={ns}"]
    launcher.node(PD, dict(setpoint=SETPOINT), name=f"pd_{tag}", ros_args=remap)
    node = launcher.node(NODE, dict(lockstep=True, lockstep_timeout=LOCKSTEP_TIMEOUT_S, realtime_factor=0.0,
                                    command_qos="reliable", record_dir=f"bags_{tag}", marker_rate_hz=0.0),
                         name=f"node_{tag}", ros_args=remap)
    return node, ros_client.collect(DiagnosticArray, "/diagnostics", RELIABLE)


def closed_loop_log(launcher, ros_client, tag: str, node, diagnostics: list) -> list[tuple[str, object]]:
    """Once the node of run `tag` reported /diagnostics (about 1 Hz of wall time) at step STEPS or
    later, so that its log's last report covers those steps: the node stopped, its log. (The states
    themselves are the log's; subscribing to them, at thousands a second from each run, kept this
    client so busy on a loaded machine that the report was not taken within 30 s.)"""
    def reported() -> bool:
        return any(s.name.startswith(f"{namespace(tag)}/") and int(conversions.parse_values(s).get("step", -1)) >= STEPS
                   for d in list(diagnostics) for s in d.status)

    ros_client.wait_for(reported, f"/diagnostics of {tag} at step {STEPS} or later", 120.0)
    status = node.stop()
    assert status == 0, f"exit status {status}:\n{node.output()}"
    return read_log(launcher.tmp / f"bags_{tag}")


def test_two_lockstep_runs_of_the_pd_controller_are_identical_under_load(launcher, ros_client):
    """The two closed loops run at the same time, beside a busy process: each loads the other too."""
    launcher.start([sys.executable, "-c", BURN], "burn")
    runs = {tag: start_closed_loop(launcher, ros_client, tag) for tag in ("a", "b")}
    first, second = (closed_loop_log(launcher, ros_client, tag, *runs[tag]) for tag in ("a", "b"))

    a, b = states_of(first, namespace("a")), states_of(second, namespace("b"))
    assert len(a) > STEPS and len(b) > STEPS
    assert [s[0] for s in a[:STEPS]] == [n * DT_NS for n in range(STEPS)]  # every step, each state once
    assert a[:STEPS] == b[:STEPS]  # bit for bit
    # each command answered state k and acted over step k → k+1: the applied mcp effort of state
    # k+1 is the PD law of state k
    for (_, pos, vel, _), (_, _, _, effort) in zip(a[:STEPS], a[1:STEPS]):
        assert effort[0] == pd_torque(SETPOINT, pos[0], vel[0], KP, KD, MAX_TORQUE)
    assert len([m for t, m in first if t == f"{namespace('a')}/motor_torque"]) >= STEPS
    assert last_values(first)["lockstep_timeouts"] == "0"


def test_joint_command_stamps_and_a_silent_controller(launcher, ros_client):
    """joint_command answers the state whose stamp it carries; a stale stamp is refused; once the
    controller stops answering, each state waits lockstep_timeout, then the held command goes on,
    /diagnostics counts it and turns WARN, and ~/command_log records each held step."""
    answers = {0: 0.01, 1: 0.02, 2: 0.03}  # state index → the effort answered
    # the first answer waits for its publisher to match the node's subscription, as a controller's does:
    # the node can see this publisher (and send state 0) before the publisher knows the node's subscription
    pub = AnswerPublisher(ros_client.publisher(JointState, "/joint_command", RELIABLE))
    states: list[JointState] = []

    def answer(msg: JointState) -> None:
        states.append(msg)
        k = stamp(msg) // DT_NS
        if k in answers:
            pub.publish(JointState(header=msg.header, name=["mcp_joint"], effort=[answers[k]]))
        if k == 3:  # an answer to state 0 arrives late: stale, refused
            pub.publish(JointState(header=states[0].header, name=["mcp_joint"], effort=[0.04]))

    ros_client.node.create_subscription(JointState, "/joint_states", answer, RELIABLE)
    events = ros_client.collect(DiagnosticStatus, "/finger_node/command_log", RELIABLE)
    diagnostics = ros_client.collect(DiagnosticArray, "/diagnostics", RELIABLE)
    launcher.node(NODE, dict(lockstep=True, lockstep_timeout=SILENCE_TIMEOUT_S, realtime_factor=0.0, command_qos="reliable",
                             command_timeout=0.0))

    def timeouts() -> int:
        for d in reversed(diagnostics):
            v = conversions.parse_values(d.status[0])
            return int(v["lockstep_timeouts"]) if d.status[0].level == DiagnosticStatus.WARN else 0
        return 0

    ros_client.wait_for(lambda: timeouts() >= 3, "lockstep timeouts in /diagnostics", 60.0)
    by_step = {stamp(m) // DT_NS: m for m in states}
    assert [by_step[k].effort[0] for k in range(1, 5)] == [0.01, 0.02, 0.03, 0.03]  # state k+1 shows answer k
    assert all(by_step[k].effort[0] == 0.03 for k in by_step if k >= 4)  # held through the timeouts
    refused = [conversions.parse_values(e) for e in events if conversions.parse_values(e)["event"] == "refused"]
    assert len(refused) == 1 and "lockstep" in refused[0]["reason"] and refused[0]["requested"] == "0.04"
    # ~/command_log (and so the log) names every held step: state k's missing answer, the torque held over step k
    held = lambda: [(int(v["step"]), float(v["torque"])) for v in map(conversions.parse_values, list(events))  # noqa: E731
                    if v["event"] == "lockstep_timeout"]
    ros_client.wait_for(lambda: len(held()) >= 3, "three lockstep_timeout events on ~/command_log")
    assert held()[:3] == [(3, 0.03), (4, 0.03), (5, 0.03)]


def test_a_lockstep_hand_waits_for_every_fingers_controller(launcher, ros_client):
    """finger_hand in lockstep with one PD controller per finger (its namespace, its setpoint):
    every finger's state k+1 shows the torque its own controller computed from its state k. The
    states are the node's log's (every one): the controllers answer within milliseconds, so the run
    can be hundreds of states on before this client's late-matched subscription gets its first."""
    fingers = {"index": 0.4, "middle": 0.8, "ring": 1.2}  # name → setpoint, rad
    for name, setpoint in fingers.items():
        launcher.node(PD, dict(setpoint=setpoint, joint=f"{name}_mcp_joint"), name=f"pd_{name}",
                      ros_args=["-r", f"__ns:=/{name}"])
    states = {name: ros_client.collect(JointState, f"/{name}/joint_states", RELIABLE) for name in fingers}
    node = launcher.node("finger_sim.ros.hand", dict(lockstep=True, lockstep_timeout=LOCKSTEP_TIMEOUT_S,
                                                     realtime_factor=0.0, command_qos="reliable", marker_rate_hz=0.0,
                                                     record_dir="bags_hand"))
    steps = 200
    ros_client.wait_for(lambda: all(s and stamp(s[-1]) >= steps * DT_NS for s in states.values()),
                        f"{steps} lockstep states of every finger", 120.0)
    status = node.stop()
    assert status == 0, f"exit status {status}:\n{node.output()}"
    log = read_log(launcher.tmp / "bags_hand")
    for name, setpoint in fingers.items():
        logged = states_of(log, f"/{name}")
        assert [s[0] for s in logged[:steps + 1]] == [n * DT_NS for n in range(steps + 1)], name  # each state once
        for (_, pos, vel, _), (_, _, _, effort) in zip(logged[:steps], logged[1:steps + 1]):
            assert effort[0] == pd_torque(setpoint, pos[0], vel[0], KP, KD, MAX_TORQUE), name
