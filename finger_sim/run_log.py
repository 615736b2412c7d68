"""The run-log contract: what a finger_node log holds beyond plain MCAP, and the tools over it.

The node writes a metadata record `finger_sim` (`RunMetadata`, built by `run_metadata`) that
holds the fully resolved scene as it ran, so the log alone is enough to rebuild the run. The
command log (`<node>/command_log`, DiagnosticStatus key-values, one `CommandEvent` each) says
from which step of which episode each torque was applied; re-applying them through the same
`Simulator` reproduces the recorded states bit for bit on the same version and platform.
Every state is stamped with `stamp_ns`, by the node and by resim alike.

Reading goes through `finger_sim.log` (a pure MCAP library); every problem with a log's
content raises RunLogError, one line naming the file and what is wrong.
"""

from __future__ import annotations

import math
import re
from collections.abc import Iterator, Mapping
from dataclasses import dataclass, field
from os import PathLike
from typing import Any, NamedTuple

import numpy as np
import yaml

from finger_sim import __version__, kinematics
from finger_sim.effects.contact_outputs import CONTACT_FORCES, GRIP_FORCE, WRENCH_TOPICS
from finger_sim.errors import FingerSimError, shown
from finger_sim.joints import JOINT_NAMES, joint_positions, joint_velocities, paper_coordinates
from finger_sim.kinematics import Vec3
from finger_sim.log.cdr import JointStateDecoder, decode_diagnostic_status
from finger_sim.log.definitions import DEFINITION_SEPARATOR
from finger_sim.log.errors import LogArgumentError
from finger_sim.log.reader import LogReader, TopicInfo
from finger_sim.run_records import NS_PER_S, CommandEvent, RunLogError, stamp_ns
from finger_sim.scene import Scene, scene_from_dict
from finger_sim.scene_yaml import parse_scene_text
from finger_sim.scene_changes import SceneChanges
from finger_sim.simulate import Simulator, Trajectory
from finger_sim.tip_force_profile import static_scene

#: Name of the metadata record the node writes.
FINGER_SIM_METADATA = "finger_sim"
#: Largest metadata record a run may store (UTF-8 bytes of its keys and values).
MAX_METADATA_BYTES = 64 * 1024
JOINT_STATE_TYPE = "sensor_msgs/msg/JointState"
COMMAND_LOG_TYPE = "diagnostic_msgs/msg/DiagnosticStatus"
#: Top-level fields (type, name) the tools need in each topic's schema.
_NEEDED_FIELDS = {
    JOINT_STATE_TYPE: {("string[]", "name"), ("float64[]", "position"), ("float64[]", "velocity")},
    COMMAND_LOG_TYPE: {("KeyValue[]", "values")},
}
_FIELD_LINE = re.compile(r"^\s*([A-Za-z0-9_/]+(?:\[[^\]]*\])?)\s+([A-Za-z_][A-Za-z0-9_]*)\b(?!\s*=)")

Vec6 = tuple[float, float, float, float, float, float]  # joint positions (rad) + rates (rad/s)


#: Log-time conventions (the node's `record_time`): sim time from 0, or wall time at the start + sim time.
RECORD_TIMES = ("sim", "wall_start")


def log_time_offset_ns(record_time: str, wall_start_ns: int) -> int:
    """What the node adds to a message's sim-time stamp to get its MCAP log time, ns.

    'sim': 0 (log time = sim time from 0, the /clock); 'wall_start': the Unix time of the
    node's start, so that log times are dates and still advance with sim time. Tools that
    compare states (resim, export) read header stamps, which are sim time either way.
    """
    if record_time not in RECORD_TIMES:
        raise RunLogError("record_time", f"expected one of {list(RECORD_TIMES)}, got {_short(record_time)}")
    return 0 if record_time == "sim" else wall_start_ns


# -- the metadata record ---------------------------------------------------------------------------


