"""A sweep's cost against the number of Dask workers, on this machine.

    python -m finger_sim.bench.dask_bench [--workers 1,2] [--springs 40] [--slopes 50] [--repeats 3]

The sweep: the paper's run (config/paper_flexion.yaml, 300 steps) over springs × slopes. Each
worker count gets a `distributed.LocalCluster` of worker processes on 127.0.0.1 (one thread
each; numba's loop inside a task uses `--numba-threads`), warmed up by one small sweep (worker
start and the numba cache load are not in the figures), then timed over `repeats` whole
sweeps (`cluster.sweep_on_dask`, CHUNKS_PER_WORKER tasks per worker): wall seconds and
finger-steps per second, medians. The local `sweep.run_chunk` of the same sweep in this
process is the baseline. Every row set is checked equal to the local one.
"""

from __future__ import annotations

import argparse
import logging
import os
import statistics
import time
from pathlib import Path

from finger_sim.cluster import sweep_on_dask
from finger_sim.sweep import run_chunk

SCENE = Path(__file__).resolve().parents[2] / "config" / "paper_flexion.yaml"
STEPS = 300  # the paper run's steps


def _vary(springs: int, slopes: int) -> list[str]:
    return ["model.spring_stiffness=" + ",".join(f"{0.0005 + 1.5e-3 * i / springs:.6g}" for i in range(springs)),
            "input.torque.slope=" + ",".join(f"{0.005 + 0.025 * i / slopes:.6g}" for i in range(slopes))]


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--workers", default="1,2")
    ap.add_argument("--springs", type=int, default=40)
    ap.add_argument("--slopes", type=int, default=50)
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--numba-threads", type=int, default=1)
    args = ap.parse_args(argv)
    os.environ["NUMBA_NUM_THREADS"] = str(args.numba_threads)  # inherited by the worker processes
    import distributed

    vary = _vary(args.springs, args.slopes)
    runs = args.springs * args.slopes
    run_chunk(SCENE, _vary(2, 2))  # warm: numba's cache load
    walls = []
    for _ in range(args.repeats):
        start = time.perf_counter()
        local = run_chunk(SCENE, vary)
        walls.append(time.perf_counter() - start)
    print(f"# {time.strftime('%Y-%m-%d %H:%M UTC', time.gmtime())}; {runs} paper runs ({runs * STEPS:,} finger-steps), "
          f"{os.cpu_count()} cores, numba threads per process {args.numba_threads}, medians of {args.repeats}")
    print("| where | workers | wall s | finger-steps / s | vs local |")
    print("|---|---:|---:|---:|---:|")
    base = statistics.median(walls)
    print(f"| local `run_chunk` (this process) | — | {base:.2f} | {runs * STEPS / base:,.0f} | 1.00 |")
    for n in (int(w) for w in args.workers.split(",")):
        with distributed.LocalCluster(n_workers=n, threads_per_worker=1, processes=True, host="127.0.0.1",
                                      dashboard_address=None, silence_logs=logging.ERROR) as cluster, \
                distributed.Client(cluster) as client:
            sweep_on_dask(SCENE, _vary(4, 4), client)  # warm the workers
            walls = []
            for _ in range(args.repeats):
                start = time.perf_counter()
                rows = sweep_on_dask(SCENE, vary, client).rows
                walls.append(time.perf_counter() - start)
                assert rows == local.rows, "the cluster's rows differ from the local sweep's"
        wall = statistics.median(walls)
        print(f"| Dask LocalCluster | {n} | {wall:.2f} | {runs * STEPS / wall:,.0f} | {base / wall:.2f} |")


if __name__ == "__main__":
    main()
