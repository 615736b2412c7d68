"""`finger_node`: steps a scene at a fixed physics rate; motor torque in, joint states and fingertip pose out.

A thin adapter: messages in → core call → messages out. The ROS-free parts are in
finger_sim.runtime (parameters, pacing, commands, timeline, diagnostics, log paths) and the
topic tables in finger_sim.ros.interfaces; this module wires them to rclpy. Physics time is
step_index·dt, never measured wall time; every stamp is sim time (runtime.timeline), and
/clock carries it. `SteppingNode` is the loop for any number of fingers (finger_sim.ros.finger):
`FingerNode` steps one, finger_sim.ros.hand's `FingerHand` several in lock-step on one /clock.

Threads and the run's state machine (pause, step, reset, lockstep, end of scene, divergence)
are finger_sim.runtime.session's, free of ROS; this module adds the rclpy side: the executor
thread only hands over (commands into each finger's Inbox, parameter changes and service jobs
into the session's queues), and every message leaves from the stepping thread through
`_publish`. Why not an rclpy timer: each wake-up of rclpy's executor walks every entity of the
node in Python (≈ 100 µs here); at 1 kHz that doubled the node's CPU and its late wake-ups.

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

robot_description (std_msgs/String, transient local): the URDF of the node's scene
(finger_sim.urdf), published once at start and logged, so Foxglove shows the finger from a log.

/clock (best effort, keep last 1: rclcpp's ClockQoS) carries each published state's stamp and,
while the run stands still (paused, finished, diverged), the last published one again about
every runtime.session.IDLE_CLOCK_PERIOD_S of wall time, as simulators do: a use_sim_time client that joins
then, or lost the last tick of a burst, still reads the time. The repeats are logged like any tick.

/diagnostics (about 1 Hz of wall time, also while paused): runtime.diagnostics, one status per
finger. A log that cannot be written shows ERROR, one that drops messages WARN, with the count
lost; another /clock publisher (a second finger with publish_clock true) is warned about once
and shows WARN.
"""

from __future__ import annotations

import contextlib
import gc
import sys
import time
from collections.abc import Callable, Sequence
from typing import Any

import rclpy
from rcl_interfaces.msg import ParameterEvent, SetParametersResult
from rclpy.duration import Duration
from rclpy.event_handler import PublisherEventCallbacks
from rclpy.exceptions import NameValidationException
from rclpy.executors import ExternalShutdownException
from rclpy.impl.implementation_singleton import rclpy_implementation as _rclpy
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.publisher import Publisher
from rclpy.qos import QoSProfile, qos_profile_parameter_events
from rclpy.serialization import serialize_message
from rclpy.task import Future
from std_msgs.msg import String
from std_srvs.srv import SetBool, Trigger

from finger_sim.errors import FingerSimError
from finger_sim.log import LogError
from finger_sim.log.cpu_clocks import name_os_thread
from finger_sim.log.cdr_writer import clock_cdr
from finger_sim.ros import conversions, parameters
from finger_sim.ros.finger import Finger
from finger_sim.ros.publication_mode import prefer_async_publication
from finger_sim.ros.spin import spin_until_done
from finger_sim.ros.state_output import BatchedStateOutput, StateOutput
from finger_sim.runtime.drive_commands import input_refusal
from finger_sim.ros.interfaces import COMMAND_INPUTS, OUTPUTS, Endpoint, InputSpec, OutputSpec, command_qos, finger_topic, raw_sender
from finger_sim.run_log import CommandEvent
from finger_sim.runtime.diagnostics import ClockWatch, Level
from finger_sim.runtime.hand_config import FingerSpec
from finger_sim.runtime.log_paths import UnwritableLog
from finger_sim.runtime.parameters import NODE_PARAMETERS, NodeSettings, Param, ParameterError, RunSettings
from finger_sim.runtime.recording import Channel, open_run_log
from finger_sim.runtime.session import EXIT_FAILED, RunState, SteppingSession
from finger_sim.runtime.timeline import Timeline
from finger_sim.scene_paths import resolve_scene
from finger_sim.urdf import finger_urdf

NODE_NAME = "finger_node"
#: The log channel of parameter changes (as `ros2 bag record /parameter_events` would hold them).
PARAMETER_EVENTS = "/parameter_events"

