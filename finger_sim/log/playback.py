"""A replay's plan, read-ahead and statistics, free of ROS (the rclpy player is finger_sim.ros.replay).

plan_replay decides from a log's index and the options what `finger_replay` publishes: the
topics, the source of /clock and the log time a pass starts from (rules in finger_sim.ros.replay's
module doc). ReadAhead decompresses chunks on a thread ahead of the player; ReplayStats counts
what a replay did and says it in one line.
"""

from __future__ import annotations

import math
import queue
import threading
from collections.abc import Iterable, Iterator
from dataclasses import dataclass
from enum import Enum
from typing import Any

from mcap.records import Channel, Message, Schema

from .errors import LogArgumentError, LogFileError
from .reader import LogReader

PROG = "finger_replay"
CLOCK_TOPIC = "/clock"
CLOCK_TYPE = "rosgraph_msgs/msg/Clock"
DEFAULT_CLOCK_HZ = 100.0  # generated /clock rate, wall Hz: 10 ms steps, finer than a control loop's timers
WAIT_SLICE_S = 0.1  # longest single wait of ReadAhead.close and of the reader thread on a full queue, s
READ_AHEAD_BATCH = 256  # messages handed from the reader thread to the player at a time
READ_AHEAD_BATCHES = 16  # batches the reader thread may hold ready (~4k messages, a few MB at most)


class ClockSource(Enum):
    """Where the /clock published during a replay comes from."""

    RECORDED = "the log's /clock topic"
    GENERATED = "generated from the log time"
    NONE = "not published"


@dataclass(frozen=True)
class ReplayPlan:
    """What to replay, decided from the log's index and the options before any ROS call.

    topics: recorded topics to republish, with their types ('pkg/msg/Type'); holds /clock
    when clock is RECORDED. origin_ns: log time played at the start of a pass.
    clock_hz: wall rate of the generated /clock (GENERATED only).
    """

    topics: dict[str, str]
    clock: ClockSource
    clock_hz: float | None
    origin_ns: int
    message_count: int  # recorded messages on `topics` (before --start-offset)


def plan_replay(
    reader: LogReader,
    *,
    topics: Iterable[str] | None = None,
    start_offset_s: float = 0.0,
    clock_hz: float | None = None,
    no_clock: bool = False,
) -> ReplayPlan:
    """Decide topics, clock source and start time (see the module docstring for the clock rules).

    Raises LogFileError for a log without messages, with a /clock that is not
    rosgraph_msgs/msg/Clock or a selected topic that is not CDR; MissingTopicsError for unknown
    `topics`; LogArgumentError for a start offset past the end or if nothing would be published.
    """
    if reader.start_ns is None or reader.end_ns is None or reader.message_count == 0:
        raise LogFileError(reader.path, "no messages to replay")
    recorded = reader.topics.get(CLOCK_TOPIC)
    if recorded is not None and recorded.type != CLOCK_TYPE:
        raise LogFileError(reader.path, f"{CLOCK_TOPIC} has type {recorded.type}, not {CLOCK_TYPE}")
    if topics is None:
        selected = set(reader.topics)
    else:
        selected = set(topics)
        reader.require_topics(selected)
    selected.discard(CLOCK_TOPIC)  # /clock follows the clock options
    if no_clock:
        clock = ClockSource.NONE
    elif recorded is not None and clock_hz is None:
        clock, selected = ClockSource.RECORDED, selected | {CLOCK_TOPIC}
    else:
        clock, clock_hz = ClockSource.GENERATED, DEFAULT_CLOCK_HZ if clock_hz is None else clock_hz
    if not (math.isfinite(start_offset_s) and 0 <= start_offset_s <= reader.duration_s):
        expected = f"seconds from 0 to the log's duration, {reader.duration_s:.6g}"
        raise LogArgumentError("--start-offset", expected, start_offset_s)
    for topic in sorted(selected):
        if reader.topics[topic].encoding != "cdr":
            problem = f"{topic} is encoded as {reader.topics[topic].encoding!r}, not ROS 2 CDR"
            raise LogFileError(reader.path, problem)
    count = sum(reader.topics[t].count for t in selected)
    if count == 0:
        expected = "topics with messages (the selected ones have none)"
        raise LogArgumentError("--topics", expected, sorted(selected))
    return ReplayPlan(
        topics={t: reader.topics[t].type for t in sorted(selected)},
        clock=clock,
        clock_hz=clock_hz if clock is ClockSource.GENERATED else None,
        origin_ns=reader.start_ns + round(start_offset_s * 1e9),
        message_count=count,
    )


