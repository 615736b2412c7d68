"""Repairing a cut log: the readable part of an MCAP file rewritten as a complete, indexed one.

A recorder killed (kill -9, power loss) or stopped by a full disk leaves a file without its
summary and closing magic; readers that start from the footer (rosbags, `mcap` tools that
seek) refuse it. `repair_log` reads the file record by record, as finger_sim.log.reader does,
up to the cut (everything up to the last intact chunk), skipping a damaged chunk (as `mcap
recover` does; after a malformed record it goes on at the next chunk the summary indexes), and
writes the header's profile, every schema, channel, message (with its log and publish
times and sequence number), metadata record and attachment into a new file with chunks,
message indexes and a summary: what `mcap recover` or `ros2 bag reindex` produce (a file cut
inside its header gets the 'ros2' profile that finger_sim.log.McapRecorder writes). The new
file is written beside the target and renamed into place, so a killed repair leaves no
half-written output.
"""

from __future__ import annotations

import contextlib
import os
import tempfile
from dataclasses import dataclass
from pathlib import Path

from mcap.records import Attachment, Channel, Header, Message, Metadata, Schema
from mcap.well_known import Profile
from mcap.writer import LIBRARY_IDENTIFIER, MCAP0_MAGIC, CompressionType, Writer

from .errors import CorruptLogError, LogArgumentError, NotMcapError, TruncatedLogError
from .reader import Damage, LogReader

REPAIR_SUFFIX = ".repaired.mcap"
LIBRARY = f"finger_sim.log repair; {LIBRARY_IDENTIFIER}"


@dataclass(frozen=True)
class RepairReport:
    """What `repair_log` wrote, and why the source ended where it did."""

    source: Path
    out: Path
    messages: int
    channels: int
    metadata: int
    attachments: int
    truncation: TruncatedLogError | None  # the source's cut, None if it was complete
    damage: CorruptLogError | None  # the first damaged record skipped, None if none
    dropped: tuple[Damage, ...] = ()  # every damaged stretch skipped
    lost_messages: int = 0  # messages in the dropped chunks (by the source's indexes; a lower bound)

    @property
    def lost(self) -> bool:
        """Whether damaged data was dropped (the copy lacks something the source once held)."""
        return bool(self.dropped)

    def summary(self) -> str:
        if self.dropped:
            first = self.dropped[0].error
            why = (f"DROPPED {len(self.dropped)} damaged part(s) holding at least {self.lost_messages} messages; "
                   f"first at byte {first.offset}: {first.reason}")
        elif self.truncation is not None:
            why = f"the source is {self.truncation.problem}"
        else:
            why = "the source was complete"
        return (f"repaired {self.source} → {self.out}: {self.messages} messages on {self.channels} channels, "
                f"{self.metadata} metadata records, {self.attachments} attachments ({why})")


def default_repair_path(log: str | os.PathLike[str]) -> Path:
    """`<stem>.repaired.mcap` next to `log`."""
    path = Path(log)
    return path.with_name(path.stem + REPAIR_SUFFIX)


def repair_log(log: str | os.PathLike[str], out: str | os.PathLike[str] | None = None, *,
               compression: CompressionType = CompressionType.ZSTD) -> RepairReport:
    """Rewrite the readable part of `log` as a complete MCAP at `out` (default: default_repair_path).

    A file cut before its magic was whole (empty: killed as it was created) becomes an empty
    log. Raises a LogFileError subclass if `log` is not an MCAP file at all, and
    LogArgumentError if `out` is `log` itself. Overwrites an existing `out`.
    """
    source = _source(Path(log))
    target = Path(out) if out is not None else default_repair_path(log)
    if target.exists() and os.path.samefile(target, log):
        raise LogArgumentError("out", "a path other than the log being repaired", str(target))
    temp = tempfile.NamedTemporaryFile(dir=target.parent, prefix=f".{target.name}.", suffix=".part", delete=False)
    try:
        with temp:
            writer = Writer(temp, compression=compression)
            counts, damage = _copy(source, writer) if source is not None else _empty(writer)
            temp.flush()
            os.fsync(temp.fileno())
        os.replace(temp.name, target)
    except BaseException:
        with contextlib.suppress(OSError):
            os.unlink(temp.name)
        raise
    truncation = source.truncation if source is not None else TruncatedLogError(log, 0, Path(log).stat().st_size, 0)
    dropped = tuple(source.damage) if source is not None else ()
    lost = sum(d.messages for d in dropped)
    if source is not None and source.indexed and dropped:  # the summary's count is the exact total
        lost = max(lost, source.message_count - counts[0])
    return RepairReport(Path(log), target, *counts, truncation=truncation, damage=damage, dropped=dropped,
                        lost_messages=lost)


