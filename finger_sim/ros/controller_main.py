"""The Jazzy `main()` shape shared by the example controllers: init, spin, clean shutdown."""

from __future__ import annotations

from collections.abc import Callable

import rclpy
from rclpy.executors import ExternalShutdownException
from rclpy.impl.implementation_singleton import rclpy_implementation as _rclpy
from rclpy.node import Node

from finger_sim.runtime.parameters import ParameterError

#: Exit status for a parameter that cannot start the controller.
EXIT_CONFIG = 2


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
