"""Sweeps on a real Dask cluster: a `distributed.LocalCluster` of worker processes on 127.0.0.1.

The rows must equal the local sweep's (the same chunks, bit for bit), also when a worker is
killed in the middle of the sweep; the CSV and the Parquet file (read back by pyarrow) hold
the same rows as the local CSV. The cluster is closed by its context manager even when a test fails.
"""

from __future__ import annotations

import csv
import logging
import os
import re
import signal
import time
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import pytest

distributed = pytest.importorskip("distributed")
pq = pytest.importorskip("pyarrow.parquet")

from finger_sim.cli import main  # noqa: E402
from finger_sim.cluster import ChunkFailed, sweep_on_dask  # noqa: E402
from finger_sim.scene import load_scene  # noqa: E402
from finger_sim.sweep import run_chunk  # noqa: E402

CONFIG = Path(__file__).resolve().parents[2] / "config"
VARY = ["model.spring_stiffness=0.0005,0.001,0.0015,0.002", "input.torque.slope=0.005,0.01,0.02"]
#: Seconds a test waits for the cluster to reach a state before failing.
DEADLINE = 120.0


@pytest.fixture(scope="module")
def cluster():
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True, host="127.0.0.1",
                                  dashboard_address=None, silence_logs=logging.ERROR) as local:
        yield local


def _csv_rows(path: Path) -> list[dict[str, str]]:
    with path.open(newline="", encoding="utf-8") as f:
        return list(csv.DictReader(f))


def test_rows_equal_the_local_sweep_in_csv_and_parquet(cluster, tmp_path, capsys):
    local = run_chunk(CONFIG / "paper_flexion.yaml", VARY)
    with distributed.Client(cluster) as client:
        remote = sweep_on_dask(CONFIG / "paper_flexion.yaml", VARY, client, chunks=5)
    assert remote.header == local.header and remote.rows == local.rows and len(remote.rows) == 12

    args = ["sweep", str(CONFIG / "paper_flexion.yaml"), *(a for v in VARY for a in ("--vary", v))]
    assert main([*args, "--out", str(tmp_path / "local.csv")]) == 0
    assert main([*args, "--out", str(tmp_path / "dask.csv"), "--parquet", str(tmp_path / "dask.parquet"),
                 "--dask", cluster.scheduler_address]) == 0
    assert f"12 runs on the Dask cluster at {cluster.scheduler_address}" in capsys.readouterr().out
    expected = _csv_rows(tmp_path / "local.csv")
    assert _csv_rows(tmp_path / "dask.csv") == expected
    table = pq.read_table(tmp_path / "dask.parquet").to_pylist()
    assert list(table[0]) == local.header
    for got, want in zip(table, expected, strict=True):
        for key, value in want.items():
            assert (got[key] == value) if key.startswith(("model.", "input.")) else (got[key] == float(value))


def test_a_worker_killed_mid_sweep_loses_no_row(cluster):
    scene = load_scene(CONFIG / "paper_flexion.yaml").with_overrides(duration=1.0)
    vary = ["model.spring_stiffness=" + ",".join(f"{0.0005 + 1e-5 * i:.5f}" for i in range(40)),
            "input.torque.slope=0.005,0.01,0.015,0.02,0.025"]
    local = run_chunk(scene, vary)
    with distributed.Client(cluster) as client:
        client.wait_for_workers(2, timeout=DEADLINE)
        pids = client.run(os.getpid)
        with ThreadPoolExecutor(1) as pool:
            running = pool.submit(sweep_on_dask, scene, vary, client, chunks=16)
            deadline = time.monotonic() + DEADLINE
            victim = None
            while victim is None and time.monotonic() < deadline:
                busy = {w: tasks for w, tasks in client.processing().items() if tasks}
                victim = next(iter(busy), None)
                time.sleep(0.01)
            assert victim is not None, "no worker took a chunk"
            os.kill(pids[victim], signal.SIGKILL)  # the nanny's worker process, started by this test's cluster
            result = running.result(timeout=DEADLINE)
    assert len(result.rows) == 200 and result.rows == local.rows


def test_a_refused_value_names_the_chunk_and_the_key(cluster, tmp_path, capsys):
    with distributed.Client(cluster) as client, pytest.raises(ChunkFailed) as err:
        sweep_on_dask(CONFIG / "paper_flexion.yaml", ["model.spring_stiffness=0.001,-1"], client, chunks=2)
    # every chunk checks each varied value before its first run (sweep_plan): whichever chunk fails first is named
    assert re.search(r"chunk [12]/2: ", str(err.value)) and "model.spring_stiffness" in str(err.value)
    assert main(["sweep", str(CONFIG / "paper_flexion.yaml"), "--vary", "model.spring_stiffness=0.001",
                 "--out", str(tmp_path / "unused.csv"), "--dask", "tcp://127.0.0.1:9", "--plot", str(tmp_path / "x.png")]) == 2
    assert "--plot: expected no --plot with --dask" in capsys.readouterr().err