@dataclass(frozen=True)
class RunMetadata:
    """The `finger_sim` metadata record: the scene as it ran and how it was driven.

    Stored as MCAP metadata (str → str); `extra` keeps keys this version does not know.
    """

    scene: Scene
    torque_source: str  # 'topic' or 'scene'
    version: str = ""
    method: str = ""  # the method that stepped (auto resolved)
    method_reason: str = ""  # why auto picked it; empty otherwise
    kernel: str = "python"  # the Simulator's kernel ("python" or "numba-<version>"); old logs lack it
    record_time: str = "sim"  # log-time convention (RECORD_TIMES); old logs lack it: sim
    log_time_offset_ns: int = 0  # log time − header stamp of every message, ns
    parameters: Mapping[str, Any] = field(default_factory=dict)  # the node's ROS parameters
    extra: Mapping[str, str] = field(default_factory=dict)

    REQUIRED = ("scene", "torque_source")
    TORQUE_SOURCES = ("topic", "scene")

    def to_dict(self) -> dict[str, str]:
        """The record as MCAP metadata; RunLogError-free, but see `check_size`."""
        return {
            **self.extra,
            "version": self.version,
            "scene": self.scene.to_yaml(),
            "method": self.method,
            "method_reason": self.method_reason,
            "kernel": self.kernel,
            "record_time": self.record_time,
            "log_time_offset_ns": str(self.log_time_offset_ns),
            "torque_source": self.torque_source,
            "dt": repr(self.scene.dt),
            "parameters": yaml.safe_dump(dict(self.parameters), sort_keys=True),
        }

    @classmethod
    def from_dict(cls, data: Mapping[str, str], path: str | PathLike[str] = "log") -> RunMetadata:
        """Parse and validate a stored record; RunLogError names the key that does not parse."""
        where = f"metadata record {FINGER_SIM_METADATA!r}"
        size = metadata_size(data)
        if size > MAX_METADATA_BYTES:  # what a node writes is bounded so: more is no node's record
            raise RunLogError(path, f"the {where} takes {size} bytes, more than the {MAX_METADATA_BYTES} "
                                    "bytes a node writes")
        missing = [k for k in cls.REQUIRED if k not in data]
        if missing:
            raise RunLogError(path, f"the {where} lacks {', '.join(missing)}: not a finger_node log?")
        scene = _parse_scene(data["scene"], path, where)
        if data["torque_source"] not in cls.TORQUE_SOURCES:
            raise RunLogError(path, f"{where}, key 'torque_source': expected one of {list(cls.TORQUE_SOURCES)}, "
                                    f"got {_short(data['torque_source'])}")
        parameters: Any = {}
        if data.get("parameters"):
            try:  # the scene files' hardened loader: no aliases (a "billion laughs"), bounded depth
                parameters = parse_scene_text(data["parameters"], f"{where}, key 'parameters'")
            except (FingerSimError, RecursionError) as exc:
                raise RunLogError(path, f"{where}, key 'parameters' is not YAML: {_first_line(exc)}") from None
            if not isinstance(parameters, dict):
                raise RunLogError(path, f"{where}, key 'parameters': expected a mapping, got {_short(parameters)}")
        record_time = data.get("record_time", "sim")
        if record_time not in RECORD_TIMES:
            raise RunLogError(path, f"{where}, key 'record_time': expected one of {list(RECORD_TIMES)}, "
                                    f"got {_short(record_time)}")
        try:
            offset = int(data.get("log_time_offset_ns", "0"))
        except ValueError:
            raise RunLogError(path, f"{where}, key 'log_time_offset_ns': expected an int (ns), "
                                    f"got {_short(data['log_time_offset_ns'])}") from None
        known = {"version", "scene", "method", "method_reason", "kernel", "record_time", "log_time_offset_ns",
                 "torque_source", "dt", "parameters"}
        return cls(
            scene=scene,
            torque_source=data["torque_source"],
            version=data.get("version", ""),
            method=data.get("method", ""),
            method_reason=data.get("method_reason", ""),
            kernel=data.get("kernel", "python"),
            record_time=record_time,
            log_time_offset_ns=offset,
            parameters=parameters,
            extra={k: v for k, v in data.items() if k not in known},
        )


