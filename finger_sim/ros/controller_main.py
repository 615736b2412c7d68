"""What the example controllers share: the Jazzy `main()` shape (init, spin, clean shutdown) and
a command publisher whose first answer waits for the node's subscription (`AnswerPublisher`)."""

from __future__ import annotations

import time
from collections.abc import Callable
from typing import Any

import rclpy
from rclpy.executors import ExternalShutdownException
from rclpy.impl.implementation_singleton import rclpy_implementation as _rclpy
from rclpy.node import Node

from finger_sim.runtime.parameters import ParameterError

#: Exit status for a parameter that cannot start the controller.
EXIT_CONFIG = 2
#: Wall s a controller's first answer waits for a subscriber of its command topic, and the poll period.
MATCH_TIMEOUT_S = 10.0
MATCH_POLL_S = 0.002


class AnswerPublisher:
    """A command publisher whose first message waits (up to MATCH_TIMEOUT_S) until a subscription
    is matched to it. DDS discovery completes on each side apart: finger_node in lockstep sees the
    controller's publisher and sends its first state, and the controller's answer can go out before
    its publisher knows the node's subscription; a volatile message sent then is lost, and the node
    waits lockstep_timeout for it, then holds the last command (a run that does not repeat)."""

    def __init__(self, publisher: Any) -> None:
        self._publisher = publisher
        self._matched = False

    def publish(self, msg: Any) -> None:
        if not self._matched:
            deadline = time.monotonic() + MATCH_TIMEOUT_S
            while self._publisher.get_subscription_count() == 0 and time.monotonic() < deadline:
                time.sleep(MATCH_POLL_S)
            self._matched = True
        self._publisher.publish(msg)


def spin_controller(make_node: Callable[[], Node], node_name: str, args: list[str] | None = None) -> int:
    """Run the node `make_node()` builds until SIGINT/SIGTERM; 0, or EXIT_CONFIG for a bad parameter."""
    rclpy.init(args=args)
    node = None
    status = 0
    try:
        node = make_node()
        rclpy.spin(node)
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    except _rclpy.RCLError:
        if rclpy.ok():
            raise
        # SIGINT/SIGTERM shut the context down while a callback was running: a clean stop.
    except ParameterError as exc:
        rclpy.logging.get_logger(node_name).error(f"cannot start: {exc}")
        status = EXIT_CONFIG
    finally:
        if node is not None:
            node.destroy_node()
        rclpy.try_shutdown()
    return status
