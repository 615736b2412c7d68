"""`finger_node`: steps a scene at a fixed physics rate; motor torque in, joint states and fingertip pose out.

A thin adapter over the core (finger_sim.simulate.Simulator): parameters → Scene → Simulator;
a stepping loop advances the simulator by whole steps of dt and publishes what each step
produced. Physics time is step_index·dt, never measured wall time; every stamp is sim time,
and /clock carries it.

Threads. The stepping loop runs in its own thread and owns the simulator: it alone steps,
resets and publishes. The rclpy executor (the main thread) only hands over what arrives:
commands go into a deque, service calls into a request queue whose jobs the loop runs
between two steps (the service answers when its job is done). No shared state needs a lock,
and every message leaves from one thread through `_publish`. Why not an rclpy timer: each
wake-up of rclpy's executor walks every entity of the node in Python (≈ 100 µs here); at
1 kHz that doubled the node's CPU (0.49 against 0.21 cores measured on the same machine) and
its late wake-ups (p99 1.1 ms against 0.25 ms); and at realtime_factor 0 a zero-period timer
spends more time in the executor than in the physics.

Pacing:
- realtime_factor > 0: step n of a run is due at anchor + n·dt/realtime_factor on the
  monotonic clock (anchor: the first tick after a start, resume or reset). The loop sleeps
  until the next step is due (waking early for a service request) and then runs every step
  that is due, so a late wake-up is caught up and the mean rate stays exact. A wake-up that
  finds more than one step due counts as an overrun; a backlog beyond CATCHUP_LIMIT_S of wall
  time is dropped (sim time slips behind wall time, the dropped steps are counted) rather
  than run in a burst.
- realtime_factor = 0: the loop steps back to back, taking commands and requests between
  steps.

Commands (`motor_torque` std_msgs/Float64, `effort_commands` std_msgs/Float64MultiArray with
one element, the ros2_control forward-command convention) use rclcpp::SystemDefaultsQoS(),
as ros2_control's forward command controller does. A command takes effect at the next step
and is held; it is saturated to ±max_torque; after command_timeout seconds of sim time
without a command the torque falls to 0. NaN, Inf and wrong-length commands are refused
(throttled warning, counted). With torque_source 'scene' the scene's scripted profile drives
the finger and commands are refused.

Command log (`~/command_log`, diagnostic_msgs/DiagnosticStatus): one event whenever the
applied torque changes (accepted, timeout, reset) and for every refused command. Keys:
event, step (the step of this episode from which `torque` is applied; the state at that step
is stamped stamp_ns), episode (resets so far), stamp_ns, torque (repr: round-trips exactly),
requested, source, saturated, reason. Re-applying each event's torque from its step
reproduces the run bit for bit.

Sim time: the state after step n of an episode is stamped offset + round(n·dt·1e9) ns. A reset
restarts the scene's own clock, not /clock: the new episode's offset is the last stamp + dt.

Diagnostics (/diagnostics, about 1 Hz of wall time, so also while paused and at any
realtime_factor): achieved real-time factor, overruns, dropped steps, late wake-ups, max |Φ|
since start, command age, refused commands and more; see `_publish_diagnostics`.
"""

from __future__ import annotations

import collections
import concurrent.futures
import itertools
import math
import sys
import threading
import time
import traceback
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from datetime import datetime, timezone
from enum import Enum
from pathlib import Path
from typing import Any

import numpy as np
import rclpy
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
from geometry_msgs.msg import PoseStamped
from rcl_interfaces.msg import FloatingPointRange, IntegerRange, ParameterDescriptor
from rclpy.duration import Duration
from rclpy.event_handler import PublisherEventCallbacks
from rclpy.exceptions import ParameterException
from rclpy.executors import ExternalShutdownException
from rclpy.impl.implementation_singleton import rclpy_implementation as _rclpy
from rclpy.node import Node
from rclpy.qos import QoSProfile, ReliabilityPolicy, qos_profile_system_default
from rclpy.serialization import serialize_message
from rclpy.task import Future
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import JointState
from std_msgs.msg import Float64, Float64MultiArray
from std_srvs.srv import SetBool, Trigger
from visualization_msgs.msg import MarkerArray

from finger_sim import kinematics
from finger_sim.errors import ConfigError, FingerSimError, SimulationDiverged, StabilityError
from finger_sim.log import FINGER_SIM_METADATA, McapRecorder
from finger_sim.log.tools import run_metadata
from finger_sim.ros import conversions
from finger_sim.scene import Scene, load_scene
from finger_sim.simulate import BREAK_EPS, Simulator, State

NODE_NAME = "finger_node"
PACKAGE = "finger_sim"