def run_metadata(scene: Scene, *, method: str, method_reason: str, torque_source: str,
                 parameters: Mapping[str, Any], kernel: str = "python", record_time: str = "sim",
                 log_time_offset_ns: int = 0) -> dict[str, str]:
    """The `finger_sim` metadata record of a run: strings only, as MCAP metadata wants.

    kernel: the Simulator's `kernel` (resim steps with the same one).
    record_time, log_time_offset_ns: the log-time convention and its offset (`log_time_offset_ns()`).

    Raises RunLogError if the record exceeds MAX_METADATA_BYTES (a scene that large is no scene).
    """
    record = RunMetadata(scene=scene, torque_source=torque_source, version=__version__, method=method,
                         method_reason=method_reason, kernel=kernel, record_time=record_time,
                         log_time_offset_ns=log_time_offset_ns, parameters=parameters).to_dict()
    size = metadata_size(record)
    if size > MAX_METADATA_BYTES:
        raise RunLogError(scene.name, f"the {FINGER_SIM_METADATA!r} metadata record would take {size} bytes, "
                                      f"more than the {MAX_METADATA_BYTES} bytes a log stores")
    return record


def metadata_size(record: Mapping[str, str]) -> int:
    """UTF-8 bytes of a metadata record's keys and values."""
    return sum(len(k.encode()) + len(v.encode()) for k, v in record.items())


def _parse_scene(text: str, path: str | PathLike[str], where: str) -> Scene:
    try:  # read as a scene file is: the hardened loader (no aliases, bounded size and depth)
        data = parse_scene_text(text, f"{where}, key 'scene'")
        return scene_from_dict(data)
    except (yaml.YAMLError, FingerSimError, RecursionError, ValueError, TypeError) as exc:
        raise RunLogError(path, f"{where}, key 'scene' does not parse as a scene: {_first_line(exc)}") from None


def _first_line(exc: BaseException) -> str:
    text = " ".join(str(exc).split())
    return text[:200] + ("…" if len(text) > 200 else "")


def _short(value: Any) -> str:
    return shown(value)


# -- reading a run ---------------------------------------------------------------------------------


class LoggedCrush(NamedTuple):
    """One `~/crush_log` record: `object` crushed at the end of the step to state `step` of
    `episode`, under `force` N (its break_force exceeded; finger_sim.grasp_objects)."""

    episode: int
    step: int
    object: str
    force: float

    @classmethod
    def from_values(cls, values: Mapping[str, str], path: str | PathLike[str] = "log") -> LoggedCrush:
        try:
            return cls(int(values["episode"]), int(values["step"]), values["object"], float(values["force"]))
        except (KeyError, ValueError) as exc:
            raise RunLogError(path, f"crush log entry {shown(dict(values))}: {_first_line(exc)}") from None


@dataclass
class RecordedRun:
    """What a log says about one node run: its metadata, commands and recorded states."""

    metadata: RunMetadata
    joint_states: list[tuple[int, Vec6]] = field(default_factory=list)  # (stamp ns, positions + velocities)
    torques: list[float] = field(default_factory=list)  # N·m, each state's mcp effort (NaN if none logged)
    events: list[CommandEvent] = field(default_factory=list)  # in recording order
    #: the objects crushed (`~/crush_log`, finger_sim.runtime.crushing): (episode, step, object, force N)
    crushes: list[LoggedCrush] = field(default_factory=list)

    @property
    def scene(self) -> Scene:
        return self.metadata.scene

    @property
    def torque_source(self) -> str:
        return self.metadata.torque_source

    @property
    def dt(self) -> float:
        return self.scene.dt


def log_fingers(reader: LogReader) -> list[str]:
    """The fingers of a log: [''] for finger_node's one finger (record `finger_sim`), else the
    names of a finger_hand log's fingers (records `finger_sim/<name>`), in the order they were written."""
    if FINGER_SIM_METADATA in reader.metadata:
        return [""]
    prefix = FINGER_SIM_METADATA + "/"
    names = [name.removeprefix(prefix) for name in reader.metadata if name.startswith(prefix)]
    if not names:
        reader.metadata_record(FINGER_SIM_METADATA)  # raises MissingMetadataError naming what is there
    return names


