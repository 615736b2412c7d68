"""The stepping node's executor: spin until the run is done, SIGINT/SIGTERM or the context ends.

Two executors, chosen by the run's `executor` parameter (runtime.parameters.Executor):

- `events` (default): rclpy.experimental.EventsExecutor. Each message, service request or
  timer is dispatched from C++ as it arrives, without rebuilding a wait set and walking every
  entity in Python: a 1 kHz command subscription costs about a quarter of the CPU it costs on
  SingleThreadedExecutor (docs/node_performance.md). It refuses guard conditions and installs
  its own SIGINT/SIGTERM handler (rclpy's is bypassed); both ends of a run reach it anyway:
  `spin_until_future_complete` adds ONE done-callback to `done` (stopping its event loop from
  whichever thread completes it), and a signal stops the loop and shuts the context down.
- `single`: rclpy's SingleThreadedExecutor, spun with `spin_once` until one guard condition,
  triggered when `done` completes, wakes it (rclpy's spin_until_future_complete would add a
  closure to `done` on every wake-up, a leak at 1 kHz). Kept for a node that owns guard
  conditions of its own, and to measure the events executor against.

Both keep nothing from one wake-up to the next (test/ros/test_spin.py).
"""

from __future__ import annotations

import contextlib

from rclpy.exceptions import InvalidHandle
from rclpy.executors import SingleThreadedExecutor
from rclpy.experimental import EventsExecutor
from rclpy.node import Node
from rclpy.task import Future

from finger_sim.runtime.parameters import Executor

__all__ = ["spin_until_done"]


def spin_until_done(node: Node, done: Future, executor: Executor = Executor.EVENTS) -> None:
    """Run `node`'s callbacks until `done` completes or the context shuts down (SIGINT, SIGTERM)."""
    if executor is Executor.EVENTS:
        _spin_events(node, done)
    else:
        _spin_single(node, done)


def _spin_events(node: Node, done: Future) -> None:
    events = EventsExecutor(context=node.context)
    events.add_node(node)
    try:
        # one blocking call for the whole run: its single done-callback stops the loop (also when
        # `done` is already complete); a signal stops it too and shuts the context down on return
        events.spin_until_future_complete(done)
    finally:
        events.shutdown(timeout_sec=0)


def _spin_single(node: Node, done: Future) -> None:
    single = SingleThreadedExecutor(context=node.context)
    finished = node.create_guard_condition(lambda: None)  # destroyed with the node

    def wake(_: Future) -> None:  # once, in the thread that completes `done` (a Future without executor)
        with contextlib.suppress(InvalidHandle):  # the node is already destroyed: nobody waits
            finished.trigger()

    done.add_done_callback(wake)
    single.add_node(node)
    try:
        while node.context.ok() and not done.done():
            single.spin_once()
    finally:
        single.shutdown(timeout_sec=0)
