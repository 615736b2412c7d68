"""The stepping node's spin on SingleThreadedExecutor (finger_sim.ros.spin, executor:=single): nothing grows per wake-up.

Reference: the number of callbacks the run's `done` future holds, and the objects the
garbage collector tracks, before and after a thousand executor wake-ups (messages received
over real DDS). rclpy Jazzy's spin_until_future_complete adds one closure to the future per
wake-up, which is how a 1 kHz controller made finger_node grow by ~0.9 GB an hour.
"""

from __future__ import annotations

import gc
import threading

import pytest

rclpy = pytest.importorskip("rclpy")

from rclpy.qos import QoSProfile  # noqa: E402
from rclpy.task import Future  # noqa: E402
from std_msgs.msg import Float64  # noqa: E402

from finger_sim.ros.spin import spin_until_done  # noqa: E402
from finger_sim.runtime.parameters import Executor  # noqa: E402

WAKE_UPS = 1000
#: Objects tracked by the gc that a thousand wake-ups may leave behind (caches, DDS
#: bookkeeping); a closure per wake-up would leave a thousand.
GC_SLACK = 100


def test_a_thousand_wake_ups_leave_nothing_behind(ros_domain, ros_client):
    ctx = ros_client.context
    node = rclpy.create_node("spun", context=ctx)
    received: list[float] = []
    node.create_subscription(Float64, "wake", lambda m: received.append(m.data), QoSProfile(depth=WAKE_UPS))
    pub = ros_client.publisher(Float64, "wake", QoSProfile(depth=WAKE_UPS))
    done = Future()
    spinner = threading.Thread(target=spin_until_done, args=(node, done, Executor.SINGLE), daemon=True)
    spinner.start()
    try:
        ros_client.wait_for(lambda: pub.get_subscription_count() > 0, "the subscription to match")
        pub.publish(Float64(data=-1.0))  # warm-up: the first wake-ups build the executor's caches
        ros_client.wait_for(lambda: received, "the warm-up message")
        gc.collect()
        callbacks_before, tracked_before = len(done._callbacks), len(gc.get_objects())
        for i in range(WAKE_UPS):
            pub.publish(Float64(data=float(i)))
            if i % 50 == 49:  # keep the executor waking up once per message, not once per burst
                ros_client.wait_for(lambda n=i: len(received) >= n + 2 - 10, "the messages to arrive")
        ros_client.wait_for(lambda: len(received) >= WAKE_UPS + 1, f"{WAKE_UPS} messages")
        gc.collect()
        callbacks_after, tracked_after = len(done._callbacks), len(gc.get_objects())
    finally:
        done.set_result(0)
        spinner.join(10.0)
    assert not spinner.is_alive(), "spin_until_done did not return once done completed"
    assert received[1:] == [float(i) for i in range(WAKE_UPS)]
    assert callbacks_after == callbacks_before == 1
    assert tracked_after - tracked_before < GC_SLACK
    node.destroy_node()
