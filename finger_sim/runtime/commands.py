"""Torque commands of a topic-driven run: hand-over, refusal, saturation, hold and timeout.

A command received between two steps takes effect at the next step and is held; it is
saturated to ±max_torque; after command_timeout s of sim time without a command the torque falls to
0. Non-finite values and wrong lengths are refused (counted, and each refusal is an event);
when the scene's scripted profile drives the finger (`accepting=False`) every command is
refused. A sensor_msgs/JointState command (`joint_command`, ros2_control's topic-based hardware
interface and Isaac Sim) is read by `joint_effort`: only the effort of the actuated joint
(`<prefix>mcp_joint`) is a command; other joints, positions and velocities are refused. Each change of the applied torque (accepted, timeout) and each refusal is a
run_records.CommandEvent, so re-applying the events reproduces the run bit for bit.

Threads: `Inbox.put` is called by the executor thread, everything else by the stepping loop.
"""

from __future__ import annotations

import collections
import math
from collections.abc import Iterator, Sequence
from dataclasses import dataclass

from finger_sim.run_records import CommandEvent
from finger_sim.runtime.timeline import Timeline

#: Slack of the float comparison on the step grid, in steps.
STEP_EPS = 1e-9
#: Refusal reasons (the `reason` of a 'refused' event).
#: Elements of a refused command written into its event (and so the node's warning and the log).
MAX_REQUESTED_SHOWN = 8
REFUSED_SCENE = "torque_source is 'scene'"
REFUSED_NOT_FINITE = "not a finite number"


def joint_effort(names: Sequence[str], positions: int, velocities: int, efforts: Sequence[float],
                 joint: str) -> tuple[tuple[float, ...], str | None]:
    """A JointState command → (its efforts, None) if it commands only `joint`'s effort, else
    (its efforts, the refusal reason). positions, velocities: how many of each it carries."""
    values = tuple(efforts)
    problems = []
    if list(names) != [joint]:
        problems.append(f"names {list(names)}")
    if positions or velocities:
        problems.append(f"{positions} positions and {velocities} velocities")
    if len(values) != 1:
        problems.append(f"{len(values)} efforts")
    if not problems:
        return values, None
    return values, f"{', '.join(problems)}: only effort on {joint} is actuated (name [{joint}], one effort, no position or velocity)"


def timeout_steps(command_timeout: float, dt: float) -> int | None:
    """Steps of silence after which a held command times out: ceil(timeout/dt); None for 0 (never)."""
    return math.ceil(command_timeout / dt - STEP_EPS) if command_timeout > 0 else None


def same(a: float, b: float) -> bool:
    """Bitwise-equal floats (0.0 and −0.0 differ)."""
    return a == b and math.copysign(1.0, a) == math.copysign(1.0, b)


class Inbox:
    """Commands handed from the executor thread to the stepping loop; counts what arrived.

    Each is (source, values, refusal): refusal is the reason an adapter already refused it for
    (e.g. `joint_effort`'s), None if the stepping loop is to check it.

    Lockstep: the stepping loop calls `expect(stamp)` just before it publishes a state; the
    command that answers it is the first one put after that with no stamp (motor_torque,
    effort_commands) or with that stamp (joint_command's header.stamp). A stamped command for
    another state is refused as stale. `waiting` is True until the answer has arrived. Without
    lock (one writer each side, attribute writes atomic): `put` records which stamp it answered,
    so an answer to an older state can never release a newer one.
    """

    def __init__(self) -> None:
        self._queue: collections.deque[tuple[str, tuple[float, ...], str | None]] = collections.deque()
        self.received = 0
        self._expected: int | None = None  # stamp (ns) of the state awaiting its answer; None: not in lockstep
        self._answered: int | None = None  # stamp the last answer was for

    def put(self, source: str, values: Sequence[float], refusal: str | None = None,
            stamp_ns: int | None = None) -> bool:
        """Hand over one command (stamp_ns: its header stamp, None if it has none); True if it
        answers the state the stepping loop waits for."""
        self.received += 1
        expected = self._expected
        answers = expected is not None and (stamp_ns is None or stamp_ns == expected)
        if expected is not None and stamp_ns is not None and stamp_ns != expected and refusal is None:
            refusal = f"lockstep: stamp {stamp_ns} ns answers no state awaited (waiting for {expected} ns)"
        self._queue.append((source, tuple(values), refusal))
        if answers:
            self._answered = expected
        return answers

    def expect(self, stamp_ns: int) -> None:
        """Lockstep: the state stamped `stamp_ns` is about to be published; wait for its answer."""
        self._expected = stamp_ns

    @property
    def waiting(self) -> bool:
        """Lockstep: the state last expected has no answer yet."""
        return self._expected is not None and self._answered != self._expected

    def __bool__(self) -> bool:
        return bool(self._queue)

    def drain(self) -> Iterator[tuple[str, tuple[float, ...], str | None]]:
        while self._queue:
            yield self._queue.popleft()

    def clear(self) -> None:
        self._queue.clear()


@dataclass(frozen=True)
class _Pending:
    torque: float  # N·m, after saturation
    requested: float  # N·m, as received
    source: str  # resolved topic name, or the parameter that changed it
    saturated: bool
    reason: str = ""
    command: bool = True  # False: a lowered max_torque re-saturates the held torque (no new command)


