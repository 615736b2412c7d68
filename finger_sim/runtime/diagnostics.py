"""finger_node's /diagnostics status: the key/values and the level, from plain numbers.

Level, most severe first:
- ERROR: the run diverged, or the log failed (the recorder could not write: nothing more is
  logged); the message says why and how many messages were lost.
- WARN: the log dropped messages (it has gaps: stays WARN for the rest of the run), another
  node publishes /clock too, or commands were refused or steps dropped in the last window.
- OK otherwise. The message starts with the run state (running, paused, finished, diverged).
Windows are the spans between two reports (about 1 s of wall time).

Recording's own CPU (`log_cpu_*`): the CPU s the log has cost, in all and by where it ran (the
stepping thread's hand-over of each state, the recorder's sender and status threads, its writer
process: finger_sim.log.McapRecorder.cpu), read once a report; `log_cpu_per_sim_s` is the
window's share per sim s, at real time the cores recording takes. All 0 without a log.
"""

from __future__ import annotations

from dataclasses import dataclass
from enum import IntEnum
from typing import Any

from finger_sim.runtime.commands import TorqueCommands
from finger_sim.runtime.pacing import Lateness, Pacer


class Level(IntEnum):
    """diagnostic_msgs/DiagnosticStatus levels."""

    OK = 0
    WARN = 1
    ERROR = 2


@dataclass(frozen=True)
class LogStatus:
    """What the run's log did so far; path None: not recording."""

    path: str | None
    written: int = 0
    dropped: int = 0
    error: str | None = None  # the first failure (unwritable folder, full disk)
    cpu: Any = None  # what recording has cost so far: a finger_sim.log RecorderCpu (caller_s, threads_s, writer_s, total_s); None: nothing


@dataclass(frozen=True)
class Snapshot:
    """The node's state at one report (everything the status says)."""

    state: str  # running, paused, finished, diverged
    diverged: bool
    scene: str
    scene_file: str
    method: str
    dt: float  # s
    dt_source: str
    torque_source: str
    clock_s: float  # s, as on /clock
    time_s: float  # s, the scene's own time in this episode
    step: int
    episode: int
    realtime_factor_target: float
    steps_total: int
    run_wall_s: float  # wall s spent running
    max_residual_m: float  # max |Φ| since start
    torque: float  # N·m, applied over the last step
    commands_received: int
    log: LogStatus
    clock_publishers: int | None = None  # publishers of /clock seen, when this node publishes it
    lockstep_timeouts: int | None = None  # states whose command did not come within lockstep_timeout; None: no lockstep
    crushes: list[str] | None = None  # this episode's crushed objects, one line each (runtime.crushing); None: none breakable


