"""McapRecorder's writer process (finger_sim.log.writer_process) outlives no caller and keeps what it was handed.

A caller killed with SIGKILL cannot close its log: the writer process sees its input end, writes
the open chunk and exits. Checked with a real child process and the file read back by
finger_sim.log.reader and mcap's own linear reader. And the runs it is handed, controls among
them, make the bytes mcap's own Writer makes of the same messages.
"""

from __future__ import annotations

import os
import select
import signal
import struct
import subprocess
import sys
import textwrap
import time
from pathlib import Path

from mcap.exceptions import McapError
from mcap.reader import NonSeekingReader

from finger_sim.log import LogReader

DEADLINE_S = 20.0  # generous bound for conditions that normally hold within a second
COUNT = 300

CALLER = textwrap.dedent("""
    import struct, sys, time
    from finger_sim.log import McapRecorder

    path, count = sys.argv[1], int(sys.argv[2])
    # chunks that never close on their own: everything handed over sits in the open chunk
    recorder = McapRecorder(path, chunk_interval_s=3600.0, idle_flush_s=3600.0, chunk_wall_s=3600.0).open()
    recorder.register_channel("/value", "std_msgs/msg/Float64")
    for i in range(count):
        recorder.write("/value", b"\\x00\\x01\\x00\\x00" + struct.pack("<d", float(i)), i * 1_000_000)  # CDR LE header, float64
    while recorder._taken < count:  # the writer process has read every message
        time.sleep(0.01)
    print(recorder._process.pid, recorder.written, flush=True)
    time.sleep(60.0)  # killed here
""")


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    return Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0] != "Z"


def test_a_killed_caller_ends_its_writer_which_keeps_the_open_chunk(tmp_path: Path) -> None:
    path = tmp_path / "killed.mcap"
    caller = subprocess.Popen([sys.executable, "-c", CALLER, str(path), str(COUNT)], stdout=subprocess.PIPE, text=True)
    writer = None
    try:
        ready, _, _ = select.select([caller.stdout], [], [], DEADLINE_S)
        assert ready, "the caller never reported"
        writer, written = (int(x) for x in caller.stdout.readline().split())
        assert written == 0  # nothing committed yet: the open chunk holds it all
        caller.send_signal(signal.SIGKILL)
        caller.wait(DEADLINE_S)
        deadline = time.monotonic() + DEADLINE_S
        while _alive(writer) and time.monotonic() < deadline:
            time.sleep(0.05)
        assert not _alive(writer), "the writer process outlived its caller"
    finally:
        if caller.poll() is None:
            caller.kill()
            caller.wait(DEADLINE_S)
        if writer is not None and _alive(writer):
            os.kill(writer, signal.SIGKILL)
    log = LogReader(path)
    assert log.truncated  # no summary: the caller never closed it
    assert [(m.log_time_ns, m.msg.data) for m in log.messages()] == [(i * 1_000_000, float(i)) for i in range(COUNT)]
    values = []
    with path.open("rb") as file:
        try:
            for _, _, message in NonSeekingReader(file).iter_messages(log_time_order=False):
                values.append(message.log_time)
        except (McapError, struct.error):  # the end of the file, where the summary would be
            pass
    assert values == [i * 1_000_000 for i in range(COUNT)]


def test_a_handover_fits_the_pipe_to_the_writer_process(tmp_path: Path) -> None:
    """The pipe takes a whole handover (a 10-finger hand's 50 ms: ~170 kB), so the writer process
    reads it in one or two reads: the kernel's own figure for the pipe's capacity (F_GETPIPE_SZ)."""
    import fcntl

    from finger_sim.log import McapRecorder

    with McapRecorder(tmp_path / "pipe.mcap") as recorder:
        assert recorder._process is not None and recorder._process.stdin is not None
        assert fcntl.fcntl(recorder._process.stdin.fileno(), fcntl.F_GETPIPE_SZ) == 1 << 20


def test_the_recorders_runs_give_mcaps_own_file_byte_for_byte(tmp_path: Path) -> None:
    """Messages handed over in runs (a handover every 10 ms, so many runs), a drop's spent number,
    a channel registered between runs, one chunk (no rule closes it before the end): the file is
    byte for byte what mcap's Writer writes alone, add_message per message, in the same order.
    Uncompressed chunks: the writer compresses at its own zstd level (compared with mcap's in
    test_writer_memory)."""
    from mcap.well_known import MessageEncoding, Profile, SchemaEncoding
    from mcap.writer import CompressionType, Writer

    from finger_sim.log import McapRecorder
    from finger_sim.log.writer_process import LIBRARY, _NO_SIZE_TRIGGER

    float64, definition, dt_ns = "std_msgs/msg/Float64", "float64 data\n", 1_000_000

    def cdr(value: float) -> bytes:
        return b"\x00\x01\x00\x00" + struct.pack("<d", value)  # CDR little-endian header, float64

    # (topic, sequence, log ns, data): /a alone, then /a and /b each step; /a's number 151 spent by a drop
    steps = [(k, ["/a"]) for k in range(150)] + [(k, ["/a", "/b"]) for k in range(150, 400)]
    expected: list[tuple[str, int, int, bytes]] = []
    path, reference = tmp_path / "ours.mcap", tmp_path / "mcap.mcap"
    with McapRecorder(path, chunk_interval_s=3600.0, idle_flush_s=3600.0, chunk_wall_s=3600.0, handover_s=0.01,
                      compression=CompressionType.NONE) as rec:
        rec.register_channel("/a", float64, definition=definition)
        sequences = {"/a": 0, "/b": 0}
        for k, topics in steps:
            if k == 150:
                rec._pending.append(rec._channels["/a"])  # what a drop leaves: its number spent (under test: no lock needed)
                sequences["/a"] += 1
                rec.register_channel("/b", float64, definition=definition)
            datas = [cdr(k + i / 10) for i in range(len(topics))]
            assert rec.write_records(topics, datas, k * dt_ns) == len(topics)
            for topic, data in zip(topics, datas):
                sequences[topic] += 1
                expected.append((topic, sequences[topic], k * dt_ns, data))
            if k % 50 == 0:
                time.sleep(0.02)  # let a handover happen: more runs
    with reference.open("wb") as f:
        writer = Writer(f, chunk_size=_NO_SIZE_TRIGGER, compression=CompressionType.NONE)
        writer.start(profile=Profile.ROS2, library=LIBRARY)
        writer.flush()
        schema = writer.register_schema(name=float64, encoding=SchemaEncoding.ROS2, data=definition.encode())
        channels = {"/a": writer.register_channel(topic="/a", message_encoding=MessageEncoding.CDR, schema_id=schema,
                                                  metadata={})}
        for topic, sequence, log_ns, data in expected:
            if log_ns == 150 * dt_ns and "/b" not in channels:  # registered before step 150's messages
                channels["/b"] = writer.register_channel(topic="/b", message_encoding=MessageEncoding.CDR,
                                                         schema_id=schema, metadata={})
            writer.add_message(channels[topic], log_ns, data, log_ns, sequence)
        writer.finish()
    assert path.read_bytes() == reference.read_bytes()
