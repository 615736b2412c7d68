"""The recorder's writer process: builds the MCAP file from a byte stream, off the caller's GIL.

Started by finger_sim.log.recorder.McapRecorder, which runs `main()` in a new interpreter.

Why a process: the mcap library's writer is Python, about 10 µs a message, and a writer
thread in the caller's process holds the GIL against the caller (a node's stepping thread)
for that long: recording tripled a node's per-step cost. Here the caller only appends each
message's bytes to one bytearray; a sender thread hands the bytearray over through this
process's stdin every few tens of ms (one write, the GIL released), and everything mcap does
happens in this process, on the other core.

Stdin carries records, each a `HEADER` (channel index, sequence, log time ns, publish time ns,
payload bytes) and its payload. Channel index `CONTROL` marks a pickled control item instead
(`Start` first, then `Register`, `Metadata` and `Close`), so that controls keep their order
among the messages. Stdout carries status lines back: `S taken taken_bytes written lost` after
each change of the counts, `E text` once for the first I/O failure, `D` when the file is
finished.

Chunking and crash safety are the recorder's (see finger_sim.log.recorder): a chunk is closed
before its log-time span would reach the interval, once its payload reaches chunk_size, after
idle_flush_s wall seconds without messages and once it has been open chunk_wall_s wall
seconds. End of input without `Close` (the caller was killed) closes the open chunk and exits
without a summary: the file reads as a crash, and keeps everything that was handed over.
The process runs in its own session, and ignores SIGINT and SIGTERM once started: the caller
decides when the file ends, by `Close` or by dying.

Cost: mcap's chunking, compression, chunk and message indexes and summary are used as they are,
but the per-message part of Writer.add_message (a Message object written field by field, a
quarter of it the message index written entry by entry) is done here in bulk, to the same bytes
(`ChunkedFile.add_messages`, `PackedMessageIndex`): 2.3x less CPU per message. This works with
mcap's Writer's private state (its open chunk, statistics and chunk index list, mcap 1.x); a
Writer without it is refused at start, and test/log/test_writer_memory.py compares whole files
with what mcap's add_message writes.

Memory: mcap's Writer keeps one ChunkIndex object per written chunk until `finish()` (about
0.8 kB each as Python objects: +6 MB an hour at two chunks a second). `SpilledChunkIndexes`
takes that list's place and keeps each chunk index as its summary record bytes in an unnamed
temporary file beside the log instead, so a recording's memory stays flat however long it runs;
`finish()` copies the records into the summary unchanged (the file is byte for byte what mcap
writes alone). A kill -9 leaves no temporary file behind (it has no name).
"""

from __future__ import annotations

import contextlib
import itertools
import os
import pickle
import select
import signal
import stat
import struct
import sys
import tempfile
import time
from collections import defaultdict
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any, BinaryIO

from mcap.data_stream import RecordBuilder
from mcap.opcode import Opcode
from mcap.records import ChunkIndex, MessageIndex
from mcap.well_known import MessageEncoding, Profile, SchemaEncoding
from mcap.writer import LIBRARY_IDENTIFIER, CompressionType, Writer

#: One record: channel index (uint16), sequence (uint32), log and publish time (uint64 ns), payload bytes (uint32).
HEADER = struct.Struct("<HIQQI")
#: The channel index of a control record, whose payload is a pickled control item.
CONTROL = 0xFFFF
#: Channels a recorder can have (indexes 0 … MAX_CHANNELS - 1).
MAX_CHANNELS = CONTROL
LIBRARY = f"finger_sim.log; {LIBRARY_IDENTIFIER}"
_READ_BYTES = 1 << 20  # largest read from stdin at a time
_NO_SIZE_TRIGGER = 1 << 62  # chunk_size given to mcap's Writer so only this module closes chunks
_RECORD_PREFIX = struct.Struct("<BQ")  # an MCAP record's opcode and body length
#: An MCAP Message record's opcode, length, channel id, sequence, log and publish time (ns); the data follows.
_MESSAGE = struct.Struct("<BQHIQQ")
_MESSAGE_FIELDS = _MESSAGE.size - _RECORD_PREFIX.size  # the Message record's length less its data
_INDEX_ENTRY_BYTES = 16  # a MessageIndex entry: log time and offset, uint64 each
# mcap.writer.Writer's private state that this module works with (mcap 1.x; checked at start):
_CHUNK_INDEX_LIST = "_Writer__chunk_indices"  # the list of ChunkIndex kept until finish()
_CHUNK_BUILDER = "_Writer__chunk_builder"  # the open chunk (mcap._chunk_builder.ChunkBuilder)
_STATISTICS = "_Writer__statistics"  # the Statistics record's counts


