"""Reading MCAP logs without ROS: topics, times, metadata, decoded messages and an info text.

`read_log(path)` (or `LogReader(path)`) indexes a file and raises a LogFileError subclass,
naming the file and the problem, for anything it cannot read. A complete file is indexed
from its summary section. A file without a valid footer (recorder killed, disk full) is
scanned record by record up to the first record that runs past its end: that prefix stays
readable and `LogReader.truncation` holds a TruncatedLogError describing the cut, for a
tool to warn and exit nonzero. Messages are decoded by mcap_ros2 from the schemas in the
file, so neither rclpy nor message packages are needed (mcap_ros2 by default, or rosbags).
Reading a few topics in file order (`raw_messages(..., log_time_order=False)`, `messages`)
goes through the summary's chunk indexes: chunks without a wanted channel are not read, and
in the others only the wanted records are parsed.
"""

from __future__ import annotations

import functools
import os
import struct
from collections.abc import Callable, Iterable, Iterator
from dataclasses import dataclass
from datetime import datetime, timezone
from pathlib import Path
from typing import Any, BinaryIO, NamedTuple

from mcap.data_stream import ReadDataStream
from mcap.reader import SeekingReader
from mcap.records import Channel, Chunk, ChunkIndex, DataEnd, Header, McapRecord, Message, Metadata, Schema
from mcap.stream_reader import StreamReader, breakup_chunk, get_chunk_data_stream
from mcap.writer import MCAP0_MAGIC
from mcap_ros2.decoder import DecoderFactory

from .errors import (
    CorruptLogError,
    LogArgumentError,
    LogDecodeError,
    LogFileError,
    LogNotFoundError,
    MissingMetadataError,
    MissingTopicsError,
    NotMcapError,
    TruncatedLogError,
)

_RECORD_PREFIX = 1 + 8  # opcode byte and uint64 record length before every record's body
_RECORD_HEAD = struct.Struct("<BQ")  # a record's opcode and body length
_MESSAGE_HEAD = struct.Struct("<HIQQ")  # a Message body's channel id, sequence, log time, publish time
_MESSAGE_OPCODE = 0x05
_CHUNK_OPCODE = 0x06
_HEAD_BYTES = 16  # bytes read to tell what a non-MCAP file is
_UNIX_TIME_NS = 10**18  # later log times are taken as Unix time (after 2001) and also shown as a date
MCAP_ROS2, ROSBAGS = "mcap_ros2", "rosbags"  # message decoders
DECODERS = (MCAP_ROS2, ROSBAGS)
_INFO_VALUE_CHARS = 60  # metadata values longer than this (or multi-line) are summarised in info()

#: Longest parser message quoted in a CorruptLogError (characters): the error stays one readable line.
MAX_REASON = 200


@dataclass(frozen=True)
class TopicInfo:
    """One topic of a log: its ROS 2 type ('pkg/msg/Type'), message encoding, message count and
    the schema's text (the complete 'ros2msg' definition; empty without a schema)."""

    topic: str
    type: str
    encoding: str
    count: int
    definition: str = ""


class LogMessage(NamedTuple):
    """A decoded message; `msg` has the fields of the ROS message as attributes."""

    topic: str
    log_time_ns: int
    msg: Any


@dataclass(frozen=True)
class _Truncated:
    """End of a scan: the record at `offset` runs past the end of the file."""

    offset: int


