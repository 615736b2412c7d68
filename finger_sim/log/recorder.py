"""A non-blocking, crash-tolerant MCAP recorder for ROS 2 messages that rosbag2 tools can read.

Life cycle: `McapRecorder(path)` → `open()` → `register_channel()` … → `write()` and
`add_metadata()` … → `close()` (safe to call twice); or `with McapRecorder(path) as rec: …`.

The file is what `ros2 bag record -s mcap` writes: header profile 'ros2'; one schema per type,
named 'pkg/msg/Type', encoding 'ros2msg', holding the complete concatenated definition
(finger_sim.log.definitions); one channel per absolute topic with message encoding 'cdr';
messages with the caller's log and publish times (ns) and a per-channel sequence number
counted from 1 (a message dropped before the queue leaves a gap); compressed chunks (zstd
by default) with CRCs and message indexes; close() writes the summary (statistics, chunk and
metadata indexes).

QoS: a channel registered with its publisher's QoS carries 'offered_qos_profiles' metadata
as rosbag2 Jazzy writes it (finger_sim.log.qos); one registered without has no such key, which
rosbag2 reads as "no recorded offers" (replay with its default QoS). The file has no 'rosbag2'
metadata record, so rosbag2 parses the QoS text with its current bag-metadata version.

Crash safety: a chunk is closed (by the writer process) — written and flushed to the operating system — before a
message that would stretch its log-time span to `chunk_interval_s`, once its uncompressed
payload reaches `chunk_size`, after `idle_flush_s` wall seconds without messages, and once it
has been open for `chunk_wall_s` wall seconds whatever arrives: a paused sim whose log time stands
still while diagnostics and commands keep coming loses at most that much wall time to a kill -9. Closing uses `mcap.writer.Writer.flush()` (mcap >= 1.5); the
Writer's own size trigger is set out of reach so that every chunk boundary goes through it. A
`kill -9` of the caller loses what it had not handed over yet (at most handover_s while the
writer keeps up; a starved writer leaves more in the caller's buffer, what the pipe cannot hold)
and the summary: the writer process (in its own session, so a signal to the caller's process group does
not reach it) sees its input end, writes the open chunk and exits. The prefix stays readable by
linear readers (mcap's StreamReader, finger_sim.log.reader).

Serialization happens in the caller, so a message object may be reused as soon as write()
returns. CDR bytes are written as given. Messages are encoded by mcap_ros2 from the channel's
schema (its `_dynamic.serialize_dynamic`, the encoder its own Writer uses): plain objects or
dicts with the message's fields, e.g. messages decoded by finger_sim.log.reader, and rclpy
messages read attribute by attribute (~30 µs for a JointState). rclpy values that encoder
does not take (numpy arrays of fixed-size fields, `byte` scalars) go through rclpy's
serialize_message and a decode first (two to three times slower). rclpy's bytes are never
written as they are: rmw sizes that buffer by an estimate and leaves uninitialised padding
and trailing bytes, so files would differ run to run and strict readers (rosbags) reject
the trailing bytes.

Processes: all file I/O and all of mcap's writing run in a writer process
(finger_sim.log.writer_process), so that building chunks and compressing them never holds the
caller's GIL. The caller only checks, serializes and appends one reference to a pending list
(a message's channel and bytes, or write_records' whole state: no record built, no wake-up); a
sender thread takes the list every `handover_s` wall seconds (earlier when half of `queue_size`
is waiting, or at close), builds the MCAP records of a batch of states at once (numbering each
channel's messages in order) and hands them over through a pipe, so a 1 kHz node's stepping
thread pays neither the packing nor the hand-over; a status thread takes the writer process's
counts. A message waits until the writer process has read it; more than
`queue_size` waiting messages, an unwritable path or a full disk never raise and never block the
caller: each kind of trouble is reported once through `on_problem` (default: logger
'finger_sim.log'; called from the status thread for I/O trouble), the first I/O failure is kept
in `error`, and the lost messages are counted in `dropped`. After an I/O error the recorder
writes nothing more. After close(), written + dropped == the number of write() calls that did
not raise. The writer process ends with the caller: at close(), or when its input ends because
the caller died (it then keeps what it was handed, without a summary).

Back-pressure: with `back_pressure` True (settable while open; a node running as fast as
possible sets it) a full queue blocks write() until the writer process has read some of it,
instead of dropping: when there is no deadline to meet, losing data is never the right trade.

Loss in the file: with `status_record` set, close() adds a metadata record of that name (before
the summary) with the messages handed to the writer and those dropped, in total and by topic
(`RECORDING_METADATA` keys), so a reader can tell a complete log from one with gaps without
the process that wrote it.

CPU: `cpu()` says what the recorder has cost so far (RecorderCpu): its callers' time inside
write_records (one call in CPU_SAMPLE_EVERY timed on the caller's thread CPU clock), its sender and
status threads and its writer process (their kernel counters, finger_sim.log.cpu_clocks). The two
threads name themselves 'mcap sender' and 'mcap status' to the operating system (`top -H`).

Creation: the file is created under a temporary name in the same folder, its header written
and flushed, and only then renamed to `path`, so a kill at any moment leaves either no file
or one that starts with a whole header (finger_sim.log.repair turns it into a valid log).
"""

