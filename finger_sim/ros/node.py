"""`finger_node`: steps a scene at a fixed physics rate; motor torque in, joint states and fingertip pose out.

A thin adapter: messages in → core call → messages out. The ROS-free parts are in
finger_sim.runtime (parameters, pacing, commands, timeline, diagnostics, log paths) and the
topic tables in finger_sim.ros.interfaces; this module wires them to rclpy. Physics time is
step_index·dt, never measured wall time; every stamp is sim time (runtime.timeline), and
/clock carries it. `SteppingNode` is the loop for any number of fingers (finger_sim.ros.finger):
`FingerNode` steps one, finger_sim.ros.hand's `FingerHand` several in lock-step on one /clock.

Threads. The stepping loop runs in its own thread and owns the simulators: it alone steps,
resets and publishes. The rclpy executor (the main thread) only hands over what arrives:
commands go into each finger's Inbox, parameter changes into a queue taken before the next
step, service calls into a request queue whose jobs the loop runs between two steps (the
service answers when its job is done). No shared state needs a lock, and every message leaves
from one thread through `_publish`. Why not an rclpy timer: each wake-up of rclpy's executor
walks every entity of the node in Python (≈ 100 µs here); at 1 kHz that doubled the node's CPU
(0.49 against 0.21 cores measured on the same machine) and its late wake-ups (p99 1.1 ms
against 0.25 ms); and at realtime_factor 0 a zero-period timer spends more time in the
executor than in the physics. With realtime_factor > 0 the loop sleeps until runtime.pacing
says a step is due; with 0 it steps back to back.

Commands (`motor_torque`, `effort_commands`, `joint_command`; runtime.commands): a command takes
effect at the next step and is held, saturated to ±max_torque, dropped to 0 after
command_timeout s of sim time without one; NaN, Inf and wrong lengths are refused, and so is a
JointState that names another joint than `<prefix>mcp_joint` or carries positions or
velocities. Every change of the applied torque and every refusal is a run_log.CommandEvent on
`~/command_log`: re-applying them reproduces the run bit for bit.

Parameters: max_torque, command_timeout, realtime_factor and publish_rate_hz may be set while
running (`ros2 param set`); the change is checked against the same table, takes effect from the
next step, and is logged as an rcl_interfaces/ParameterEvent on /parameter_events at the stamp of
that step. The others are read-only.

Lockstep (`lockstep`): the state of step k is published and step k+1 waits until every finger's
Inbox holds the command that answers it (runtime.commands.Inbox: joint_command by its
header.stamp, motor_torque and effort_commands the first after the publish), or until
lockstep_timeout wall s have passed (counted, in /diagnostics). The first state waits for a
command publisher on every finger. realtime_factor is not used.

robot_description (std_msgs/String, transient local): the URDF of the node's scene
(finger_sim.urdf), published once at start and logged, so Foxglove shows the finger from a log.

/clock (best effort, keep last 1: rclcpp's ClockQoS) carries each published state's stamp and,
while the run stands still (paused, finished, diverged), the last published one again about
every IDLE_CLOCK_PERIOD_S of wall time, as simulators do: a use_sim_time client that joins
then, or lost the last tick of a burst, still reads the time. The repeats are logged like any tick.

/diagnostics (about 1 Hz of wall time, also while paused): runtime.diagnostics, one status per
finger. A log that cannot be written shows ERROR, one that drops messages WARN, with the count
lost; another /clock publisher (a second finger with publish_clock true) is warned about once
and shows WARN.
"""

from __future__ import annotations

import collections
import concurrent.futures
import contextlib
import gc
import sys
import threading
import time
import traceback
from collections.abc import Callable, Sequence
from datetime import datetime, timezone
from enum import Enum
from typing import Any

import rclpy
from rcl_interfaces.msg import ParameterEvent, SetParametersResult
from rclpy.duration import Duration
from rclpy.event_handler import PublisherEventCallbacks
from rclpy.exceptions import InvalidHandle, NameValidationException
from rclpy.executors import ExternalShutdownException, SingleThreadedExecutor
from rclpy.impl.implementation_singleton import rclpy_implementation as _rclpy
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.publisher import Publisher
from rclpy.qos import QoSProfile, qos_profile_parameter_events
from rclpy.serialization import serialize_message
from rclpy.task import Future
from std_msgs.msg import String
from std_srvs.srv import SetBool, Trigger

