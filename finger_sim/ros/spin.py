"""The stepping node's executor: spin until the run is done, SIGINT/SIGTERM or the context ends.

Two executors, chosen by the run's `executor` parameter (runtime.parameters.Executor):

- `events` (default): rclpy.experimental.EventsExecutor. Each message, service request or
  timer is dispatched from C++ as it arrives, without rebuilding a wait set and walking every
  entity in Python: a 1 kHz command subscription costs about a quarter of the CPU it costs on
  SingleThreadedExecutor (docs/node_performance.md). It refuses guard conditions; its own
  SIGINT/SIGTERM handler (asio's, replacing rclpy's) did not end a node's spin, and its blocking
  spin() busy-waited holding the lock that shutdown() needs. So it spins in a thread of its own,
  `spin_once` slices of at most SPIN_SLICE_S, while the main thread waits in Python for the run's
  end with Python's handlers on SIGINT and SIGTERM: a signal raises KeyboardInterrupt there at
  once, the spin thread sees the end within a slice, and the executor is shut down.
- `single`: rclpy's SingleThreadedExecutor, spun with `spin_once` until one guard condition,
  triggered when `done` completes, wakes it (rclpy's spin_until_future_complete would add a
  closure to `done` on every wake-up, a leak at 1 kHz). Kept for a node that owns guard
  conditions of its own, and to measure the events executor against.

Neither keeps anything from one wake-up to the next (test/ros/test_spin.py checks `single`;
`events` adds one done-callback per run and none per wake-up).
"""

from __future__ import annotations

import contextlib
import signal
import threading

from rclpy.exceptions import InvalidHandle
from rclpy.executors import SingleThreadedExecutor
from rclpy.experimental import EventsExecutor
from rclpy.node import Node
from rclpy.task import Future

from finger_sim.log.cpu_clocks import name_os_thread
from finger_sim.runtime.parameters import Executor

__all__ = ["EXIT_SIGNALS", "spin_until_done"]

#: The signals that end a run cleanly (log closed): Ctrl-C and a supervisor's stop.
EXIT_SIGNALS = (signal.SIGINT, signal.SIGTERM)
#: Wall seconds granted to the executor's loop to stop once the run is over.
SHUTDOWN_TIMEOUT_S = 5.0
#: Longest wall time, s, one spin_once of the events executor waits: how soon its thread sees the
#: end of the run. (Its blocking spin() busy-waited in the asio loop and starved shutdown's lock.)
SPIN_SLICE_S = 0.1


def spin_until_done(node: Node, done: Future, executor: Executor = Executor.EVENTS) -> None:
    """Run `node`'s callbacks until `done` completes or the context shuts down (SIGINT, SIGTERM)."""
    if executor is Executor.EVENTS:
        _spin_events(node, done)
    else:
        _spin_single(node, done)


def _spin_events(node: Node, done: Future) -> None:
    events = EventsExecutor(context=node.context)  # installs its own SIGINT/SIGTERM handler (asio) ...
    in_main = threading.current_thread() is threading.main_thread()  # only it may set signal handlers
    previous = {sig: signal.signal(sig, _interrupt) for sig in EXIT_SIGNALS} if in_main else {}  # ... replaced
    events.add_node(node)
    finished = threading.Event()
    failure: list[BaseException] = []

    def spin() -> None:  # the executor's thread; also ends on the context's shutdown or a callback's exception
        name_os_thread("executor")  # as the operating system shows it (`top -H`)
        try:
            while not finished.is_set() and node.context.ok():
                events.spin_once(timeout_sec=SPIN_SLICE_S)
        except BaseException as exc:  # handed to the main thread  # noqa: BLE001
            failure.append(exc)
        finally:
            finished.set()

    spinner = threading.Thread(target=spin, name="executor", daemon=True)
    done.add_done_callback(lambda _: finished.set())
    spinner.start()
    try:
        finished.wait()  # in Python, where a signal's handler runs at once (never inside the C++ loop)
    finally:
        finished.set()
        spinner.join(SHUTDOWN_TIMEOUT_S)
        events.shutdown(timeout_sec=SHUTDOWN_TIMEOUT_S)
        for sig, handler in previous.items():
            signal.signal(sig, handler)
    if failure:
        raise failure[0]


def _interrupt(signum: int, _frame: object) -> None:
    """SIGINT or SIGTERM: end the spin as Ctrl-C does (the caller's KeyboardInterrupt path)."""
    raise KeyboardInterrupt(signal.Signals(signum).name)


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
