"""What the viewer shows, read from a run: each finger's scene, states and signals.

A run is a `finger-sim simulate` CSV (either column set; its scene from `--scene`) or a
finger_node / finger_hand MCAP log (its scenes from the `finger_sim` metadata records). The
viewer is generic over the signals: every numeric CSV column and every Float64, String and
WrenchStamped topic of a finger becomes one, so columns or topics added later (a drive's
motor_current, mesh_mode, ...) are plotted without a change here.
"""

from __future__ import annotations

import csv
import math
import sys
from collections.abc import Iterable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from finger_sim import kinematics
from finger_sim.errors import FingerSimError
from finger_sim.joints import JOINT_NAMES, paper_coordinates
from finger_sim.scene import Scene

NS_PER_S = 1_000_000_000
#: CSV columns of the state in the paper's coordinates (`--columns paper`).
PAPER_ANGLES = ("theta1", "theta2", "theta3")
PAPER_RATES = ("theta1_dot", "theta2_dot", "theta3_dot")
#: CSV columns of the state as ROS joints (`--columns ros`, spec §6).
ROS_POSITIONS = ("mcp_position", "coupler_position", "pip_position")
ROS_VELOCITIES = ("mcp_velocity", "coupler_velocity", "pip_velocity")
#: Columns the linkage drawing already shows (the state and the tip pose): not plotted again.
DRAWN_COLUMNS = frozenset({*PAPER_ANGLES, *ROS_POSITIONS, "tip_x", "tip_y", "tip_z",
                           "tip_qx", "tip_qy", "tip_qz", "tip_qw", "tip_pitch"})
#: Log topics of a finger that are not signals: the state (read separately), what the drawing
#: shows already, the run's bookkeeping, grip_force_stamped (grip_force again, with its stamp).
NOT_SIGNALS = frozenset({"joint_states", "fingertip_pose", "finger_markers", "robot_description", "command_log",
                         "clock", "diagnostics", "parameter_events", "grip_force_stamped"})
FLOAT64 = "std_msgs/msg/Float64"
STRING = "std_msgs/msg/String"
WRENCH = "geometry_msgs/msg/WrenchStamped"
#: Metadata record of a finger's scene: `finger_sim` (finger_node) or `finger_sim/<name>` (finger_hand).
METADATA = "finger_sim"


@dataclass(frozen=True)
class Signal:
    """One plotted quantity: samples (t s, value) of a number, or of a mode (text)."""

    name: str
    t: np.ndarray  # s, ascending
    values: np.ndarray  # float64, or an object array of str for a mode

    @property
    def is_mode(self) -> bool:
        return self.values.dtype == object


@dataclass
class FingerRun:
    """One finger of a run: its name ("" for a single finger), scene, states and signals."""

    name: str
    scene: Scene
    t: np.ndarray  # (N,) s
    q: np.ndarray  # (N, 3) paper coordinates (θ1, θ2, θ3), rad
    v: np.ndarray  # (N, 3) rad/s
    signals: list[Signal] = field(default_factory=list)


class ViewInputError(FingerSimError):
    """A run the viewer cannot show: names the file and what is wrong."""

    def __init__(self, path: Path, problem: str) -> None:
        super().__init__(f"{path}: {problem}")


def read_run(path: Path, scene: Scene | None = None) -> list[FingerRun]:
    """The fingers of a run file: an MCAP log (by its magic bytes) or a simulate CSV.

    scene: the scene of a CSV (geometry, objects, scripted torque); None draws the default
    geometry without objects. Ignored for a log, which holds its scenes.
    """
    from mcap.writer import MCAP0_MAGIC

    with path.open("rb") as file:
        head = file.read(len(MCAP0_MAGIC))
    if head == MCAP0_MAGIC:
        return read_log(path)
    return [read_csv(path, scene or Scene(name=path.stem, objects=()))]


# -- CSV ---------------------------------------------------------------------------------------------


