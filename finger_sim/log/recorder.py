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

Crash safety: a chunk is closed — written and flushed to the operating system — before a
message that would stretch its log-time span to `chunk_interval_s`, once its uncompressed
payload reaches `chunk_size`, after `idle_flush_s` wall seconds without messages, and once it
has been open for `chunk_wall_s` wall seconds whatever arrives: a paused sim whose log time stands
still while diagnostics and commands keep coming loses at most that much wall time to a kill -9. Closing uses `mcap.writer.Writer.flush()` (mcap >= 1.5); the Writer's own size trigger
is set out of reach so that every chunk boundary goes through it. A `kill -9` loses the open
chunk and the summary; the prefix stays readable by linear readers (mcap's StreamReader,
finger_sim.log.reader).

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

Threading: all file I/O runs on one writer thread. The caller only checks, serializes and
appends to a buffer (a deque: no semaphore, no wake-up per message); the writer thread takes
everything buffered once every `handover_s` wall seconds (earlier when half of `queue_size`
is waiting, or at close), so a 1 kHz node hands over a batch of steps at a time. More than
`queue_size` pending messages, an unwritable path or a full disk never raise and never block
the caller: each kind of trouble is reported once through `on_problem` (default: logger
'finger_sim.log'; may be called from the writer thread), the first I/O failure is kept in
`error`, and the lost messages are counted in `dropped`. After an I/O error the recorder
writes nothing more. After close(), written + dropped == the number of write() calls that
did not raise.

Back-pressure: with `back_pressure` True (settable while open; a node running as fast as
possible sets it) a full queue blocks write() until the writer thread has taken the buffer,
instead of dropping: when there is no deadline to meet, losing data is never the right trade.

Loss in the file: with `status_record` set, close() adds a metadata record of that name (before
the summary) with the messages handed to the writer and those dropped, in total and by topic
(`RECORDING_METADATA` keys), so a reader can tell a complete log from one with gaps without
the process that wrote it.