from __future__ import annotations

import contextlib
import fcntl
import logging
import math
import operator
import os
import re
import subprocess
import sys
import threading
import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from enum import Enum, auto
from pathlib import Path
from time import thread_time_ns
from types import TracebackType
from typing import Any

from mcap.records import Schema
from mcap.well_known import MessageEncoding, SchemaEncoding
from mcap.writer import CompressionType
from mcap_ros2._dynamic import serialize_dynamic
from mcap_ros2.decoder import DecoderFactory

from .cpu_clocks import name_os_thread, process_cpu_ns, task_cpu_ns
from .definitions import message_definition, normalize_type_name, type_name_of
from .errors import LogArgumentError, RecorderStateError
from . import writer_process
from .qos import OFFERED_QOS_PROFILES, offered_qos_profiles
from .writer_process import (HEADER, MAX_CHANNELS, MESSAGE_FIELDS, MESSAGE_OPCODE, Close, Metadata, Register, Start, control_record,
                             close_run, open_run)

DEFAULT_CHUNK_INTERVAL_S = 0.5  # log-time span of one chunk: what a kill -9 may lose
DEFAULT_CHUNK_SIZE = 1 << 20  # uncompressed bytes; bounds memory if an interval holds many messages
DEFAULT_QUEUE_SIZE = 10_000  # pending messages (~1 s of a 1 kHz node's six topics) before dropping
MAX_QUEUED_BYTES = 64 << 20  # pending payload bytes before dropping: a few huge messages cannot fill memory
DEFAULT_IDLE_FLUSH_S = 1.0  # wall seconds without messages after which the open chunk is closed
DEFAULT_CHUNK_WALL_S = 1.0  # wall seconds after which an open chunk is closed, whatever its log-time span
#: Wall seconds between handovers to the writer process. Its CPU, the sender's and the status thread's
#: at a node's few messages a step is largely per handover: 0.1 s cost the three about 3.5 µs a 1 kHz
#: step more than 0.25 s, and 0.25 s about 3 µs more than 0.5 s in the node (docs/node_performance.md).
#: A kill -9 of the caller loses at most this much: as much log time as one chunk holds.
DEFAULT_HANDOVER_S = 0.5
_PIPE_BYTES = 1 << 20  # the pipe to the writer process: Linux's default pipe-max-size (its default is 64 kB)
MAX_METADATA_BYTES = 1 << 16  # UTF-8 bytes of one metadata record's keys and values
_MAX_TIME_NS = 1 << 64  # MCAP timestamps are uint64
_SEQUENCE_MODULUS = 1 << 32  # MCAP sequence numbers are uint32: they wrap
#: write_records calls per one timed by the caller's thread CPU clock (`cpu()`): its three reads are system
#: calls (~0.5 µs each warm, more cold), as dear as the call they time; one call in 32 adds ~50 ns a call.
CPU_SAMPLE_EVERY = 32
#: The usual name of the status record (finger_sim's nodes write it; LogReader.dropped reads it).
RECORDING_STATUS = "recording"
#: The keys of the status record written at close (see `status_record`).
MESSAGES_RECORDED, MESSAGES_DROPPED, DROPPED_BY_TOPIC = "messages_recorded", "messages_dropped", "dropped_by_topic"
#: Longest a blocked write() waits before it checks the recorder's state again, wall s.
_BACK_PRESSURE_POLL_S = 0.1
_TOPIC = re.compile(r"^(/[A-Za-z_][A-Za-z0-9_]*)+$")  # absolute, fully expanded ROS 2 topic name

_logger = logging.getLogger("finger_sim.log")
_pack_header = HEADER.pack


class _State(Enum):
    NEW = "not open yet"
    OPEN = "open"
    CLOSED = "closed"


class _Problem(Enum):
    """Kinds of trouble, each reported once per recorder."""

    QUEUE_FULL = auto()
    IO = auto()
    CLOSED = auto()  # write() after close()
    STUCK = auto()  # close() timed out


@dataclass(frozen=True, slots=True)
class _Codec:
    """CDR encoder and decoder of one type, both built from the definition stored in the file."""

    definition: str
    encode: Callable[[Any], bytes]
    decode: Callable[[bytes], Any]