from finger_sim.errors import FingerSimError, SimulationDiverged
from finger_sim.log import RECORDING_STATUS, LogError, McapRecorder
from finger_sim.log.cdr_writer import clock_cdr
from finger_sim.ros import conversions, parameters
from finger_sim.ros.finger import Finger
from finger_sim.runtime.drive_commands import input_refusal
from finger_sim.ros.interfaces import COMMAND_INPUTS, OUTPUTS, Endpoint, InputSpec, OutputSpec, command_qos, finger_topic
from finger_sim.run_log import FINGER_SIM_METADATA, NS_PER_S, CommandEvent, log_time_offset_ns, run_metadata, stamp_ns
from finger_sim.runtime.diagnostics import Level, LogStatus, Snapshot
from finger_sim.runtime.hand_config import FingerSpec
from finger_sim.runtime.log_paths import UnwritableLog, create_log_file
from finger_sim.runtime.pacing import Pacer
from finger_sim.runtime.parameters import NODE_PARAMETERS, NodeSettings, Param, ParameterError, RunSettings, TorqueSource
from finger_sim.runtime.timeline import Timeline
from finger_sim.scene_paths import resolve_scene
from finger_sim.simulate import Simulator
from finger_sim.urdf import finger_urdf

NODE_NAME = "finger_node"
#: The log channel of parameter changes (as `ros2 bag record /parameter_events` would hold them).
PARAMETER_EVENTS = "/parameter_events"

#: Wall time the loop sleeps at most while paused or finished (commands are still taken,
#: diagnostics still published).
IDLE_WAIT_S = 0.1
#: Period of /diagnostics (and of the check for other /clock publishers), wall s.
DIAGNOSTICS_PERIOD_S = 1.0
#: Characters of an rmw/rclpy error shown when the node cannot be created (it may echo the name).
MAX_START_ERROR = 400
#: Period of the repeated (unchanging) /clock while not running, wall s: a use_sim_time client
#: that joins late, or lost the last tick of a burst (/clock is best effort), has the time within it.
IDLE_CLOCK_PERIOD_S = 0.1
#: Minimum wall time between two warnings about refused commands.
WARN_THROTTLE_S = 1.0
#: Wall time a service call waits for the stepping loop to run its job.
REQUEST_TIMEOUT_S = 10.0
#: At a clean exit, wall time granted to reliable subscribers to acknowledge the last messages.
ACK_TIMEOUT_S = 1.0
#: Wall time stop() waits for the stepping loop to end.
JOIN_TIMEOUT_S = 5.0
#: Lockstep: wall time between a controller's first command publisher showing up and the first
#: state, so that discovery completes both ways and neither the state nor its answer is lost.
LOCKSTEP_SETTLE_S = 0.5
#: Lockstep: how often the loop looks for a controller before the first state, wall s.
LOCKSTEP_POLL_S = 0.01
#: Slack of the float comparisons on the time grid (publish instants), in steps.
RATE_EPS = 1e-9
#: Exit status for a configuration that cannot start (a bad parameter, scene or method).
EXIT_CONFIG = 2
#: Exit status after a failure while running: a diverged scene run with exit_at_end, a crash.
EXIT_FAILED = 1


class RunState(Enum):
    RUNNING = "running"
    PAUSED = "paused"
    FINISHED = "finished"
    DIVERGED = "diverged"