@dataclass(frozen=True, slots=True)
class Start:
    """The first control item: where and how to write."""

    path: str
    interval_ns: int
    chunk_size: int
    compression: str  # a CompressionType value
    idle_flush_s: float
    chunk_wall_s: float
    handover_s: float


@dataclass(frozen=True, slots=True)
class Register:
    """A channel: its index in HEADER records, topic, type, definition and channel metadata."""

    index: int
    topic: str
    type_name: str
    definition: str
    metadata: dict[str, str]


@dataclass(frozen=True, slots=True)
class Metadata:
    name: str
    data: dict[str, str]


@dataclass(frozen=True, slots=True)
class Close:
    """Finish the file: the open chunk, the summary and the footer."""


def control_record(item: Start | Register | Metadata | Close) -> bytes:
    """A control item as one stdin record."""
    payload = pickle.dumps(item, protocol=pickle.HIGHEST_PROTOCOL)
    return HEADER.pack(CONTROL, 0, 0, 0, len(payload)) + payload


class _Record:
    """A record's bytes, written as they are (stands in for a ChunkIndex in Writer.finish())."""

    __slots__ = ("data",)

    def __init__(self, data: bytes) -> None:
        self.data = data

    def write(self, builder: RecordBuilder) -> None:
        builder.write(self.data)


class PackedMessageIndex(MessageIndex):
    """mcap's MessageIndex record, written with one struct call (mcap's makes two calls per entry,
    a quarter of the writer's time per message): the same bytes."""

    def write(self, stream: RecordBuilder) -> None:
        entries = len(self.records)
        stream.start_record(Opcode.MESSAGE_INDEX)
        stream.write(struct.pack(f"<HI{2 * entries}Q", self.channel_id, entries * _INDEX_ENTRY_BYTES,
                                 *itertools.chain.from_iterable(self.records)))
        stream.finish_record()


class SpilledChunkIndexes:
    """The list of chunk indexes of mcap's Writer, kept as record bytes in a temporary file.

    The Writer only appends to that list (one ChunkIndex per chunk) and iterates it once, in
    finish(); this class does both with one record in memory at a time.
    """

    def __init__(self, folder: Path) -> None:
        try:  # beside the log: on its disk, not in a RAM-backed /tmp
            self._file = tempfile.TemporaryFile(dir=folder)
        except OSError:  # a log written to a pipe or device: its folder may not take files
            self._file = tempfile.TemporaryFile()
        self._builder = RecordBuilder()
        self._count = 0

    def append(self, index: ChunkIndex) -> None:
        index.write(self._builder)
        self._file.write(self._builder.end())
        self._count += 1

    def __len__(self) -> int:
        return self._count

    def __iter__(self) -> Iterator[_Record]:
        self._file.flush()
        self._file.seek(0)
        for _ in range(self._count):
            prefix = self._file.read(_RECORD_PREFIX.size)
            body = self._file.read(_RECORD_PREFIX.unpack(prefix)[1])
            yield _Record(prefix + body)
        self._file.seek(0, os.SEEK_END)

    def close(self) -> None:
        self._file.close()


def writer_state(writer: Writer, name: str) -> object:
    """One of a Writer's private attributes, or a clear error if this mcap version has none."""
    value = getattr(writer, name, None)
    if value is None:
        raise RuntimeError(f"mcap's Writer has no {name}: an mcap version this module does not know")
    return value