def read_csv(path: Path, scene: Scene) -> FingerRun:
    """A simulate/export CSV (`paper` or `ros` columns; a `# units:` first line is skipped)."""
    with path.open(newline="", encoding="utf-8") as file:
        rows = csv.reader(line for line in file if not line.startswith("#"))
        header = next(rows, None)
        if not header:
            raise ViewInputError(path, "an empty file: expected a CSV header (t, theta1, ...) or an MCAP log")
        columns: list[list[str]] = [[] for _ in header]
        for n, row in enumerate(rows, start=2):
            if len(row) != len(header):
                raise ViewInputError(path, f"row {n} has {len(row)} values, the header {len(header)} columns")
            for column, value in zip(columns, row):
                column.append(value)
    data = {name: _column(path, name, values) for name, values in zip(header, columns)}
    if "t" not in data or data["t"].dtype == object or len(data["t"]) == 0:
        raise ViewInputError(path, "expected a numeric time column 't' with at least one row")
    t = data["t"]
    if np.any(np.diff(t) < 0.0):
        raise ViewInputError(path, "column 't' goes back in time")
    if all(c in data for c in PAPER_ANGLES):
        q = np.column_stack([data[c] for c in PAPER_ANGLES])
        v = np.column_stack([data[c] for c in PAPER_RATES]) if all(c in data for c in PAPER_RATES) else np.zeros_like(q)
    elif all(c in data for c in ROS_POSITIONS):
        q, v = _from_joints(scene, np.column_stack([data[c] for c in ROS_POSITIONS]),
                            np.column_stack([data[c] for c in ROS_VELOCITIES]) if all(c in data for c in ROS_VELOCITIES)
                            else np.zeros((len(t), 3)))
    else:
        raise ViewInputError(path, f"expected the state columns {', '.join(PAPER_ANGLES)} (paper) or "
                                   f"{', '.join(ROS_POSITIONS)} (ros), got {', '.join(header)}")
    if q.dtype == object:
        raise ViewInputError(path, "the state columns must be numbers")
    signals = [Signal(name, t, values) for name, values in data.items() if name != "t" and name not in DRAWN_COLUMNS]
    if "torque" not in data and not any("voltage" in name for name in data):
        # the paper columns lack the command: the scene's scripted τ(t), N·m
        signals.insert(0, Signal("torque", t, np.array([scene.torque(s) for s in t.tolist()])))
    return FingerRun("", scene, t, q, v, signals)


def _column(path: Path, name: str, values: list[str]) -> np.ndarray:
    """Numbers as float64; a column with any non-number (a mode such as 'stuck') as text."""
    try:
        return np.array([float(s) for s in values], dtype=float)
    except ValueError:
        if name == "t":
            raise ViewInputError(path, "column 't' must be numbers (s)") from None
        return np.array([s.strip() for s in values], dtype=object)