class SteppingNode(Node):
    """Steps one or more fingers in lock-step at a fixed physics rate, with one /clock and one log.

    Subclasses say which fingers (`_finger_specs`) and which URDF (`_description`). Life cycle:
    construction (raises ConfigError, StabilityError or ParameterError when a parameter cannot
    start it) → start() (the stepping thread) → spin → stop() → close() → destroy_node().
    `done` completes with the exit status when the run is over.
    """

    def __init__(self, node_name: str, table: tuple[Param, ...], settings_type: type[RunSettings], **kwargs: Any) -> None:
        super().__init__(node_name, **kwargs)
        self.settings = s = settings_type.from_values(parameters.declare(self, table))
        self.timeline = Timeline(1.0 / s.physics_rate_hz)
        self.fingers = [Finger(spec, s, self.timeline) for spec in self._finger_specs()]
        self.dt = self.sim.dt
        self.done = Future()

        # -- owned by the stepping thread once start() has run --
        self.state = RunState.PAUSED if s.start_paused else RunState.RUNNING
        self.stamp_ns = 0  # stamp of the current state: sim time on /clock, ns
        ends = [f.scene_steps for f in self.fingers if f.scene_steps is not None]
        self._scene_steps = min(ends) if ends else None  # a scripted run ends with its shortest scene
        self._marker_ratio = min(s.marker_rate_hz / s.physics_rate_hz, 1.0)
        self.pacer: Pacer | None = None
        self.recorder: McapRecorder | UnwritableLog | None = None  # opened at the end of __init__
        self._clock_wall = 0.0  # perf_counter s of the last /clock published
        self._apply_settings(s)
        self._last_published = -1  # stamp of the last published state, ns
        self.steps_total = 0
        self._run_wall = 0.0  # wall s spent running before _run_since
        self._run_since: float | None = None  # set by start() and by state changes
        self._clock_warned = False
        self._lockstep = s.lockstep
        self._awaited_since = 0.0  # lockstep: wall time (perf_counter) the last state went out
        self._controller_seen: float | None = None  # lockstep: wall time a controller of every finger showed up
        self._lockstep_started = False  # lockstep: the first state has gone out

        # -- the hand-over from the executor thread --
        self._requests: collections.deque[tuple[Callable[[], Any], concurrent.futures.Future]] = collections.deque()
        self._changes: collections.deque[tuple[RunSettings, list[Parameter]]] = collections.deque()
        self._requested = s  # the settings with every accepted change (executor thread)
        self._wake = threading.Event()
        self._stopping = threading.Event()
        self._thread = threading.Thread(target=self._loop, name=f"{node_name} stepping", daemon=True)

        # -- interfaces, from the tables --
        self._outputs = o = {key: self._publisher(spec, spec.topic) for key, spec in OUTPUTS.items()
                             if not spec.per_finger and spec.enabled(s)}
        qos = command_qos(s)
        fqn = self.get_fully_qualified_name()
        for f in self.fingers:
            f.connect(fqn, {key: self._publisher(spec, finger_topic(spec.topic, f.spec.name)) for key, spec in OUTPUTS.items()
                            if spec.per_finger and spec.wanted(s, f.reported)},
                      [self._subscribe(f, spec, qos) for spec in COMMAND_INPUTS if f.driven or not spec.driven_only])
        # bound here, so that a missing table entry fails at start, never inside the stepping loop
        self._clock_out = o.get("clock")  # optional
        self._diagnostics_out, self._description_out = o["diagnostics"], o["robot_description"]
        self.create_service(Trigger, "~/reset", self._on_reset)
        self.create_service(SetBool, "~/pause", self._on_pause)
        self.create_service(Trigger, "~/step", self._on_step)
        self.add_on_set_parameters_callback(self._on_set_parameters)
        self.robot_description = self._description()
        self.recorder = self._open_recorder() if s.record else None
        self._log_start()

    @property
    def sim(self) -> Simulator:
        """The first finger's simulator: the step index and time every finger shares."""
        return self.fingers[0].sim

    # -- what a subclass provides --------------------------------------------------------------
    def _finger_specs(self) -> list[FingerSpec]:
        raise NotImplementedError

    def _description(self) -> str:
        """The URDF published on robot_description."""
        raise NotImplementedError

    def _log_name(self) -> str:
        """The first part of the log's file name (a scene's or the hand's name)."""
        raise NotImplementedError

    # -- interfaces ------------------------------------------------------------------------
    def _publisher(self, spec: OutputSpec, topic: str) -> Endpoint:
        """A publisher without rclpy's default QoS-event handlers: each is one more entity the
        executor walks on every wake-up (a controller's 1 kHz commands). A subscriber with an
        incompatible QoS still gets its own warning."""
        pub = self.create_publisher(spec.msg_type, topic, spec.qos,
                                    event_callbacks=PublisherEventCallbacks(use_default_callbacks=False))
        return Endpoint(pub, pub.topic_name, spec.msg_type, spec.recorded, spec.acked)

    def _subscribe(self, finger: Finger, spec: InputSpec, qos: QoSProfile) -> Endpoint:
        endpoint: list[Endpoint] = []
        inbox, read, joint, stamped = finger.inbox, spec.read, finger.mcp_joint, spec.stamped
        refused = input_refusal(spec.topic, finger.driven)  # a torque topic of a driven finger, or the reverse

        def on_command(msg: Any) -> None:  # executor thread: hand over, never touch the simulator
            self._record(endpoint[0], msg)
            values, refusal = read(msg, joint)
            answers = inbox.put(endpoint[0].topic, values, refusal or refused,
                                conversions.from_time(msg.header.stamp) if stamped else None)
            if answers or self.state is not RunState.RUNNING:  # an idle loop answers refusals without waiting
                self._wake.set()

        sub = self.create_subscription(spec.msg_type, finger_topic(spec.topic, finger.spec.name), on_command, qos)
        endpoint.append(Endpoint(sub, sub.topic_name, spec.msg_type, spec.recorded))
        return endpoint[0]

    def _endpoints(self) -> list[Endpoint]:
        return [*self._outputs.values(), *(e for f in self.fingers for e in (*f.outputs.values(), *f.inputs))]

    def _open_recorder(self) -> McapRecorder | UnwritableLog:
        """The run's MCAP log (runtime.log_paths): every recorded topic a channel, the resolved
        scene in its metadata. If no file can be made the node simulates on without a log,
        counts what it lost and shows ERROR in /diagnostics."""
        s = self.settings
        namespace = self.get_namespace().strip("/").replace("/", "_")
        try:
            path = create_log_file(s.record_dir, self._log_name(), namespace, started=datetime.now(timezone.utc))
        except OSError as exc:
            log = UnwritableLog(s.record_dir, f"cannot create a log in record_dir '{s.record_dir}': {exc}")
            self.get_logger().error(f"{log.error}; simulating without a log")
            return log
        offset = log_time_offset_ns(s.record_time, time.time_ns())  # log time = stamp + offset
        rec = McapRecorder(path, chunk_interval_s=s.record_chunk_interval, on_problem=self.get_logger().error,
                           queue_size=s.record_queue_size, back_pressure=s.realtime_factor == 0.0,
                           status_record=RECORDING_STATUS,
                           time_offset_ns=offset).open()
        for endpoint in self._endpoints():
            if endpoint.recorded:
                # a publisher's QoS goes into the log, so that `ros2 bag play` offers the same
                rec.register_channel(endpoint.topic, endpoint.msg_type,
                                     qos=endpoint.handle.qos_profile if isinstance(endpoint.handle, Publisher) else None)
        rec.register_channel(PARAMETER_EVENTS, ParameterEvent, qos=qos_profile_parameter_events)
        for f in self.fingers:
            name = FINGER_SIM_METADATA + (f"/{f.spec.name}" if f.spec.name else "")
            rec.add_metadata(name, run_metadata(
                f.scene, method=f.sim.method, method_reason=f.sim.method_reason,
                torque_source=s.torque_source.value, parameters=s.to_values(), kernel=f.sim.kernel,
                record_time=s.record_time, log_time_offset_ns=offset))
        return rec

    def close_log(self) -> None:
        """Close the MCAP log with its summary and index; safe to call twice."""
        if self.recorder is not None:
            self.recorder.close()
            # after Ctrl-C the context is shut down: the node's logger would fail to reach /rosout
            # ("Failed to publish log message to rosout"), a logger of another name writes to the console only
            logger = self.get_logger() if self.context.ok() else rclpy.logging.get_logger(f"{self.get_name()}.exit")
            logger.info(f"log {self.recorder.path}: {self.recorder.written} messages written, "
                        f"{self.recorder.dropped} dropped")

    # -- life cycle (main thread) ----------------------------------------------------------
    def start(self) -> None:
        """Publish the description and the initial state, and start stepping (or wait, with start_paused)."""
        self._publish(self._description_out, String(data=self.robot_description))
        if not self._lockstep:  # lockstep: the first state waits for a controller (_lockstep_turn)
            self._publish_state(force=True)
        now = time.perf_counter()
        self._run_since = None if self.state is RunState.PAUSED else now
        for f in self.fingers:
            f.diagnostics.restart(now)
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
        for out in self._endpoints():
            if out.acked:
                out.handle.wait_for_all_acked(timeout)

    def _log_start(self) -> None:
        s = self.settings
        if s.torque_source is TorqueSource.SCENE:
            source = "the scenes' profiles"
        else:
            topics = [e.topic for e in self.fingers[0].inputs] if len(self.fingers) == 1 else \
                [f"<finger>/{spec.topic}" for spec in COMMAND_INPUTS]
            source = " and ".join(topics) + f" ({s.command_qos.value} QoS)"
        end = f"exit at t = {self._scene_steps * self.dt:g} s" if self._scene_steps is not None and s.exit_at_end else "run until stopped"
        for f in self.fingers:
            sc, sim = f.scene, f.sim
            method = sim.method + (f" (auto: {sim.method_reason})" if sim.method_reason else "")
            script = f" (torque {sc.torque.to_dict()})" if f.scene_steps is not None else ""
            self.get_logger().info(
                f"{f.spec.name + ': ' if f.spec.name else ''}scene '{sc.name}' from {f.spec.scene_path}{script}; "
                f"method {method}; dt = {self.dt!r} s (physics_rate_hz {s.physics_rate_hz:g} replaces the scene's dt "
                f"{f.file_dt!r} s)")
        self.get_logger().info(f"realtime_factor {s.realtime_factor:g}; torque from {source}; {end}"
                               + ("; paused" if s.start_paused else ""))

    # -- the stepping loop (its own thread) ------------------------------------------------
    def _loop(self) -> None:
        try:
            while not self._stopping.is_set():
                self._serve()
                if self.state is not RunState.RUNNING:
                    if self._changes:
                        self._take_changes()
                    if any(f.inbox for f in self.fingers):  # refusals are answered while paused; a valid command waits
                        self._take_commands()
                    self._repeat_clock()
                    self._sleep(IDLE_WAIT_S)
                elif self._lockstep:
                    self._lockstep_turn()
                elif self.pacer is not None:
                    self._paced(self.pacer)
                else:
                    self._advance()
                if time.perf_counter() - self._diagnostics_wall >= DIAGNOSTICS_PERIOD_S:
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

    @property
    def _diagnostics_wall(self) -> float:
        return self.fingers[0].diagnostics.wall

    def _crashed(self) -> None:
        self.get_logger().fatal(f"the stepping loop failed:\n{traceback.format_exc()}")
        self.state = RunState.DIVERGED
        if not self.done.done():
            self.done.set_result(EXIT_FAILED)

    def _sleep(self, timeout: float) -> None:
        """Sleep up to `timeout` wall s, waking at once for a service request or a parameter change."""
        if timeout > 0 and not self._requests and not self._changes:
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

    def _paced(self, pacer: Pacer) -> None:
        """Run every step the wall clock says is due, or sleep until one is."""
        now = time.perf_counter()
        due = pacer.due(now)
        if not due:
            self._sleep(pacer.next_due - now)
        for _ in range(due):
            if not self._advance() or self.pacer is not pacer:  # a new realtime_factor: a new pacing run
                return

    def _lockstep_turn(self) -> None:
        """Lockstep: step once every finger's command answering the published state has arrived,
        or lockstep_timeout wall s after it went out (then count it and hold the last command).
        The first state goes out once a controller publishes on a command topic of every finger."""
        if not self._lockstep_started:
            now = time.perf_counter()
            if self._controller_seen is None and all(f.has_controller() for f in self.fingers):
                self._controller_seen = now
            if self._controller_seen is None or now - self._controller_seen < LOCKSTEP_SETTLE_S:
                self._sleep(LOCKSTEP_POLL_S)
                return
            self._lockstep_started = True
            self.get_logger().info("lockstep: a controller is connected; publishing the first state")
            self._publish_state(force=True)
            return
        waiting = [f for f in self.fingers if f.inbox.waiting]
        if waiting:
            left = self._awaited_since + self.settings.lockstep_timeout - time.perf_counter()
            if left > 0:
                self._sleep(left)  # a command, a service request or a parameter change wakes it
                return
            for f in waiting:
                f.lockstep_timeouts += 1
            self.get_logger().warning(
                f"lockstep: no command for the state at {self.stamp_ns * 1e-9!r} s within lockstep_timeout "
                f"{self.settings.lockstep_timeout:g} s from {', '.join(f.spec.name or 'the finger' for f in waiting)}; "
                "holding the last command", throttle_duration_sec=WARN_THROTTLE_S)
        self._advance()

    def _advance(self) -> bool:
        """One physics step of every finger, then their messages; False once the run cannot go on."""
        if self._changes:
            self._take_changes()
        n = self.sim.step_index
        for f in self.fingers:
            if f.inbox:
                self._take_commands(f)
            torque, event = f.commands.torque_for_step(n)
            if event is not None:
                self._event(f, event)
            try:
                f.step(torque)
            except SimulationDiverged as exc:
                self._diverged(f, exc)
                return False
            for crush in f.crushed_now:  # runtime.crushing; its record goes out with the state
                self.get_logger().warning(f"{f.spec.name + ': ' if f.spec.name else ''}{crush.log_line()}")
        self.steps_total += 1
        self._publish_state()
        if self._scene_steps is not None and n + 1 >= self._scene_steps:
            self._end_of_scene()
            return False
        return True

    def _take_commands(self, finger: Finger | None = None) -> None:
        """Check the commands received since the last step; the last valid one is held from the next."""
        for f in self.fingers if finger is None else (finger,):
            for source, values, refusal in f.inbox.drain():
                event = f.commands.take(source, values, self.sim.step_index, refusal)
                if event is not None:
                    self.get_logger().warning(f"refused command [{event.requested}] on {source}: {event.reason} "
                                              f"({f.commands.counts.refused} refused so far)",
                                              throttle_duration_sec=WARN_THROTTLE_S)
                    self._event(f, event, Level.WARN)

    def _end_of_scene(self) -> None:
        self._set_state(RunState.FINISHED)
        names = ", ".join(f"'{f.scene.name}'" for f in self.fingers)
        self.get_logger().info(f"scene {names} ended at t = {self.sim.time:g} s after {self.sim.step_index} steps")
        self._publish_diagnostics()
        if self.settings.exit_at_end and not self.done.done():
            self.done.set_result(0)

    def _diverged(self, finger: Finger, exc: SimulationDiverged) -> None:
        self._set_state(RunState.DIVERGED)
        self.get_logger().error(f"simulation{' of ' + finger.spec.name if finger.spec.name else ''} diverged: {exc}; "
                                "call ~/reset to start the scene again")
        self._publish_diagnostics()
        if self.settings.torque_source is TorqueSource.SCENE and self.settings.exit_at_end and not self.done.done():
            self.done.set_result(EXIT_FAILED)

    def _set_state(self, state: RunState) -> None:
        now = time.perf_counter()
        if self._run_since is not None:
            self._run_wall += now - self._run_since
        self._run_since = now if state is RunState.RUNNING else None
        self._awaited_since = now  # lockstep: a resumed run waits lockstep_timeout anew
        if self.pacer is not None:
            self.pacer.restart()
        self.state = state

    def _event(self, finger: Finger, event: CommandEvent, level: Level = Level.OK) -> None:
        """One ~/command_log entry."""
        msg = conversions.status(finger.event_name, finger.hardware_id, bytes([level]), event.event, event.to_values())
        self._publish(finger.command_log_out, msg)

    # -- run-time parameters -----------------------------------------------------------------
    def _on_set_parameters(self, params: list[Parameter]) -> SetParametersResult:
        """Executor thread: check a change against the table and its rules (rclpy has already
        refused read-only parameters and values out of the descriptors' ranges); the stepping
        loop applies it before the next step."""
        settings = self._requested
        try:
            for p in params:
                settings = settings.with_change(p.name, p.value)
        except ParameterError as exc:
            return SetParametersResult(successful=False, reason=str(exc))
        if settings != self._requested:
            self._requested = settings
            self._changes.append((settings, list(params)))
            self._wake.set()
        return SetParametersResult(successful=True)

    def _apply_settings(self, s: RunSettings) -> None:
        """The run-time parameters' effect (stepping thread, between two steps)."""
        self.settings = s
        self._publish_ratio = 1.0 if s.publish_rate_hz == 0.0 else s.publish_rate_hz / s.physics_rate_hz
        for f in self.fingers:
            if f.commands.max_torque != s.max_torque:
                f.commands.set_max_torque(s.max_torque)
            f.commands.command_timeout = s.command_timeout
        if self.recorder is not None:  # as fast as possible: no deadline, so wait for the log rather than drop
            self.recorder.back_pressure = s.realtime_factor == 0.0
        if s.realtime_factor == 0.0:
            self.pacer = None
        elif self.pacer is None:
            self.pacer = Pacer(self.dt, s.realtime_factor)
        elif self.pacer.wall_per_step != self.dt / s.realtime_factor:
            self.pacer.set_realtime_factor(s.realtime_factor)

    def _take_changes(self) -> None:
        """Apply the parameter changes accepted since the last step and log them at this step's stamp."""
        while self._changes:
            settings, params = self._changes.popleft()
            self._apply_settings(settings)
            self.get_logger().info("set " + ", ".join(f"{p.name} = {p.value!r}" for p in params)
                                   + f" from step {self.sim.step_index} on")
            if self.recorder is not None:
                event = ParameterEvent(node=self.get_fully_qualified_name(), changed_parameters=[p.to_parameter_msg() for p in params])
                event.stamp = conversions.to_time(self.stamp_ns)  # the state the change applies from
                # encoded by the recorder: rclpy's CDR of this type carries trailing bytes strict readers refuse
                self.recorder.write(PARAMETER_EVENTS, event, self.stamp_ns)

    # -- the executor's side: hand over, never touch the simulator -------------------------
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
        self.timeline.new_episode(self.stamp_ns)  # /clock goes on from the last stamp
        for f in self.fingers:
            self._event(f, f.reset())
        self._set_state(RunState.PAUSED if self.state is RunState.PAUSED else RunState.RUNNING)
        self._publish_state(force=True)
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
            self._publish_state(force=True)
        return True, self._where()

    def _where(self) -> str:
        """Machine-readable position in time: clock (s, /clock), time (s, the scene's), step, episode."""
        return (f"clock={self.stamp_ns / NS_PER_S!r} time={self._episode_time()!r} step={self.sim.step_index} "
                f"episode={self.timeline.episode}")

    def _episode_time(self) -> float:
        """The scene's time in this episode, s: step·dt rounded to the ns grid of the stamps (no float noise)."""
        return stamp_ns(0, self.sim.step_index, self.dt) / NS_PER_S

    # -- output (stepping loop) --------------------------------------------------------------
    def _publish_state(self, *, force: bool = False) -> None:
        n = self.sim.step_index
        self.stamp_ns = stamp = self.timeline.stamp(n)
        states = force or _due(n, self._publish_ratio)
        markers = force or _due(n, self._marker_ratio)
        if states:
            self._last_published = stamp
            if self._lockstep:  # before anything goes out: the answer may come back at once
                self._awaited_since = time.perf_counter()
                for f in self.fingers:
                    f.inbox.expect(stamp)
            self._publish_clock(stamp)
        for f in self.fingers:
            f.publish_state(self._publish, stamp, states=states, markers=markers)
        if states:
            self._publish_run_state(stamp)

    def _publish_run_state(self, stamp: int) -> None:
        """What the run publishes beside its fingers' states at `stamp` ns (a subclass's; none here)."""

    def _publish_clock(self, stamp: int) -> None:
        """/clock at `stamp` ns (published and logged, as `ros2 bag record` would hold it)."""
        if self._clock_out is not None:
            self._publish(self._clock_out, clock_cdr(stamp))
            self._clock_wall = time.perf_counter()

    def _repeat_clock(self) -> None:
        """While not running: the last tick again, every IDLE_CLOCK_PERIOD_S of wall time (a
        best-effort tick can be lost, and sim time stands still until the next step). It is the
        last published state's stamp, so that /clock only ever carries the states' sim times."""
        if self._last_published >= 0 and time.perf_counter() - self._clock_wall >= IDLE_CLOCK_PERIOD_S:
            self._publish_clock(self._last_published)

    def _publish(self, out: Endpoint, msg: Any) -> None:
        """Every outgoing message passes here, from the stepping thread, at sim time self.stamp_ns.

        When recording, the message is serialized once (rclpy's C serializer) and the same
        CDR bytes are published and logged: a Python encoder costs ~30 µs a message, which
        at 1 kHz doubled the node's CPU (docs/recording_performance.md).
        """
        if self.recorder is None or not out.recorded:
            out.handle.publish(msg)
            return
        data = msg if type(msg) is bytes else serialize_message(msg)  # the hot topics come as CDR bytes
        out.handle.publish(data)
        self.recorder.write(out.topic, data, self.stamp_ns)

    def _record(self, endpoint: Endpoint, msg: Any) -> None:
        """Log a received message at the current sim time (never blocks)."""
        if self.recorder is not None and endpoint.recorded:
            self.recorder.write(endpoint.topic, serialize_message(msg), self.stamp_ns)

    def _log_status(self) -> LogStatus:
        rec = self.recorder
        if rec is None:
            return LogStatus(None)
        return LogStatus(str(rec.path), rec.written, rec.dropped, rec.error)

    def _clock_publishers(self) -> int | None:
        """Publishers of /clock in the graph when this node publishes it; warns once about a second one."""
        if self._clock_out is None:
            return None
        n = self.count_publishers(self._clock_out.topic)
        if n > 1 and not self._clock_warned:
            self._clock_warned = True
            self.get_logger().warning(
                f"{n} publishers on /clock: another node publishes sim time too, so /clock jumps back and forth; "
                "run several fingers in one finger_hand (one clock), or publish_clock:=false on all but one")
        return n

    def _publish_diagnostics(self) -> None:
        s, sim = self.settings, self.sim
        now = time.perf_counter()
        run_wall = self._run_wall + (now - self._run_since if self._run_since is not None else 0.0)
        log, clocks = self._log_status(), self._clock_publishers()
        statuses = []
        for i, f in enumerate(self.fingers):
            snap = Snapshot(
                state=self.state.value, diverged=self.state is RunState.DIVERGED, scene=f.scene.name,
                scene_file=str(f.spec.scene_path), method=f.sim.method, dt=self.dt,
                dt_source=f"physics_rate_hz {s.physics_rate_hz:g} (scene file: {f.file_dt!r} s)",
                torque_source=s.torque_source.value, clock_s=self.stamp_ns / NS_PER_S, time_s=self._episode_time(), step=sim.step_index,
                episode=self.timeline.episode, realtime_factor_target=s.realtime_factor, steps_total=self.steps_total,
                run_wall_s=run_wall, max_residual_m=f.max_residual, torque=f.applied,
                commands_received=f.inbox.received, log=log, clock_publishers=clocks,
                lockstep_timeouts=f.lockstep_timeouts if self._lockstep else None,
                crushes=[c.log_line() for c in f.changes.crushes] if f.crush_log_out is not None else None)
            last = i == len(self.fingers) - 1
            level, message, values = f.diagnostics.report(snap, f.commands, self.pacer, now, new_window=last)
            statuses.append(conversions.status(f.diag_name, f.hardware_id, bytes([level]), message, values))
        self._publish(self._diagnostics_out, conversions.diagnostic_array(self.stamp_ns, statuses))