def select_fingers(reader: LogReader, finger: str | None) -> list[str]:
    """`finger` (checked against the log's fingers), or every finger of the log when None."""
    fingers = log_fingers(reader)
    if finger is None:
        return fingers
    if finger not in fingers:
        known = ", ".join(repr(f) for f in fingers) if fingers != [""] else "none: a one-finger finger_node log"
        raise RunLogError(reader.path, f"--finger {finger!r}: no such finger in the log (fingers: {known})")
    return [finger]


def load_run(reader: LogReader, *, events: bool = True, finger: str = "") -> RecordedRun:
    """Metadata, command events (unless `events` is False) and joint states of a node's log;
    `finger`: one finger of a finger_hand log (log_fingers), '' for finger_node's.

    RunLogError names what is missing or foreign (a topic whose schema is not the one expected).
    """
    record = FINGER_SIM_METADATA + (f"/{finger}" if finger else "")
    meta = RunMetadata.from_dict(reader.metadata_record(record), reader.path)
    run = RecordedRun(metadata=meta)
    states = _states_topic(reader, finger)
    ending = f"/{finger}/command_log" if finger else "/command_log"
    log_topics = [t for t in reader.topics if t.endswith(ending)] if events else []
    crush_ending = f"/{finger}/crush_log" if finger else "/crush_log"
    crush_topics = [t for t in reader.topics if t.endswith(crush_ending)] if events else []
    for topic in (*log_topics, *crush_topics):
        check_schema(reader, reader.topics[topic], COMMAND_LOG_TYPE)
    order: list[int] | None = None
    decode_state = JointStateDecoder()
    # One pass in file order over the chunks that hold these topics, through fixed-layout CDR
    # readers (a few µs a message, against 30-100 µs for a general deserializer; schemas checked above).
    for _, channel, record in reader.raw_messages([states, *log_topics, *crush_topics], log_time_order=False):
        if channel.topic != states:
            try:
                status = decode_diagnostic_status(record.data)
            except LogArgumentError as exc:
                raise RunLogError(reader.path, f"{channel.topic} at {record.log_time} ns: {exc}") from None
            if channel.topic in crush_topics:
                run.crushes.append(LoggedCrush.from_values(dict(status.values), reader.path))
            else:
                run.events.append(CommandEvent.from_values(dict(status.values), reader.path))
            continue
        try:
            js = decode_state(record.data)
        except LogArgumentError as exc:
            raise RunLogError(reader.path, f"{states} at {record.log_time} ns: {exc}") from None
        if order is None:
            order = _joint_order(reader, list(js.name))
        try:
            state = tuple(js.position[i] for i in order) + tuple(js.velocity[i] for i in order)
        except IndexError:
            raise RunLogError(reader.path, f"{states} at {js.stamp_ns} ns: fewer positions or velocities than "
                                           f"joints {list(js.name)}") from None
        run.joint_states.append((js.stamp_ns, state))  # type: ignore[arg-type]
        run.torques.append(js.effort[order[0]] if len(js.effort) > order[0] else math.nan)
    return run


def crush_lines(reader: LogReader) -> list[str] | None:
    """`finger-sim info`'s lines on the objects a log's run crushed (every `~/crush_log` record);
    None for a log without that topic (a scene without breakable objects)."""
    topics = sorted(t for t in reader.topics if t.endswith("/crush_log"))
    if not topics:
        return None
    lines = []
    for topic in topics:
        check_schema(reader, reader.topics[topic], COMMAND_LOG_TYPE)
        for _, _, record in reader.raw_messages([topic]):
            status = decode_diagnostic_status(record.data)
            values = dict(status.values)
            lines.append(f"{topic}: episode {values.get('episode', '?')}, step {values.get('step', '?')}: {status.message}")
    return lines


