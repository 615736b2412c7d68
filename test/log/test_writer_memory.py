"""The log writer process's file (finger_sim.log.writer_process): flat memory, mcap's own bytes.

mcap's Writer keeps one ChunkIndex object per chunk until finish() (~0.8 kB each: +6 MB an hour
for a node's two chunks a second); the writer process spills them to a temporary file. And it
appends each message's MCAP record to mcap's open chunk itself, not through Writer.add_message.
References: the Python heap's growth over many chunks (tracemalloc), set against the chunk count
read back by mcap's own linear reader; the file compared byte for byte with one that mcap's Writer
writes alone (add_message per message, chunks closed by the same rule, written out in the test);
every message read back through the spilled index by mcap's indexed reader and by rosbags.
"""

from __future__ import annotations

import random
import struct
import tracemalloc
import zlib
from pathlib import Path

import pytest
import zstandard
from mcap.reader import SeekingReader
from mcap.records import Chunk
from mcap.stream_reader import StreamReader
from mcap.well_known import MessageEncoding, Profile, SchemaEncoding
from mcap.writer import CompressionType, Writer
from rosbags.highlevel import AnyReader

from finger_sim.log.writer_process import (LIBRARY, MCAP_ZSTD_LEVEL, ZSTD_LEVEL, ChunkedFile, Register, _NO_SIZE_TRIGGER,
                                           message_record)

TOPICS = ("/a", "/b", "/c", "/d", "/e", "/f")  # a node logs about six topics
WARMUP_CHUNKS = 200  # chunks before the heap is first measured (buffers, caches, first allocations)
CHUNKS = 2_000  # chunks after it: ~17 minutes of a node's log at two chunks a second
#: Heap growth allowed per chunk after the warm-up, bytes. The unspilled index takes ~800.
MAX_BYTES_PER_CHUNK = 16
FLOAT64 = "std_msgs/msg/Float64"
DT_NS = 1_000_000  # 1 kHz log times


def cdr_float64(value: float) -> bytes:
    return b"\x00\x01\x00\x00" + struct.pack("<d", value)  # CDR little-endian header, float64


def chunk_messages(chunk: int) -> list[tuple[int, int, int, int, bytes]]:
    """One message per topic: (channel index, sequence, log ns, publish ns, CDR bytes)."""
    t = chunk * DT_NS
    return [(i, chunk + 1, t, t, cdr_float64(chunk + i / 10)) for i in range(len(TOPICS))]


def framed(messages: list[tuple[int, int, int, int, bytes]]) -> bytearray:
    """Messages as the writer process reads them: each its MCAP Message record."""
    out = bytearray()
    for index, sequence, log_ns, publish_ns, data in messages:
        out += message_record(index, sequence, log_ns, publish_ns, data)
    return out


def add(log: ChunkedFile, messages: list[tuple[int, int, int, int, bytes]]) -> int:
    records = framed(messages)
    return log.add_messages(records, 0, len(records))


def write_chunks(path: Path, chunks: int, *, measure_after: int | None = None, compression: CompressionType = CompressionType.ZSTD,
                 zstd_level: int = ZSTD_LEVEL) -> tuple[int, int]:
    """`chunks` chunks through ChunkedFile, finished; returns the traced heap after chunk
    `measure_after` and after the last chunk (bytes), or zeros when not measured."""
    log = ChunkedFile(path, interval_ns=1 << 62, chunk_size=1 << 30, compression=compression, zstd_level=zstd_level)
    for i, topic in enumerate(TOPICS):
        log.register(Register(i, topic, FLOAT64, "float64 data\n", {}))
    heap = [0, 0]
    for chunk in range(chunks):
        if chunk == measure_after:
            heap[0] = tracemalloc.get_traced_memory()[0]
        assert add(log, chunk_messages(chunk)) == 0
        assert log.close_chunk() == len(TOPICS)
    if measure_after is not None:
        heap[1] = tracemalloc.get_traced_memory()[0]
    log.finish()
    return heap[0], heap[1]