class FingerNode(SteppingNode):
    """The simulated finger as a ROS 2 node: one finger, its scene from the `scene` parameter."""

    def __init__(self, **kwargs: Any) -> None:
        super().__init__(NODE_NAME, NODE_PARAMETERS, NodeSettings, **kwargs)

    def _finger_specs(self) -> list[FingerSpec]:
        s = self.settings
        assert isinstance(s, NodeSettings)
        return [FingerSpec("", resolve_scene(s.scene), s.frame_prefix)]

    def _description(self) -> str:
        f = self.fingers[0]
        return finger_urdf(f.scene.params, prefix=f.spec.frame_prefix, radii=f.scene.phalanx_radius,
                           mcp_effort=self.settings.max_torque, mcp_limits=f.scene.mcp_limits, drive=f.scene.drive)

    def _log_name(self) -> str:
        return self.fingers[0].scene.name


def _due(n: int, ratio: float) -> bool:
    """True if state n is the first at or after a publish instant (ratio = publish/physics rate)."""
    return ratio >= 1.0 or n == 0 or int(n * ratio + RATE_EPS) != int((n - 1) * ratio + RATE_EPS)


def spin_until_done(node: Node, done: Future) -> None:
    """Run `node`'s callbacks until `done` completes or the context shuts down.

    rclpy's spin_until_future_complete adds a done-callback closure to the future on every
    executor wake-up (Jazzy's spin_once_until_future_complete): a future that stays pending for
    a whole run (1 kHz of commands) grows without bound, and so does every full garbage
    collection. Here one guard condition, triggered once when `done` completes, ends the
    executor's plain spin_once loop, which keeps nothing from one wake-up to the next.
    """
    executor = SingleThreadedExecutor(context=node.context)
    finished = node.create_guard_condition(lambda: None)  # destroyed with the node

    def wake(_: Future) -> None:  # once, in the thread that completes `done` (a Future without executor)
        with contextlib.suppress(InvalidHandle):  # the node is already destroyed: nobody waits
            finished.trigger()

    done.add_done_callback(wake)
    executor.add_node(node)
    try:
        while node.context.ok() and not done.done():
            executor.spin_once()
    finally:
        executor.shutdown(timeout_sec=0)


