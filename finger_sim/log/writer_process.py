"""The recorder's writer process: builds the MCAP file from a byte stream, off the caller's GIL.

Started by finger_sim.log.recorder.McapRecorder, which runs `main()` in a new interpreter.

Why a process: the mcap library's writer is Python, about 10 µs a message, and a writer
thread in the caller's process holds the GIL against the caller (a node's stepping thread)
for that long: recording tripled a node's per-step cost. Here the caller only appends a
reference to each message (or state) to a list; a sender thread builds their records and hands
them over through this process's stdin every handover_s (one write, the GIL released), and
everything mcap does happens in this process, on the other core.

Stdin carries records, each an opcode and a length (`_RECORD_PREFIX`) and its body. Messages
come in runs (opcode `RUN`, `open_run`): a count (uint32), the messages as the MCAP Message
records they become in the file (`HEADER`:
opcode, length, channel id = the recorder's channel index + 1, sequence, log and publish time ns;
then the data: `message_record`), then each one's data size (uint32), so that a run is appended to the open chunk as it is and this
process finds its messages without reading them one by one. Opcode `CONTROL` marks a pickled
control item instead (`Start` first, then `Register`, `Metadata` and `Close`), so that controls
keep their order among the messages. Both opcodes are outside MCAP's (0x80-0xFF are left to users). Stdout carries status lines back: `S taken taken_bytes written lost` after
each change of the counts, `E text` once for the first I/O failure, `D` when the file is
finished.

Chunking and crash safety are the recorder's (see finger_sim.log.recorder): a chunk is closed
before its log-time span would reach the interval, once its payload reaches chunk_size, after
idle_flush_s wall seconds without messages and once it has been open chunk_wall_s wall
seconds. The process sleeps in its read until input comes or the open chunk's next such deadline
(no periodic wake-up). End of input without `Close` (the caller was killed) closes the open chunk and exits
without a summary: the file reads as a crash, and keeps everything that was handed over.
The process runs in its own session, and ignores SIGINT and SIGTERM once started: the caller
decides when the file ends, by `Close` or by dying.

Cost: mcap's records, chunk index and summary are used as they are, but the per-message part of
Writer.add_message (a Message object written field by field, a quarter of it the message index
written entry by entry) is done here in bulk, to the same bytes (`ChunkedFile.add_messages`,
`PackedMessageIndex`): the records arrive as mcap writes them, each run between two chunk
boundaries is appended in one write, its time range and counts are taken with numpy over the
whole run, and the chunk's message index over all its runs when it closes; Python does not touch
a message (docs/node_performance.md: 2.0 µs a message before, 22k messages a second for a
10-finger hand). A chunk is closed here too (`ChunkedFile.close_chunk`: mcap's Chunk, MessageIndex
and ChunkIndex records, as its Writer.flush writes them) so that zstd runs at ZSTD_LEVEL (1: faster
and smaller than mcap's fixed 3 on a node's chunks). This works with mcap's Writer's private state
(its open chunk, statistics and chunk index list, mcap 1.x); a Writer without it is refused at
start, and test/log/test_writer_memory.py compares whole files, at mcap's zstd level, with what
mcap's add_message and flush write.

Memory: mcap's Writer keeps one ChunkIndex object per written chunk until `finish()` (about
0.8 kB each as Python objects: +6 MB an hour at two chunks a second). `SpilledChunkIndexes`
takes that list's place and keeps each chunk index as its summary record bytes in an unnamed
temporary file beside the log instead, so a recording's memory stays flat however long it runs;
`finish()` copies the records into the summary unchanged (the file is byte for byte what mcap
writes alone). A kill -9 leaves no temporary file behind (it has no name).
"""

from __future__ import annotations

import contextlib
import os
import pickle
import select
import signal
import stat
import struct
import sys
import tempfile
import time
import zlib
from collections.abc import Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any, BinaryIO

import lz4.frame  # lz4 and zstandard: mcap's own requirements
import numpy as np
import zstandard
from mcap.data_stream import RecordBuilder
from mcap.opcode import Opcode
from mcap.records import Chunk, ChunkIndex, MessageIndex
from mcap.well_known import MessageEncoding, Profile, SchemaEncoding
from mcap.writer import LIBRARY_IDENTIFIER, CompressionType, Writer