def test_the_chunk_index_does_not_grow_the_heap(tmp_path: Path) -> None:
    path = tmp_path / "long.mcap"
    tracemalloc.start()
    try:
        before, after = write_chunks(path, WARMUP_CHUNKS + CHUNKS, measure_after=WARMUP_CHUNKS)
    finally:
        tracemalloc.stop()
    with path.open("rb") as f:  # the chunks really were written: counted by mcap's linear reader
        chunks = sum(isinstance(r, Chunk) for r in StreamReader(f, emit_chunks=True).records)
    assert chunks == WARMUP_CHUNKS + CHUNKS
    growth = after - before
    assert growth <= MAX_BYTES_PER_CHUNK * CHUNKS, (
        f"heap grew by {growth} B over {CHUNKS} chunks ({growth / CHUNKS:.0f} B per chunk)")


def mcaps_own_file(path: Path, chunks: int, compression: CompressionType) -> None:
    """write_chunks's input through mcap's Writer alone."""
    with path.open("wb") as f:
        writer = Writer(f, chunk_size=_NO_SIZE_TRIGGER, compression=compression)
        writer.start(profile=Profile.ROS2, library=LIBRARY)
        writer.flush()
        schema = writer.register_schema(name=FLOAT64, encoding=SchemaEncoding.ROS2, data=b"float64 data\n")
        channels = [writer.register_channel(topic=t, message_encoding=MessageEncoding.CDR, schema_id=schema, metadata={})
                    for t in TOPICS]
        for chunk in range(chunks):
            for index, sequence, log_ns, publish_ns, data in chunk_messages(chunk):
                writer.add_message(channels[index], log_ns, data, publish_ns, sequence)
            writer.flush()
        writer.finish()


@pytest.mark.parametrize("compression", list(CompressionType))
def test_the_spilled_index_gives_mcaps_own_file_byte_for_byte(tmp_path: Path, compression: CompressionType) -> None:
    """At mcap's zstd level (and with lz4 or none) the file is the one mcap's Writer writes."""
    chunks = 50
    ours, reference = tmp_path / "ours.mcap", tmp_path / "mcap.mcap"
    write_chunks(ours, chunks, compression=compression, zstd_level=MCAP_ZSTD_LEVEL)
    mcaps_own_file(reference, chunks, compression)
    assert ours.read_bytes() == reference.read_bytes()


def chunk_records(path: Path) -> list[Chunk]:
    with path.open("rb") as f:
        return [record for record in StreamReader(f, emit_chunks=True).records if isinstance(record, Chunk)]


def test_our_zstd_level_changes_only_the_compressed_bytes(tmp_path: Path) -> None:
    """At ZSTD_LEVEL each chunk holds mcap's uncompressed bytes and CRC, compressed at that level
    (zstandard's frame header does not name a level: checked by compressing again)."""
    chunks = 20
    ours, reference = tmp_path / "ours.mcap", tmp_path / "mcap.mcap"
    write_chunks(ours, chunks)
    mcaps_own_file(reference, chunks, CompressionType.ZSTD)
    got, expected = chunk_records(ours), chunk_records(reference)
    assert len(got) == len(expected) == chunks
    for ours_chunk, mcap_chunk in zip(got, expected):
        plain = zstandard.decompress(mcap_chunk.data)
        assert zstandard.decompress(ours_chunk.data) == plain
        assert (ours_chunk.uncompressed_crc, ours_chunk.uncompressed_size) == (zlib.crc32(plain), len(plain))
        assert ours_chunk.compression == "zstd"
        assert ours_chunk.data == zstandard.ZstdCompressor(level=ZSTD_LEVEL).compress(plain)
        assert (ours_chunk.message_start_time, ours_chunk.message_end_time) == (
            mcap_chunk.message_start_time, mcap_chunk.message_end_time)


@pytest.mark.parametrize("chunks", [1, 37])
def test_every_message_reads_back_through_the_spilled_index(tmp_path: Path, chunks: int) -> None:
    path = tmp_path / "log.mcap"
    write_chunks(path, chunks)  # at ZSTD_LEVEL
    expected = [(TOPICS[i], log_ns, data) for c in range(chunks) for i, _, log_ns, _, data in chunk_messages(c)]
    with path.open("rb") as f:
        reader = SeekingReader(f)
        summary = reader.get_summary()
        assert summary is not None and len(summary.chunk_indexes) == chunks == summary.statistics.chunk_count
        got = [(channel.topic, message.log_time, message.data)
               for _, channel, message in reader.iter_messages(log_time_order=False)]
    assert got == expected
    with AnyReader([path]) as reader:  # rosbags, through the summary's chunk indexes
        got = [(c.topic, t, bytes(d)) for c, t, d in reader.messages()]
        assert [reader.deserialize(d, FLOAT64).data for _, _, d in got] == [
            struct.unpack("<d", data[4:])[0] for _, _, data in expected]
    assert sorted(got) == sorted(expected)


