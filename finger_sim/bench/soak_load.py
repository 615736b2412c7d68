"""A foreign load for a soak: CPU burners, a disk writer that fsyncs, and memory churn.

Each part runs in its own process at normal priority (SCHED_OTHER, nice 0), as another user's
build or test run would; this process waits for SIGINT or SIGTERM and then stops them.

    python -m finger_sim.bench.soak_load --cpu 2 --fsync-mb 4 --mem-mb 1024 --dir /tmp &
    ...
    kill <its pid>

- cpu: processes that spin in Python.
- fsync: writes `fsync_mb` MB to a file in `dir` and fsyncs it, over and over (the file is
  rewritten in place, so the disk does not fill).
- mem: allocates `mem_mb` MB, touches every page, frees it, over and over (page faults, page
  zeroing and unmapping in the kernel).
"""

from __future__ import annotations

import argparse
import mmap
import multiprocessing
import os
import signal
import tempfile
from pathlib import Path

#: Bytes per page touched by the memory churn (the common page size).
PAGE = mmap.PAGESIZE
MB = 1 << 20


def _cpu() -> None:
    while True:
        pass


def _fsync(dir_: str, size_mb: int) -> None:
    block = os.urandom(MB)
    with tempfile.TemporaryFile(dir=dir_) as f:
        while True:
            f.seek(0)
            for _ in range(size_mb):
                f.write(block)
            f.flush()
            os.fsync(f.fileno())


def _mem(size_mb: int) -> None:
    while True:
        m = mmap.mmap(-1, size_mb * MB)
        for i in range(0, size_mb * MB, PAGE):
            m[i] = 1
        m.close()


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--cpu", type=int, default=2, help="CPU burner processes")
    parser.add_argument("--fsync-mb", type=int, default=4, help="MB written and fsynced per round (0: none)")
    parser.add_argument("--mem-mb", type=int, default=1024, help="MB allocated, touched and freed per round (0: none)")
    parser.add_argument("--dir", type=Path, default=Path(tempfile.gettempdir()), help="folder of the fsync writer's file")
    args = parser.parse_args(argv)
    jobs = [multiprocessing.Process(target=_cpu, daemon=True) for _ in range(args.cpu)]
    if args.fsync_mb > 0:
        jobs.append(multiprocessing.Process(target=_fsync, args=(str(args.dir), args.fsync_mb), daemon=True))
    if args.mem_mb > 0:
        jobs.append(multiprocessing.Process(target=_mem, args=(args.mem_mb,), daemon=True))
    for job in jobs:
        job.start()
    signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGINT, signal.SIGTERM})  # after the start: the workers keep the default
    print(f"load: pid {os.getpid()}, workers {[job.pid for job in jobs]}", flush=True)
    try:
        signal.sigwait({signal.SIGINT, signal.SIGTERM})
    finally:
        for job in jobs:
            job.terminate()
            job.join()
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