Creation: the file is created under a temporary name in the same folder, its header written
and flushed, and only then renamed to `path`, so a kill at any moment leaves either no file
or one that starts with a whole header (finger_sim.log.repair turns it into a valid log).
"""

from __future__ import annotations

import contextlib
import logging
import math
import operator
import os
import re
import stat
import threading
import time
from collections import deque
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from enum import Enum, auto
from pathlib import Path
from types import TracebackType
from typing import Any

from mcap.records import Schema
from mcap.well_known import MessageEncoding, Profile, SchemaEncoding
from mcap.writer import LIBRARY_IDENTIFIER, CompressionType, Writer
from mcap_ros2._dynamic import serialize_dynamic
from mcap_ros2.decoder import DecoderFactory

from .definitions import message_definition, normalize_type_name, type_name_of
from .errors import LogArgumentError, RecorderStateError
from .qos import OFFERED_QOS_PROFILES, offered_qos_profiles

DEFAULT_CHUNK_INTERVAL_S = 0.5  # log-time span of one chunk: what a kill -9 may lose
DEFAULT_CHUNK_SIZE = 1 << 20  # uncompressed bytes; bounds memory if an interval holds many messages
DEFAULT_QUEUE_SIZE = 10_000  # pending messages (~1 s of a 1 kHz node's six topics) before dropping
MAX_QUEUED_BYTES = 64 << 20  # pending payload bytes before dropping: a few huge messages cannot fill memory
DEFAULT_IDLE_FLUSH_S = 1.0  # wall seconds without messages after which the open chunk is closed
DEFAULT_CHUNK_WALL_S = 1.0  # wall seconds after which an open chunk is closed, whatever its log-time span
DEFAULT_HANDOVER_S = 0.05  # wall seconds between the writer thread's takes of the buffer
MAX_METADATA_BYTES = 1 << 16  # UTF-8 bytes of one metadata record's keys and values
_NO_SIZE_TRIGGER = 1 << 62  # chunk_size given to mcap's Writer so only this module closes chunks
_MAX_TIME_NS = 1 << 64  # MCAP timestamps are uint64
_SEQUENCE_MODULUS = 1 << 32  # MCAP sequence numbers are uint32: they wrap
#: The usual name of the status record (finger_sim's nodes write it; LogReader.dropped reads it).
RECORDING_STATUS = "recording"
#: The keys of the status record written at close (see `status_record`).
MESSAGES_RECORDED, MESSAGES_DROPPED, DROPPED_BY_TOPIC = "messages_recorded", "messages_dropped", "dropped_by_topic"
#: Longest a blocked write() waits before it checks the recorder's state again, wall s.
_BACK_PRESSURE_POLL_S = 0.1
_TOPIC = re.compile(r"^(/[A-Za-z_][A-Za-z0-9_]*)+$")  # absolute, fully expanded ROS 2 topic name
LIBRARY = f"finger_sim.log; {LIBRARY_IDENTIFIER}"

_logger = logging.getLogger("finger_sim.log")


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
class _Register:
    topic: str
    type_name: str
    definition: str
    metadata: dict[str, str]


@dataclass(frozen=True, slots=True)
class _Metadata:
    name: str
    data: dict[str, str]


@dataclass(slots=True)  # not frozen: built once per message on the caller's thread, kept cheap
class _Message:
    topic: str
    data: bytes
    log_time_ns: int
    publish_time_ns: int
    sequence: int


_CLOSE = object()  # buffer sentinel: finish the file and end the writer thread


@dataclass(frozen=True, slots=True)
class _Codec:
    """CDR encoder and decoder of one type, both built from the definition stored in the file."""

    definition: str
    encode: Callable[[Any], bytes]
    decode: Callable[[bytes], Any]


@dataclass(slots=True)
class _Channel:
    type_name: str
    codec: _Codec
    last_sequence: int = 0


class McapRecorder:
    """Records ROS 2 messages to one MCAP file without blocking the caller. Thread-safe.

    path: the .mcap file, overwritten if it exists.
    chunk_interval_s: longest log-time span of a chunk (s of the caller's clock, e.g. sim time).
    chunk_size: uncompressed bytes after which a chunk is closed whatever its span.
    compression: chunk compression (mcap.writer.CompressionType).
    queue_size: messages that may wait for the writer thread before new ones are dropped.
    idle_flush_s: wall seconds without messages after which the open chunk is closed.
    chunk_wall_s: wall seconds after its first message after which a chunk is closed.
    handover_s: wall seconds between the writer thread's takes of what the caller buffered.
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
        self._idle_flush_s = idle_flush_s
        self._chunk_wall_s = chunk_wall_s
        self._on_problem = on_problem if on_problem is not None else _logger.warning
        self._handover_s = handover_s
        # Items for the writer thread; deque.append and popleft are atomic, so neither side locks.
        self._buffer: deque[object] = deque()
        self._wake = threading.Event()  # set at close or when half of queue_size waits
        self._room = threading.Event()  # set by the writer thread after each take of the buffer
        self.back_pressure = back_pressure
        self._status_record = status_record
        self._dropped_by_topic: dict[str, int] = {}  # caller side, under _lock
        self._queued = 0  # messages appended to the buffer (caller side, under _lock)
        self._taken = 0  # messages taken from it (writer thread only)
        self._queued_bytes = self._taken_bytes = 0  # their payload bytes, counted on the same sides
        # Guards state, sequences, dropped. Reentrant: a signal handler that calls close()
        # while the interrupted main thread is inside write() must not deadlock. The writer
        # thread never takes it.
        self._lock = threading.RLock()
        self._report_lock = threading.Lock()
        self._state = _State.NEW
        self._thread: threading.Thread | None = None
        self._channels: dict[str, _Channel] = {}
        self._codecs: dict[str, _Codec] = {}
        self._reported: set[_Problem] = set()
        self._written = 0  # changed by the writer thread only
        self._dropped = 0  # caller side, under _lock
        self._lost = 0  # writer side: handed over, then hit by an I/O error
        self._error: str | None = None

    # -- life cycle -------------------------------------------------------------------------

    def open(self) -> McapRecorder:
        """Start the writer thread, which creates the file. Raises RecorderStateError if reopened."""
        with self._lock:
            if self._state is not _State.NEW:
                raise RecorderStateError("open", self._state.value)
            self._state = _State.OPEN
        # Daemon: a node that dies without close() must still exit; its file then reads as a crash.
        self._thread = threading.Thread(target=self._run, name=f"mcap {self._path.name}", daemon=True)
        self._thread.start()
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
                    self._buffer.append(_Metadata(self._status_record, self._status()))
                self._buffer.append(_CLOSE)
                self._wake.set()
        if was_open and self._thread is not None:
            self._thread.join(timeout_s)
            if self._thread.is_alive():
                self._report(_Problem.STUCK, f"MCAP recorder {self._path}: writer still busy after "
                             f"{timeout_s} s; the file may lack its summary")

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
            self._channels[topic] = _Channel(type_name, codec)
            self._buffer.append(_Register(topic, type_name, codec.definition, metadata))

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
            self._buffer.append(_Metadata(name, dict(data)))

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
                # The number is spent: the gap tells a reader where the drop was.
                channel.last_sequence = (channel.last_sequence + 1) % _SEQUENCE_MODULUS
                problem, text = _Problem.QUEUE_FULL, (
                    f"MCAP recorder {self._path}: {waiting} messages wait for the writer "
                    f"({self._queued_bytes - self._taken_bytes} bytes; limits {self._queue_size} and {MAX_QUEUED_BYTES}); "
                    "dropping messages (see the dropped count)"
                )
            else:
                channel.last_sequence = (channel.last_sequence + 1) % _SEQUENCE_MODULUS
                self._buffer.append(_Message(topic, data, log_ns, publish_ns, channel.last_sequence))
                self._queued += 1
                self._queued_bytes += len(data)
                if waiting == self._queue_size // 2:
                    self._wake.set()  # a burst: take it before the bound is reached
                return True
        self._report(problem, text)
        return False

    @property
    def path(self) -> Path:
        """The file being written."""
        return self._path

    @property
    def written(self) -> int:
        """Messages in chunks that reached the file (flushed to the operating system)."""
        return self._written

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
        while self._queued - self._taken >= self._queue_size and self._state is _State.OPEN and self._error is None:
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

    def _run(self) -> None:
        """Writer thread: every handover_s, write what was buffered; end at the close sentinel."""
        file = self._create_file()
        handed = 0  # messages given to the file; each one ends up written or lost
        last_message = time.monotonic()
        while True:
            self._wake.wait(self._handover_s)
            self._wake.clear()
            got_messages = False
            while self._buffer:
                item = self._buffer.popleft()
                if isinstance(item, _Message):
                    self._taken += 1
                    self._taken_bytes += len(item.data)
                    got_messages = True
                    if file is None:
                        self._lost += 1
                        continue
                    handed += 1
                elif item is _CLOSE:
                    if file is not None:
                        file = self._apply(file, _CLOSE, handed)
                    return
                if file is not None:
                    file = self._apply(file, item, handed)
            self._room.set()
            now = time.monotonic()
            if got_messages:
                last_message = now
            elif file is not None and file.pending and now - last_message >= self._idle_flush_s:
                file = self._apply(file, None, handed)  # idle (a paused sim): close the open chunk
            if file is not None and file.pending and now - file.opened_at >= self._chunk_wall_s:
                file = self._apply(file, None, handed)  # open too long in wall time (sim time stands still)

    def _apply(self, file: _ChunkedFile, item: object, handed: int) -> _ChunkedFile | None:
        """Hand one item (None: idle, _CLOSE: finish) to the file; None after an I/O failure."""
        try:
            self._written += file.finish() if item is _CLOSE else file.handle(item)
            return file
        except Exception as exc:  # OSError (disk full, I/O error) or a failure inside mcap
            self._fail(exc)
            self._lost += handed - self._written
            file.abandon()
            return None

    def _create_file(self) -> _ChunkedFile | None:
        try:
            return _ChunkedFile(self._path, interval_ns=self._interval_ns, chunk_size=self._chunk_size,
                                compression=self._compression)
        except Exception as exc:  # OSError, or mcap's UnsupportedCompressionError
            self._fail(exc)
            return None

    def _fail(self, exc: Exception) -> None:
        if self._error is None:
            self._error = f"cannot write {self._path}: {exc}"
        self._report(_Problem.IO, f"MCAP recorder cannot write {self._path}: {exc}; "
                     "dropping every further message")


class _ChunkedFile:
    """The writer thread's file: one mcap Writer whose chunks this class closes (see module doc)."""

    def __init__(
        self, path: Path, *, interval_ns: int, chunk_size: int, compression: CompressionType
    ) -> None:
        # A new or regular file is written under a temporary name until its header is out, so
        # `path` never holds a partial header; a pipe or device is written in place.
        temp = None if path.exists() and not path.is_file() else path.with_name(f".{path.name}.{os.urandom(4).hex()}.part")
        # 0o666 less the umask, as open() would create `path`; closed by finish() or abandon().
        self._file = open(path, "wb") if temp is None else os.fdopen(
            os.open(temp, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o666), "wb")
        try:
            self._writer = Writer(self._file, chunk_size=_NO_SIZE_TRIGGER, compression=compression)
            self._writer.start(profile=Profile.ROS2, library=LIBRARY)
            self._writer.flush()  # the header reaches the operating system before the name
            if temp is not None:
                os.replace(temp, path)
        except BaseException:
            self.abandon()
            if temp is not None:
                with contextlib.suppress(OSError):
                    os.unlink(temp)
            raise
        if temp is not None:
            _sync_folder(path.parent)  # the name survives a power cut too
        self._interval_ns = interval_ns
        self._chunk_size = chunk_size
        self._schema_ids: dict[str, int] = {}
        self._channel_ids: dict[str, int] = {}
        self.pending = 0  # messages in the open chunk
        self.opened_at = 0.0  # time.monotonic() at the open chunk's first message
        self._pending_bytes = 0
        self._first_ns = self._last_ns = 0  # log-time range of the open chunk

    def handle(self, item: object) -> int:
        """Apply one queue item (None: idle); returns messages newly committed to the file."""
        if isinstance(item, _Message):
            return self._add_message(item)
        if isinstance(item, _Register):
            schema_id = self._schema_ids.get(item.type_name)
            if schema_id is None:
                schema_id = self._writer.register_schema(
                    name=item.type_name, encoding=SchemaEncoding.ROS2, data=item.definition.encode()
                )
                self._schema_ids[item.type_name] = schema_id
            self._channel_ids[item.topic] = self._writer.register_channel(
                topic=item.topic, message_encoding=MessageEncoding.CDR, schema_id=schema_id, metadata=item.metadata
            )
            return 0
        if isinstance(item, _Metadata):
            self._writer.add_metadata(item.name, item.data)
            self._file.flush()  # the record is outside chunks: push it out without cutting the chunk
            return 0
        return self._close_chunk()  # idle

    def _add_message(self, message: _Message) -> int:
        t = message.log_time_ns
        span = max(self._last_ns, t) - min(self._first_ns, t)
        committed = self._close_chunk() if self.pending and span >= self._interval_ns else 0
        self._writer.add_message(
            channel_id=self._channel_ids[message.topic],
            log_time=t,
            data=message.data,
            publish_time=message.publish_time_ns,
            sequence=message.sequence,
        )
        if self.pending == 0:
            self._first_ns = self._last_ns = t
            self.opened_at = time.monotonic()
        else:
            self._first_ns, self._last_ns = min(self._first_ns, t), max(self._last_ns, t)
        self.pending += 1
        self._pending_bytes += len(message.data)
        if self._pending_bytes >= self._chunk_size:
            committed += self._close_chunk()
        return committed

    def _close_chunk(self) -> int:
        self._writer.flush()  # finalizes the open chunk (if it holds messages) and flushes the stream
        committed, self.pending, self._pending_bytes = self.pending, 0, 0
        return committed

    def finish(self) -> int:
        """Close the open chunk, write the summary and footer, fsync and close the file."""
        try:
            self._writer.finish()  # closes the open chunk too
            self._file.flush()
            if stat.S_ISREG(os.fstat(self._file.fileno()).st_mode):  # not a pipe or device
                os.fsync(self._file.fileno())  # a finished log survives a power cut
        finally:
            self._file.close()
        committed, self.pending = self.pending, 0
        return committed

    def abandon(self) -> None:
        """Close the file after a failure, ignoring further errors; the file stays as it is."""
        with contextlib.suppress(OSError):  # closing flushes the buffer: fails again on a full disk
            self._file.close()


def _sync_folder(folder: Path) -> None:
    """fsync a folder so that a new name in it is on disk; skipped where folders cannot be opened."""
    with contextlib.suppress(OSError):
        fd = os.open(folder, os.O_RDONLY)
        try:
            os.fsync(fd)
        finally:
            os.close(fd)


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