#: Wall-time backlog that pacing catches up; beyond it the backlog is dropped and counted.
CATCHUP_LIMIT_S = 0.05
#: Wall time the loop sleeps at most while paused or finished (commands are still taken,
#: diagnostics still published).
IDLE_WAIT_S = 0.1
#: Period of /diagnostics, wall s.
DIAGNOSTICS_PERIOD_S = 1.0
#: Minimum wall time between two warnings about refused commands.
WARN_THROTTLE_S = 1.0
#: Wall time a service call waits for the stepping loop to run its job.
REQUEST_TIMEOUT_S = 10.0
#: At a clean exit, wall time granted to reliable subscribers to acknowledge the last messages.
ACK_TIMEOUT_S = 1.0
#: Wall time stop() waits for the stepping loop to end.
JOIN_TIMEOUT_S = 5.0
#: History depth of the state and log publishers (reliable, volatile).
STATE_DEPTH = 10
EVENT_DEPTH = 100
#: Slack of the float comparisons on the time grid (publish instants, due steps), in steps.
RATE_EPS = 1e-9
#: Exit status for a configuration that cannot start (a bad parameter, scene or method).
EXIT_CONFIG = 2
#: Exit status after a failure while running: a diverged scene run with exit_at_end, a crash.
EXIT_FAILED = 1

#: rclcpp::ClockQoS(): best effort, keep last 1, as rclpy's TimeSource and rosbag2 subscribe.
CLOCK_QOS = QoSProfile(depth=1, reliability=ReliabilityPolicy.BEST_EFFORT)
STATE_QOS = QoSProfile(depth=STATE_DEPTH)
EVENT_QOS = QoSProfile(depth=EVENT_DEPTH)
#: rclcpp::SystemDefaultsQoS(), what ros2_control's forward command controller subscribes with
#: (with Fast DDS: best effort, volatile, keep last 1 — any publisher's QoS matches it).
COMMAND_QOS = qos_profile_system_default

OK, WARN, ERROR = DiagnosticStatus.OK, DiagnosticStatus.WARN, DiagnosticStatus.ERROR


class ParameterError(FingerSimError):
    """A ROS parameter has the wrong type or is out of its declared range."""

    def __init__(self, name: str, reason: str) -> None:
        self.name = name
        hint = " (a float parameter needs a decimal point, e.g. 500.0)" if "type" in reason.lower() else ""
        super().__init__(f"parameter '{name}': {reason}{hint}")


class TorqueSource(Enum):
    TOPIC = "topic"
    SCENE = "scene"


class RunState(Enum):
    RUNNING = "running"
    PAUSED = "paused"
    FINISHED = "finished"
    DIVERGED = "diverged"


@dataclass(frozen=True)
class _Param:
    name: str
    default: object
    description: str
    range: tuple[float, float] | None = None


#: Every parameter, its default (as in config/finger_node.yaml), meaning and range. All are
#: read once at start (read-only): changing one means restarting the node.
PARAMETERS = (
    _Param("scene", "paper_flexion", "scene file path, or the name of an installed scene (share/finger_sim/config/<name>.yaml)"),
    _Param("physics_rate_hz", 1000.0, "physics steps per second of sim time; dt = 1/rate replaces the scene's dt", (1.0, 100000.0)),
    _Param("publish_rate_hz", 0.0, "joint_states, fingertip_pose and /clock per second of sim time; 0 = every step", (0.0, 100000.0)),
    _Param("marker_rate_hz", 30.0, "finger_markers per second of sim time; 0 = none", (0.0, 100000.0)),
    _Param("realtime_factor", 1.0, "sim seconds per wall second; 0 = as fast as possible", (0.0, 1000.0)),
    _Param("torque_source", TorqueSource.TOPIC.value, "'topic' (motor_torque, effort_commands) or 'scene' (the scene's scripted torque)"),
    _Param("exit_at_end", True, "with torque_source 'scene': exit with status 0 at the scene's duration"),
    _Param("max_torque", 0.05, "commands are saturated to ±max_torque, N·m", (0.0, 100.0)),
    _Param("command_timeout", 0.5, "sim seconds without a command after which the torque falls to 0; 0 = hold forever", (0.0, 3600.0)),
    _Param("frame_prefix", "", "prefix of the frame id (<prefix>finger_base) and of the joint names"),
    _Param("steps_per_trigger", 1, "steps that one ~/step call advances while paused", (1, 1_000_000)),
    _Param("start_paused", False, "start paused; ~/pause false or ~/step to advance"),
    _Param("publish_clock", True, "publish /clock; with several fingers let exactly one node do it"),
    _Param("record", True, "log every message the node publishes and receives to <record_dir>/<scene>_<UTC start>.mcap"),
    _Param("record_dir", "bags", "folder of the MCAP logs (created if missing)"),
    _Param("record_chunk_interval", 0.5, "sim seconds after which the log's open chunk is closed: what a kill -9 can lose", (0.01, 60.0)),
)


@dataclass(frozen=True)
class NodeSettings:
    """The node's parameters, validated, SI."""

    scene: str
    physics_rate_hz: float
    publish_rate_hz: float
    marker_rate_hz: float
    realtime_factor: float
    torque_source: TorqueSource
    exit_at_end: bool
    max_torque: float
    command_timeout: float
    frame_prefix: str
    steps_per_trigger: int
    start_paused: bool
    publish_clock: bool
    record: bool
    record_dir: str
    record_chunk_interval: float


@dataclass(frozen=True)
class _Command:
    torque: float  # N·m, after saturation
    requested: float  # N·m, as received
    source: str  # resolved topic name
    saturated: bool


