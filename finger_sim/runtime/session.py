"""The stepping session of a node, free of ROS: the run's state machine, pause/step/reset, pacing,
lockstep, the end of a scene and divergence.

A stepping node (finger_sim.ros.node's SteppingNode) is this session plus its ROS adapter. The
stepping loop runs in its own thread and owns the simulators: it alone steps, resets and
publishes. Another thread (rclpy's executor) only hands over what arrives: commands go into each
finger's Inbox, parameter changes into `_changes`, taken before the next step, service calls
into `_requests`, whose jobs the loop runs between two steps (`_in_loop` answers when its job is
done). No shared state needs a lock. With realtime_factor > 0 the loop sleeps until
runtime.pacing says a step is due; with 0 it steps back to back. Physics time is
step_index·dt, never measured wall time; every stamp is sim time (runtime.timeline).

Lockstep (`lockstep`): the state of step k is published and step k+1 waits until every finger's
Inbox holds the command that answers it (runtime.commands.Inbox: joint_command by its
header.stamp, motor_torque and effort_commands the first after the publish), or until
lockstep_timeout wall s have passed (counted, in /diagnostics). The first state waits for a
command publisher on every finger. realtime_factor is not used.

What the adapter provides (the hooks below raise NotImplementedError here): `_publish(out, msg)`
for every outgoing message, `_publish_clock(stamp)`, `_publish_diagnostics()`, `_event(finger,
event, level)` for ~/command_log, `_log_parameter_change(params)`, `get_logger()` (info, warning
with throttle_duration_sec, error, fatal), `count_subscribers(topic)` (the ROS graph's count, for
lockstep's first state), `_shutting_down()` and `_shutdown_errors` (the
middleware's errors that mean a clean stop while shutting down). A finger is
finger_sim.ros.finger.Finger, or anything with its attributes (sim, scene, spec, commands,
inbox, step, reset, publish_state, has_controller, outputs_matched, lockstep_timeouts).
"""

from __future__ import annotations

import collections
import concurrent.futures
import threading
import time
import traceback
from collections.abc import Callable, Sequence
from enum import Enum
from typing import Any

from finger_sim.errors import SimulationDiverged
from finger_sim.run_records import NS_PER_S, CommandEvent, stamp_ns
from finger_sim.runtime import realtime, stall_trace
from finger_sim.runtime.diagnostics import Level, LogStatus, Snapshot
from finger_sim.runtime.pacing import Pacer
from finger_sim.runtime.parameters import RunSettings, TorqueSource
from finger_sim.runtime.timeline import Timeline

#: Wall time the loop sleeps at most while paused or finished (commands are still taken,
#: diagnostics still published).
IDLE_WAIT_S = 0.1
#: Period of /diagnostics (and of the check for other /clock publishers), wall s.
DIAGNOSTICS_PERIOD_S = 1.0
#: Period of the repeated (unchanging) /clock while not running, wall s: a use_sim_time client
#: that joins late, or lost the last tick of a burst (/clock is best effort), has the time within it.
IDLE_CLOCK_PERIOD_S = 0.1
#: Rounds of due steps one paced turn runs at most: the due ones, then those that fell due while
#: they ran (a stall within a step); further backlog waits for the next turn.
CATCHUP_PASSES = 2
#: Minimum wall time between two warnings about refused commands.
WARN_THROTTLE_S = 1.0
#: Wall time a service call waits for the stepping loop to run its job.
REQUEST_TIMEOUT_S = 10.0
#: Wall time stop() waits for the stepping loop to end.
JOIN_TIMEOUT_S = 5.0
#: Lockstep: wall time between a controller's first command publisher showing up and the first
#: state, so that discovery completes both ways and neither the state nor its answer is lost.
LOCKSTEP_SETTLE_S = 0.5
#: Lockstep: wall time after a controller showed up that the first state waits at most for the
#: node's publishers to match every subscription the graph knows (one that never matches, e.g. of
#: an incompatible QoS, then delays the start by this much, not for ever).
LOCKSTEP_MATCH_TIMEOUT_S = 10.0
#: Lockstep: how often the loop looks for a controller before the first state, wall s.
LOCKSTEP_POLL_S = 0.01
#: Slack of the float comparisons on the time grid (publish instants), in steps.
RATE_EPS = 1e-9
#: Exit status after a failure while running: a diverged scene run with exit_at_end, a crash.
EXIT_FAILED = 1


class RunState(Enum):
    RUNNING = "running"
    PAUSED = "paused"
    FINISHED = "finished"
    DIVERGED = "diverged"


