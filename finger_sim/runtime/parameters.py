"""Parameters of the ROS nodes as one table each: name, default, meaning, range, choices.

The table is the one source of truth: finger_sim.ros.parameters declares it with rclpy
(descriptors carry the description, range and read-only flag, so `ros2 param describe`
shows them), and `check()` validates values without ROS (types as ROS types them, except that
an integer is taken for a float parameter, as 1000 for 1000.0; ranges inclusive; choices). Cross-parameter rules are in
`RunSettings.from_values` (and its subclasses' `_rules`).

Most parameters are read once at start (read-only). RUNTIME_PARAMETERS (max_torque,
command_timeout, realtime_factor, publish_rate_hz) may be set while running: `with_change`
checks a new value against the same table and rules, and the node applies it from the next step.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, fields
from enum import Enum
from typing import Any, ClassVar, Self

from finger_sim.errors import FingerSimError
from finger_sim.runtime.pacing import CATCHUP_LIMIT_S

Value = bool | int | float | str


class ParameterError(FingerSimError, ValueError):
    """A ROS parameter has the wrong type, is out of its range or not one of its choices."""

    def __init__(self, name: str, problem: str) -> None:
        self.name = name
        super().__init__(f"parameter '{name}': {problem}")

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
        if kind is float and type(value) is int:  # physics_rate_hz:=1000 means 1000.0
            value = float(value)
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


class Executor(Enum):
    """The rclpy executor that runs the node's callbacks (finger_sim.ros.spin)."""

    EVENTS = "events"  # rclpy.experimental.EventsExecutor: callbacks dispatched from C++ as they arrive
    SINGLE = "single"  # rclpy's SingleThreadedExecutor: a wait set rebuilt and walked in Python per wake-up


class CommandQos(Enum):
    """QoS of the command subscriptions."""

    SYSTEM_DEFAULT = "system_default"  # rclcpp::SystemDefaultsQoS(), as ros2_control's controllers
    RELIABLE = "reliable"  # reliable, keep last command_depth: no command lost to DDS


#: The scene of a finger_node whose `scene` parameter is empty, by torque_source: the live
#: default (MCP stops, damping, no scripted input) for commands, the paper's run for its script.
DEFAULT_SCENES = {TorqueSource.TOPIC: "finger_default", TorqueSource.SCENE: "paper_flexion"}

#: The parameters every stepping run has (finger_node and finger_hand), their defaults (as in
#: config/finger_node.yaml), meanings and ranges.
RUN_PARAMETERS = (
    Param("physics_rate_hz", 1000.0, "physics steps per second of sim time; dt = 1/rate replaces the scene's dt", (1.0, 100000.0)),
    Param("publish_rate_hz", 0.0, "joint_states, fingertip_pose and /clock per second of sim time; 0 = every step "
          "(settable while running)", (0.0, 100000.0), read_only=False),
    Param("catchup_limit", CATCHUP_LIMIT_S, "real time: wall seconds of backlog (a stall of the node) run in one burst to catch "
          "up; a longer backlog is dropped and counted (dropped_steps in /diagnostics), sim time then slips", (0.0, 10.0)),
    Param("marker_rate_hz", 30.0, "finger_markers per second of sim time; 0 = none", (0.0, 100000.0)),
    Param("realtime_factor", 1.0, "sim seconds per wall second; 0 = as fast as possible (settable while running)",
          (0.0, 1000.0), read_only=False),
    Param("torque_source", TorqueSource.TOPIC.value,
          "'topic' (motor_torque, effort_commands, joint_command) or 'scene' (the scene's scripted torque)",
          choices=tuple(t.value for t in TorqueSource)),
    Param("exit_at_end", True, "with torque_source 'scene': exit with status 0 at the scene's duration"),
    Param("max_torque", 0.05, "commands are saturated to ±max_torque, N·m (settable while running)", (0.0, 100.0),
          read_only=False),
    Param("command_timeout", 0.5, "sim seconds without a command after which the torque falls to 0; 0 = hold forever "
          "(settable while running)", (0.0, 3600.0), read_only=False),
    Param("command_qos", CommandQos.SYSTEM_DEFAULT.value,
          "'system_default' (best effort, keep last 1 with Fast DDS, as ros2_control) or 'reliable' (keep last command_depth)",
          choices=tuple(q.value for q in CommandQos)),
    Param("command_depth", 1000, "history depth of the command subscriptions with command_qos 'reliable'", (1, 100_000)),
    Param("steps_per_trigger", 1, "steps that one ~/step call advances while paused", (1, 1_000_000)),
    Param("start_paused", False, "start paused; ~/pause false or ~/step to advance"),
    Param("publish_clock", True, "publish /clock; with several fingers use finger_hand (one clock), or let exactly one node do it"),
    Param("record", True, "log every message the node publishes and receives to <record_dir>/<scene>_<UTC start>.mcap"),
    Param("record_dir", "bags", "folder of the MCAP logs (created if missing)"),
    Param("record_chunk_interval", 0.5, "sim seconds after which the log's open chunk is closed (and after 1 s of wall time, "
          "also while paused): what a kill -9 can lose", (0.01, 60.0)),
    Param("record_queue_size", 10_000, "messages that may wait for the log's writer; beyond it a real-time run drops "
          "(counted in the log and /diagnostics) and a run as fast as possible waits", (1, 10_000_000)),
    Param("lockstep", False, "wait for the controller: step k+1 only when the command answering the state of step k "
          "has arrived (joint_command: header.stamp = that state's stamp; motor_torque, effort_commands: the first "
          "command after it), or after lockstep_timeout"),
    Param("lockstep_timeout", 1.0, "with lockstep: wall seconds to wait for a command before stepping on with the held "
          "one (counted in /diagnostics)", (0.001, 3600.0)),
    Param("record_time", "sim", "log time of the MCAP messages: 'sim' (sim time from 0, as /clock) or 'wall_start' "
          "(Unix time at the node's start + sim time); header stamps are sim time either way", choices=("sim", "wall_start")),
    Param("executor", Executor.EVENTS.value, "rclpy executor of the node's callbacks: 'events' (rclpy.experimental.EventsExecutor, "
          "about a quarter of the CPU per received message) or 'single' (SingleThreadedExecutor)",
          choices=tuple(e.value for e in Executor)),
)
#: finger_node's parameters: the run's, its scene and frame prefix.
NODE_PARAMETERS = (
    Param("scene", "", "scene file path, or the name of an installed scene (share/finger_sim/config/<name>.yaml); "
          "empty: finger_default with torque_source 'topic', paper_flexion with 'scene'"),
    *RUN_PARAMETERS,
    Param("frame_prefix", "", "prefix of the frame id (<prefix>finger_base) and of the joint names"),
)
#: finger_hand's parameters: the run's and the hand file.
HAND_PARAMETERS = (
    Param("hand", "three_fingers", "hand file path, or the name of an installed one (share/finger_sim/config/hands/<name>.yaml): "
          "its fingers' names, scenes, base poses and frame prefixes"),
    *RUN_PARAMETERS,
)
#: The parameters that may be set while running (the others are read-only).
RUNTIME_PARAMETERS = tuple(p.name for p in RUN_PARAMETERS if not p.read_only)