def _from_joints(scene: Scene, positions: np.ndarray, velocities: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Paper coordinates from spec §6 joint positions and rates (finger_sim.joints)."""
    p = scene.params
    q_ext, alpha = kinematics.extended_pose(p), kinematics.distal_offset(p)
    pairs = [paper_coordinates(tuple(a), tuple(b), q_ext, alpha) for a, b in zip(positions.tolist(), velocities.tolist())]
    return (np.array([a for a, _ in pairs], dtype=float).reshape(-1, 3),
            np.array([b for _, b in pairs], dtype=float).reshape(-1, 3))


# -- MCAP --------------------------------------------------------------------------------------------


def read_log(path: Path) -> list[FingerRun]:
    """Every finger of a finger_node or finger_hand log, in the order of their metadata records."""
    from finger_sim.log import read_log as open_log
    from finger_sim.log.cdr import JointStateDecoder
    from finger_sim.run_log import JOINT_STATE_TYPE, RunLogError, RunMetadata, check_schema

    reader = open_log(path)
    if reader.truncated:  # as `export` does: the intact part is shown
        print(f"finger-sim: warning: {reader.truncation}; showing the intact part", file=sys.stderr)
    names = [n for n in reader.metadata if n == METADATA or n.startswith(METADATA + "/")]
    if not names:
        raise ViewInputError(path, f"no '{METADATA}' metadata record: not a finger_node or finger_hand log")
    runs = []
    for record in names:
        meta = RunMetadata.from_dict(reader.metadata_record(record), path)
        finger = record.removeprefix(METADATA).removeprefix("/")
        states = f"/{finger}/joint_states" if finger else _states_topic(reader.topics)
        ns = states.removesuffix("/joint_states")
        if states not in reader.topics:
            raise RunLogError(path, f"no topic {states} for the finger '{finger or meta.scene.name}'")
        check_schema(reader, reader.topics[states], JOINT_STATE_TYPE)
        decode = JointStateDecoder()
        stamps, positions, velocities, torques = [], [], [], []
        order: list[int] | None = None
        for _, _, message in reader.raw_messages([states], log_time_order=False):
            js = decode(message.data)
            if order is None:
                order = _joint_order(js.name)
                if order is None:
                    raise RunLogError(path, f"{states}: expected joints {list(JOINT_NAMES)} (with a frame prefix "
                                            f"or none), got {list(js.name)}")
            stamps.append(js.stamp_ns)
            positions.append([js.position[i] for i in order])
            velocities.append([js.velocity[i] for i in order])
            torques.append(js.effort[order[0]] if len(js.effort) > order[0] else math.nan)
        if not stamps:
            raise RunLogError(path, f"no message on {states}")
        t = np.array(stamps, dtype=np.int64) / NS_PER_S
        q, v = _from_joints(meta.scene, np.array(positions), np.array(velocities))
        signals = [Signal("torque", t, np.array(torques, dtype=float))]  # the applied mcp effort, N·m
        signals += _topic_signals(reader, ns, meta.log_time_offset_ns)
        runs.append(FingerRun(finger, meta.scene, t, q, v, signals))
    return runs


def _joint_order(names: tuple[str, ...]) -> list[int] | None:
    """Indices of mcp, coupler and pip among a JointState's names (`<frame_prefix>mcp_joint`, ...)."""
    order = [next((i for i, name in enumerate(names) if name.endswith(joint)), -1) for joint in JOINT_NAMES]
    return None if -1 in order else order


def _states_topic(topics: Iterable[str]) -> str:
    """finger_node's joint states: `/joint_states`, or in the node's namespace (`/ns/joint_states`)."""
    found = sorted(t for t in topics if t.rsplit("/", 1)[-1] == "joint_states")
    return "/joint_states" if "/joint_states" in found or not found else found[0]


def _topic_signals(reader, ns: str, offset_ns: int) -> list[Signal]:  # type: ignore[no-untyped-def]
    """The finger's Float64 (a number), String (a mode) and WrenchStamped (force x, y in the model
    plane: finger_base (x, z) → (X, −Y), spec §6) topics, by their names below the namespace."""
    wanted = {topic: info.type for topic, info in reader.topics.items()
              if topic.startswith(ns + "/") and info.type in (FLOAT64, STRING, WRENCH)
              and topic.rsplit("/", 1)[-1] not in NOT_SIGNALS}
    samples: dict[str, tuple[list[float], list]] = {topic: ([], []) for topic in wanted}
    decode = reader.decoding()
    for schema, channel, message in (reader.raw_messages(sorted(wanted), log_time_order=False) if wanted else ()):
        times, values = samples[channel.topic]
        msg = decode(schema, channel, message)
        times.append((message.log_time - offset_ns) / NS_PER_S)
        kind = wanted[channel.topic]
        values.append(msg.data if kind in (FLOAT64, STRING) else (msg.wrench.force.x, -msg.wrench.force.z))
    signals = []
    for topic in sorted(wanted):
        times, values = samples[topic]
        if not times:
            continue
        name = topic[len(ns) + 1:]
        t = np.array(times)
        if wanted[topic] == WRENCH:  # contact_wrench/proximal → contact_force_proximal_{x,y}, as the CSV names it
            base = name.replace("wrench", "force").replace("/", "_")
            xy = np.array(values, dtype=float)
            signals += [Signal(f"{base}_x", t, xy[:, 0]), Signal(f"{base}_y", t, xy[:, 1])]
        else:
            signals.append(Signal(name.replace("/", "_"), t,
                                  np.array(values, dtype=object if wanted[topic] == STRING else float)))
    return signals