class _Lateness:
    """Late wake-ups of the paced loop (wall s), binned so that a percentile costs microseconds
    (it is taken inside the stepping loop, once per diagnostics period)."""

    BIN_S = 1e-5
    BINS = 20_000  # up to 200 ms; later ones land in the last bin (the max is kept exactly)

    def __init__(self) -> None:
        self.counts = np.zeros(self.BINS, dtype=np.int64)
        self.n = 0
        self.max = 0.0

    def add(self, late: float) -> None:
        self.counts[min(int(max(late, 0.0) / self.BIN_S), self.BINS - 1)] += 1
        self.n += 1
        if late > self.max:
            self.max = late

    def percentile(self, p: float) -> float:
        """Upper edge of the bin holding the p-th percentile, s (0 with no samples)."""
        if not self.n:
            return 0.0
        i = int(np.searchsorted(np.cumsum(self.counts), p / 100.0 * self.n))
        return min((i + 1) * self.BIN_S, self.max) if i < self.BINS - 1 else self.max


def scene_dirs() -> list[Path]:
    """Where installed scenes are looked for, in order: the ament index (colcon install), the
    venv prefix (pip install), the source tree (editable install)."""
    dirs = []
    try:
        from ament_index_python.packages import get_package_share_directory

        dirs.append(Path(get_package_share_directory(PACKAGE)) / "config")
    except (ImportError, LookupError, OSError):  # no ament_index, package not indexed, no AMENT_PREFIX_PATH
        pass
    dirs.append(Path(sys.prefix) / "share" / PACKAGE / "config")
    dirs.append(Path(__file__).resolve().parents[2] / "config")
    seen: list[Path] = []
    for d in dirs:
        if d.is_dir() and d not in seen:
            seen.append(d)
    return seen


def resolve_scene(value: str) -> Path:
    """A scene parameter → a file: a path if it looks like one, else an installed scene's name."""
    if "/" in value or value.endswith((".yaml", ".yml")):
        return Path(value).expanduser()
    dirs = scene_dirs()
    for d in dirs:
        if (d / f"{value}.yaml").is_file():
            return d / f"{value}.yaml"
    names = sorted({p.stem for d in dirs for p in d.glob("*.yaml")} - {"finger_node"})
    raise ConfigError("parameter 'scene'", f"a scene file path or an installed scene name {names}", value)


