"""A sweep's chunks on a Dask distributed cluster: `finger-sim sweep … --dask ADDRESS`.

    from finger_sim.cluster import sweep_on_dask
    result = sweep_on_dask("config/paper_flexion.yaml", ["model.spring_stiffness=0.001,0.002"],
                           "tcp://scheduler:8786")
    result.rows   # one dict per run, in combination order: the same rows as the local sweep

The sweep is cut into `chunks` contiguous slices (`sweep.run_chunk(scene, vary, i, n)`, the
local sweep's own unit), each one task; every worker runs its task on the compiled batch. The
scene is shipped as a value, so workers need no scene file, only finger_sim installed. When a
worker dies mid-task the scheduler reruns its tasks on the others (Dask's own recovery,
`distributed.scheduler.allowed-failures` times per task): no row is lost, and the rows are
gathered in chunk order, so the result equals the local sweep's whatever ran where.
"""

from __future__ import annotations

import uuid
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from finger_sim.errors import ConfigError, FingerSimError
from finger_sim.scene import Scene, load_scene
from finger_sim.sweep import DEFAULT_MAX_SWEEP_STEPS, Chunk, combination_count, parse_vary, run_chunk

#: Tasks per worker when the caller names no chunk count: small enough that a lost worker
#: costs little rerun, large enough that each task's fixed cost (≈ 10 ms) stays small.
CHUNKS_PER_WORKER = 4
#: Seconds to wait for the scheduler at ADDRESS before giving up.
CONNECT_TIMEOUT = 30.0


class ChunkFailed(FingerSimError):
    """A chunk refused on a worker (a bad value in one combination): the worker's message."""

    def __init__(self, message: str) -> None:
        self.message = message
        super().__init__(message)

    def __reduce__(self) -> tuple[type, tuple[str]]:  # crosses the process boundary intact
        return (ChunkFailed, (self.message,))


def _run_chunk(scene: Scene, vary: list[str], index: int, count: int, max_steps: int) -> Chunk:
    """One task: `run_chunk`, with a refusal re-raised as a picklable ChunkFailed."""
    try:
        return run_chunk(scene, vary, index, count, max_steps=max_steps)
    except FingerSimError as exc:
        raise ChunkFailed(f"chunk {index}/{count}: {exc}") from None


def sweep_on_dask(scene: str | Path | Scene, vary: Sequence[str], cluster: Any, *, chunks: int | None = None,
                  max_steps: int = DEFAULT_MAX_SWEEP_STEPS) -> Chunk:
    """The whole sweep's rows, run as `chunks` tasks on a Dask cluster.

    cluster: a scheduler address ("tcp://host:8786"), or a `distributed.Client` (kept open).
    chunks: default CHUNKS_PER_WORKER per worker, at most one per combination. max_steps: the
    finger-step limit of each chunk (`run_chunk`). ConfigError for a bad argument or an
    unreachable scheduler; ChunkFailed names the chunk and the refused value.
    """
    try:
        from distributed import Client
    except ImportError:
        raise ConfigError("--dask", "dask's distributed package installed (pip install 'finger_sim[cluster]')",
                          "not installed") from None
    base = scene if isinstance(scene, Scene) else load_scene(scene)
    texts = list(vary)
    total = combination_count([parse_vary(v) for v in texts])  # checks every --vary before anything is sent
    own = not isinstance(cluster, Client)
    if own:
        try:
            client = Client(cluster, timeout=CONNECT_TIMEOUT)
        except (OSError, TimeoutError, ValueError) as exc:
            raise ConfigError("--dask", "the address of a running Dask scheduler (tcp://host:port)", cluster,
                              problem=f"cannot connect: {exc}") from None
    else:
        client = cluster
    try:
        workers = max(1, len(client.scheduler_info().get("workers", {})))
        count = chunks if chunks is not None else min(total, CHUNKS_PER_WORKER * workers)
        if not isinstance(count, int) or not 1 <= count <= total:
            raise ConfigError("chunks", f"an integer in 1..{total} (the number of combinations)", count)
        sweep_id = uuid.uuid4().hex[:12]
        futures = [client.submit(_run_chunk, base, texts, i, count, max_steps, key=f"finger-sim-sweep-{sweep_id}-{i}",
                                 pure=False) for i in range(1, count + 1)]
        parts: list[Chunk] = client.gather(futures)
    finally:
        if own:
            client.close()
    return Chunk(parts[0].header, [row for part in parts for row in part.rows], [], [])
