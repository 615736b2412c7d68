"""Parameters of the ROS nodes as one table each: name, default, meaning, range, choices.

The table is the one source of truth: finger_sim.ros.parameters declares it with rclpy
(descriptors carry the description, range and read-only flag, so `ros2 param describe`
shows them), and `check()` validates values without ROS (types as ROS types them: a float
parameter needs a decimal point; ranges inclusive; choices). Cross-parameter rules of the
node are in `NodeSettings.from_values`.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, fields
from enum import Enum
from typing import Any

from finger_sim.errors import FingerSimError

Value = bool | int | float | str


class ParameterError(FingerSimError, ValueError):
    """A ROS parameter has the wrong type, is out of its range or not one of its choices."""

    def __init__(self, name: str, problem: str) -> None:
        self.name = name
        hint = " (a float parameter needs a decimal point, e.g. 500.0)" if "type" in problem.lower() else ""
        super().__init__(f"parameter '{name}': {problem}{hint}")

    @classmethod
    def expected(cls, name: str, allowed: str, got: Any) -> ParameterError:
        return cls(name, f"expected {allowed}, got {got!r}")


@dataclass(frozen=True)
class Param:
    """One parameter: its default fixes its type; range is inclusive; read_only: set at start only."""

    name: str
    default: Value
    description: str
    range: tuple[float, float] | None = None
    choices: tuple[str, ...] | None = None
    read_only: bool = True

    def check(self, value: Any) -> Value:
        """`value` if it has this parameter's type and lies in its range and choices, else ParameterError."""
        kind = type(self.default)
        if type(value) is not kind:
            raise ParameterError.expected(self.name, f"type {kind.__name__}", value)
        if self.range is not None and not self.range[0] <= value <= self.range[1]:
            raise ParameterError.expected(self.name, f"a value in [{self.range[0]:g}, {self.range[1]:g}]", value)
        if self.choices is not None and value not in self.choices:
            raise ParameterError.expected(self.name, f"one of {list(self.choices)}", value)
        return value


def check_all(table: tuple[Param, ...], values: Mapping[str, Any]) -> dict[str, Value]:
    """Every parameter of `table` checked; missing ones take their default; unknown names refused."""
    known = {p.name for p in table}
    for name in values:
        if name not in known:
            raise ParameterError.expected(name, f"one of {sorted(known)}", "an unknown parameter")
    return {p.name: p.check(values.get(p.name, p.default)) for p in table}


class TorqueSource(Enum):
    TOPIC = "topic"
    SCENE = "scene"


class CommandQos(Enum):
    """QoS of the command subscriptions."""

    SYSTEM_DEFAULT = "system_default"  # rclcpp::SystemDefaultsQoS(), as ros2_control's controllers
    RELIABLE = "reliable"  # reliable, keep last command_depth: no command lost to DDS


#: finger_node's parameters, their defaults (as in config/finger_node.yaml), meanings and ranges.
#: All are read once at start (read-only): changing one means restarting the node.
NODE_PARAMETERS = (
    Param("scene", "paper_flexion", "scene file path, or the name of an installed scene (share/finger_sim/config/<name>.yaml)"),
    Param("physics_rate_hz", 1000.0, "physics steps per second of sim time; dt = 1/rate replaces the scene's dt", (1.0, 100000.0)),
    Param("publish_rate_hz", 0.0, "joint_states, fingertip_pose and /clock per second of sim time; 0 = every step", (0.0, 100000.0)),
    Param("marker_rate_hz", 30.0, "finger_markers per second of sim time; 0 = none", (0.0, 100000.0)),
    Param("realtime_factor", 1.0, "sim seconds per wall second; 0 = as fast as possible", (0.0, 1000.0)),
    Param("torque_source", TorqueSource.TOPIC.value, "'topic' (motor_torque, effort_commands) or 'scene' (the scene's scripted torque)",
          choices=tuple(t.value for t in TorqueSource)),
    Param("exit_at_end", True, "with torque_source 'scene': exit with status 0 at the scene's duration"),
    Param("max_torque", 0.05, "commands are saturated to ±max_torque, N·m", (0.0, 100.0)),
    Param("command_timeout", 0.5, "sim seconds without a command after which the torque falls to 0; 0 = hold forever", (0.0, 3600.0)),
    Param("command_qos", CommandQos.SYSTEM_DEFAULT.value,
          "'system_default' (best effort, keep last 1 with Fast DDS, as ros2_control) or 'reliable' (keep last command_depth)",
          choices=tuple(q.value for q in CommandQos)),
    Param("command_depth", 1000, "history depth of the command subscriptions with command_qos 'reliable'", (1, 100_000)),
    Param("frame_prefix", "", "prefix of the frame id (<prefix>finger_base) and of the joint names"),
    Param("steps_per_trigger", 1, "steps that one ~/step call advances while paused", (1, 1_000_000)),
    Param("start_paused", False, "start paused; ~/pause false or ~/step to advance"),
    Param("publish_clock", True, "publish /clock; with several fingers let exactly one node do it"),
    Param("record", True, "log every message the node publishes and receives to <record_dir>/<scene>_<UTC start>.mcap"),
    Param("record_dir", "bags", "folder of the MCAP logs (created if missing)"),
    Param("record_chunk_interval", 0.5, "sim seconds after which the log's open chunk is closed: what a kill -9 can lose", (0.01, 60.0)),
)


@dataclass(frozen=True)
class NodeSettings:
    """finger_node's parameters, validated, SI."""

    scene: str
    physics_rate_hz: float
    publish_rate_hz: float
    marker_rate_hz: float
    realtime_factor: float
    torque_source: TorqueSource
    exit_at_end: bool
    max_torque: float
    command_timeout: float
    command_qos: CommandQos
    command_depth: int
    frame_prefix: str
    steps_per_trigger: int
    start_paused: bool
    publish_clock: bool
    record: bool
    record_dir: str
    record_chunk_interval: float

    @classmethod
    def from_values(cls, values: Mapping[str, Any]) -> NodeSettings:
        """Check every value against NODE_PARAMETERS and the rules between them; ParameterError if one fails."""
        v: dict[str, Any] = check_all(NODE_PARAMETERS, values)
        if v["publish_rate_hz"] > v["physics_rate_hz"]:
            raise ParameterError.expected("publish_rate_hz", f"0 or a rate ≤ physics_rate_hz ({v['physics_rate_hz']:g} Hz)",
                                          v["publish_rate_hz"])
        if any(c.isspace() for c in v["frame_prefix"]):
            raise ParameterError.expected("frame_prefix", "a prefix without white space", v["frame_prefix"])
        v["torque_source"] = TorqueSource(v["torque_source"])
        v["command_qos"] = CommandQos(v["command_qos"])
        return cls(**v)

    def to_values(self) -> dict[str, Value]:
        """The parameters as ROS values (enums as their strings), e.g. for the log's metadata."""
        return {f.name: (x.value if isinstance(x := getattr(self, f.name), Enum) else x) for f in fields(self)}