def _states_topic(reader: LogReader, finger: str = "") -> str:
    """The node's joint-state topic (`/joint_states`, or `/<finger>/joint_states`, maybe
    namespaced), its schema checked."""
    ending = f"/{finger}/joint_states" if finger else "/joint_states"
    found = sorted(t for t in reader.topics if t.endswith(ending))
    if not found:
        reader.require_topics([ending])  # raises MissingTopicsError naming what is there
    topic = ending if ending in found else found[0]
    check_schema(reader, reader.topics[topic], JOINT_STATE_TYPE)
    return topic


def check_schema(reader: LogReader, topic: TopicInfo, type_name: str) -> None:
    """RunLogError unless `topic` carries `type_name` in CDR with the fields the tools read."""
    if topic.type != type_name:
        raise RunLogError(reader.path, f"topic {topic.topic}: expected schema {type_name}, got {topic.type}")
    if topic.encoding != "cdr":
        raise RunLogError(reader.path, f"topic {topic.topic}: expected message encoding 'cdr', got {topic.encoding!r}")
    top = topic.definition.split(f"\n{DEFINITION_SEPARATOR}\n", 1)[0]
    declared = set()
    for line in top.splitlines():
        match = _FIELD_LINE.match(line.split("#", 1)[0])
        if match:
            declared.add((match[1].rsplit("/", 1)[-1], match[2]))
    missing = _NEEDED_FIELDS[type_name] - declared
    if missing:
        fields = ", ".join(f"{t} {n}" for t, n in sorted(missing))
        raise RunLogError(reader.path, f"topic {topic.topic}: the {type_name} schema in the log lacks {fields}: "
                                       "a foreign definition")


def _joint_order(reader: LogReader, names: list[str]) -> list[int]:
    """Where each of JOINT_NAMES is in `names`, under the finger's frame prefix (the one of the first joint)."""
    prefix = next((n[:-len(JOINT_NAMES[0])] for n in names if n.endswith(JOINT_NAMES[0])), "")
    try:
        return [names.index(prefix + n) for n in JOINT_NAMES]
    except ValueError:
        raise RunLogError(reader.path, f"joint states: expected joints {list(JOINT_NAMES)} (with one frame "
                                       f"prefix), got {names}") from None


# -- export ----------------------------------------------------------------------------------------


def logged_samples(run: RecordedRun) -> Iterator[tuple[float, Vec3, Vec3, float]]:
    """Each recorded state as (t on /clock (s), q (rad), q' (rad/s), the logged motor torque (N·m)),
    in the paper's coordinates: what the `ros` CSV columns are built from (finger_sim.csv_columns)."""
    p = run.scene.params
    q_ext, alpha = kinematics.extended_pose(p), kinematics.distal_offset(p)
    for (stamp, state), torque in zip(run.joint_states, run.torques):
        q, v = paper_coordinates(state[:3], state[3:], q_ext, alpha)
        yield stamp / NS_PER_S, q, v, torque


#: The contact topics of a finger (the contact outputs' declared topics): grip force and each phalanx's wrench.
GRIP_FORCE_TOPIC = GRIP_FORCE.topic