@dataclass(slots=True, eq=False)  # compared by identity (`None in channels` in C, no __eq__ call)
class _Channel:
    index: int  # in the writer process's Register records
    type_name: str
    codec: _Codec
    last_sequence: int = 0
    record_id: int = 0  # the channel id in the file's records: index + 1

    def __post_init__(self) -> None:
        self.record_id = self.index + 1


@dataclass(frozen=True, slots=True)
class RecorderCpu:
    """The CPU s a recorder has cost so far, by where it ran.

    caller_s: its callers' threads inside write_records (a node's stepping thread handing over each
        state), estimated from one call in CPU_SAMPLE_EVERY timed with the calling thread's CPU clock,
        the clock reads' own cost (a pair read just before, in the same state of the caches) taken off;
        write() and the serializing a caller does before are not in it. Made for one calling thread (a
        node's): callers contending on several threads make it err high (a timed call also catches the
        GIL's hand-overs; 2.4x once in a test of two threads calling back to back).
    threads_s: its sender and status threads.
    writer_s: its writer process (all its threads).
    """

    caller_s: float = 0.0
    threads_s: float = 0.0
    writer_s: float = 0.0

    @property
    def total_s(self) -> float:
        return self.caller_s + self.threads_s + self.writer_s


class McapRecorder:
    """Records ROS 2 messages to one MCAP file without blocking the caller. Thread-safe.

    path: the .mcap file, overwritten if it exists.
    chunk_interval_s: longest log-time span of a chunk (s of the caller's clock, e.g. sim time).
    chunk_size: uncompressed bytes after which a chunk is closed whatever its span.
    compression: chunk compression (mcap.writer.CompressionType).
    queue_size: messages that may wait for the writer process before new ones are dropped.
    idle_flush_s: wall seconds without messages after which the open chunk is closed.
    chunk_wall_s: wall seconds after its first message after which a chunk is closed.
    handover_s: wall seconds between two handovers of what the caller buffered to the writer process.
    time_offset_ns: added to every message's log and publish time (e.g. a wall-clock start
        for a caller whose clock starts at 0).
    on_problem: called once per kind of trouble with a one-line description.
    back_pressure: a full queue blocks write() until there is room, instead of dropping.
    status_record: name of the metadata record close() writes with the counts of messages
        recorded and dropped (None: none).
    """

    def __init__(
        self,
        path: str | os.PathLike[str],
        *,
        chunk_interval_s: float = DEFAULT_CHUNK_INTERVAL_S,
        chunk_size: int = DEFAULT_CHUNK_SIZE,
        compression: CompressionType = CompressionType.ZSTD,
        queue_size: int = DEFAULT_QUEUE_SIZE,
        idle_flush_s: float = DEFAULT_IDLE_FLUSH_S,
        chunk_wall_s: float = DEFAULT_CHUNK_WALL_S,
        handover_s: float = DEFAULT_HANDOVER_S,
        on_problem: Callable[[str], None] | None = None,
        time_offset_ns: int = 0,
        back_pressure: bool = False,
        status_record: str | None = None,
    ) -> None:
        if not (math.isfinite(chunk_interval_s) and chunk_interval_s > 0):
            raise LogArgumentError("chunk_interval_s", "a finite number > 0", chunk_interval_s)
        if chunk_size < 1:
            raise LogArgumentError("chunk_size", "an int >= 1", chunk_size)
        if queue_size < 1:
            raise LogArgumentError("queue_size", "an int >= 1", queue_size)
        if not (math.isfinite(idle_flush_s) and idle_flush_s > 0):
            raise LogArgumentError("idle_flush_s", "a finite number > 0", idle_flush_s)
        if not (math.isfinite(chunk_wall_s) and chunk_wall_s > 0):
            raise LogArgumentError("chunk_wall_s", "a finite number > 0", chunk_wall_s)
        if not (math.isfinite(handover_s) and handover_s > 0):
            raise LogArgumentError("handover_s", "a finite number > 0", handover_s)
        if not isinstance(compression, CompressionType):
            raise LogArgumentError("compression", "a mcap.writer.CompressionType", compression)
        self._path = Path(path)
        self._interval_ns = round(chunk_interval_s * 1e9)
        self._chunk_size = chunk_size
        self._offset_ns = _as_time_ns("time_offset_ns", time_offset_ns)
        self._time_limit_ns = _MAX_TIME_NS - self._offset_ns  # caller times at or past it overflow uint64
        self._compression = compression
        self._queue_size = queue_size
        self._half_queue = queue_size // 2  # waiting messages that wake the sender before its handover time
        self._idle_flush_s = idle_flush_s
        self._chunk_wall_s = chunk_wall_s
        self._on_problem = on_problem if on_problem is not None else _logger.warning
        self._handover_s = handover_s
        # What the writer process is to get, in order (appended and taken under _lock; `_records` builds it)
        self._pending: list[_Pending] = []
        self._wake = threading.Event()  # set at close or when half of queue_size waits
        self._room = threading.Event()  # set by the status thread after each report of the writer process
        self.back_pressure = back_pressure
        self._status_record = status_record
        self._dropped_by_topic: dict[str, int] = {}  # caller side, under _lock
        self._queued = 0  # messages appended to the buffer (caller side, under _lock)
        self._taken = 0  # messages the writer process has read (status thread only)
        self._queued_bytes = self._taken_bytes = 0  # their payload bytes, counted on the same sides
        # Guards state, sequences, dropped, the buffer. Reentrant: a signal handler that calls
        # close() while the interrupted main thread is inside write() must not deadlock.
        self._lock = threading.RLock()
        self._report_lock = threading.Lock()
        self._state = _State.NEW
        self._process: subprocess.Popen[bytes] | None = None
        self._sender: threading.Thread | None = None
        self._listener: threading.Thread | None = None
        self._broken = False  # the writer process is gone (or its pipe failed)
        self._finished = False  # the writer process reported the file finished
        self._start = Start(str(self._path), self._interval_ns, chunk_size, compression.value, idle_flush_s,
                            chunk_wall_s)
        self._channels: dict[str, _Channel] = {}
        # write_records' last topic list and its channels, one tuple: replaced whole, read whole (threads)
        self._last_batch: tuple[list[str], list[_Channel]] = ([], [])
        self._codecs: dict[str, _Codec] = {}
        self._reported: set[_Problem] = set()
        self._written = 0  # reported by the writer process (status thread only)
        self._dropped = 0  # caller side, under _lock
        self._lost = 0  # writer process: handed over, then hit by an I/O error
        self._error: str | None = None
        # CPU accounting (`cpu()`): write_records calls until the next timed one, the timed calls' CPU ns,
        # the last reading of each thread and of the writer process
        self._calls_to_sample = CPU_SAMPLE_EVERY
        self._sampled_ns = 0
        self._cpu_ns: dict[str, int] = {}

    # -- life cycle -------------------------------------------------------------------------

    def open(self) -> McapRecorder:
        """Start the writer process, which creates the file. Raises RecorderStateError if reopened."""
        with self._lock:
            if self._state is not _State.NEW:
                raise RecorderStateError("open", self._state.value)
            self._state = _State.OPEN
            self._pending.append(control_record(self._start))
        self._start_process()
        return self

    def close(self, timeout_s: float | None = None) -> None:
        """Write what is queued, the open chunk and the summary, then close the file.

        Blocks until done, or for at most `timeout_s` seconds (then reports it once).
        Idempotent; a recorder never opened just becomes closed.
        """
        with self._lock:
            if self._state is _State.CLOSED:
                return
            was_open, self._state = self._state is _State.OPEN, _State.CLOSED
            if was_open:
                if self._status_record is not None:
                    self._pending.append(control_record(Metadata(self._status_record, self._status())))
                self._pending.append(control_record(Close()))
                self._wake.set()
        if not was_open or self._process is None:
            return
        assert self._sender is not None and self._listener is not None
        deadline = None if timeout_s is None else time.monotonic() + timeout_s
        for thread in (self._sender, self._listener):  # the listener ends when the writer process does
            thread.join(None if deadline is None else max(0.0, deadline - time.monotonic()))
        if self._listener.is_alive():
            self._report(_Problem.STUCK, f"MCAP recorder {self._path}: writer still busy after "
                         f"{timeout_s} s; the file may lack its summary")
            return
        self._process.wait()
        if not self._finished:  # the writer process died: what it did not report written is lost
            self._lost = self._queued - self._written

    def __enter__(self) -> McapRecorder:
        return self.open()

    def __exit__(self, exc_type: type[BaseException] | None, exc: BaseException | None,
                 tb: TracebackType | None) -> None:
        self.close()

    # -- setup --------------------------------------------------------------------------------

    def register_channel(
        self, topic: str, msg_type: str | type, *, definition: str | None = None, qos: Any = None
    ) -> None:
        """Declare a topic and its type (an rclpy message class or 'pkg/msg/Type').

        definition: the complete 'ros2msg' text (e.g. a schema copied from another log); by default
        built from the installed .msg files (MessageDefinitionNotFoundError if one is missing).
        qos: the rclpy QoSProfile of the topic's publisher, stored as the channel's
        `offered_qos_profiles` (finger_sim.log.qos) so that `ros2 bag play` offers it; without
        it the channel has no such key and rosbag2 replays with its default QoS.
        Registering a topic again with the same type does nothing; with another type, or a type
        again with a different definition, raises LogArgumentError.
        """
        if not isinstance(topic, str) or not _TOPIC.match(topic):
            raise LogArgumentError("topic", "an absolute ROS 2 name such as '/joint_states'", topic)
        type_name = normalize_type_name(msg_type) if isinstance(msg_type, str) else type_name_of(msg_type)
        metadata = {} if qos is None else {OFFERED_QOS_PROFILES: offered_qos_profiles(qos)}
        existing = self._channels.get(topic)
        if existing is not None:
            if existing.type_name != type_name:
                expected = f"{existing.type_name} (as registered for {topic})"
                raise LogArgumentError("msg_type", expected, type_name)
            return
        codec = self._codecs.get(type_name)
        if codec is None:
            codec = _codec(type_name, message_definition(type_name) if definition is None else definition)
        elif definition is not None and definition != codec.definition:
            expected = f"the text registered before for {type_name}"
            raise LogArgumentError("definition", expected, "another text")
        with self._lock:
            self._require_open("register a channel")
            self._codecs[type_name] = codec
            if len(self._channels) >= MAX_CHANNELS:
                raise LogArgumentError("topic", f"one of at most {MAX_CHANNELS} channels", topic)
            channel = self._channels[topic] = _Channel(len(self._channels), type_name, codec)
            self._pending.append(control_record(Register(channel.index, topic, type_name, codec.definition, metadata)))

    def add_metadata(self, name: str, data: Mapping[str, str]) -> None:
        """Queue a metadata record (e.g. scene YAML, parameters, version) of at most
        MAX_METADATA_BYTES (UTF-8 bytes of keys and values); LogArgumentError if larger."""
        if not isinstance(name, str) or not name:
            raise LogArgumentError("name", "a non-empty str", name)
        if not all(isinstance(k, str) and isinstance(v, str) for k, v in data.items()):
            raise LogArgumentError("data", "a mapping of str to str", data)
        size = sum(len(k.encode()) + len(v.encode()) for k, v in data.items())
        if size > MAX_METADATA_BYTES:
            raise LogArgumentError(f"metadata record {name!r}", f"at most {MAX_METADATA_BYTES} bytes", f"{size} bytes")
        with self._lock:
            self._require_open("add metadata")
            self._pending.append(control_record(Metadata(name, dict(data))))

    # -- hot path -----------------------------------------------------------------------------

    def write(
        self, topic: str, message: Any, log_time_ns: int, *, publish_time_ns: int | None = None
    ) -> bool:
        """Buffer one message; True if buffered, False if dropped. Never blocks, never raises
        for I/O trouble.

        message: CDR bytes, an rclpy message of the topic's type, or an object or dict with
        its fields. log_time_ns, publish_time_ns: ns on the caller's clock (sim time);
        publish defaults to log. Raises LogArgumentError for an unregistered topic, a message
        that does not fit the topic's type or a bad time, and RecorderStateError before
        open(); after close() the message is dropped and counted.
        """
        # The hot path (a node's CDR bytes and int times) takes the cheapest checks first.
        offset = self._offset_ns
        if type(log_time_ns) is int and 0 <= log_time_ns < self._time_limit_ns:
            log_ns = log_time_ns + offset
        else:
            log_ns = self._time_ns("log_time_ns", log_time_ns)
        publish_ns = log_ns if publish_time_ns is None else self._time_ns("publish_time_ns", publish_time_ns)
        if self._state is _State.NEW:
            raise RecorderStateError("write", self._state.value)
        channel = self._channels.get(topic)
        if channel is None and self._state is _State.OPEN:
            registered = ", ".join(self._channels) or "none yet"
            raise LogArgumentError("topic", f"a registered topic ({registered})", topic)
        if type(message) is bytes:  # immutable: kept as it is, no copy
            data = message
        else:
            data = self._serialized(topic, channel, message) if channel is not None else b""
        if self.back_pressure:
            self._wait_for_room()
        with self._lock:
            if self._state is not _State.OPEN or channel is None:  # closed, maybe meanwhile
                self._dropped += 1
                problem, text = _Problem.CLOSED, f"MCAP recorder {self._path} is closed; dropping messages"
            elif ((waiting := self._queued - self._taken) >= self._queue_size
                  or (waiting and self._queued_bytes - self._taken_bytes + len(data) > MAX_QUEUED_BYTES)):
                self._dropped += 1
                self._dropped_by_topic[topic] = self._dropped_by_topic.get(topic, 0) + 1
                self._pending.append(channel)  # its number is spent: the gap tells a reader where the drop was
                problem, text = _Problem.QUEUE_FULL, (
                    f"MCAP recorder {self._path}: {waiting} messages wait for the writer "
                    f"({self._queued_bytes - self._taken_bytes} bytes; limits {self._queue_size} and {MAX_QUEUED_BYTES}); "
                    "dropping messages (see the dropped count)"
                )
            else:
                self._pending.append(((channel,), (data,), log_ns, publish_ns))
                self._queued += 1
                self._queued_bytes += len(data)
                if waiting == self._half_queue:
                    self._wake.set()  # a burst: take it before the bound is reached
                return True
        self._report(problem, text)
        return False

    def write_batch(self, messages: Sequence[tuple[str, bytes]], log_time_ns: int) -> int:
        """Buffer several messages of CDR bytes at one log time (publish time the same), in
        order: what write() does for each, under one lock and one check of the queue's room
        (a node's state of one step, ~22 messages for a 10-finger hand). Returns how many were
        buffered; the rest were dropped and counted exactly as write() would have."""
        return self.write_records([topic for topic, _ in messages], [data for _, data in messages], log_time_ns)

    def write_records(self, topics: Sequence[str], datas: Sequence[bytes], log_time_ns: int, _timed: bool = False) -> int:
        """write_batch with the topics and their CDR bytes as two parallel sequences: a caller that
        hands over the same topics every step (a node's state) builds no object per message, the
        channels of the last topic list are looked up once (compared, not hashed), and the state
        is kept as one reference (its records are built by the sender thread, `_records`).
        One call in CPU_SAMPLE_EVERY is timed on the caller's CPU clock (`cpu()`; `_timed`: that call)."""
        if not _timed:
            self._calls_to_sample -= 1
            if self._calls_to_sample <= 0:  # <=: two calling threads may both count one call down past 0
                return self._timed_write_records(topics, datas, log_time_ns)
        if len(topics) != len(datas):
            raise LogArgumentError("datas", f"one CDR message per topic ({len(topics)})", f"{len(datas)} messages")
        last_topics, channels = self._last_batch  # only lists of registered topics are kept
        if topics != last_topics:  # not the last state's topics (equal str objects compare by identity)
            get = self._channels.get
            channels = [get(topic) for topic in topics]  # type: ignore[misc]
            if None in channels:
                return self._write_each(topics, datas, log_time_ns)  # its checks and errors
            self._last_batch = (list(topics), channels)
        # The fewest operations on the hot path: a 1 kHz caller runs it with cold caches (~3.5 µs, against 1.2 µs
        # back to back); one loop checks the types and adds the sizes (a paced loop: 0.72x the set test and two maps).
        # The recorder's state is checked under the lock only: a recorder not open takes the slow path there.
        if type(log_time_ns) is not int or not 0 <= log_time_ns < self._time_limit_ns:
            return self._write_each(topics, datas, log_time_ns)
        size = 0
        for data in datas:
            if type(data) is not bytes:  # bytes are immutable: kept as they are, no copy
                return self._write_each(topics, datas, log_time_ns)
            size += len(data)
        if self.back_pressure:
            self._wait_for_room()
        count = len(datas)
        log_ns = log_time_ns + self._offset_ns
        with self._lock:
            waiting = self._queued - self._taken
            fits = (self._state is _State.OPEN and waiting + count <= self._queue_size
                    and (not waiting or self._queued_bytes - self._taken_bytes + size <= MAX_QUEUED_BYTES))
            if fits:
                self._pending.append((channels, tuple(datas), log_ns, log_ns))  # type: ignore[arg-type]
                self._queued += count
                self._queued_bytes += size
                if waiting < self._half_queue <= waiting + count:
                    self._wake.set()  # a burst: take it before the bound is reached
        if not fits:  # outside the lock: a blocked write() (back-pressure) must let the sender take the buffer
            return self._write_each(topics, datas, log_time_ns)
        return count

    def _timed_write_records(self, topics: Sequence[str], datas: Sequence[bytes], log_time_ns: int) -> int:
        """write_records timed on the calling thread's CPU clock: three reads, the first two giving the
        reads' own cost in the same (cold or warm) state of the caches, taken off the time of the call."""
        self._calls_to_sample = CPU_SAMPLE_EVERY
        first = thread_time_ns()
        start = thread_time_ns()
        try:
            return self.write_records(topics, datas, log_time_ns, True)
        finally:
            self._sampled_ns += thread_time_ns() - start - (start - first)

    def _write_each(self, topics: Sequence[str], datas: Sequence[Any], log_time_ns: int) -> int:
        """write() of each message in turn: how many were buffered."""
        return sum(self.write(topic, data, log_time_ns) for topic, data in zip(topics, datas))

    @property
    def path(self) -> Path:
        """The file being written."""
        return self._path

    def cpu(self) -> RecorderCpu:
        """The CPU this recorder has cost so far (RecorderCpu), read from the kernel's counters
        (cpu_clocks): ~30 µs, for a report, not for every step. Any thread; after close, the last
        readings. Its threads and writer process count from their start (none before `open`)."""
        pid, seen = os.getpid(), self._cpu_ns
        for key, thread in (("sender", self._sender), ("status", self._listener)):
            if thread is not None and thread.native_id is not None:
                seen[key] = max(task_cpu_ns(pid, thread.native_id) or 0, seen.get(key, 0))
        if self._process is not None:
            seen["writer"] = max(process_cpu_ns(self._process.pid) or 0, seen.get("writer", 0))
        return RecorderCpu(caller_s=max(self._sampled_ns, 0) * CPU_SAMPLE_EVERY / 1e9,
                           threads_s=(seen.get("sender", 0) + seen.get("status", 0)) / 1e9,
                           writer_s=seen.get("writer", 0) / 1e9)

    @property
    def written(self) -> int:
        """Messages in chunks that reached the file (flushed to the operating system)."""
        return self._written

    @property
    def writer_pid(self) -> int | None:
        """The writer process's pid (None before `open`): it outlives a killed caller until it has
        written what it was handed."""
        return self._process.pid if self._process is not None else None

    @property
    def dropped(self) -> int:
        """Messages lost: queue full, written after close, or hit by an I/O error."""
        return self._dropped + self._lost

    @property
    def error(self) -> str | None:
        """The first failure to write the file (cannot create it, write failed, disk full), or None.

        Set by the writer thread; from then on every message is dropped.
        """
        return self._error

    # -- internals ----------------------------------------------------------------------------

    def _wait_for_room(self) -> None:
        """Back-pressure: block while the queue is full and the writer can still take it."""
        while (self._queued - self._taken >= self._queue_size and self._state is _State.OPEN and self._error is None
               and not self._broken):
            self._wake.set()
            self._room.wait(_BACK_PRESSURE_POLL_S)
            self._room.clear()

    def _status(self) -> dict[str, str]:
        """The status record: messages handed to the writer and dropped (in total and by topic)."""
        by_topic = ", ".join(f"{topic}={n}" for topic, n in sorted(self._dropped_by_topic.items()))
        return {MESSAGES_RECORDED: str(self._queued), MESSAGES_DROPPED: str(self._dropped), DROPPED_BY_TOPIC: by_topic}

    def _serialized(self, topic: str, channel: _Channel, message: Any) -> bytes:
        if isinstance(message, (bytes, bytearray, memoryview)):
            return bytes(message)
        is_rclpy = hasattr(type(message), "get_fields_and_field_types")
        if is_rclpy and (got := type_name_of(message)) != channel.type_name:
            raise LogArgumentError("message", f"a {channel.type_name} for {topic}", got)
        try:
            if is_rclpy:
                try:
                    return channel.codec.encode(message)
                except Exception:  # a numpy array or a byte scalar: let rclpy lay the values out
                    # Imported here: offline tools never hand over rclpy messages and need no ROS.
                    from rclpy.serialization import serialize_message

                    message = channel.codec.decode(serialize_message(message))
            return channel.codec.encode(message)
        except Exception as exc:  # rclpy's and mcap_ros2's encoders raise assorted types on a misfit
            expected = f"the fields of {channel.type_name} for {topic}"
            raise LogArgumentError("message", expected, exc) from exc

    def _time_ns(self, argument: str, value: Any) -> int:
        """A caller's time plus the offset as an MCAP timestamp, or LogArgumentError."""
        ns = _as_time_ns(argument, value)
        if ns >= self._time_limit_ns:
            raise LogArgumentError(argument, f"0 <= ns < 2**64 - time_offset_ns ({self._offset_ns})", value)
        return ns + self._offset_ns

    def _require_open(self, action: str) -> None:
        if self._state is not _State.OPEN:
            raise RecorderStateError(action, self._state.value)

    def _report(self, problem: _Problem, text: str) -> None:
        with self._report_lock:
            if problem in self._reported:
                return
            self._reported.add(problem)
        self._on_problem(text)

    def _start_process(self) -> None:
        """Start the writer process (finger_sim.log.writer_process) and the two threads that talk to it."""
        self._process = subprocess.Popen(
            [sys.executable, "-c", f"import sys; from {writer_process.__name__} import main; sys.exit(main())"],
            stdin=subprocess.PIPE, stdout=subprocess.PIPE, env={**os.environ, "PYTHONPATH": os.pathsep.join(p for p in sys.path if p)},
            # its own session: a signal to the caller's process group (a terminal's Ctrl-C, a supervisor's
            # SIGTERM) must not end the writer before the caller has handed over the rest and Close
            start_new_session=True)
        # A pipe that takes a whole handover at once: the writer process then reads it in one or two
        # reads (a 64 kB pipe split a 10-finger hand's 50 ms into six, each with its fixed costs).
        with contextlib.suppress(OSError, AttributeError):  # not Linux, or above the system's pipe-max-size
            fcntl.fcntl(self._process.stdin.fileno(), fcntl.F_SETPIPE_SZ, _PIPE_BYTES)  # type: ignore[union-attr]
        # Daemons: a process that dies without close() must still exit; the writer then sees the
        # end of its input, keeps what it was handed and leaves the file reading as a crash.
        self._sender = threading.Thread(target=self._send, name=f"mcap {self._path.name} sender", daemon=True)
        self._listener = threading.Thread(target=self._listen, name=f"mcap {self._path.name} status", daemon=True)
        self._sender.start()
        self._listener.start()

    def _send(self) -> None:
        """Sender thread: every handover_s (earlier when woken), build the records of what is
        pending and hand them to the writer process in one write; the GIL is released while the
        pipe takes it."""
        assert self._process is not None and self._process.stdin is not None
        pipe = self._process.stdin
        name_os_thread("mcap sender")
        while True:
            self._wake.wait(self._handover_s)
            self._wake.clear()
            with self._lock:
                pending, self._pending = self._pending, []
                closing = self._state is _State.CLOSED
            if pending and not self._broken:
                try:
                    pipe.write(_records(pending))
                    pipe.flush()
                except OSError as exc:  # the writer process died (BrokenPipeError)
                    self._broken = True
                    self._fail(f"the writer process ended ({exc})")
                    self._room.set()
            if closing:
                with contextlib.suppress(OSError):
                    pipe.close()  # the end of input: the writer finishes (or, without Close, stops)
                return

    def _listen(self) -> None:
        """Status thread: take the writer process's counts and failures (writer_process's lines)."""
        assert self._process is not None and self._process.stdout is not None
        name_os_thread("mcap status")
        for line in self._process.stdout:
            kind, _, rest = line.decode().rstrip("\n").partition(" ")
            if kind == "S":
                self._taken, self._taken_bytes, self._written, self._lost = map(int, rest.split())
                self._room.set()
            elif kind == "E":
                self._fail(rest)
            elif kind == "D":
                self._finished = True
        self._broken = True  # the writer process is gone: nothing more can be handed over
        self._room.set()

    def _fail(self, reason: str) -> None:
        if self._error is None:
            self._error = f"cannot write {self._path}: {reason}"
        self._report(_Problem.IO, f"MCAP recorder cannot write {self._path}: {reason}; "
                     "dropping every further message")


