"""/clock while the node stands still (issue 19, item 9): a use_sim_time client that subscribes
after the start of a paused node reads the (unchanging) sim time, and the repeats never go back.

Reference: the node's own answer to ~/step (its clock=, in s) and the 1 kHz step grid.
"""

from __future__ import annotations

from pathlib import Path

import pytest

rclpy = pytest.importorskip("rclpy")

from rclpy.qos import QoSProfile, ReliabilityPolicy  # noqa: E402
from rosgraph_msgs.msg import Clock  # noqa: E402
from std_srvs.srv import Trigger  # noqa: E402

from finger_sim.ros import conversions  # noqa: E402

NODE = "finger_sim.ros.node"
PAPER = Path(__file__).resolve().parents[2] / "config" / "paper_flexion.yaml"
DT_NS = 1_000_000
STEPS = 5
#: rclcpp::ClockQoS, as rclpy's TimeSource subscribes.
CLOCK_QOS = QoSProfile(depth=1_000, reliability=ReliabilityPolicy.BEST_EFFORT)
REPEATS = 3  # ticks of the same stamp that show the clock is published while paused


def ticks(clocks: list) -> list[int]:
    return [conversions.from_time(c.clock) for c in clocks]


def test_a_paused_node_keeps_publishing_its_clock(launcher, ros_client):
    launcher.node(NODE, dict(scene=str(PAPER), start_paused=True, steps_per_trigger=STEPS, record=False))
    # service up: the node has started and published its one tick at t = 0, before we subscribe
    ros_client.wait_for(lambda: ros_client.node.count_publishers("/clock"), "the node's /clock publisher")
    clocks = ros_client.collect(Clock, "/clock", CLOCK_QOS)
    ros_client.wait_for(lambda: ticks(clocks).count(0) >= REPEATS, f"{REPEATS} ticks at t = 0 while paused")
    assert set(ticks(clocks)) == {0}

    answer = ros_client.call(Trigger, "/finger_node/step")
    assert answer.success, answer.message
    clock_ns = round(float(answer.message.split("clock=")[1].split()[0]) * 1e9)
    assert clock_ns == STEPS * DT_NS
    ros_client.wait_for(lambda: ticks(clocks).count(clock_ns) >= REPEATS, f"{REPEATS} ticks at the stepped time")
    seen = ticks(clocks)
    assert all(b >= a for a, b in zip(seen, seen[1:]))
    assert set(seen) <= set(range(0, clock_ns + 1, DT_NS))