def logged_outputs(reader: LogReader, run: RecordedRun, finger: str = "") -> dict[str, np.ndarray]:
    """The force columns `simulate --csv` writes for a contact scene, from the log's contact topics,
    one value per recorded joint state (NaN where none was logged at its stamp); {} without them.

    grip_force (N) from `grip_force` (a Float64: matched by log time, stamp + log_time_offset_ns);
    contact_force_<phalanx>_x/_y (N, model plane) from `contact_wrench/<phalanx>`
    (WrenchStamped in finger_base, where a model (X, Y) is (X, 0, −Y)).
    """
    ending = f"/{finger}/" if finger else "/"
    topics = {name: next((t for t in sorted(reader.topics, key=len) if t.endswith(ending + name)), None)
              for name in (GRIP_FORCE_TOPIC, *WRENCH_TOPICS.values())}  # the shortest: un-namespaced first
    if topics[GRIP_FORCE_TOPIC] is None:
        return {}
    row = {stamp: i for i, (stamp, _) in enumerate(run.joint_states)}
    columns = [GRIP_FORCE.name] + [o.name for pair in CONTACT_FORCES.values() for o in pair]
    out = {name: np.full(len(run.joint_states), np.nan) for name in columns}
    by_topic = {t: name for name, t in topics.items() if t is not None}
    offset = run.metadata.log_time_offset_ns
    for message in reader.messages(list(by_topic)):
        name, msg = by_topic[message.topic], message.msg
        if name == GRIP_FORCE_TOPIC:
            i = row.get(message.log_time_ns - offset)
            if i is not None:
                out[GRIP_FORCE.name][i] = msg.data
            continue
        i = row.get(msg.header.stamp.sec * NS_PER_S + msg.header.stamp.nanosec)
        if i is not None:
            x, y = CONTACT_FORCES[name.rsplit("/", 1)[1]]
            out[x.name][i] = msg.wrench.force.x
            out[y.name][i] = -msg.wrench.force.z + 0.0
    return out


def trajectory_from_log(run: RecordedRun) -> Trajectory:
    """The recorded joint states as a Trajectory in the paper's coordinates (the simulate CSV's columns)."""
    p = run.scene.params
    q_ext, alpha = kinematics.extended_pose(p), kinematics.distal_offset(p)
    system = run.scene.build_system()
    t, qs, vs = [], [], []
    for stamp, state in run.joint_states:
        q, v = paper_coordinates(state[:3], state[3:], q_ext, alpha)
        t.append(stamp / NS_PER_S)
        qs.append(q)
        vs.append(v)
    return Trajectory(
        t=np.array(t),
        q=np.array(qs).reshape(-1, 3),
        v=np.array(vs).reshape(-1, 3),
        energy=np.array([system.energy(q, v) for q, v in zip(qs, vs)]),
        residual=np.array([kinematics.constraint_norm(p, q) for q in qs]),
        method=run.metadata.method or run.scene.method,
        method_reason=run.metadata.method_reason,
        wall_time=math.nan,
    )


# -- resim -----------------------------------------------------------------------------------------


@dataclass(frozen=True)
class ResimResult:
    """Largest deviation of the re-simulated joint states from the recorded ones."""

    compared: int
    max_deviation: float  # over positions (rad) and velocities (rad/s)
    first_stamp_ns: int | None  # stamp of the first recorded state that differs, None if none
    #: the objects the re-simulation crushed, and whether they equal the log's `~/crush_log` exactly
    crushes: tuple[LoggedCrush, ...] = ()
    crushes_match: bool = True

    @property
    def exact(self) -> bool:
        return self.first_stamp_ns is None and self.crushes_match

    def summary(self) -> str:
        crushed = "".join(f"; object '{c.object}' crushed at step {c.step} of episode {c.episode} ({c.force!r} N)"
                          for c in self.crushes)
        if not self.crushes_match:
            crushed += "; the crushes differ from the log's ~/crush_log"
        if self.first_stamp_ns is None:
            return f"resim: {self.compared} recorded states reproduced bit for bit (max deviation 0){crushed}"
        return (
            f"resim: max deviation {self.max_deviation:.3e} over {self.compared} recorded states; "
            f"first at t = {self.first_stamp_ns / NS_PER_S:.6f} s on /clock{crushed}"
        )


def _recorded_method(scene: Scene, method: str) -> Scene:
    """The scene to resimulate: under `method: auto`, a log made when auto chose another method (before
    auto moved scenes with events to the error-controlled dop853) is re-run with the method that made it.
    Today's choice is the Simulator's (auto's, then a drive's fallback), not `choose_method`'s alone."""
    from finger_sim.integrators import METHODS
    from finger_sim.scene import AUTO

    if scene.method != AUTO or method not in METHODS or method == Simulator(static_scene(scene), kernel="python").method:
        return scene
    return scene.with_overrides(method=method)