@dataclass
class CommandCounts:
    accepted: int = 0
    refused: int = 0
    saturated: int = 0
    timeouts: int = 0


class TorqueCommands:
    """The held motor torque of a run and the events that change it.

    max_torque: saturation, N·m; command_timeout: sim s without a command before the torque
    falls to 0 (0: hold forever); accepting: False when the scene's profile drives the finger.
    Both limits may be changed between steps (`set_max_torque`, `command_timeout`); they apply
    from the next step: a lowered max_torque also saturates the torque held or pending.
    """

    def __init__(self, timeline: Timeline, *, max_torque: float, command_timeout: float, accepting: bool) -> None:
        self.timeline = timeline
        self.max_torque = max_torque
        self.command_timeout = command_timeout
        self.accepting = accepting
        self.counts = CommandCounts()
        self.held = 0.0  # the command in force, N·m
        self.command_step: int | None = None  # step of this episode at which the last command took effect
        self._pending: _Pending | None = None

    @property
    def command_timeout(self) -> float:
        return self._command_timeout

    @command_timeout.setter
    def command_timeout(self, seconds: float) -> None:
        self._command_timeout = seconds
        self.timeout_steps = timeout_steps(seconds, self.timeline.dt)

    def set_max_torque(self, limit: float) -> None:
        """A new saturation, N·m, from the next step on: a pending command is saturated anew,
        and a held torque beyond it is cut to it (an 'accepted' event from source max_torque,
        which does not restart the command timeout)."""
        self.max_torque = limit
        cmd = self._pending
        if cmd is not None:
            torque = min(max(cmd.requested, -limit), limit)
            self._pending = _Pending(torque, cmd.requested, cmd.source, torque != cmd.requested, cmd.reason, cmd.command)
        elif abs(self.held) > limit:
            self._pending = _Pending(math.copysign(limit, self.held), self.held, "max_torque", True,
                                     f"max_torque set to {limit!r} N·m", command=False)

    def take(self, source: str, values: Sequence[float], step: int, refusal: str | None = None) -> CommandEvent | None:
        """Check one received command (between steps; `step` is the next step's index): None
        if accepted (it takes effect at the next step), else the 'refused' event. `refusal`:
        the reason an adapter refused it for already."""
        if refusal is not None:
            return self.refuse(source, values, refusal, step)
        if not self.accepting:
            return self.refuse(source, values, REFUSED_SCENE, step)
        if len(values) != 1:
            return self.refuse(source, values, f"expected exactly 1 element, got {len(values)}", step)
        value = float(values[0])
        if not math.isfinite(value):
            return self.refuse(source, values, REFUSED_NOT_FINITE, step)
        limit = self.max_torque
        torque = min(max(value, -limit), limit)
        saturated = torque != value
        self.counts.accepted += 1
        self.counts.saturated += saturated
        self._pending = _Pending(torque, value, source, saturated)
        return None

    def refuse(self, source: str, values: Sequence[float], reason: str, step: int) -> CommandEvent:
        """Count and describe a refused command (also for refusals an adapter decides itself)."""
        self.counts.refused += 1
        shown = ", ".join(repr(float(v)) for v in values[:MAX_REQUESTED_SHOWN])
        if len(values) > MAX_REQUESTED_SHOWN:  # a bounded summary: the log and the node's output stay small
            shown += f", … ({len(values)} elements)"
        return self._event("refused", step, requested=shown, source=source, reason=reason)

    def unanswered(self, step: int, timeout: float) -> CommandEvent:
        """Lockstep: the state before step `step` had no answer within `timeout` wall s; the
        command held acts over that step (the 'lockstep_timeout' event)."""
        return self._event("lockstep_timeout", step, reason=f"no command within lockstep_timeout {timeout:g} s "
                                                             "of wall time: holding the last command")

    def torque_for_step(self, n: int) -> tuple[float | None, CommandEvent | None]:
        """The torque of step n (None: the scene's profile), N·m, and the event if it changed."""
        if not self.accepting:
            return None, None
        cmd, self._pending = self._pending, None
        event = None
        if cmd is not None:
            if cmd.command:
                self.command_step = n
            if not same(cmd.torque, self.held):
                self.held = cmd.torque
                event = self._event("accepted", n, requested=repr(cmd.requested), source=cmd.source,
                                    saturated=cmd.saturated, reason=cmd.reason)
        elif (self.timeout_steps is not None and self.command_step is not None
              and n - self.command_step >= self.timeout_steps and not same(self.held, 0.0)):
            self.held = 0.0
            self.counts.timeouts += 1
            event = self._event("timeout", n, reason=f"no command for {self.command_timeout:g} s of sim time")
        return self.held, event

    def reset(self, reason: str) -> CommandEvent:
        """A new episode: no command pending or held; the 'reset' event at its step 0."""
        self._pending, self.held, self.command_step = None, 0.0, None
        return self._event("reset", 0, reason=reason)

    def _event(self, event: str, step: int, *, requested: str = "", source: str = "", saturated: bool = False,
               reason: str = "") -> CommandEvent:
        t = self.timeline
        return CommandEvent(event=event, step=step, episode=t.episode, stamp_ns=t.stamp(step), torque=float(self.held),
                            requested=requested, source=source, saturated=saturated, reason=reason)