class DiagnosticsWindow:
    """Turns snapshots into (level, message, values), keeping the counts of the last report."""

    def __init__(self, now: float) -> None:
        self.wall = now  # wall s at the start of the current window
        self._steps, self._refused, self._dropped_steps = 0, 0, 0
        self._lockstep_timeouts = 0
        self._log_cpu_s = 0.0  # the recorder's CPU s at the last report

    def restart(self, now: float) -> None:
        """Start the first window at `now` (when stepping begins)."""
        self.wall = now

    def report(self, snap: Snapshot, commands: TorqueCommands, pacer: Pacer | None,
               now: float, *, new_window: bool = True) -> tuple[Level, str, dict[str, object]]:
        """The status at wall time `now` (s); starts the next window (and the pacer's, unless
        new_window is False: a hand reports each finger against one pacer, then starts it)."""
        window = now - self.wall
        counts = commands.counts
        dropped_steps = pacer.dropped_steps if pacer is not None else 0
        refused_new = counts.refused - self._refused
        dropped_new = dropped_steps - self._dropped_steps
        log = snap.log
        lost = f"{log.dropped} messages lost"
        level, problems = Level.OK, []
        if snap.diverged:
            level = Level.ERROR
        if log.error is not None:
            level = Level.ERROR
            problems.append(f"log failed: {log.error}; {lost}")
        elif log.dropped:
            level = max(level, Level.WARN)
            problems.append(f"log incomplete: {lost}")
        if snap.clock_publishers is not None and snap.clock_publishers > 1:
            level = max(level, Level.WARN)
            problems.append(f"{snap.clock_publishers} publishers on /clock: sim time jumps; "
                            "set publish_clock false on all fingers but one")
        if refused_new or dropped_new:
            level = max(level, Level.WARN)
            problems.append(f"{refused_new} commands refused, {dropped_new} steps dropped in the last {window:.1f} s")
        lockstep_new = (snap.lockstep_timeouts or 0) - self._lockstep_timeouts
        if lockstep_new:
            level = max(level, Level.WARN)
            problems.append(f"lockstep: {lockstep_new} states without a command within lockstep_timeout "
                            f"in the last {window:.1f} s (the held command went on)")
        if snap.crushes:  # an event of the simulated world, not a fault of the node: the level stays
            problems.append(f"{len(snap.crushes)} objects crushed this episode, the last: {snap.crushes[-1]}")
        message = "; ".join([snap.state, *problems])
        cpu = log.cpu
        log_cpu_s = cpu.total_s if cpu is not None else 0.0
        window_sim_s = (snap.steps_total - self._steps) * snap.dt
        late_w = pacer.window if pacer is not None else Lateness()  # at realtime_factor 0: no wake-ups
        late = pacer.lateness if pacer is not None else late_w
        age: object = (snap.step - commands.command_step) * snap.dt if commands.command_step is not None else "none"
        values: dict[str, object] = {
            "scene": snap.scene,
            "scene_file": snap.scene_file,
            "method": snap.method,
            "dt": snap.dt,
            "dt_source": snap.dt_source,
            "torque_source": snap.torque_source,
            "clock": snap.clock_s,
            "time": snap.time_s,
            "step": snap.step,
            "episode": snap.episode,
            "realtime_factor_target": snap.realtime_factor_target,
            "realtime_factor": (snap.steps_total - self._steps) * snap.dt / window if window > 0 else 0.0,  # this window
            "realtime_factor_mean": snap.steps_total * snap.dt / snap.run_wall_s if snap.run_wall_s > 0 else 0.0,
            "overruns": pacer.overruns if pacer is not None else 0,
            "dropped_steps": dropped_steps,
            "late_wakeup_p99_ms": late_w.percentile(99) * 1e3,
            "late_wakeup_max_ms": late_w.max * 1e3,
            "late_wakeup_p99_ms_total": late.percentile(99) * 1e3,
            "late_wakeup_max_ms_total": late.max * 1e3,
            "late_wakeups_total": late.n,
            "max_constraint_residual_m": snap.max_residual_m,
            "torque": float(snap.torque),
            "command_age_s": age,  # sim s since the last command took effect
            "command_step": commands.command_step if commands.command_step is not None else "none",
            "commands_received": snap.commands_received,
            "commands_accepted": counts.accepted,
            "refused_commands": counts.refused,
            "saturated_commands": counts.saturated,
            "command_timeouts": counts.timeouts,
            "log_file": log.path if log.path is not None else "off",
            "log_messages_written": log.written,
            "log_messages_dropped": log.dropped,
            "log_error": log.error if log.error is not None else "none",
            # recording's own CPU: this window's per sim s (0 while sim time stands still), the total and its parts
            "log_cpu_per_sim_s": (log_cpu_s - self._log_cpu_s) / window_sim_s if window_sim_s > 0 else 0.0,
            "log_cpu_s": log_cpu_s,
            "log_cpu_caller_s": cpu.caller_s if cpu is not None else 0.0,
            "log_cpu_threads_s": cpu.threads_s if cpu is not None else 0.0,
            "log_cpu_writer_s": cpu.writer_s if cpu is not None else 0.0,
            "clock_publishers": snap.clock_publishers if snap.clock_publishers is not None else "not publishing",
            "lockstep_timeouts": snap.lockstep_timeouts if snap.lockstep_timeouts is not None else "no lockstep",
        }
        if snap.crushes is not None:
            values["objects_crushed"] = len(snap.crushes)
            values["last_crush"] = snap.crushes[-1] if snap.crushes else "none"
        self._lockstep_timeouts = snap.lockstep_timeouts or 0
        self._log_cpu_s = log_cpu_s
        self.wall, self._steps = now, snap.steps_total
        self._refused, self._dropped_steps = counts.refused, dropped_steps
        if pacer is not None and new_window:
            pacer.new_window()
        return level, message, values


class ClockWatch:
    """The console warning about another /clock publisher: once per run, the first time the graph
    holds more than this node's (the diagnostics say it in every window; the log says it once)."""

    def __init__(self) -> None:
        self.warned = False

    def warning(self, publishers: int) -> str | None:
        """The warning to log, given the count of /clock publishers now; None: nothing (more) to say."""
        if publishers <= 1 or self.warned:
            return None
        self.warned = True
        return (f"{publishers} publishers on /clock: another node publishes sim time too, so /clock jumps back and "
                "forth; run several fingers in one finger_hand (one clock), or publish_clock:=false on all but one")
