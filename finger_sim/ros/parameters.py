"""Declare a parameter table (finger_sim.runtime.parameters) on an rclpy node, once, with descriptors.

An integer given for a float parameter (`physics_rate_hz:=1000`, `ros2 param set ... 2`) is
taken as that float, as rclcpp's users expect; every other type mismatch is refused.
"""

from __future__ import annotations

from typing import Any

from rcl_interfaces.msg import FloatingPointRange, IntegerRange, ParameterDescriptor
from rclpy.exceptions import InvalidParameterTypeException, ParameterException
from rclpy.node import Node
from rclpy.parameter import Parameter

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
    floats = {p.name for p in table if isinstance(p.default, float)}
    node.add_pre_set_parameters_callback(lambda params: [_as_float(q) if q.name in floats else q for q in params])
    values = {}
    for p in table:
        try:
            try:
                values[p.name] = node.declare_parameter(p.name, p.default, descriptor(p)).value
            except InvalidParameterTypeException:
                # rclpy applies no pre-set callback to overrides: an int override is read here
                override = node._parameter_overrides.get(p.name)  # noqa: SLF001 - no public accessor
                if p.name not in floats or override is None or _as_float(override) is override:
                    raise
                values[p.name] = node.declare_parameter(p.name, float(override.value), descriptor(p),
                                                        ignore_override=True).value
        except ParameterException as exc:  # a wrong type, or out of the descriptor's range
            raise ParameterError(p.name, str(exc).removesuffix(f": {p.name}")) from None
    return values


def _as_float(param: Parameter) -> Parameter:
    """An integer parameter as the same float; any other parameter unchanged."""
    if param.type_ is Parameter.Type.INTEGER:
        return Parameter(param.name, Parameter.Type.DOUBLE, float(param.value))
    return param