class SteppingSession:
    """Steps one or more fingers in lock-step at a fixed physics rate (see the module doc).

    `_start_session()` sets the session up; `_thread` runs `_loop` once started; `stop()` ends it.
    `done` completes with the exit status when the run is over.
    """

    _shutdown_errors: tuple[type[BaseException], ...] = ()
    #: The late wake-up probe of a soak (FINGER_SIM_STALL_TRACE), set by the stepping thread.
    _stall_trace: stall_trace.StallTrace | None = None

    @property
    def sim(self) -> Any:
        """The first finger's simulator (after a crush, that of the scene without the object): the step
        index and time every finger shares."""
        return self.fingers[0].sim

    def _start_session(self, name: str, settings: RunSettings, timeline: Timeline, fingers: list[Any],
                       done: Any | None = None) -> None:
        """The session's state: `fingers` stepped on `timeline` with `settings`; `done` a future
        (concurrent.futures.Future by default) completed with the exit status."""
        s = self.settings = settings
        self.timeline = timeline
        self.fingers = fingers
        self.dt = self.sim.dt
        self.done = done if done is not None else concurrent.futures.Future()

        # -- owned by the stepping thread once started --
        self.state = RunState.PAUSED if s.start_paused else RunState.RUNNING
        self.stamp_ns = 0  # stamp of the current state: sim time on /clock, ns
        ends = [f.scene_steps for f in fingers if f.scene_steps is not None]
        self._scene_steps = min(ends) if ends else None  # a scripted run ends with its shortest scene
        self._marker_ratio = min(s.marker_rate_hz / s.physics_rate_hz, 1.0)
        self.pacer: Pacer | None = None
        self.recorder: Any = None  # a finger_sim.log McapRecorder or runtime.log_paths.UnwritableLog, set by the adapter
        self._clock_wall = 0.0  # perf_counter s of the last /clock published
        self._apply_settings(s)
        self._last_published = -1  # stamp of the last published state, ns
        self.steps_total = 0
        self._run_wall = 0.0  # wall s spent running before _run_since
        self._run_since: float | None = None  # set by start() and by state changes
        self._lockstep = s.lockstep
        self._awaited_since = 0.0  # lockstep: wall time (perf_counter) the last state went out
        self._controller_seen: float | None = None  # lockstep: wall time a controller of every finger showed up
        self._lockstep_started = False  # lockstep: the first state has gone out

        # -- the hand-over from other threads --
        self._requests: collections.deque[tuple[Callable[[], Any], concurrent.futures.Future]] = collections.deque()
        self._changes: collections.deque[tuple[RunSettings, Sequence[Any]]] = collections.deque()
        self._requested = s  # the settings with every accepted change (the executor's thread)
        self._wake = threading.Event()
        self._stopping = threading.Event()
        self._thread = threading.Thread(target=self._loop, name=f"{name} stepping", daemon=True)

    # -- what the adapter provides ---------------------------------------------------------------
    def get_logger(self) -> Any:
        raise NotImplementedError

    def _publish(self, out: Any, msg: Any) -> None:
        """Publish (and log) one message at sim time self.stamp_ns."""
        raise NotImplementedError

    def _publish_clock(self, stamp: int) -> None:
        """/clock at `stamp` ns; sets _clock_wall."""
        raise NotImplementedError

    def _publish_diagnostics(self) -> None:
        raise NotImplementedError

    def _event(self, finger: Any, event: CommandEvent, level: Level = Level.OK) -> None:
        """One ~/command_log entry."""
        raise NotImplementedError

    def _log_parameter_change(self, params: Sequence[Any]) -> None:
        """Log run-time parameter changes at the stamp they apply from."""
        raise NotImplementedError

    def _shutting_down(self) -> bool:
        """True once the middleware is shut down (SIGINT, SIGTERM)."""
        return False

    # -- the session -----------------------------------------------------------------------------
    def _log_start(self, input_topics: Sequence[str]) -> None:
        """Log what the run steps, how, and where its commands come from (`input_topics`)."""
        s = self.settings
        if s.torque_source is TorqueSource.SCENE:
            source = "the scenes' profiles"
        else:
            source = " and ".join(input_topics) + f" ({s.command_qos.value} QoS)"
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

    def _reports(self, clock_publishers: int | None) -> list[tuple[Level, str, dict[str, Any]]]:
        """Each finger's /diagnostics status (level, message, values; runtime.diagnostics); the last
        finger's report starts a new window. clock_publishers: /clock publishers seen, or None."""
        s, sim = self.settings, self.sim
        now = time.perf_counter()
        run_wall = self._run_wall + (now - self._run_since if self._run_since is not None else 0.0)
        log, clocks = self._log_status(), clock_publishers
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
            statuses.append(f.diagnostics.report(snap, f.commands, self.pacer, now, new_window=last))
        return statuses

    def stop(self) -> None:
        """End the stepping loop; safe to call twice."""
        self._stopping.set()
        self._wake.set()
        if self._thread.is_alive() and threading.current_thread() is not self._thread:
            self._thread.join(JOIN_TIMEOUT_S)

    def _log_status(self) -> LogStatus:
        rec = self.recorder
        if rec is None:
            return LogStatus(None)
        return LogStatus(str(rec.path), rec.written, rec.dropped, rec.error, rec.cpu())

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
            self.pacer = Pacer(self.dt, s.realtime_factor, s.catchup_limit)
        elif self.pacer.wall_per_step != self.dt / s.realtime_factor:
            self.pacer.set_realtime_factor(s.realtime_factor)

    def _take_changes(self) -> None:
        """Apply the parameter changes accepted since the last step and log them at this step's stamp."""
        while self._changes:
            settings, params = self._changes.popleft()
            self._apply_settings(settings)
            self.get_logger().info("set " + ", ".join(f"{p.name} = {p.value!r}" for p in params)
                                   + f" from step {self.sim.step_index} on")
            self._log_parameter_change(params)

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

    def _repeat_clock(self) -> None:
        """While not running: the last tick again, every IDLE_CLOCK_PERIOD_S of wall time (a
        best-effort tick can be lost, and sim time stands still until the next step). It is the
        last published state's stamp, so that /clock only ever carries the states' sim times."""
        if self._last_published >= 0 and time.perf_counter() - self._clock_wall >= IDLE_CLOCK_PERIOD_S:
            self._publish_clock(self._last_published)

    def _loop(self) -> None:
        try:
            realtime.prepare(self.get_logger().info, self.get_logger().warning)  # before the first step is due
            self._stall_trace = stall_trace.from_environment()
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
        except Exception as exc:  # noqa: BLE001 - a bug must not leave a node that silently stopped
            if not (isinstance(exc, self._shutdown_errors) and self._shutting_down()):
                self._crashed()
            # else: the middleware was shut down under a publish (SIGINT, SIGTERM): a clean stop
        if self._shutting_down() and not self.done.done():
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
        """Run every step the wall clock says is due, or sleep until one is. The steps that fell
        due meanwhile (a late wake-up, a stall within a step) run before the loop's next
        diagnostics report, so that a caught-up stall does not read as a slow window; at most
        CATCHUP_PASSES rounds, so that a node that cannot keep up still serves and reports."""
        now = time.perf_counter()
        due = pacer.due(now)
        if not due:
            if self._stall_trace is not None:
                self._stall_trace.sleeping(pacer.next_due)
            self._sleep(pacer.next_due - now)
            if self._stall_trace is not None:
                self._stall_trace.woke()
            due = pacer.due(time.perf_counter())
        for round_ in range(CATCHUP_PASSES):
            if round_:
                due = pacer.due(time.perf_counter())
            for _ in range(due):
                if not self._advance() or self.pacer is not pacer:  # a new realtime_factor: a new pacing run
                    return

    def _lockstep_turn(self) -> None:
        """Lockstep: step once every finger's command answering the published state has arrived,
        or lockstep_timeout wall s after it went out (then count it and hold the last command).
        The first state goes out once a controller publishes on a command topic of every finger, and
        the fingers' publishers have matched the subscriptions the graph knows (LOCKSTEP_MATCH_TIMEOUT_S)."""
        if not self._lockstep_started:
            now = time.perf_counter()
            if self._controller_seen is None and all(f.has_controller() for f in self.fingers):
                self._controller_seen = now
            waited = now - self._controller_seen if self._controller_seen is not None else None
            if waited is None or waited < LOCKSTEP_SETTLE_S or (
                    waited < LOCKSTEP_MATCH_TIMEOUT_S
                    and not all(f.outputs_matched(self.count_subscribers) for f in self.fingers)):
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
                self._event(f, f.commands.unanswered(self.sim.step_index, self.settings.lockstep_timeout), Level.WARN)
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

    def _take_commands(self, finger: Any = None) -> None:
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

    def _diverged(self, finger: Any, exc: SimulationDiverged) -> None:
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


def _due(n: int, ratio: float) -> bool:
    """True if state n is the first at or after a publish instant (ratio = publish/physics rate)."""
    return ratio >= 1.0 or n == 0 or int(n * ratio + RATE_EPS) != int((n - 1) * ratio + RATE_EPS)