def _no_space(name: str, value: str) -> None:
    if any(c.isspace() for c in value):
        raise ParameterError.expected(name, "a prefix without white space", value)


@dataclass(frozen=True)
class RunSettings:
    """The parameters of a stepping run (RUN_PARAMETERS), validated, SI."""

    TABLE: ClassVar[tuple[Param, ...]] = RUN_PARAMETERS

    physics_rate_hz: float
    publish_rate_hz: float
    catchup_limit: float
    marker_rate_hz: float
    realtime_factor: float
    torque_source: TorqueSource
    exit_at_end: bool
    max_torque: float
    command_timeout: float
    command_qos: CommandQos
    command_depth: int
    steps_per_trigger: int
    start_paused: bool
    publish_clock: bool
    record: bool
    record_dir: str
    record_chunk_interval: float
    record_queue_size: int
    lockstep: bool
    lockstep_timeout: float
    record_time: str
    executor: Executor

    @classmethod
    def from_values(cls, values: Mapping[str, Any]) -> Self:
        """Check every value against the class's TABLE and the rules between them; ParameterError if one fails."""
        v: dict[str, Any] = check_all(cls.TABLE, values)
        if v["publish_rate_hz"] > v["physics_rate_hz"]:
            raise ParameterError.expected("publish_rate_hz", f"0 or a rate ≤ physics_rate_hz ({v['physics_rate_hz']:g} Hz)",
                                          v["publish_rate_hz"])
        v["torque_source"] = TorqueSource(v["torque_source"])
        if v["lockstep"] and v["torque_source"] is TorqueSource.SCENE:
            raise ParameterError.expected("lockstep", "false with torque_source 'scene' (no controller to wait for)", True)
        v["command_qos"] = CommandQos(v["command_qos"])
        v["executor"] = Executor(v["executor"])
        cls._rules(v)
        return cls(**v)

    @classmethod
    def _rules(cls, v: dict[str, Any]) -> None:
        """A subclass's own checks and resolutions of the values (in place)."""

    def with_change(self, name: str, value: Any) -> Self:
        """These settings with `name` set to `value` while running; ParameterError if `name` is
        read-only or the value fails the table or the rules."""
        if name not in RUNTIME_PARAMETERS:
            raise ParameterError.expected(name, f"one of {list(RUNTIME_PARAMETERS)} (the others are read-only)", value)
        return self.from_values({**self.to_values(), name: value})

    def to_values(self) -> dict[str, Value]:
        """The parameters as ROS values (enums as their strings), e.g. for the log's metadata."""
        return {f.name: (x.value if isinstance(x := getattr(self, f.name), Enum) else x) for f in fields(self)}


@dataclass(frozen=True)
class NodeSettings(RunSettings):
    """finger_node's parameters: the run's, its scene (resolved: never empty) and frame prefix."""

    TABLE: ClassVar[tuple[Param, ...]] = NODE_PARAMETERS

    scene: str
    frame_prefix: str

    @classmethod
    def _rules(cls, v: dict[str, Any]) -> None:
        _no_space("frame_prefix", v["frame_prefix"])
        if not v["scene"]:
            v["scene"] = DEFAULT_SCENES[v["torque_source"]]


@dataclass(frozen=True)
class HandSettings(RunSettings):
    """finger_hand's parameters: the run's and the hand file."""

    TABLE: ClassVar[tuple[Param, ...]] = HAND_PARAMETERS

    hand: str