def spill_chunk_indexes(writer: Writer, folder: Path) -> SpilledChunkIndexes:
    """Put a SpilledChunkIndexes in place of a new Writer's chunk index list; returns it."""
    if getattr(writer, _CHUNK_INDEX_LIST, None) != []:
        raise RuntimeError(f"mcap's Writer has no empty {_CHUNK_INDEX_LIST} list: its chunk index cannot be spilled "
                           "(an mcap version this module does not know)")
    spilled = SpilledChunkIndexes(folder)
    setattr(writer, _CHUNK_INDEX_LIST, spilled)
    return spilled


class ChunkedFile:
    """One mcap Writer whose chunks this class closes (see finger_sim.log.recorder's module doc)."""

    def __init__(self, path: Path, *, interval_ns: int, chunk_size: int, compression: CompressionType) -> None:
        # A new or regular file is written under a temporary name until its header is out, so
        # `path` never holds a partial header; a pipe or device is written in place.
        temp = None if path.exists() and not path.is_file() else path.with_name(f".{path.name}.{os.urandom(4).hex()}.part")
        # 0o666 less the umask, as open() would create `path`; closed by finish() or abandon().
        self._file = open(path, "wb") if temp is None else os.fdopen(
            os.open(temp, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o666), "wb")
        self.chunk_indexes: SpilledChunkIndexes | None = None
        try:
            self._writer = Writer(self._file, chunk_size=_NO_SIZE_TRIGGER, compression=compression)
            self.chunk_indexes = spill_chunk_indexes(self._writer, path.parent)
            self._chunk: Any = writer_state(self._writer, _CHUNK_BUILDER)
            self._stats: Any = writer_state(self._writer, _STATISTICS)
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
            sync_folder(path.parent)  # the name survives a power cut too
        self._interval_ns = interval_ns
        self._chunk_size = chunk_size
        self._schema_ids: dict[str, int] = {}
        self._channel_ids: dict[int, int] = {}  # the caller's channel index → mcap channel id
        self.pending = 0  # messages in the open chunk
        self.opened_at = 0.0  # time.monotonic() at the open chunk's first message
        self._pending_bytes = 0
        self._first_ns = self._last_ns = 0  # log-time range of the open chunk
        self._unsynced = 0  # messages in the open chunk not yet counted in mcap's state (see _append)
        self._counts: defaultdict[int, int] = defaultdict(int)  # the same, per mcap channel id

    def register(self, item: Register) -> None:
        schema_id = self._schema_ids.get(item.type_name)
        if schema_id is None:
            schema_id = self._writer.register_schema(
                name=item.type_name, encoding=SchemaEncoding.ROS2, data=item.definition.encode())
            self._schema_ids[item.type_name] = schema_id
        self._channel_ids[item.index] = self._writer.register_channel(
            topic=item.topic, message_encoding=MessageEncoding.CDR, schema_id=schema_id, metadata=item.metadata)

    def add_metadata(self, item: Metadata) -> None:
        self._writer.add_metadata(item.name, item.data)
        self._file.flush()  # the record is outside chunks: push it out without cutting the chunk

    def add_messages(self, records: bytearray, start: int, stop: int) -> int:
        """Add the HEADER-framed messages in records[start:stop] (no control among them), in order;
        returns the messages newly committed to the file (chunks closed).

        This is the writer's per-message path. Each message becomes the MCAP Message record that
        mcap's Writer.add_message would write (the same bytes: test_writer_memory compares whole
        files), appended to the open chunk in one write per run, and the chunk's message index,
        time range and the file's statistics are updated as mcap updates them; mcap still closes,
        compresses and indexes the chunks. Less than half the CPU per message of add_message, which
        builds a record object and writes it field by field (docs/recording_performance.md).
        """
        committed = 0
        channel_ids, interval, size_limit = self._channel_ids, self._interval_ns, self._chunk_size
        header_size, unpack_from, pack = HEADER.size, HEADER.unpack_from, _MESSAGE.pack
        out = bytearray()  # the open chunk's new records
        base = self._chunk.count  # offset of `out` in the chunk's uncompressed records
        indexes = self._chunk.message_indices
        counts = self._counts
        with memoryview(records) as view:
            at = start
            while at < stop:
                index, sequence, log_ns, publish_ns, size = unpack_from(view, at)
                body, at = at + header_size, at + header_size + size
                if self.pending:
                    first, last = self._first_ns, self._last_ns
                    if (last if last > log_ns else log_ns) - (first if first < log_ns else log_ns) >= interval:
                        self._append(out)
                        committed += self.close_chunk()
                        out, base = bytearray(), self._chunk.count
                channel_id = channel_ids[index]
                entries = indexes.get(channel_id)
                if entries is None:
                    entries = indexes[channel_id] = PackedMessageIndex(channel_id=channel_id, records=[])
                entries.records.append((log_ns, base + len(out)))
                out += pack(Opcode.MESSAGE, _MESSAGE_FIELDS + size, channel_id, sequence, log_ns, publish_ns)
                out += view[body:at]
                counts[channel_id] += 1
                if self.pending == 0:
                    self._first_ns = self._last_ns = log_ns
                    self.opened_at = time.monotonic()
                elif log_ns < self._first_ns:
                    self._first_ns = log_ns
                elif log_ns > self._last_ns:
                    self._last_ns = log_ns
                self.pending += 1
                self._unsynced += 1
                self._pending_bytes += size
                if self._pending_bytes >= size_limit:
                    self._append(out)
                    committed += self.close_chunk()
                    out, base = bytearray(), self._chunk.count
        self._append(out)
        return committed

    def _append(self, out: bytearray) -> None:
        """Hand the open chunk's new records to mcap's chunk builder, with the counts that
        Writer.add_message keeps per message: the chunk's message count and log-time range, the
        file's message counts and range."""
        added, self._unsynced = self._unsynced, 0
        if not added:
            return
        chunk, stats = self._chunk, self._stats
        chunk.record_writer.write(out)
        chunk.message_start_time, chunk.message_end_time = self._first_ns, self._last_ns  # the whole open chunk's
        chunk.num_messages += added
        stats.message_start_time = self._first_ns if stats.message_count == 0 else min(stats.message_start_time, self._first_ns)
        stats.message_end_time = max(stats.message_end_time, self._last_ns)
        stats.message_count += added
        for channel_id, count in self._counts.items():
            stats.channel_message_counts[channel_id] += count
        self._counts.clear()

    def close_chunk(self) -> int:
        """Write the open chunk (if any) and flush; returns the messages it held."""
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
            if self.chunk_indexes is not None:
                self.chunk_indexes.close()
        committed, self.pending = self.pending, 0
        return committed

    def abandon(self) -> None:
        """Close the file after a failure, ignoring further errors; the file stays as it is."""
        with contextlib.suppress(OSError):  # closing flushes the buffer: fails again on a full disk
            self._file.close()
        if self.chunk_indexes is not None:
            self.chunk_indexes.close()