def run(node_type: Callable[[], SteppingNode], name: str, args: Sequence[str] | None = None) -> int:
    """main() of a stepping node: start it, spin until it is done or interrupted, close its log."""
    rclpy.init(args=args)
    node = None
    status = 0
    try:
        node = node_type()
        node.start()
        gc.freeze()  # what start-up built lives for the run: no full collection walks it again
        spin_until_done(node, node.done)
        if node.done.done():
            status = node.done.result()
            node.stop()
            node.close()
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    except (_rclpy.RCLError, NameValidationException) as exc:
        if node is None and rclpy.ok():  # the node itself cannot be made: a name or namespace rmw refuses
            rclpy.logging.get_logger(name).error(f"cannot start: {' '.join(str(exc).split())[:MAX_START_ERROR]}")
            status = EXIT_CONFIG
        elif rclpy.ok():
            raise
        # SIGINT/SIGTERM shut the context down while a callback was running: a clean stop.
    except (FingerSimError, LogError) as exc:
        rclpy.logging.get_logger(name).error(f"cannot start: {exc}")
        status = EXIT_CONFIG
    finally:
        if node is not None:
            node.stop()
            node.close_log()
            node.destroy_node()
        rclpy.try_shutdown()
    return status


def main(args: list[str] | None = None) -> int:
    return run(FingerNode, NODE_NAME, args)


if __name__ == "__main__":
    sys.exit(main())