def resimulate(run: RecordedRun, *, kernel: str | None = None, max_steps: int | None = None) -> ResimResult:
    """Re-run the log's scene, re-applying its torques at the steps they were applied, and
    compare every recorded joint state with the re-simulated one (exact comparison).

    Episodes: a reset restarts the scene at step 0; its states are stamped from the reset
    event's stamp on (the node's sim time never runs backwards). In topic mode the torque of
    step n is that of the last accepted/timeout/reset event of the episode with step ≤ n (0
    before any); in scene mode the scene's profile drives every step, as in the node.
    kernel: the Simulator's kernel; None (the default) takes the one the log was made with.
    max_steps: refuse (ResourceError, before the first step) a re-simulation of more steps in all;
    None: `simulate`'s default budget (finger_sim.budget.DEFAULT_MAX_STEPS).
    """
    # the scene's changes (a tip-force profile, crushing) as the node stepped them (finger_sim.scene_changes)
    stepper = SceneChanges(_recorded_method(run.scene, run.metadata.method),
                           kernel=run.metadata.kernel if kernel is None else kernel)
    dt_ns = run.dt * NS_PER_S
    q_ext, alpha = kinematics.extended_pose(run.scene.params), kinematics.distal_offset(run.scene.params)
    offsets = [0] + [e.stamp_ns for e in run.events if e.event == "reset"]
    changes: dict[int, list[tuple[int, float]]] = {}
    for e in run.events:
        if e.applies_torque:
            changes.setdefault(e.episode, []).append((e.step, e.torque))
    wanted: dict[int, dict[int, Vec6]] = {}  # episode → step → recorded state
    for stamp, state in run.joint_states:
        episode = max(i for i, off in enumerate(offsets) if off <= stamp)
        wanted.setdefault(episode, {})[round((stamp - offsets[episode]) / dt_ns)] = state
    _check_resim_budget(run, sum(max(recorded) + 1 for recorded in wanted.values()), max_steps)
    compared, worst, first = 0, 0.0, None
    crushes = []
    for episode in sorted(wanted):
        stepper.reset()  # every object again (a crush took one out of the scene)
        torques = sorted(changes.get(episode, []))
        held, k = 0.0, 0
        recorded = wanted[episode]
        for n in range(max(recorded) + 1):
            theirs = recorded.get(n)
            if theirs is not None:
                compared += 1
                mine = joint_positions(stepper.sim.q, q_ext, alpha) + joint_velocities(stepper.sim.v)
                if mine != theirs:  # the deviation only where there is one (resim is read-bound)
                    dev = max(abs(a - b) for a, b in zip(mine, theirs))
                    if math.isnan(dev):  # a NaN on either side is a deviation, not "no larger than the max"
                        dev = math.inf
                    worst = max(worst, dev)
                    if dev > 0.0 and first is None:
                        first = stamp_ns(offsets[episode], n, run.dt)
            while k < len(torques) and torques[k][0] <= n:
                held = torques[k][1]
                k += 1
            stepper.step(None if run.torque_source == "scene" else held)
            # the step after the last recorded state is taken too: what it crushed the log cannot hold
            crushes += [LoggedCrush(episode, c.step, c.object, c.force) for c in stepper.new() if c.step <= max(recorded)]
    logged = run.crushes
    return ResimResult(compared, worst, first, tuple(crushes), crushes == logged)


def _check_resim_budget(run: RecordedRun, steps: int, max_steps: int | None) -> None:
    """Refuse a re-simulation of more than `max_steps` steps (a log's scene of dt = 1e-12 s would run for hours)."""
    from finger_sim.budget import DEFAULT_MAX_STEPS

    limit = DEFAULT_MAX_STEPS if max_steps is None else max_steps
    if steps > limit:
        raise FingerSimError(f"re-simulating the log takes {steps:,} steps (its states span that many steps of its "
                             f"scene's dt = {run.dt:g} s), over the limit of {limit:,} steps; to go ahead on purpose "
                             f"pass --max-steps {steps}")