class LogReader:
    """The index of one MCAP log plus decoding access to its messages.

    Attributes: path, size (bytes), profile, library, topics (by name, sorted),
    message_count, chunk_count, start_ns and end_ns (log times; None without messages),
    metadata (record name → key → value; for a repeated name later keys win),
    truncation (TruncatedLogError or None).
    """

    def __init__(self, path: str | os.PathLike[str]) -> None:
        self.path = Path(path)
        if not self.path.exists():
            raise LogNotFoundError(self.path)
        if self.path.is_dir():
            raise NotMcapError(self.path, "a directory; for a rosbag2 bag pass the .mcap file inside it")
        self.size = self.path.stat().st_size
        self.profile = self.library = ""
        self.chunk_count = self.message_count = 0
        self.start_ns: int | None = None
        self.end_ns: int | None = None
        self.metadata: dict[str, dict[str, str]] = {}
        self.truncation: TruncatedLogError | None = None
        self._schemas: dict[int, Schema] = {}
        self._channels: dict[int, Channel] = {}
        self._counts: dict[int, int] = {}
        self._chunk_indexes: list[ChunkIndex] = []  # in file order; only from a valid summary
        with self._open() as file:
            head = file.read(_HEAD_BYTES)
            if not head.startswith(MCAP0_MAGIC):
                raise NotMcapError(self.path, _describe(head))
            file.seek(-len(MCAP0_MAGIC), os.SEEK_END)
            # Without the closing magic the file was cut short; with it, damage is corruption.
            self._complete = file.read() == MCAP0_MAGIC
            if not (self._complete and self._index_summary(file)):
                self._index_scan(file)
        self.topics = self._topics()

    # -- queries --------------------------------------------------------------------------------

    @property
    def truncated(self) -> bool:
        """True if the file ends inside a record (only its intact prefix is readable)."""
        return self.truncation is not None

    @property
    def duration_s(self) -> float:
        """Log time from the first to the last message, s (0 without messages)."""
        if self.start_ns is None or self.end_ns is None:
            return 0.0
        return (self.end_ns - self.start_ns) / 1e9

    def metadata_record(self, name: str) -> dict[str, str]:
        """The metadata record `name`, or MissingMetadataError."""
        if name not in self.metadata:
            raise MissingMetadataError(self.path, name, self.metadata)
        return dict(self.metadata[name])

    def require_topics(self, topics: Iterable[str]) -> None:
        """Raise MissingTopicsError unless every topic in `topics` is in the log."""
        missing = set(topics) - self.topics.keys()
        if missing:
            raise MissingTopicsError(self.path, missing, self.topics)

    def messages(self, topics: str | Iterable[str] | None = None, *, decoder: str = MCAP_ROS2) -> Iterator[LogMessage]:
        """Decoded messages (topic, log_time_ns, msg) in file order, optionally of some topics only.

        decoder: MCAP_ROS2 (plain objects, arrays as lists) or ROSBAGS (rosbags' compiled CDR
        deserializer: dataclasses, numeric arrays as numpy arrays; 1.5-2x faster per message on a
        node's log). Both build the types from the schemas in the file.

        File order is recording order. For a truncated log the iteration ends at the cut;
        a corrupt chunk raises CorruptLogError, an undecodable message LogDecodeError, both
        after the messages before them have been yielded.
        """
        if decoder not in DECODERS:
            raise LogArgumentError("decoder", f"one of {list(DECODERS)}", decoder)
        wanted = None if topics is None else {topics} if isinstance(topics, str) else set(topics)
        if wanted is not None:
            self.require_topics(wanted)  # here, not at the first next()
        return self._messages(wanted, decoder)

    def _messages(self, wanted: set[str] | None, kind: str) -> Iterator[LogMessage]:
        decode = self.decoding(kind)
        for schema, channel, record in self._file_order(None if wanted is None else frozenset(wanted), 0):
            yield LogMessage(channel.topic, record.log_time, decode(schema, channel, record))

    def decoding(self, decoder: str = MCAP_ROS2) -> Callable[[Schema | None, Channel, Message], Any]:
        """A function that decodes the raw records of `raw_messages` (decoder: see `messages`);
        it builds each channel's decoder on first use. LogDecodeError for what does not decode."""
        if decoder not in DECODERS:
            raise LogArgumentError("decoder", f"one of {list(DECODERS)}", decoder)
        decoders: dict[int, Callable[[bytes], Any]] = {}
        make = self._decoder if decoder == MCAP_ROS2 else _RosbagsDecoders(self).decoder

        def decode(schema: Schema | None, channel: Channel, record: Message) -> Any:
            function = decoders.get(channel.id)
            if function is None:
                function = decoders[channel.id] = make(channel, schema)
            return self._decode(function, channel, record)

        return decode

    def raw_messages(
        self, topics: Iterable[str] | None = None, *, start_ns: int = 0, log_time_order: bool = True
    ) -> Iterator[tuple[Schema | None, Channel, Message]]:
        """Undecoded (schema, channel, message) records of `topics` (default all) logged at or
        after `start_ns`; Message.data is the CDR bytes.

        Log-time order for a complete log (mcap's indexed reader) unless `log_time_order` is
        False; file order, up to the cut, for a truncated one. File order reads only the chunks
        that hold a wanted topic and parses only the wanted messages (the fast way to read a
        few topics of a long log). A record that cannot be read raises CorruptLogError after
        the records before it.
        """
        wanted = None if topics is None else frozenset(topics)
        if wanted is not None:
            self.require_topics(wanted)
        if self.truncated or not log_time_order:
            return self._file_order(wanted, start_ns)
        return self._log_time_order(wanted, start_ns)

    def _log_time_order(self, wanted: frozenset[str] | None, start_ns: int) -> Iterator[tuple[Schema | None, Channel, Message]]:
        with self._open() as file:
            try:
                mcap = SeekingReader(file, validate_crcs=True, record_size_limit=self.size)
                yield from mcap.iter_messages(topics=wanted, start_time=start_ns, log_time_order=True)
            except Exception as exc:  # mcap raises assorted types on damaged records
                text = str(exc)
                problem = f"{type(exc).__name__}: {text}" if text else repr(exc)
                raise CorruptLogError(self.path, None, f"cannot read a message ({problem})") from exc

    def _file_order(self, wanted: frozenset[str] | None, start_ns: int) -> Iterator[tuple[Schema | None, Channel, Message]]:
        if self._chunk_indexes:
            return self._indexed_file_order(wanted, start_ns)
        return self._scanned_file_order(wanted, start_ns)

    def _indexed_file_order(self, wanted: frozenset[str] | None, start_ns: int) -> Iterator[tuple[Schema | None, Channel, Message]]:
        """File order through the summary's chunk indexes: a chunk whose message indexes name no
        wanted channel, or whose messages all precede `start_ns`, is not read; in a chunk read,
        only the wanted messages are parsed. (As mcap's own indexed reader, this assumes that a
        log with chunk indexes keeps every message in a chunk, as chunked writers do.)"""
        targets = {cid: (self._schemas.get(ch.schema_id), ch) for cid, ch in self._channels.items()
                   if wanted is None or ch.topic in wanted}
        with self._open() as file:
            for index in self._chunk_indexes:
                if index.message_end_time < start_ns or targets.keys().isdisjoint(index.message_index_offsets):
                    continue
                data = self._chunk_data(file, index)
                yield from _chunk_messages(data, targets, start_ns, self.path, index.chunk_start_offset)

    def _chunk_data(self, file: BinaryIO, index: ChunkIndex) -> bytes:
        """The decompressed, CRC-checked records of the chunk that `index` points to."""
        file.seek(index.chunk_start_offset)
        head = file.read(_RECORD_PREFIX)
        expected = (_CHUNK_OPCODE, index.chunk_length - _RECORD_PREFIX)
        if len(head) < _RECORD_PREFIX or _RECORD_HEAD.unpack(head) != expected:
            got = _RECORD_HEAD.unpack(head) if len(head) == _RECORD_PREFIX else head
            raise CorruptLogError(self.path, index.chunk_start_offset,
                                  f"malformed record (the chunk index expects opcode, length {expected}; got {got})")
        try:
            chunk = Chunk.read(ReadDataStream(file))
            stream, length = get_chunk_data_stream(chunk, validate_crc=True)
            return stream.read(length)
        except Exception as exc:  # mcap's parser, decompressors and the CRC check raise assorted types
            raise CorruptLogError(
                self.path, index.chunk_start_offset, f"chunk does not decompress or fails its CRC ({exc!r})"
            ) from exc

    def _scanned_file_order(self, wanted: frozenset[str] | None, start_ns: int) -> Iterator[tuple[Schema | None, Channel, Message]]:
        schemas, channels = dict(self._schemas), dict(self._channels)
        with self._open() as file:
            for record in self._records(file):
                if isinstance(record, Schema):
                    schemas[record.id] = record
                elif isinstance(record, Channel):
                    channels[record.id] = record
                elif isinstance(record, Message):
                    channel = channels.get(record.channel_id)
                    if channel is None:
                        problem = f"a message names undeclared channel {record.channel_id}"
                        raise CorruptLogError(self.path, None, problem)
                    if (wanted is None or channel.topic in wanted) and record.log_time >= start_ns:
                        yield schemas.get(channel.schema_id), channel, record

    def records(self) -> Iterator[McapRecord]:
        """The data section's records in file order, each chunk replaced by its contents.

        Ends at the end of the data or at the cut of a truncated log; raises CorruptLogError
        at damage, after the records before it.
        """
        with self._open() as file:
            for record in self._records(file):
                if not isinstance(record, (Chunk, _Truncated)):
                    yield record

    def info(self, detail: str | None = None) -> str:
        """A short human summary, like `ros2 bag info`, plus the keys of metadata record `detail`."""
        rows = [
            ("File", str(self.path)),
            ("Size", _format_bytes(self.size)),
            ("Status", "complete" if self.truncation is None else f"TRUNCATED, {self.truncation.problem}"),
            ("Profile", f"{self.profile or '(none)'} (written by {self.library or 'unknown'})"),
            ("Duration", f"{self.duration_s:.9f} s"),
            ("Start", _format_time(self.start_ns)),
            ("End", _format_time(self.end_ns)),
            ("Messages", f"{self.message_count} in {self.chunk_count} chunks"),
        ]
        topics = [f"{t.topic} | {t.type} | {t.count} msgs | {t.encoding}" for t in self.topics.values()]
        rows += [("Topics" if i == 0 else "", text) for i, text in enumerate(topics or ["none"])]
        names = sorted(self.metadata, key=lambda name: (name != detail, name))
        rows.append(("Metadata", ", ".join(names) or "none"))
        for key, value in sorted(self.metadata.get(detail, {}).items()) if detail is not None else ():
            rows.append(("", f"  {key}: {_summarise(value)}"))
        width = max(len(label) for label, _ in rows) + 2
        return "\n".join(f"{label + ':' if label else '':<{width}}{value}" for label, value in rows)

    # -- indexing -------------------------------------------------------------------------------

    def _open(self) -> BinaryIO:
        try:
            return self.path.open("rb")
        except OSError as exc:
            raise LogFileError(self.path, f"cannot open ({exc.strerror or exc})") from exc

    def _index_summary(self, file: BinaryIO) -> bool:
        """Index from the summary section; False if there is none or it is damaged."""
        file.seek(0)
        try:
            reader = SeekingReader(file)
            header = reader.get_header()
            summary = reader.get_summary()
            if summary is None or summary.statistics is None:
                return False
            metadata = list(reader.iter_metadata())
        except Exception:  # any damage at the end: the record-by-record scan will say exactly what
            return False
        stats = summary.statistics
        self.profile, self.library = header.profile, header.library
        self._schemas, self._channels = dict(summary.schemas), dict(summary.channels)
        self._counts = dict(stats.channel_message_counts)
        self._chunk_indexes = sorted(summary.chunk_indexes, key=lambda index: index.chunk_start_offset)
        self.message_count, self.chunk_count = stats.message_count, stats.chunk_count
        if stats.message_count:
            self.start_ns, self.end_ns = stats.message_start_time, stats.message_end_time
        for record in metadata:
            self.metadata.setdefault(record.name, {}).update(record.metadata)
        return True

    def _index_scan(self, file: BinaryIO) -> None:
        """Index by reading every record up to the end of the data section or the cut."""
        for record in self._records(file):
            if isinstance(record, Message):
                self._counts[record.channel_id] = self._counts.get(record.channel_id, 0) + 1
                self.message_count += 1
                t = record.log_time
                self.start_ns = t if self.start_ns is None else min(self.start_ns, t)
                self.end_ns = t if self.end_ns is None else max(self.end_ns, t)
            elif isinstance(record, Schema):
                self._schemas[record.id] = record
            elif isinstance(record, Channel):
                self._channels[record.id] = record
            elif isinstance(record, Chunk):
                self.chunk_count += 1
            elif isinstance(record, Metadata):
                self.metadata.setdefault(record.name, {}).update(record.metadata)
            elif isinstance(record, Header):
                self.profile, self.library = record.profile, record.library
            elif isinstance(record, _Truncated):
                self.truncation = TruncatedLogError(self.path, record.offset, self.size, self.message_count)

    def _records(self, file: BinaryIO) -> Iterator[McapRecord | _Truncated]:
        """Data-section records in file order, chunks followed by their contents.

        A parse failure in a file without a valid footer, at a record that runs past the end
        of the file, ends the scan with _Truncated; any other failure is CorruptLogError.
        """
        file.seek(len(MCAP0_MAGIC))
        # A record longer than the file is damage: refuse it before reading it.
        records = StreamReader(file, skip_magic=True, emit_chunks=True, record_size_limit=self.size).records
        while True:
            offset = file.tell()
            try:
                record = next(records)
            except StopIteration:  # the file ends between two records
                if not self._complete:
                    yield _Truncated(offset)
                return
            except Exception as exc:  # mcap's parsers raise assorted types at a cut or on garbage
                if not self._complete and _runs_past_end(file, offset, self.size):
                    yield _Truncated(offset)
                    return
                # str, not repr: a UnicodeDecodeError's repr holds the whole record (100 kB of metadata)
                reason = f"{type(exc).__name__}: {exc}"
                raise CorruptLogError(self.path, offset, f"malformed record ({reason[:MAX_REASON]})") from exc
            if isinstance(record, DataEnd):
                if not self._complete:  # the data is whole, the summary or the closing magic is cut
                    yield _Truncated(file.tell())
                return
            yield record
            if isinstance(record, Chunk):
                try:
                    contents = breakup_chunk(record, validate_crc=True)
                except Exception as exc:  # decompressors and the CRC check raise assorted types
                    raise CorruptLogError(
                        self.path, offset, f"chunk does not decompress or fails its CRC ({exc!r})"
                    ) from exc
                yield from contents

    def _topics(self) -> dict[str, TopicInfo]:
        topics: dict[str, TopicInfo] = {}
        for channel in sorted(self._channels.values(), key=lambda c: (c.topic, c.id)):
            schema = self._schemas.get(channel.schema_id)
            count = self._counts.get(channel.id, 0)
            if channel.topic in topics:  # several channels on one topic: add up
                count += topics[channel.topic].count
            topics[channel.topic] = TopicInfo(
                channel.topic, schema.name if schema else "(no schema)", channel.message_encoding, count,
                schema.data.decode(errors="replace") if schema else "",
            )
        return topics

    def _decoder(self, channel: Channel, schema: Schema | None) -> Callable[[bytes], Any]:
        try:
            decoder = DecoderFactory().decoder_for(channel.message_encoding, schema)
        except Exception as exc:  # the .msg parser raises assorted types on a bad schema
            raise LogDecodeError(self.path, channel.topic, f"bad schema ({exc!r})") from exc
        if decoder is None:
            encodings = f"message encoding {channel.message_encoding!r} with schema encoding "
            encodings += repr(schema.encoding if schema else "none")
            raise LogDecodeError(self.path, channel.topic, f"{encodings} is not ROS 2 CDR")
        return decoder

    def _decode(self, decoder: Callable[[bytes], Any], channel: Channel, message: Message) -> Any:
        try:
            return decoder(message.data)
        except Exception as exc:  # the CDR reader raises assorted types on bad data
            problem = f"message at {message.log_time} ns: {exc!r}"
            raise LogDecodeError(self.path, channel.topic, problem) from exc