#: A pending item: a control record (bytes), messages (their channels, CDR bytes, log and publish
#: time in ns), or a channel whose next sequence number a dropped message spent.
_Pending = bytes | tuple[Sequence[_Channel], Sequence[bytes], int, int] | _Channel


def _records(pending: list[_Pending]) -> bytearray:
    """The writer process's input for `pending`, in order: control records as they are, the
    messages between two of them as one run (writer_process.open_run) of MCAP Message records
    (writer_process.HEADER + data) numbered per channel from its last number (uint32: wraps).
    Built in place in one buffer (a 10-finger hand's handover is ~1 MB: no copy of it).
    Sender thread only: it alone counts the channels' numbers."""
    out, sizes, run_at, pack = bytearray(), [], None, _pack_header
    for item in pending:
        if type(item) is tuple:
            channels, datas, log_ns, publish_ns = item
            if run_at is None:
                run_at = open_run(out)
            sizes += map(len, datas)
            for channel, data in zip(channels, datas):
                sequence = channel.last_sequence + 1
                if sequence == _SEQUENCE_MODULUS:
                    sequence = 0
                channel.last_sequence = sequence
                out += pack(MESSAGE_OPCODE, MESSAGE_FIELDS + len(data), channel.record_id, sequence, log_ns, publish_ns)
                out += data
        elif type(item) is _Channel:
            item.last_sequence = (item.last_sequence + 1) % _SEQUENCE_MODULUS
        else:
            if run_at is not None:
                close_run(out, run_at, sizes)
                run_at, sizes = None, []
            out += item  # type: ignore[arg-type]
    if run_at is not None:
        close_run(out, run_at, sizes)
    return out


def _codec(type_name: str, definition: str) -> _Codec:
    """Encoder and decoder for `type_name` from its complete 'ros2msg' definition."""
    schema = Schema(id=0, name=type_name, encoding=SchemaEncoding.ROS2, data=definition.encode())
    try:
        encode = serialize_dynamic(type_name, definition)[type_name]
        decode = DecoderFactory().decoder_for(MessageEncoding.CDR, schema)
    except Exception as exc:  # the .msg parser raises assorted types on a bad text
        expected = f"a complete ros2msg definition of {type_name}"
        raise LogArgumentError("definition", expected, exc) from exc
    assert decode is not None  # cdr with a ros2msg schema always has a decoder
    return _Codec(definition, encode, decode)


def _as_time_ns(argument: str, value: Any) -> int:
    """An MCAP timestamp (uint64 ns) from an int-like value, or LogArgumentError."""
    try:
        ns = operator.index(value)
    except TypeError:
        raise LogArgumentError(argument, "an integer number of nanoseconds", value) from None
    if not 0 <= ns < _MAX_TIME_NS:
        raise LogArgumentError(argument, "0 <= ns < 2**64", value)
    return ns