def sync_folder(folder: Path) -> None:
    """fsync a folder so that a new name in it is on disk; skipped where folders cannot be opened."""
    with contextlib.suppress(OSError):
        fd = os.open(folder, os.O_RDONLY)
        try:
            os.fsync(fd)
        finally:
            os.close(fd)


class _Writer:
    """This process's state: the file, the counts reported to the caller, the chunk timers."""

    def __init__(self, start: Start, status: BinaryIO) -> None:
        self.start = start
        self._status = status
        self.taken = self.taken_bytes = 0  # messages (and their payload bytes) read from stdin
        self.handed = 0  # messages given to the file; each ends up written or lost
        self.written = 0
        self.lost = 0  # taken without a file, or handed and hit by an I/O failure
        self._reported = (0, 0, 0, 0)
        self.last_message = time.monotonic()
        self.file: ChunkedFile | None = None
        try:
            self.file = ChunkedFile(Path(start.path), interval_ns=start.interval_ns, chunk_size=start.chunk_size,
                                    compression=CompressionType(start.compression))
        except Exception as exc:  # OSError, or mcap's UnsupportedCompressionError
            self._fail(exc)

    def messages(self, records: bytearray, start: int, stop: int, count: int, payload_bytes: int) -> None:
        """`count` HEADER-framed messages (`payload_bytes` of data) in records[start:stop]."""
        self.taken += count
        self.taken_bytes += payload_bytes
        if self.file is None:
            self.lost += count
            return
        self.handed += count
        self._do(lambda file: file.add_messages(records, start, stop))

    def control(self, item: object) -> bool:
        """Apply a control item; True at Close (the file is finished)."""
        if isinstance(item, Close):
            self._do(ChunkedFile.finish)
            return True
        if isinstance(item, Register):
            self._do(lambda file: file.register(item) or 0)
        elif isinstance(item, Metadata):
            self._do(lambda file: file.add_metadata(item) or 0)
        return False

    def tick(self, got_messages: bool) -> None:
        """After each read (or timeout): close the open chunk if idle or open too long in wall time."""
        now = time.monotonic()
        if got_messages:
            self.last_message = now
        file = self.file
        if file is not None and file.pending and (now - self.last_message >= self.start.idle_flush_s
                                                  or now - file.opened_at >= self.start.chunk_wall_s):
            self._do(ChunkedFile.close_chunk)
        self.report()

    def report(self) -> None:
        """A status line, if the counts changed since the last one."""
        counts = (self.taken, self.taken_bytes, self.written, self.lost)
        if counts != self._reported:
            self._reported = counts
            self._line("S %d %d %d %d" % counts)

    def _do(self, action: object) -> None:
        if self.file is None:
            return
        try:
            self.written += action(self.file)  # type: ignore[operator]
        except Exception as exc:  # OSError (disk full, I/O error) or a failure inside mcap
            self._fail(exc)
            self.lost += self.handed - self.written
            self.file.abandon()
            self.file = None

    def _fail(self, exc: Exception) -> None:
        self._line("E " + " ".join(str(exc).split()))

    def _line(self, text: str) -> None:
        with contextlib.suppress(OSError):  # the caller is gone: nobody to tell
            self._status.write(text.encode() + b"\n")
            self._status.flush()