class _RosbagsDecoders:
    """rosbags deserializers for one pass over a log: one type store, types from the file's schemas."""

    def __init__(self, reader: LogReader) -> None:
        from rosbags.typesys import Stores, get_typestore  # imported here: only this decoder needs it

        self._reader = reader
        self._store = get_typestore(Stores.EMPTY)

    def decoder(self, channel: Channel, schema: Schema | None) -> Callable[[bytes], Any]:
        from rosbags.typesys import get_types_from_msg

        if channel.message_encoding != "cdr" or schema is None or schema.encoding != "ros2msg":
            encodings = f"message encoding {channel.message_encoding!r} with schema encoding "
            encodings += repr(schema.encoding if schema else "none")
            raise LogDecodeError(self._reader.path, channel.topic, f"{encodings} is not ROS 2 CDR")
        try:
            self._store.register(get_types_from_msg(schema.data.decode(), schema.name))
        except Exception as exc:  # rosbags' parser and type store raise assorted types on a bad schema
            raise LogDecodeError(self._reader.path, channel.topic, f"bad schema ({exc!r})") from exc
        return functools.partial(self._store.deserialize_cdr, typename=schema.name)


def _chunk_messages(
    data: bytes, targets: dict[int, tuple[Schema | None, Channel]], start_ns: int, path: Path, offset: int
) -> Iterator[tuple[Schema | None, Channel, Message]]:
    """The Message records of one decompressed chunk's `data` on the channels in `targets`,
    logged at or after `start_ns`; other records are stepped over unparsed (MCAP record
    layout: opcode u8, body length u64, body; a Message body starts with channel id u16,
    sequence u32, log time u64 and publish time u64, then the payload)."""
    unpack_record, unpack_message = _RECORD_HEAD.unpack_from, _MESSAGE_HEAD.unpack_from
    head = _MESSAGE_HEAD.size
    pos, end = 0, len(data)
    try:
        while pos < end:
            opcode, length = unpack_record(data, pos)
            body, pos = pos + _RECORD_PREFIX, pos + _RECORD_PREFIX + length
            if pos > end:
                raise ValueError(f"a record of {length} bytes runs past the chunk's end")
            if opcode != _MESSAGE_OPCODE:
                continue
            channel_id, sequence, log_time, publish_time = unpack_message(data, body)
            target = targets.get(channel_id)
            if target is not None and log_time >= start_ns:
                message = Message(channel_id=channel_id, log_time=log_time, data=data[body + head:pos],
                                  publish_time=publish_time, sequence=sequence)
                yield target[0], target[1], message
    except (struct.error, ValueError) as exc:
        raise CorruptLogError(path, offset, f"chunk holds a malformed record ({exc})") from exc