def reference_file(path: Path, messages: list[tuple[int, int, int, int, bytes]], *, interval_ns: int, chunk_size: int,
                   cut_after: set[int]) -> None:
    """mcap's Writer alone, add_message per message; a chunk closes before a message that would
    stretch its log-time span to interval_ns, once its data reaches chunk_size bytes, and after
    each message numbered in cut_after (the ends of the writer process's add_messages calls)."""
    with path.open("wb") as f:
        writer = Writer(f, chunk_size=_NO_SIZE_TRIGGER, compression=CompressionType.ZSTD)
        writer.start(profile=Profile.ROS2, library=LIBRARY)
        writer.flush()
        schema = writer.register_schema(name=FLOAT64, encoding=SchemaEncoding.ROS2, data=b"float64 data\n")
        channels = [writer.register_channel(topic=t, message_encoding=MessageEncoding.CDR, schema_id=schema, metadata={})
                    for t in TOPICS]
        times: list[int] = []
        size = 0
        for n, (index, sequence, log_ns, publish_ns, data) in enumerate(messages):
            if times and max(times + [log_ns]) - min(times + [log_ns]) >= interval_ns:
                writer.flush()
                times, size = [], 0
            writer.add_message(channels[index], log_ns, data, publish_ns, sequence)
            times.append(log_ns)
            size += len(data)
            if size >= chunk_size:
                writer.flush()
                times, size = [], 0
            if n in cut_after:
                writer.flush()
                times, size = [], 0
        writer.finish()


@pytest.mark.parametrize("out_of_order", [True, False])
def test_chunks_cut_inside_a_call_give_mcaps_own_file_byte_for_byte(tmp_path: Path, out_of_order: bool) -> None:
    """Log times out of order (or in order, as a node logs them: ChunkedFile's binary search),
    channels in any order, payloads of any size, chunks closed on the log-time span and on size in
    the middle of a call: the same bytes as mcap's add_message."""
    rng = random.Random(15)
    early_or_late = [-5 * DT_NS, 100 * DT_NS] if out_of_order else []
    interval_ns, chunk_size = 40 * DT_NS, 3_000
    messages, t = [], 0
    for n in range(3_000):
        t += rng.choice([0, DT_NS, 2 * DT_NS])
        log_ns = max(0, t + rng.choice([0] * 20 + early_or_late))  # now and then a late or early one
        data = b"\x00\x01\x00\x00" + rng.randbytes(rng.choice([8, 8, 64, 900]))
        messages.append((rng.randrange(len(TOPICS)), n + 1, log_ns, log_ns + rng.randrange(1000), data))
    calls = sorted(rng.sample(range(1, len(messages)), 40)) + [len(messages)]  # where each add_messages call ends
    ours, reference = tmp_path / "ours.mcap", tmp_path / "mcap.mcap"
    log = ChunkedFile(ours, interval_ns=interval_ns, chunk_size=chunk_size, compression=CompressionType.ZSTD,
                      zstd_level=MCAP_ZSTD_LEVEL)
    for i, topic in enumerate(TOPICS):
        log.register(Register(i, topic, FLOAT64, "float64 data\n", {}))
    committed, begin = 0, 0
    for n, end in enumerate(calls):
        committed += add(log, messages[begin:end])
        if n % 3 == 0:  # every third call ends with a chunk closed on idle or wall time
            committed += log.close_chunk()
        begin = end
    committed += log.finish()
    assert committed == len(messages)
    reference_file(reference, messages, interval_ns=interval_ns, chunk_size=chunk_size,
                   cut_after={end - 1 for n, end in enumerate(calls) if n % 3 == 0})
    assert ours.read_bytes() == reference.read_bytes()
