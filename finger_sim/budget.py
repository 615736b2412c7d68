"""Resource bounds of an offline run: refuse up front a run that would not fit in memory.

`simulate` holds every step of a run until it returns a `Trajectory`; a scene such as
`duration: 100` at `dt: 1e-9` would take the machine's memory long before it ended. The
CLI calls `check_budget` before such a run. A run streamed to a file holds no steps, so
only the scene's own ceiling (`scene.MAX_STEPS`) bounds it.
"""

from __future__ import annotations

from finger_sim.errors import ResourceError
from finger_sim.scene import Scene

#: Steps an in-memory run may take unless the user raises the limit (~1.2 GB at BYTES_PER_STEP;
#: a 600 s run at dt = 1 ms is 600,000 steps).
DEFAULT_MAX_STEPS = 2_000_000
#: Peak memory per step of an in-memory run, bytes: measured with tracemalloc on CPython 3.11
#: (537 B: the State tuples and per-step records held while stepping, then the Trajectory's
#: nine float64 columns, 72 B, built from them), with a margin; test_budget re-measures it.
BYTES_PER_STEP = 600


def run_memory(scene: Scene) -> int:
    """Peak memory of running `scene` in memory, bytes (estimate: BYTES_PER_STEP per step)."""
    return (scene.step_count + 1) * BYTES_PER_STEP


def check_budget(scene: Scene, *, max_steps: int, streaming: bool) -> None:
    """Refuse (ResourceError) an in-memory run of more than `max_steps` steps.

    streaming: the run writes each step out instead of holding it (no memory bound).
    The message states the step count, the memory and how to go ahead on purpose.
    """
    if streaming or scene.step_count <= max_steps:
        return
    raise ResourceError(
        scene.step_count,
        run_memory(scene),
        max_steps,
        f"duration {scene.duration:g} s at dt = {scene.dt:g} s; to go ahead on purpose pass "
        f"--max-steps {scene.step_count}, or write the run to a file with --csv FILE, which streams it "
        f"instead of holding it in memory",
    )