def read_log(path: str | os.PathLike[str], *, expected_topics: Iterable[str] = ()) -> LogReader:
    """Index the log at `path`; raise MissingTopicsError if any of `expected_topics` is absent."""
    reader = LogReader(path)
    reader.require_topics(expected_topics)
    return reader


def _runs_past_end(file: BinaryIO, offset: int, size: int) -> bool:
    """Whether the record starting at `offset` needs bytes beyond the end of the file."""
    if offset + _RECORD_PREFIX > size:
        return True
    file.seek(offset + 1)
    length = int.from_bytes(file.read(8), "little")
    return offset + _RECORD_PREFIX + length > size


def _describe(head: bytes) -> str:
    """What a file that does not start with the MCAP magic looks like."""
    if not head:
        return "the file is empty"
    if head.startswith(b"SQLite format 3"):
        return "an SQLite database, e.g. a rosbag2 .db3 file"
    if head.startswith(b"#ROSBAG"):
        return "a ROS 1 bag"
    return f"it starts with {head!r}"


def _format_bytes(size: int) -> str:
    if size < 1024:
        return f"{size} B"
    value, unit = size / 1024, "KiB"
    for larger in ("MiB", "GiB"):
        if value < 1024:
            break
        value, unit = value / 1024, larger
    return f"{value:.1f} {unit}"


def _format_time(ns: int | None) -> str:
    if ns is None:
        return "-"
    text = f"{ns // 10**9}.{ns % 10**9:09d} s"
    if ns >= _UNIX_TIME_NS:
        text += f" ({datetime.fromtimestamp(ns / 1e9, timezone.utc):%Y-%m-%d %H:%M:%S} UTC)"
    return text


def _summarise(value: str) -> str:
    if "\n" not in value.strip() and len(value) <= _INFO_VALUE_CHARS:
        return value
    return f"<{len(value.splitlines())} lines, {len(value)} chars>"