def main() -> int:
    """Read records from stdin until `Close` or the end of input; status lines to stdout."""
    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, signal.SIG_IGN)
    fd, status = sys.stdin.buffer.fileno(), sys.stdout.buffer
    pending = bytearray()
    writer: _Writer | None = None
    header_size, unpack_from = HEADER.size, HEADER.unpack_from
    while True:
        wait = writer.start.handover_s if writer is not None else None
        chunk = os.read(fd, _READ_BYTES) if select.select([fd], [], [], wait)[0] else None
        if chunk == b"":  # the caller ended without Close (killed): keep what was handed over
            if writer is not None:
                writer._do(ChunkedFile.close_chunk)
                writer.report()
            return 0
        got = False
        if chunk:
            pending += chunk
            at, end = 0, len(pending)
            run, count, payload_bytes = 0, 0, 0  # the messages since the last control: where, how many, data bytes
            while end - at >= header_size:
                index, _, _, _, size = unpack_from(pending, at)
                stop = at + header_size + size
                if stop > end:
                    break
                if index != CONTROL:
                    at, count, payload_bytes = stop, count + 1, payload_bytes + size
                    continue
                if count:  # the messages before a control go first
                    assert writer is not None
                    writer.messages(pending, run, at, count, payload_bytes)
                    got = True
                item = pickle.loads(pending[at + header_size:stop])
                at = run = stop
                count = payload_bytes = 0
                if isinstance(item, Start):
                    writer = _Writer(item, status)
                elif writer is not None and writer.control(item):
                    writer.report()
                    writer._line("D")
                    return 0
            if count:
                assert writer is not None
                writer.messages(pending, run, at, count, payload_bytes)
                got = True
            del pending[:at]
        if writer is not None:
            writer.tick(got)