class FingerNode(Node):
    """The simulated finger as a ROS 2 node.

    Life cycle: FingerNode() (raises ConfigError, StabilityError or ParameterError when a
    parameter cannot start it) → start() (the stepping thread) → spin → stop() → close() →
    destroy_node(). `done` completes with the exit status when the run is over.
    """

    def __init__(self, **kwargs: Any) -> None:
        super().__init__(NODE_NAME, **kwargs)
        self.settings = self._read_parameters()
        s = self.settings
        self.scene_path = resolve_scene(s.scene)
        self.sim = _make_simulator(self.scene_path, s.physics_rate_hz)
        self.scene: Scene = self.sim.scene
        self._file_dt = load_scene(self.scene_path).dt  # the scene file's own dt, for the record
        self.frames = conversions.FingerFrames.from_system(self.sim.system, s.frame_prefix)
        self.dt = self.sim.dt
        self.done = Future()

        # -- owned by the stepping thread once start() has run --
        self.state = RunState.PAUSED if s.start_paused else RunState.RUNNING
        self.episode = 0
        self._offset_ns = 0
        self.stamp_ns = 0  # stamp of the current state: sim time on /clock, ns
        self._dt_ns = round(self.dt * 1e9)
        self._scene_steps = math.ceil(self.scene.duration / self.dt - BREAK_EPS) if s.torque_source is TorqueSource.SCENE else None
        self._publish_ratio = 1.0 if s.publish_rate_hz == 0.0 else s.publish_rate_hz / s.physics_rate_hz
        self._marker_ratio = min(s.marker_rate_hz / s.physics_rate_hz, 1.0)
        self._timeout_steps = math.ceil(s.command_timeout / self.dt - RATE_EPS) if s.command_timeout > 0 else None
        self.applied = self.scene.torque(0.0) if s.torque_source is TorqueSource.SCENE else 0.0  # N·m, over the last step
        self._held = 0.0  # topic mode: the command in force, N·m
        self._pending: _Command | None = None
        self._command_step: int | None = None  # step of this episode at which the last command took effect
        self._last_published = -1  # stamp of the last published state, ns
        self.steps_total = 0
        self.max_residual = kinematics.constraint_norm(self.sim.system.params, self.sim.q)
        self.counts = dict(accepted=0, refused=0, saturated=0, timeouts=0, overruns=0, dropped_steps=0)
        self._lateness = _Lateness()
        self._window_lateness = _Lateness()
        self._anchor: float | None = None  # wall time of step 0 of the current pacing run
        self._anchor_steps = 0
        self._wall_per_step = self.dt / s.realtime_factor if s.realtime_factor > 0 else 0.0
        self._catchup_steps = max(1, int(CATCHUP_LIMIT_S / self._wall_per_step)) if s.realtime_factor > 0 else 0
        self._run_wall = 0.0  # wall s spent running before _run_since
        self._run_since: float | None = None  # set by start() and by state changes
        self._diag_wall, self._diag_steps, self._diag_refused, self._diag_dropped = time.perf_counter(), 0, 0, 0
        self._msgs: dict[str, Any] = {}  # reused outgoing messages (conversions' out=)

        # -- the hand-over from the executor thread --
        self._commands: collections.deque[tuple[str, tuple[float, ...]]] = collections.deque()
        self._requests: collections.deque[tuple[Callable[[], Any], concurrent.futures.Future]] = collections.deque()
        self._wake = threading.Event()
        self._stopping = threading.Event()
        self._thread = threading.Thread(target=self._loop, name="finger_node stepping", daemon=True)

        # -- interfaces --
        pub = self._publisher
        self._joint_pub = pub(JointState, "joint_states", STATE_QOS)
        self._pose_pub = pub(PoseStamped, "fingertip_pose", STATE_QOS)
        self._marker_pub = pub(MarkerArray, "finger_markers", STATE_QOS) if s.marker_rate_hz > 0 else None
        self._clock_pub = pub(Clock, "/clock", CLOCK_QOS) if s.publish_clock else None
        self._diag_pub = pub(DiagnosticArray, "/diagnostics", STATE_QOS)
        self._event_pub = pub(DiagnosticStatus, "~/command_log", EVENT_QOS)
        self._torque_sub = self.create_subscription(Float64, "motor_torque", self._on_motor_torque, COMMAND_QOS)
        self._effort_sub = self.create_subscription(Float64MultiArray, "effort_commands", self._on_effort_commands, COMMAND_QOS)
        self.create_service(Trigger, "~/reset", self._on_reset)
        self.create_service(SetBool, "~/pause", self._on_pause)
        self.create_service(Trigger, "~/step", self._on_step)
        self._diag_name = f"{self.get_fully_qualified_name()}: simulation"
        self._event_name = f"{self.get_fully_qualified_name()}: command"
        self._hardware_id = s.frame_prefix + "finger"
        self.recorder = self._open_recorder() if s.record else None
        self._log_start()

    def _open_recorder(self) -> McapRecorder:
        """The run's MCAP log: every channel registered, the resolved scene in its metadata.

        A log that cannot be written (unwritable folder, full disk) is reported once; the
        node keeps simulating and counts what it dropped (see /diagnostics).
        """
        s = self.settings
        namespace = self.get_namespace().strip("/").replace("/", "_")
        started = datetime.now(timezone.utc).strftime("%Y%m%dT%H%M%S.%f")[:-3] + "Z"
        stem = "_".join(part for part in (self.scene.name, namespace, started) if part)
        path = Path(s.record_dir) / f"{stem}.mcap"
        for i in itertools.count(1):  # two fingers started in the same millisecond
            if not path.exists():
                break
            path = path.with_name(f"{stem}_{i}.mcap")
        try:
            path.parent.mkdir(parents=True, exist_ok=True)
        except OSError:
            pass  # the recorder reports the failure once, and counts the messages it drops
        rec = McapRecorder(path, chunk_interval_s=s.record_chunk_interval, on_problem=self.get_logger().error).open()
        self._record_topics = {}
        for endpoint, msg_type in (
            (self._clock_pub, Clock), (self._joint_pub, JointState), (self._pose_pub, PoseStamped),
            (self._marker_pub, MarkerArray), (self._diag_pub, DiagnosticArray), (self._event_pub, DiagnosticStatus),
            (self._torque_sub, Float64), (self._effort_sub, Float64MultiArray),
        ):
            if endpoint is not None:
                rec.register_channel(endpoint.topic_name, msg_type)
                self._record_topics[endpoint] = endpoint.topic_name
        parameters = {p.name: getattr(s, p.name) for p in PARAMETERS}
        parameters["torque_source"] = s.torque_source.value
        rec.add_metadata(FINGER_SIM_METADATA, run_metadata(
            self.scene, method=self.sim.method, method_reason=self.sim.method_reason,
            torque_source=s.torque_source.value, parameters=parameters))
        return rec

    def close_log(self) -> None:
        """Close the MCAP log with its summary and index; safe to call twice."""
        if self.recorder is not None:
            self.recorder.close()
            self.get_logger().info(f"log {self.recorder.path}: {self.recorder.written} messages written, "
                                   f"{self.recorder.dropped} dropped")

    def _publisher(self, msg_type: type, topic: str, qos: QoSProfile):
        """A publisher without rclpy's default QoS-event handlers: each is one more entity the
        executor walks on every wake-up (a controller's 1 kHz commands). A subscriber with an
        incompatible QoS still gets its own warning."""
        return self.create_publisher(msg_type, topic, qos, event_callbacks=PublisherEventCallbacks(use_default_callbacks=False))

    # -- life cycle (main thread) ----------------------------------------------------------
    def start(self) -> None:
        """Publish the initial state and start stepping (or wait, with start_paused)."""
        self._publish_state(self.sim.state, force=True)
        now = time.perf_counter()
        self._run_since = None if self.state is RunState.PAUSED else now
        self._diag_wall = now
        self._thread.start()

    def stop(self) -> None:
        """End the stepping loop; safe to call twice."""
        self._stopping.set()
        self._wake.set()
        if self._thread.is_alive() and threading.current_thread() is not self._thread:
            self._thread.join(JOIN_TIMEOUT_S)

    def close(self) -> None:
        """After stop(), at a clean exit: let reliable subscribers acknowledge the last messages."""
        if not self.context.ok():
            return
        timeout = Duration(seconds=ACK_TIMEOUT_S)
        for pub in (self._joint_pub, self._pose_pub, self._event_pub, self._diag_pub):
            pub.wait_for_all_acked(timeout)

    # -- parameters ----------------------------------------------------------------------
    def _read_parameters(self) -> NodeSettings:
        values = {}
        for p in PARAMETERS:
            descriptor = ParameterDescriptor(description=p.description, read_only=True)
            if isinstance(p.default, float) and p.range:
                descriptor.floating_point_range = [FloatingPointRange(from_value=p.range[0], to_value=p.range[1], step=0.0)]
            elif isinstance(p.default, int) and not isinstance(p.default, bool) and p.range:
                descriptor.integer_range = [IntegerRange(from_value=int(p.range[0]), to_value=int(p.range[1]), step=1)]
            try:
                values[p.name] = self.declare_parameter(p.name, p.default, descriptor).value
            except ParameterException as exc:  # a wrong type, or out of the descriptor's range
                raise ParameterError(p.name, str(exc).removesuffix(f": {p.name}")) from None
        try:
            source = TorqueSource(values["torque_source"])
        except ValueError:
            raise ConfigError("parameter 'torque_source'", f"one of {[t.value for t in TorqueSource]}", values["torque_source"]) from None
        if values["publish_rate_hz"] > values["physics_rate_hz"]:
            raise ConfigError("parameter 'publish_rate_hz'", f"0 or a rate ≤ physics_rate_hz ({values['physics_rate_hz']:g} Hz)",
                              values["publish_rate_hz"])
        if any(c.isspace() for c in values["frame_prefix"]):
            raise ConfigError("parameter 'frame_prefix'", "a prefix without white space", values["frame_prefix"])
        values["torque_source"] = source
        return NodeSettings(**values)

    def _log_start(self) -> None:
        s, sc = self.settings, self.scene
        method = self.sim.method + (f" (auto: {self.sim.method_reason})" if self.sim.method_reason else "")
        if s.torque_source is TorqueSource.SCENE:
            source = f"the scene's profile {sc.torque.to_dict()}"
        else:
            source = f"{self._torque_sub.topic_name} and {self._effort_sub.topic_name}"
        end = f"exit at t = {self._scene_steps * self.dt:g} s" if self._scene_steps is not None and s.exit_at_end else "run until stopped"
        self.get_logger().info(
            f"scene '{sc.name}' from {self.scene_path}; method {method}; dt = {self.dt!r} s "
            f"(physics_rate_hz {s.physics_rate_hz:g} replaces the scene's dt {self._file_dt!r} s); "
            f"realtime_factor {s.realtime_factor:g}; torque from {source}; {end}" + ("; paused" if s.start_paused else ""))

    # -- the stepping loop (its own thread) ------------------------------------------------
    def _loop(self) -> None:
        try:
            while not self._stopping.is_set():
                self._serve()
                if self.state is not RunState.RUNNING:
                    if self._commands:  # refusals are answered while paused; a valid command waits for the next step
                        self._take_commands()
                    self._sleep(IDLE_WAIT_S)
                elif self._wall_per_step:
                    self._paced()
                else:
                    self._advance()
                if time.perf_counter() - self._diag_wall >= DIAGNOSTICS_PERIOD_S:
                    self._publish_diagnostics()
        except _rclpy.RCLError:
            if self.context.ok():
                self._crashed()
            # else: the context was shut down under a publish (SIGINT, SIGTERM): a clean stop
        except Exception:  # noqa: BLE001 - a bug must not leave a node that silently stopped
            self._crashed()
        if not self.context.ok() and not self.done.done():
            # SIGTERM shuts the context down without waking the executor (rclpy wakes it for
            # SIGINT only): end main()'s spin, so that it closes the log with its summary.
            self.done.set_result(0)

    def _crashed(self) -> None:
        self.get_logger().fatal(f"the stepping loop failed:\n{traceback.format_exc()}")
        self.state = RunState.DIVERGED
        if not self.done.done():
            self.done.set_result(EXIT_FAILED)

    def _sleep(self, timeout: float) -> None:
        """Sleep up to `timeout` wall s, waking at once for a service request."""
        if timeout > 0 and not self._requests:
            self._wake.wait(timeout)
        self._wake.clear()

    def _serve(self) -> None:
        """Run the service jobs that arrived (each between two steps)."""
        while self._requests:
            job, future = self._requests.popleft()
            if future.set_running_or_notify_cancel():
                try:
                    future.set_result(job())
                except Exception as exc:  # noqa: BLE001 - handed back to the service call
                    future.set_exception(exc)

    def _paced(self) -> None:
        """Run every step the wall clock says is due (realtime_factor > 0), or sleep until one is."""
        now = time.perf_counter()
        wps = self._wall_per_step
        if self._anchor is None:  # first tick after a start, resume or reset: step 1 is due now
            self._anchor, self._anchor_steps = now - wps, 0
        next_due = self._anchor + (self._anchor_steps + 1) * wps
        if now < next_due:
            self._sleep(next_due - now)
            return
        due = int((now - self._anchor) / wps + RATE_EPS) - self._anchor_steps
        late = now - next_due
        self._lateness.add(late)
        self._window_lateness.add(late)
        if due > 1:
            self.counts["overruns"] += 1
        if due > self._catchup_steps:  # too far behind: drop the backlog, slip behind the wall clock
            dropped = due - self._catchup_steps
            self.counts["dropped_steps"] += dropped
            self._anchor += dropped * wps
            due = self._catchup_steps
        for _ in range(due):
            self._anchor_steps += 1
            if not self._advance():
                return

    def _advance(self) -> bool:
        """One physics step and its messages; False once the run cannot go on."""
        sim = self.sim
        n = sim.step_index
        torque = self._torque_for_step(n)
        try:
            state = sim.step(torque)
        except SimulationDiverged as exc:
            self._diverged(exc)
            return False
        self.applied = sim.torque
        self.steps_total += 1
        residual = kinematics.constraint_norm(sim.system.params, state.q)
        if residual > self.max_residual:
            self.max_residual = residual
        self._publish_state(state)
        if self._scene_steps is not None and sim.step_index >= self._scene_steps:
            self._end_of_scene()
            return False
        return True

    def _torque_for_step(self, n: int) -> float | None:
        """The torque of step n: None (the scene's profile) or the held command, N·m."""
        if self._commands:
            self._take_commands()
        if self.settings.torque_source is TorqueSource.SCENE:
            return None
        cmd, self._pending = self._pending, None
        if cmd is not None:
            self._command_step = n
            if not _same(cmd.torque, self._held):
                self._held = cmd.torque
                self._event("accepted", n, requested=cmd.requested, source=cmd.source, saturated=cmd.saturated)
        elif (self._timeout_steps is not None and self._command_step is not None
              and n - self._command_step >= self._timeout_steps and not _same(self._held, 0.0)):
            self._held = 0.0
            self.counts["timeouts"] += 1
            self._event("timeout", n, reason=f"no command for {self.settings.command_timeout:g} s of sim time")
        return self._held

    def _take_commands(self) -> None:
        """Check the commands received since the last step; the last valid one is held from the next."""
        limit = self.settings.max_torque
        while self._commands:
            source, values = self._commands.popleft()
            if self.settings.torque_source is TorqueSource.SCENE:
                self._refuse(source, values, "torque_source is 'scene'")
            elif len(values) != 1:
                self._refuse(source, values, f"expected exactly 1 element, got {len(values)}")
            elif not math.isfinite(values[0]):
                self._refuse(source, values, "not a finite number")
            else:
                value = float(values[0])
                torque = min(max(value, -limit), limit)
                saturated = torque != value
                self.counts["accepted"] += 1
                self.counts["saturated"] += saturated
                self._pending = _Command(torque, value, source, saturated)

    def _refuse(self, source: str, values: Sequence[float], reason: str) -> None:
        self.counts["refused"] += 1
        requested = ", ".join(repr(float(v)) for v in values)
        self.get_logger().warning(f"refused command [{requested}] on {source}: {reason} "
                                  f"({self.counts['refused']} refused so far)", throttle_duration_sec=WARN_THROTTLE_S)
        self._event("refused", self.sim.step_index, requested=requested, source=source, reason=reason, level=WARN)

    def _end_of_scene(self) -> None:
        self._set_state(RunState.FINISHED)
        self.get_logger().info(f"scene '{self.scene.name}' ended at t = {self.sim.time:g} s after {self.sim.step_index} steps")
        self._publish_diagnostics()
        if self.settings.exit_at_end and not self.done.done():
            self.done.set_result(0)

    def _diverged(self, exc: SimulationDiverged) -> None:
        self._set_state(RunState.DIVERGED)
        self.get_logger().error(f"simulation diverged: {exc}; call ~/reset to start the scene again")
        self._publish_diagnostics()
        if self.settings.torque_source is TorqueSource.SCENE and self.settings.exit_at_end and not self.done.done():
            self.done.set_result(EXIT_FAILED)

    def _set_state(self, state: RunState) -> None:
        now = time.perf_counter()
        if self._run_since is not None:
            self._run_wall += now - self._run_since
        self._run_since = now if state is RunState.RUNNING else None
        self._anchor = None
        self.state = state

    def _event(self, event: str, step: int, *, requested: object = "", source: str = "", saturated: bool = False,
               reason: str = "", level: bytes = OK) -> None:
        """One ~/command_log entry: `torque` is applied from `step` of this episode on."""
        values = {
            "event": event,
            "step": step,
            "episode": self.episode,
            "stamp_ns": self._offset_ns + round(step * self.dt * 1e9),
            "torque": float(self._held),
            "requested": requested if isinstance(requested, str) else repr(float(requested)),
            "source": source,
            "saturated": saturated,
            "reason": reason,
        }
        self._publish(self._event_pub, conversions.status(self._event_name, self._hardware_id, level, event, values))

    # -- the executor's side: hand over, never touch the simulator -------------------------
    def _on_motor_torque(self, msg: Float64) -> None:
        self._record(self._torque_sub, msg)
        self._received(self._torque_sub.topic_name, (msg.data,))

    def _on_effort_commands(self, msg: Float64MultiArray) -> None:
        self._record(self._effort_sub, msg)
        self._received(self._effort_sub.topic_name, tuple(msg.data))

    def _received(self, source: str, values: tuple[float, ...]) -> None:
        self._commands.append((source, values))
        if self.state is not RunState.RUNNING:  # an idle loop answers refusals without waiting
            self._wake.set()

    def _in_loop(self, job: Callable[[], tuple[bool, str]]) -> tuple[bool, str]:
        """Run `job` in the stepping loop between two steps; (success, message) of the service."""
        future: concurrent.futures.Future = concurrent.futures.Future()
        self._requests.append((job, future))
        self._wake.set()
        try:
            return future.result(REQUEST_TIMEOUT_S)
        except concurrent.futures.TimeoutError:
            future.cancel()
            return False, f"the stepping loop did not answer within {REQUEST_TIMEOUT_S:g} s"

    def _on_reset(self, request: Trigger.Request, response: Trigger.Response) -> Trigger.Response:
        response.success, response.message = self._in_loop(self._reset)
        return response

    def _on_pause(self, request: SetBool.Request, response: SetBool.Response) -> SetBool.Response:
        response.success, response.message = self._in_loop(lambda: self._pause(request.data))
        return response

    def _on_step(self, request: Trigger.Request, response: Trigger.Response) -> Trigger.Response:
        response.success, response.message = self._in_loop(self._step_while_paused)
        return response

    # -- service jobs (in the stepping loop) -------------------------------------------------
    def _reset(self) -> tuple[bool, str]:
        self._offset_ns = self.stamp_ns + self._dt_ns  # /clock goes on from the last stamp
        self.sim.reset()
        self.episode += 1
        self._commands.clear()
        self._pending, self._held, self._command_step = None, 0.0, None
        self.applied = self.scene.torque(0.0) if self.settings.torque_source is TorqueSource.SCENE else 0.0
        self._event("reset", 0, reason="~/reset")
        self._set_state(RunState.PAUSED if self.state is RunState.PAUSED else RunState.RUNNING)
        self._publish_state(self.sim.state, force=True)
        return True, self._where()

    def _pause(self, pause: bool) -> tuple[bool, str]:
        if pause and self.state is RunState.RUNNING:
            self._set_state(RunState.PAUSED)
        elif not pause and self.state is RunState.PAUSED:
            self._set_state(RunState.RUNNING)
        elif not pause and self.state is not RunState.RUNNING:
            return False, f"{self.state.value}: call ~/reset to run again; {self._where()}"
        return True, f"{self.state.value}; {self._where()}"

    def _step_while_paused(self) -> tuple[bool, str]:
        if self.state is not RunState.PAUSED:
            return False, f"{self.state.value}: ~/step works while paused; {self._where()}"
        for _ in range(self.settings.steps_per_trigger):
            if not self._advance():
                break
        if self._last_published != self.stamp_ns:
            self._publish_state(self.sim.state, force=True)
        return True, self._where()

    def _where(self) -> str:
        """Machine-readable position in time: clock (s, /clock), time (s, the scene's), step, episode."""
        return f"clock={self.stamp_ns * 1e-9!r} time={self.sim.time!r} step={self.sim.step_index} episode={self.episode}"

    # -- output (stepping loop) --------------------------------------------------------------
    def _publish_state(self, state: State, *, force: bool = False) -> None:
        n = self.sim.step_index
        self.stamp_ns = stamp = self._offset_ns + round(state.t * 1e9)
        m = self._msgs
        if force or _due(n, self._publish_ratio):
            self._last_published = stamp
            if self._clock_pub is not None:
                m["clock"] = conversions.clock(stamp, out=m.get("clock"))
                self._publish(self._clock_pub, m["clock"])
            m["joints"] = conversions.joint_state(self.frames, state.q, state.v, self.applied, stamp, out=m.get("joints"))
            self._publish(self._joint_pub, m["joints"])
            m["pose"] = conversions.fingertip_pose(self.frames, state.q, stamp, out=m.get("pose"))
            self._publish(self._pose_pub, m["pose"])
        if self._marker_pub is not None and (force or _due(n, self._marker_ratio)):
            self._publish(self._marker_pub, conversions.markers(self.frames, state.q, stamp))

    def _publish(self, publisher, msg) -> None:
        """Every outgoing message passes here, from the stepping thread, at sim time self.stamp_ns.

        When recording, the message is serialized once (rclpy's C serializer) and the same
        CDR bytes are published and logged: a Python encoder costs ~30 µs a message, which
        at 1 kHz doubled the node's CPU (docs/recording_performance.md).
        """
        if self.recorder is None:
            publisher.publish(msg)
            return
        data = serialize_message(msg)
        publisher.publish(data)
        self.recorder.write(self._record_topics[publisher], data, self.stamp_ns)

    def _record(self, endpoint, msg) -> None:
        """Log a received message at the current sim time (never blocks)."""
        if self.recorder is not None:
            self.recorder.write(self._record_topics[endpoint], serialize_message(msg), self.stamp_ns)

    def _publish_diagnostics(self) -> None:
        now = time.perf_counter()
        s = self.settings
        window = now - self._diag_wall
        stepped = self.steps_total - self._diag_steps
        run_wall = self._run_wall + (now - self._run_since if self._run_since is not None else 0.0)
        refused_new = self.counts["refused"] - self._diag_refused
        dropped_new = self.counts["dropped_steps"] - self._diag_dropped
        level, message = OK, self.state.value
        if self.state is RunState.DIVERGED:
            level = ERROR
        elif refused_new or dropped_new:
            level = WARN
            message += f"; {refused_new} commands refused, {dropped_new} steps dropped in the last {window:.1f} s"
        age = (self.sim.step_index - self._command_step) * self.dt if self._command_step is not None else "none"
        values = {
            "scene": self.scene.name,
            "scene_file": str(self.scene_path),
            "method": self.sim.method,
            "dt": self.dt,
            "dt_source": f"physics_rate_hz {s.physics_rate_hz:g} (scene file: {self._file_dt!r} s)",
            "torque_source": s.torque_source.value,
            "clock": self.stamp_ns * 1e-9,  # s, as on /clock
            "time": self.sim.time,  # s, the scene's own time in this episode
            "step": self.sim.step_index,
            "episode": self.episode,
            "realtime_factor_target": s.realtime_factor,
            "realtime_factor": stepped * self.dt / window if window > 0 else 0.0,  # over the last window
            "realtime_factor_mean": self.steps_total * self.dt / run_wall if run_wall > 0 else 0.0,  # while running
            "overruns": self.counts["overruns"],
            "dropped_steps": self.counts["dropped_steps"],
            "late_wakeup_p99_ms": self._window_lateness.percentile(99) * 1e3,
            "late_wakeup_max_ms": self._window_lateness.max * 1e3,
            "late_wakeup_p99_ms_total": self._lateness.percentile(99) * 1e3,
            "late_wakeup_max_ms_total": self._lateness.max * 1e3,
            "late_wakeups_total": self._lateness.n,
            "max_constraint_residual_m": self.max_residual,  # max |Φ| since start
            "torque": float(self.applied),
            "command_age_s": age,  # sim s since the last command took effect
            "command_step": self._command_step if self._command_step is not None else "none",
            "commands_accepted": self.counts["accepted"],
            "refused_commands": self.counts["refused"],
            "saturated_commands": self.counts["saturated"],
            "command_timeouts": self.counts["timeouts"],
            "log_file": str(self.recorder.path) if self.recorder is not None else "off",
            "log_messages_written": self.recorder.written if self.recorder is not None else 0,
            "log_messages_dropped": self.recorder.dropped if self.recorder is not None else 0,
        }
        status = conversions.status(self._diag_name, self._hardware_id, level, message, values)
        self._publish(self._diag_pub, conversions.diagnostic_array(self.stamp_ns, [status]))
        self._diag_wall, self._diag_steps = now, self.steps_total
        self._diag_refused, self._diag_dropped = self.counts["refused"], self.counts["dropped_steps"]
        self._window_lateness = _Lateness()