def raw_messages(
    reader: LogReader, topics: Iterable[str], start_ns: int
) -> Iterator[tuple[Schema | None, Channel, Message]]:
    """The recorded (schema, channel, message) records of `topics` logged at or after `start_ns`:
    `LogReader.raw_messages` (log-time order; file order up to the cut of a truncated log)."""
    return reader.raw_messages(topics, start_ns=start_ns)


class ReadAhead:
    """Iterates `source` on a thread, up to READ_AHEAD_BATCHES batches ahead of the consumer.

    mcap reads a whole chunk (~1500 messages of a 1 kHz log, 5 ms) at the first next() into it;
    on the player's thread that stall would delay every message due meanwhile. The thread does
    that work while the player sleeps, as rosbag2's player does with its read-ahead queue. An
    exception in `source` is raised by the consumer's next(), after the items before it.
    A context manager: leaving it stops the thread, also when the consumer stops early.
    """

    _END = object()

    def __init__(self, source: Iterator[Any]) -> None:
        self._source = source
        self._queue: queue.Queue[Any] = queue.Queue(maxsize=READ_AHEAD_BATCHES)
        self._cancelled = threading.Event()
        self._thread = threading.Thread(target=self._read, name="finger_replay read-ahead", daemon=True)
        self._thread.start()

    def __enter__(self) -> ReadAhead:
        return self

    def __exit__(self, *exc_info: object) -> None:
        self.close()

    def __iter__(self) -> Iterator[Any]:
        while True:
            batch = self._queue.get()
            if batch is self._END:
                return
            if isinstance(batch, BaseException):
                raise batch
            yield from batch

    def close(self) -> None:
        """Stop the thread (it may be blocked on a full queue) and wait for it."""
        self._cancelled.set()
        while self._thread.is_alive():
            try:
                self._queue.get(timeout=WAIT_SLICE_S)
            except queue.Empty:
                pass

    def _read(self) -> None:
        batch: list[Any] = []
        try:
            for item in self._source:
                batch.append(item)
                if len(batch) >= READ_AHEAD_BATCH:
                    self._put(batch)
                    batch = []
                if self._cancelled.is_set():
                    return
            self._put(batch)
            self._put(self._END)
        except BaseException as exc:  # handed to the consumer, raised there; it must not wait forever
            self._put(batch)
            self._put(exc)
        finally:
            close = getattr(self._source, "close", None)
            if close is not None:
                close()  # a generator closes its file

    def _put(self, item: Any) -> None:
        while not self._cancelled.is_set():
            try:
                self._queue.put(item, timeout=WAIT_SLICE_S)
                return
            except queue.Full:
                pass


@dataclass
class ReplayStats:
    """What a replay did; times on time.monotonic(), s."""

    published: int = 0
    clock_ticks: int = 0  # generated /clock messages
    passes: int = 0  # passes through the log that published a message (the last one may be cut short)
    first_due: float | None = None
    last_due: float | None = None
    last_wall: float | None = None
    total_late_s: float = 0.0
    max_late_s: float = 0.0
    stopped_by: str | None = None  # name of the signal that stopped the replay

    def record(self, due: float, wall: float) -> None:
        if self.first_due is None:
            self.first_due = due
        self.last_due, self.last_wall = due, wall
        late = wall - due
        self.total_late_s += late
        self.max_late_s = max(self.max_late_s, late)
        self.published += 1

    @property
    def wall_s(self) -> float:
        """Wall time from the first message's due time to the last publication, s."""
        return 0.0 if self.first_due is None else self.last_wall - self.first_due

    def achieved_rate(self, rate: float) -> float | None:
        """Log time played per wall second (at most the requested rate); None below 2 messages.

        Counted from the first message's due time, so a late start or end lowers it.
        """
        if self.wall_s <= 0:
            return None
        return rate * (self.last_due - self.first_due) / self.wall_s

    def summary(self, rate: float, topics: int) -> str:
        achieved = self.achieved_rate(rate)
        text = f"{PROG}: published {self.published} messages on {topics} topics in {self.wall_s:.3f} s"
        if achieved is not None:
            text += f" ({self.published / self.wall_s:.0f} msg/s): {achieved:.4g}x recorded time"
        text += f" (requested {rate:g}x)"
        if self.published:
            text += (f", lateness mean {1e3 * self.total_late_s / self.published:.3f} ms"
                     f" max {1e3 * self.max_late_s:.3f} ms")
        if self.clock_ticks:
            text += f", {self.clock_ticks} /clock ticks generated"
        if self.passes > 1:
            text += f", {self.passes} passes"
        if self.stopped_by:
            text += f", stopped by {self.stopped_by}"
        return text