#: A message's record on stdin, as in the file: an MCAP Message record's opcode, length, channel id,
#: sequence, log and publish time (ns); the data follows.
HEADER = struct.Struct("<BQHIQQ")
MESSAGE_OPCODE = int(Opcode.MESSAGE)
#: A Message record's length less its data.
MESSAGE_FIELDS = HEADER.size - struct.calcsize("<BQ")  # less its opcode and length
#: The opcode of a control record, whose body is a pickled control item (MCAP leaves 0x80-0xFF to users).
CONTROL = 0xFF
#: The opcode of a run of messages (`open_run`, `close_run`).
RUN = 0xFE
_RUN_HEAD = struct.Struct("<BQI")  # a run's opcode, length and message count
_COUNT = struct.Struct("<I")  # a run's message count, at the start of its body
_SIZE_BYTES = 4  # a run's data size of one message (uint32, little-endian)
#: Channels a recorder can have (indexes 0 … MAX_CHANNELS - 1; MCAP channel id = index + 1, a uint16).
MAX_CHANNELS = 0xFFFF
LIBRARY = f"finger_sim.log; {LIBRARY_IDENTIFIER}"
_READ_BYTES = 1 << 20  # largest read from stdin at a time
_NO_SIZE_TRIGGER = 1 << 62  # chunk_size given to mcap's Writer so only this module closes chunks
#: zstd's level for chunks. On a 1 kHz node's 0.5 s chunks (~200 kB) level 1 took 205 µs a chunk with cold
#: caches against mcap's level 3's 306 µs, and its chunks were 7 % smaller (docs/node_performance.md).
ZSTD_LEVEL = 1
#: The level mcap's Writer compresses with (zstandard.compress's default): its files byte for byte.
MCAP_ZSTD_LEVEL = 3
_RECORD_PREFIX = struct.Struct("<BQ")  # an MCAP record's opcode and body length
_LENGTH = struct.Struct("<Q")
_LENGTH_AT = 1  # the body length's offset in a record
_FIELDS_AT = 9  # a Message record's channel id, sequence and log time: 14 bytes from here
#: Those fields as numpy reads them from the 14 bytes (little-endian, unaligned; the sequence is not read).
_FIELDS = np.dtype({"names": ["channel", "log_ns"], "formats": ["<u2", "<u8"], "offsets": [0, 6], "itemsize": 14})
_FIELD_BYTES = np.arange(_FIELDS.itemsize)
_MAX_LOG_NS = (1 << 64) - 1  # MCAP log times are uint64
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
    return _RECORD_PREFIX.pack(CONTROL, len(payload)) + payload


def open_run(out: bytearray) -> int:
    """Begin a run of messages at the end of `out`: append its `message_record`s, then `close_run`.
    Returns where the run begins."""
    at = len(out)
    out += bytes(_RUN_HEAD.size)  # filled by close_run
    return at


def close_run(out: bytearray, at: int, sizes: list[int]) -> None:
    """End the run begun at `at`; `sizes`: the data bytes of each message in it (a sender gets
    them with one call per state; the reader adds HEADER.size to find where each starts)."""
    out += struct.pack(f"<{len(sizes)}I", *sizes)
    _RUN_HEAD.pack_into(out, at, RUN, len(out) - at - _RECORD_PREFIX.size, len(sizes))


def message_run(records: bytes, sizes: list[int]) -> bytearray:
    """Message records (`message_record`s, concatenated; `sizes`: their data bytes) as one run."""
    out = bytearray()
    at = open_run(out)
    out += records
    close_run(out, at, sizes)
    return out


def message_record(index: int, sequence: int, log_ns: int, publish_ns: int, data: bytes) -> bytes:
    """A message of the recorder's channel `index` as one stdin record (its MCAP Message record)."""
    return HEADER.pack(MESSAGE_OPCODE, MESSAGE_FIELDS + len(data), index + 1, sequence, log_ns, publish_ns) + data


class _Record:
    """A record's bytes, written as they are (stands in for a ChunkIndex in Writer.finish())."""

    __slots__ = ("data",)

    def __init__(self, data: bytes) -> None:
        self.data = data

    def write(self, builder: RecordBuilder) -> None:
        builder.write(self.data)


