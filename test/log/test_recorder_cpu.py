"""McapRecorder.cpu(): what recording costs, held against readers the recorder does not use.

References: the calling thread's own CPU clock over the whole loop of write_records (the estimate
of the time inside it must fall within the loop's), the sender's and status thread's POSIX CPU
clocks (`time.pthread_getcpuclockid`) read before and after, and utime + stime of this process and
of the writer process in /proc/<pid>/stat (clock ticks). No timed assertion: CPU counters only.
"""

from __future__ import annotations

import gc
import os
import time
from pathlib import Path

import pytest

from finger_sim.log import McapRecorder
from finger_sim.log.cpu_clocks import name_os_thread, threads_cpu_ns
from finger_sim.log.recorder import CPU_SAMPLE_EVERY
from finger_sim.runtime.log_paths import UnwritableLog

DEADLINE_S = 10.0  # wall s a started thread gets to run
STATES = 8000  # write_records calls: 250 of them timed
TICK_S = 1.0 / os.sysconf("SC_CLK_TCK")
TOPICS = ["/clock", "/joint_states"]
DATAS = [b"\x00\x01\x00\x00" + bytes(8), b"\x00\x01\x00\x00" + bytes(120)]  # CDR header + payload


def stat_cpu_s(pid: int) -> float:
    """utime + stime of process `pid`, s (all its threads, ended ones included), from /proc/<pid>/stat."""
    fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) * TICK_S


def pthread_cpu_s(*threads) -> float:
    return sum(time.clock_gettime(time.pthread_getcpuclockid(t.ident)) for t in threads)


def test_recorder_counts_its_own_cpu_within_independent_readings(tmp_path):
    rec = McapRecorder(tmp_path / "cpu.mcap", queue_size=10 * STATES).open()
    try:
        rec.register_channel("/clock", "rosgraph_msgs/msg/Clock")
        rec.register_channel("/joint_states", "sensor_msgs/msg/JointState")
        # No garbage collection inside the loop: a full one walks the whole suite's heap (0.08 s for a process that only
        # ran the kernel's warm-up, 150k objects) and is charged to the loop's CPU and to no sampled call. Once in
        # `make test` (2026-11-27) the loop read 0.52 s of CPU, the sampled calls 0.009 s; alone it reads ~0.01 s.
        gc.collect()
        gc.disable()
        try:
            loop_start = time.thread_time()
            for k in range(STATES):
                assert rec.write_records(TOPICS, DATAS, k * 1_000_000) == 2
            loop_s = time.thread_time() - loop_start
        finally:
            gc.enable()
        threads = (rec._sender, rec._listener)
        writer_before, threads_before = stat_cpu_s(rec.writer_pid), pthread_cpu_s(*threads)
        cpu = rec.cpu()
        writer_after, threads_after = stat_cpu_s(rec.writer_pid), pthread_cpu_s(*threads)
        own_after = stat_cpu_s(os.getpid())
    finally:
        rec.close()
    # the callers' share: one call in CPU_SAMPLE_EVERY timed, scaled; it is inside the loop's own CPU time, up to
    # what the clock reads themselves leave in it (at most one read pair, ~0.5 µs, per call it stands for)
    assert 0.5 * loop_s < cpu.caller_s < loop_s + STATES * 1e-6, (cpu, loop_s)
    assert STATES // CPU_SAMPLE_EVERY == 250
    # the POSIX clocks of the same two threads (1 ns: the float sum of two readings)
    assert 0 < threads_before - 1e-9 <= cpu.threads_s <= threads_after + 1e-9
    # the writer process: its own counters, within its utime + stime (ticks: each reading may lag a tick a thread)
    assert 0 < cpu.writer_s and writer_before - 2 * TICK_S <= cpu.writer_s <= writer_after + 2 * TICK_S
    assert cpu.caller_s + cpu.threads_s <= own_after + 2 * TICK_S  # inside this process's CPU
    assert cpu.total_s == pytest.approx(cpu.caller_s + cpu.threads_s + cpu.writer_s)
    assert rec.cpu() == rec.cpu()  # after close: the last readings, frozen


def test_recorder_threads_carry_their_names_to_the_operating_system(tmp_path):
    with McapRecorder(tmp_path / "names.mcap"):
        deadline = time.monotonic() + DEADLINE_S  # each thread names itself once it runs

        def named() -> bool:
            return {"mcap sender", "mcap status"} <= {name for name, _ in threads_cpu_ns(os.getpid()).values()}

        while not named() and time.monotonic() < deadline:
            time.sleep(0.01)
        assert named()


def test_name_os_thread_keeps_the_kernels_15_bytes():
    import threading

    seen: list[str] = []

    def run() -> None:
        name_os_thread("a name longer than fifteen bytes")
        seen.append(Path(f"/proc/self/task/{threading.get_native_id()}/comm").read_text().rstrip("\n"))

    thread = threading.Thread(target=run)
    thread.start()
    thread.join()
    assert seen == ["a name longer t"]


def test_no_log_costs_nothing():
    assert UnwritableLog("/nonexistent", "cannot create").cpu() is None