def _source(log: Path) -> LogReader | None:
    """The log's reader; None for a file cut before its magic was whole (a kill as it was created)."""
    try:
        return LogReader(log, salvage=True)
    except NotMcapError:
        with contextlib.suppress(OSError):
            if log.is_file() and MCAP0_MAGIC.startswith(_head(log, len(MCAP0_MAGIC) + 1)):
                return None
        raise


def _head(path: Path, size: int) -> bytes:
    """The first `size` bytes of a file (not the whole of it)."""
    with path.open("rb") as f:
        return f.read(size)


def _empty(writer: Writer) -> tuple[tuple[int, int, int, int], None]:
    writer.start(profile=Profile.ROS2, library=LIBRARY)
    writer.finish()
    return (0, 0, 0, 0), None


def _copy(source: LogReader, writer: Writer) -> tuple[tuple[int, int, int, int], CorruptLogError | None]:
    """Copy records into `writer` and finish it; (messages, channels, metadata, attachments), damage."""
    schema_ids: dict[int, int] = {0: 0}  # source id → written id; 0 is "no schema"
    channel_ids: dict[int, int] = {}
    messages = metadata = attachments = 0
    started = False
    damage = None
    try:
        for record in source.records():
            if isinstance(record, Header):
                writer.start(profile=record.profile, library=LIBRARY)
                started = True
            elif not started:  # a record before the header: the file is damaged
                raise CorruptLogError(source.path, None, "records before the header")
            if isinstance(record, Schema) and record.id not in schema_ids:
                schema_ids[record.id] = writer.register_schema(record.name, record.encoding, record.data)
            elif isinstance(record, Channel) and record.id not in channel_ids:
                if record.schema_id not in schema_ids:
                    raise CorruptLogError(source.path, None, f"channel {record.topic} names undeclared schema "
                                                             f"{record.schema_id}")
                channel_ids[record.id] = writer.register_channel(
                    record.topic, record.message_encoding, schema_ids[record.schema_id], dict(record.metadata))
            elif isinstance(record, Message):
                if record.channel_id not in channel_ids and not _declare(source, writer, record.channel_id,
                                                                         schema_ids, channel_ids):
                    continue  # declared in a dropped chunk and not in a summary: counted as lost
                writer.add_message(channel_ids[record.channel_id], record.log_time, record.data,
                                   record.publish_time, record.sequence)
                messages += 1
            elif isinstance(record, Metadata):
                writer.add_metadata(record.name, dict(record.metadata))
                metadata += 1
            elif isinstance(record, Attachment):
                writer.add_attachment(record.create_time, record.log_time, record.name, record.media_type, record.data)
                attachments += 1
    except CorruptLogError as exc:
        damage = exc
    if damage is None and source.damage:
        damage = source.damage[0].error
    if not started:  # the file was cut inside its header: assume what McapRecorder writes
        writer.start(profile=Profile.ROS2, library=LIBRARY)
    writer.finish()
    return (messages, len(channel_ids), metadata, attachments), damage


def _declare(source: LogReader, writer: Writer, channel_id: int, schema_ids: dict[int, int],
             channel_ids: dict[int, int]) -> bool:
    """Register a channel declared only in a dropped chunk from the source's summary; False if it has none."""
    channel = source.channels.get(channel_id)
    if channel is None:
        return False
    if channel.schema_id not in schema_ids:
        schema = source.schemas.get(channel.schema_id)
        if schema is None:
            return False
        schema_ids[schema.id] = writer.register_schema(schema.name, schema.encoding, schema.data)
    channel_ids[channel.id] = writer.register_channel(channel.topic, channel.message_encoding,
                                                      schema_ids[channel.schema_id], dict(channel.metadata))
    return True
