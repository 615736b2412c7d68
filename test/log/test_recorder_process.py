"""McapRecorder's writer process (finger_sim.log.writer_process) outlives no caller and keeps what it was handed.

A caller killed with SIGKILL cannot close its log: the writer process sees its input end, writes
the open chunk and exits. Checked with a real child process and the file read back by
finger_sim.log.reader and mcap's own linear reader.
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