#: Characters of an rmw/rclpy error shown when the node cannot be created (it may echo the name).
MAX_START_ERROR = 400
#: At a clean exit, wall time granted to reliable subscribers to acknowledge the last messages, in all:
#: more than Fast DDS's heartbeat period (3 s by default), after which a writer sends again what a
#: subscriber missed (a burst of states at realtime_factor 0 can overrun its socket).
ACK_TIMEOUT_S = 4.0
#: Exit status for a configuration that cannot start (a bad parameter, scene or method).
EXIT_CONFIG = 2
__all__ = ["EXIT_CONFIG", "EXIT_FAILED", "NODE_NAME", "FingerNode", "RunState", "SteppingNode", "main", "run", "spin_until_done"]


#: The node's services: name, type, the job run in the stepping loop (node, request) → (success, message).
SERVICES: tuple[tuple[str, type, Callable[[Any, Any], tuple[bool, str]]], ...] = (
    ("~/reset", Trigger, lambda node, _: node._reset()),
    ("~/pause", SetBool, lambda node, request: node._pause(request.data)),
    ("~/step", Trigger, lambda node, _: node._step_while_paused()),
)


class SteppingNode(Node, BatchedStateOutput, SteppingSession):
    """Steps one or more fingers in lock-step at a fixed physics rate, with one /clock and one log.

    Subclasses say which fingers (`_finger_specs`) and which URDF (`_description`). Life cycle:
    construction (raises ConfigError, StabilityError or ParameterError when a parameter cannot
    start it) → start() (the stepping thread) → spin → stop() → close() → destroy_node().
    `done` completes with the exit status when the run is over.
    """

    def __init__(self, node_name: str, table: tuple[Param, ...], settings_type: type[RunSettings], **kwargs: Any) -> None:
        super().__init__(node_name, **kwargs)
        self.settings = s = settings_type.from_values(parameters.declare(self, table))  # _finger_specs reads it
        timeline = Timeline(1.0 / s.physics_rate_hz)
        self._start_session(node_name, s, timeline, [Finger(spec, s, timeline) for spec in self._finger_specs()], Future())
        self._clock_watch = ClockWatch()
        self._shutdown_errors = (_rclpy.RCLError,)

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
        for name, srv_type, job in SERVICES:
            self.create_service(srv_type, name, self._service(job))
        self.add_on_set_parameters_callback(self._on_set_parameters)
        self.robot_description = self._description()
        self.recorder = self._open_recorder() if s.record else None
        self._output = StateOutput(self.recorder)
        self._log_start([e.topic for e in self.fingers[0].inputs] if len(self.fingers) == 1 else
                        [f"<finger>/{spec.topic}" for spec in COMMAND_INPUTS])

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
        return Endpoint(pub, pub.topic_name, spec.msg_type, spec.recorded, spec.acked, raw_sender(pub))

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

    def _open_recorder(self) -> Any:
        """The run's MCAP log (runtime.recording): every recorded topic a channel (a publisher's
        with its QoS), /parameter_events, the resolved scenes in its metadata."""
        channels = [Channel(e.topic, e.msg_type, e.handle.qos_profile if isinstance(e.handle, Publisher) else None)
                    for e in self._endpoints() if e.recorded]
        channels.append(Channel(PARAMETER_EVENTS, ParameterEvent, qos_profile_parameter_events))
        log = open_run_log(self.settings, self._log_name(), self.get_namespace().strip("/").replace("/", "_"), self.fingers,
                           channels, on_problem=self.get_logger().error)
        if isinstance(log, UnwritableLog):
            self.get_logger().error(f"{log.error}; simulating without a log")
        return log

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

    def close(self) -> None:
        """After stop(), at a clean exit: let reliable subscribers acknowledge the last messages
        (ACK_TIMEOUT_S in all); the topics some subscriber had not acknowledged are named in the log."""
        if not self.context.ok():
            return
        deadline = time.monotonic() + ACK_TIMEOUT_S
        unacked = [out.topic for out in self._endpoints() if out.acked and not out.handle.wait_for_all_acked(
            Duration(seconds=max(deadline - time.monotonic(), 0.0)))]
        if unacked:
            self.get_logger().warning(f"exit: not every reliable subscriber acknowledged the last messages of "
                                      f"{', '.join(unacked)} within {ACK_TIMEOUT_S:g} s")

    def _loop(self) -> None:
        """The session's stepping loop, holding every publisher's use guard for its run: the
        endpoints send with the C publisher's publish_raw alone (interfaces.raw_sender), and a
        destroy_node meanwhile is deferred until the loop ends, as each message's guard did. The
        thread is 'stepping' to the operating system (`top -H`, a benchmark's per-thread CPU)."""
        name_os_thread("stepping")
        with contextlib.ExitStack() as held:
            for out in self._endpoints():
                if out.send is not None:
                    held.enter_context(out.handle.handle)
            super()._loop()  # type: ignore[misc]

    # -- the session's output (stepping thread) -----------------------------------------------
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

    def _service(self, job: Callable[[SteppingNode, Any], tuple[bool, str]]) -> Callable[[Any, Any], Any]:
        """A service callback (executor thread): `job` runs in the stepping loop between two steps."""
        def serve(request: Any, response: Any) -> Any:
            response.success, response.message = self._in_loop(lambda: job(self, request))
            return response
        return serve

    def _shutting_down(self) -> bool:
        return not self.context.ok()

    # -- output (stepping loop) --------------------------------------------------------------
    def _publish_clock(self, stamp: int) -> None:
        """/clock at `stamp` ns (published and logged, as `ros2 bag record` would hold it)."""
        if self._clock_out is not None:
            self._publish(self._clock_out, clock_cdr(stamp))
            self._clock_wall = time.perf_counter()

    def _log_parameter_change(self, params: Sequence[Parameter]) -> None:
        if self.recorder is not None:
            event = ParameterEvent(node=self.get_fully_qualified_name(), changed_parameters=[p.to_parameter_msg() for p in params])
            event.stamp = conversions.to_time(self.stamp_ns)  # the state the change applies from
            # encoded by the recorder: rclpy's CDR of this type carries trailing bytes strict readers refuse
            self.recorder.write(PARAMETER_EVENTS, event, self.stamp_ns)

    def _publish(self, out: Endpoint, msg: Any) -> None:
        """Every outgoing message passes here, from the stepping thread, at sim time self.stamp_ns.

        When recording, the message is serialized once (rclpy's C serializer) and the same
        CDR bytes are published and logged: a Python encoder costs ~30 µs a message, which
        at 1 kHz doubled the node's CPU (docs/recording_performance.md).
        """
        if type(msg) is not bytes:  # the hot topics come as CDR bytes: sent as they are (interfaces.raw_sender)
            if self.recorder is None or not out.recorded:
                out.handle.publish(msg)
                return
            msg = serialize_message(msg)
        self._output.add(out, msg, self.stamp_ns)  # a state's messages: one hand-over to the log (state_output)

    def _record(self, endpoint: Endpoint, msg: Any) -> None:
        """Log a received message at the current sim time (never blocks)."""
        if self.recorder is not None and endpoint.recorded:
            self.recorder.write(endpoint.topic, serialize_message(msg), self.stamp_ns)

    def _clock_publishers(self) -> int | None:
        """Publishers of /clock in the graph when this node publishes it; warns once about a second one."""
        if self._clock_out is None:
            return None
        n = self.count_publishers(self._clock_out.topic)
        if (warning := self._clock_watch.warning(n)) is not None:
            self.get_logger().warning(warning)
        return n

    def _publish_diagnostics(self) -> None:
        clocks = self._clock_publishers()
        statuses = [conversions.status(f.diag_name, f.hardware_id, bytes([level]), message, values)
                    for f, (level, message, values) in zip(self.fingers, self._reports(clocks))]
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


def run(node_type: Callable[[], SteppingNode], name: str, args: Sequence[str] | None = None) -> int:
    """main() of a stepping node: start it, spin until it is done or interrupted, close its log."""
    prefer_async_publication()
    rclpy.init(args=args)
    node = None
    status = 0
    try:
        node = node_type()
        node.start()
        gc.freeze()  # what start-up built lives for the run: no full collection walks it again
        spin_until_done(node, node.done, node.settings.executor)
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