def _make_simulator(path: Path, physics_rate_hz: float) -> Simulator:
    try:
        scene = load_scene(path)
    except ConfigError as exc:
        raise ConfigError(f"parameter 'scene' ({path}): {exc.key}", exc.allowed, exc.got) from None
    try:
        scene = scene.with_overrides(dt=1.0 / physics_rate_hz)
    except ConfigError as exc:
        raise ConfigError("parameter 'physics_rate_hz'", f"a rate whose step 1/rate fits the scene ({exc})", physics_rate_hz) from None
    try:
        return Simulator(scene)
    except StabilityError as exc:
        raise StabilityError(f"{exc} (dt = 1/physics_rate_hz, physics_rate_hz = {physics_rate_hz:g})") from None


def _due(n: int, ratio: float) -> bool:
    """True if state n is the first at or after a publish instant (ratio = publish/physics rate)."""
    return ratio >= 1.0 or n == 0 or int(n * ratio + RATE_EPS) != int((n - 1) * ratio + RATE_EPS)


def _same(a: float, b: float) -> bool:
    """Bitwise-equal floats (0.0 and −0.0 differ)."""
    return a == b and math.copysign(1.0, a) == math.copysign(1.0, b)


def main(args: list[str] | None = None) -> int:
    rclpy.init(args=args)
    node = None
    status = 0
    try:
        node = FingerNode()
        node.start()
        rclpy.spin_until_future_complete(node, node.done)
        if node.done.done():
            status = node.done.result()
            node.stop()
            node.close()
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    except _rclpy.RCLError:
        if rclpy.ok():
            raise
        # SIGINT/SIGTERM shut the context down while a callback was running: a clean stop.
    except FingerSimError as exc:
        rclpy.logging.get_logger(NODE_NAME).error(f"cannot start: {exc}")
        status = EXIT_CONFIG
    finally:
        if node is not None:
            node.stop()
            node.close_log()
            node.destroy_node()
        rclpy.try_shutdown()
    return status


if __name__ == "__main__":
    sys.exit(main())
