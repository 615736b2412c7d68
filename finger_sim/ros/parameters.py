"""Declare a parameter table (finger_sim.runtime.parameters) on an rclpy node, once, with descriptors."""

from __future__ import annotations

from typing import Any

from rcl_interfaces.msg import FloatingPointRange, IntegerRange, ParameterDescriptor
from rclpy.exceptions import ParameterException
from rclpy.node import Node

from finger_sim.runtime.parameters import Param, ParameterError


def descriptor(p: Param) -> ParameterDescriptor:
    """The ROS descriptor of `p`: its description (with its choices), range and read-only flag."""
    text = p.description if p.choices is None else f"{p.description}; one of {list(p.choices)}"
    d = ParameterDescriptor(description=text, read_only=p.read_only)
    if p.range is not None and isinstance(p.default, float):
        d.floating_point_range = [FloatingPointRange(from_value=p.range[0], to_value=p.range[1], step=0.0)]
    elif p.range is not None and isinstance(p.default, int) and not isinstance(p.default, bool):
        d.integer_range = [IntegerRange(from_value=int(p.range[0]), to_value=int(p.range[1]), step=1)]
    return d


def declare(node: Node, table: tuple[Param, ...]) -> dict[str, Any]:
    """Declare every parameter of `table` on `node`; their values (overrides applied).

    rclpy checks the type and range of an override against the descriptor; its refusal
    becomes a ParameterError naming the parameter.
    """
    values = {}
    for p in table:
        try:
            values[p.name] = node.declare_parameter(p.name, p.default, descriptor(p)).value
        except ParameterException as exc:  # a wrong type, or out of the descriptor's range
            raise ParameterError(p.name, str(exc).removesuffix(f": {p.name}")) from None
    return values