class PackedMessageIndex(MessageIndex):
    """mcap's MessageIndex record whose `records` is one array of (log time, offset) rows (uint64),
    written as one block (mcap's makes two struct calls per entry): the same bytes."""

    def write(self, stream: RecordBuilder) -> None:
        entries: np.ndarray = self.records  # type: ignore[assignment]
        stream.start_record(Opcode.MESSAGE_INDEX)
        stream.write(struct.pack("<HI", self.channel_id, len(entries) * _INDEX_ENTRY_BYTES))
        stream.write(entries.astype("<u8", copy=False).tobytes())
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

    def __init__(self, path: Path, *, interval_ns: int, chunk_size: int, compression: CompressionType,
                 zstd_level: int = ZSTD_LEVEL) -> None:
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
        # a chunk's compression as its record names it, and the compressor (mcap's Writer's but zstd's level)
        self._compression, self._compress = {
            CompressionType.ZSTD: ("zstd", zstandard.ZstdCompressor(level=zstd_level).compress),
            CompressionType.LZ4: ("lz4", lz4.frame.compress), CompressionType.NONE: ("", bytes)}[compression]
        self._records = RecordBuilder()  # a closed chunk's records on their way to the file
        self._schema_ids: dict[str, int] = {}
        self._channel_ids: dict[int, int] = {}  # the caller's channel index → mcap channel id
        self.pending = 0  # messages in the open chunk
        self.opened_at = 0.0  # time.monotonic() at the open chunk's first message
        self._pending_bytes = 0
        self._first_ns = self._last_ns = 0  # log-time range of the open chunk
        #: the open chunk's runs not yet in its message index: channel ids, log times, offsets in the chunk
        self._runs: list[tuple[np.ndarray, np.ndarray, np.ndarray]] = []

    def register(self, item: Register) -> None:
        schema_id = self._schema_ids.get(item.type_name)
        if schema_id is None:
            schema_id = self._writer.register_schema(
                name=item.type_name, encoding=SchemaEncoding.ROS2, data=item.definition.encode())
            self._schema_ids[item.type_name] = schema_id
        channel_id = self._writer.register_channel(
            topic=item.topic, message_encoding=MessageEncoding.CDR, schema_id=schema_id, metadata=item.metadata)
        if channel_id != item.index + 1:  # the records carry index + 1 as their channel id
            raise RuntimeError(f"channel {item.topic}: mcap gave id {channel_id}, the records carry {item.index + 1}")

    def add_metadata(self, item: Metadata) -> None:
        self._writer.add_metadata(item.name, item.data)
        self._file.flush()  # the record is outside chunks: push it out without cutting the chunk

    def add_messages(self, records: bytearray, start: int, stop: int, positions: Sequence[int] | None = None) -> int:
        """Add the Message records in records[start:stop] (no control among them; `positions`:
        where each starts, if known), in order; returns the messages newly committed to the file
        (chunks closed).

        This is the writer's per-message path: the records are what mcap's Writer.add_message
        would write (the same bytes: test_writer_memory compares whole files); each run of them
        within one chunk is appended to the open chunk in one write, its time range and the
        file's statistics are updated as mcap updates them, and the chunk's message index is
        built with numpy over all its runs when it closes (close_chunk). A wake-up runs few numpy
        calls (its caches are cold): a run that fits the open chunk, the usual case, is checked
        with its minimum and maximum alone.
        """
        if positions is None:
            positions, at, length_at = [], start, _RECORD_PREFIX.size
            unpack_length = _LENGTH.unpack_from
            while at < stop:  # the one per-message Python step: where each record starts
                positions.append(at)
                at += length_at + unpack_length(records, at + _LENGTH_AT)[0]
        if not len(positions):
            return 0
        pos = np.asarray(positions, dtype=np.int64)
        raw = np.frombuffer(records, dtype=np.uint8)
        try:  # a copy: `records` must not stay exported (the caller resizes it)
            fields = raw[(pos + _FIELDS_AT)[:, None] + _FIELD_BYTES].view(_FIELDS)[:, 0]
        finally:
            del raw
        channels, log_ns = fields["channel"], fields["log_ns"]
        data_bytes = stop - int(pos[0]) - len(pos) * HEADER.size
        lo, hi = int(log_ns.min()), int(log_ns.max())
        if self.pending:
            lo, hi = min(lo, self._first_ns), max(hi, self._last_ns)
        if hi - lo < self._interval_ns and self._pending_bytes + data_bytes < self._chunk_size:
            self._append(records, pos, stop, channels, log_ns, data_bytes, lo, hi)
            return 0
        return self._add_across_chunks(records, pos, stop, channels, log_ns)

    def _add_across_chunks(self, records: bytearray, pos: np.ndarray, stop: int, channels: np.ndarray,
                           log_ns: np.ndarray) -> int:
        """add_messages of a run that closes a chunk: the pieces each chunk takes, found with numpy."""
        ends = np.append(pos[1:], stop)
        sizes = ends - pos - HEADER.size  # the data bytes of each
        in_order = bool((log_ns[1:] >= log_ns[:-1]).all())
        committed, i, n = 0, 0, len(pos)
        while i < n:
            times = log_ns[i:]
            first, last = (self._first_ns, self._last_ns) if self.pending else (int(times[0]), int(times[0]))
            take = self._time_room(times, first, last, in_order)
            full = np.flatnonzero(self._pending_bytes + np.cumsum(sizes[i:i + take]) >= self._chunk_size)
            if full.size:  # the chunk closes after that message
                take = int(full[0]) + 1
            if take == 0:  # the open chunk cannot take the next message's log time
                committed += self.close_chunk()
                continue
            piece = times[:take]
            self._append(records, pos[i:i + take], int(ends[i + take - 1]), channels[i:i + take], piece,
                         int(sizes[i:i + take].sum()), min(first, int(piece.min())), max(last, int(piece.max())))
            i += take
            if full.size:
                committed += self.close_chunk()
        return committed

    def _time_room(self, times: np.ndarray, first: int, last: int, in_order: bool) -> int:
        """How many of the next messages (log `times`, ns) the open chunk (log-time range `first` …
        `last`) takes before its span would reach the interval; `in_order`: the times never decrease,
        so the span grows with each and one binary search finds the end (else cumulative min and max)."""
        if in_order:
            lo = min(first, int(times[0]))
            if last - lo >= self._interval_ns:
                return 0
            limit = lo + self._interval_ns
            return len(times) if limit > _MAX_LOG_NS else int(np.searchsorted(times, np.uint64(limit)))
        lo = np.minimum.accumulate(np.minimum(times, np.uint64(first)))
        hi = np.maximum.accumulate(np.maximum(times, np.uint64(last)))
        too_long = np.flatnonzero(hi - lo >= self._interval_ns)  # closes the chunk before that message
        return int(too_long[0]) if too_long.size else len(times)

    def _append(self, records: bytearray, pos: np.ndarray, stop: int, channels: np.ndarray, log_ns: np.ndarray,
                data_bytes: int, first_ns: int, last_ns: int) -> None:
        """Append the Message records at `pos` (up to `stop`) to the open chunk, with what
        Writer.add_message keeps per message: the run for the chunk's message index
        (`_index_runs`), the chunk's message count and log-time range (`first_ns`, `last_ns`: the
        open chunk's with these), the file's message count and range."""
        chunk, stats = self._chunk, self._stats
        start = int(pos[0])
        self._runs.append((channels, log_ns, pos + (chunk.count - start)))
        with memoryview(records) as view:
            chunk.record_writer.write(view[start:stop])
        if self.pending == 0:
            self.opened_at = time.monotonic()
        added = len(pos)
        self.pending += added
        self._pending_bytes += data_bytes
        self._first_ns, self._last_ns = first_ns, last_ns
        chunk.message_start_time, chunk.message_end_time = first_ns, last_ns  # the whole open chunk's
        chunk.num_messages += added
        stats.message_start_time = first_ns if stats.message_count == 0 else min(stats.message_start_time, first_ns)
        stats.message_end_time = max(stats.message_end_time, last_ns)
        stats.message_count += added

    def _index_runs(self) -> None:
        """The open chunk's message index and the file's message counts by channel, from its runs:
        every message's entry, grouped by channel (in order within each), the channels in the order
        they first appear, as mcap's add_message leaves them."""
        if not self._runs:
            return
        channels, log_ns, offsets = (np.concatenate(parts) for parts in zip(*self._runs))
        self._runs = []
        order = np.argsort(channels, kind="stable")
        entries = np.empty((len(order), 2), np.uint64)
        entries[:, 0], entries[:, 1] = log_ns[order], offsets[order]
        ids, first_at, counts = np.unique(channels, return_index=True, return_counts=True)
        bounds = np.concatenate(([0], np.cumsum(counts))).tolist()
        indexes, channel_counts = self._chunk.message_indices, self._stats.channel_message_counts
        for k in np.argsort(first_at, kind="stable").tolist():
            channel_id = int(ids[k])
            indexes[channel_id] = PackedMessageIndex(channel_id=channel_id, records=entries[bounds[k]:bounds[k + 1]])
            channel_counts[channel_id] += bounds[k + 1] - bounds[k]

    def close_chunk(self) -> int:
        """Write the open chunk (if any) and flush; returns the messages it held."""
        if self._chunk.num_messages:
            self._write_chunk()
        self._file.flush()
        committed, self.pending, self._pending_bytes = self.pending, 0, 0
        return committed

    def _write_chunk(self) -> None:
        """Write the open chunk and its message indexes, as mcap's Writer does when it closes one,
        but compressed with this file's compressor (mcap's Writer has no level: zstd at 3)."""
        self._index_runs()
        chunk, records, file = self._chunk, self._records, self._file
        data = chunk.end()
        compressed = self._compress(data)
        start = file.tell()
        Chunk(compression=self._compression, data=compressed, message_start_time=chunk.message_start_time,
              message_end_time=chunk.message_end_time, uncompressed_crc=zlib.crc32(data),
              uncompressed_size=len(data)).write(records)
        length = records.count
        file.write(records.end())
        indexes_start, offsets = file.tell(), {}
        for channel_id, index in chunk.message_indices.items():
            offsets[channel_id] = indexes_start + records.count
            index.write(records)
        indexes_length = records.count
        file.write(records.end())
        self._stats.chunk_count += 1
        assert self.chunk_indexes is not None
        self.chunk_indexes.append(ChunkIndex(
            message_start_time=chunk.message_start_time, message_end_time=chunk.message_end_time,
            chunk_start_offset=start, chunk_length=length, message_index_offsets=offsets,
            message_index_length=indexes_length, compression=self._compression, compressed_size=len(compressed),
            uncompressed_size=len(data)))
        chunk.reset()

    def finish(self) -> int:
        """Close the open chunk, write the summary and footer, fsync and close the file."""
        try:
            if self._chunk.num_messages:
                self._write_chunk()
            self._writer.finish()
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

    def messages(self, records: bytearray, positions: Sequence[int], stop: int) -> None:
        """The Message records that start at `positions` in `records`, the last ending at `stop`."""
        count = len(positions)
        self.taken += count
        self.taken_bytes += stop - int(positions[0]) - count * HEADER.size
        if self.file is None:
            self.lost += count
            return
        self.handed += count
        self._do(lambda file: file.add_messages(records, positions[0], stop, positions))

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

    def tick(self, got_messages: bool) -> float | None:
        """After each read (or timeout): close the open chunk if idle or open too long in wall time.
        Returns the wall s until the open chunk's next such deadline (None: no open chunk, nothing to
        wait for but input)."""
        now = time.monotonic()
        if got_messages:
            self.last_message = now
        file = self.file
        if file is not None and file.pending and (now - self.last_message >= self.start.idle_flush_s
                                                  or now - file.opened_at >= self.start.chunk_wall_s):
            self._do(ChunkedFile.close_chunk)
        self.report()
        file = self.file
        if file is None or not file.pending:
            return None
        return max(0.0, min(self.last_message + self.start.idle_flush_s, file.opened_at + self.start.chunk_wall_s) - now)

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
    wait: float | None = None  # wall s until the open chunk's idle or wall-time deadline: no wake-up without one
    prefix_size, unpack_from = _RECORD_PREFIX.size, _RECORD_PREFIX.unpack_from
    while True:
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
            while end - at >= prefix_size:
                opcode, length = unpack_from(pending, at)
                stop = at + prefix_size + length
                if stop > end:
                    break
                body, at = at + prefix_size, stop
                if opcode == RUN:
                    assert writer is not None
                    count = _COUNT.unpack_from(pending, body)[0]
                    if count:
                        records_stop = stop - _SIZE_BYTES * count
                        # a copy: `pending` must not stay exported (it is resized below)
                        lengths = np.frombuffer(pending, "<u4", count, records_stop).astype(np.int64) + HEADER.size
                        starts = np.cumsum(lengths) - lengths  # where each record starts in the run
                        writer.messages(pending, starts + (body + _COUNT.size), records_stop)
                        got = True
                    continue
                item = pickle.loads(pending[body:stop])
                if isinstance(item, Start):
                    writer = _Writer(item, status)
                elif writer is not None and writer.control(item):
                    writer.report()
                    writer._line("D")
                    return 0
            del pending[:at]
        if writer is not None:
            wait = writer.tick(got)

