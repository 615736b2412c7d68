"""Simulating a scene: `simulate` runs a whole scene offline; `Simulator` steps it one dt at a time.

The pieces live in `finger_sim.simulation`: the driver (`Simulator`, `State`), its set-up, the
event location (`locate`, `crossings`), the impact and the stop's rest mode (`impact`), and the
results (`Trajectory`, the per-state columns). This module is the public face of all of them.
"""

from __future__ import annotations

import time
from collections.abc import Mapping

import numpy as np

from finger_sim import stepper_slot
from finger_sim.inputs import BREAK_EPS
from finger_sim.scene import Scene
from finger_sim.sensors import SensorBank
from finger_sim.simulation.driver import Simulator, State
from finger_sim.simulation.results import Trajectory, output_names, output_values, state_columns, summary_line
from finger_sim.simulation.setup import setup_for as _setup  # noqa: F401  (its cache, which tests clear)

__all__ = ["BREAK_EPS", "Simulator", "State", "Trajectory", "output_names", "output_values", "simulate",
           "state_columns", "summary_line"]


def simulate(scene: Scene, *, kernel: str = "auto", energy_report: bool = False) -> Trajectory:
    """Run `scene` from t = 0 to its duration (rounded up to whole steps) and record every step.

    On the compiled kernel a smooth scene's steps run in one kernel loop (`kernel.runner`);
    "auto" runs a short scene in Python (`kernel.offline_kernel`: loading numba costs more).
    An owner whose outputs are discrete state (`ModeStepping.record_run`) takes the run and its outputs
    as it goes; its `energy_report` is filled during the run when asked for here, else on its first read
    by running the scene again (the same states, bit for bit).
    """
    n = scene.step_count
    chosen = stepper_slot.kernel().offline_kernel(kernel, n, scene)
    sim = Simulator(scene, kernel=chosen)
    x0 = (*sim.q, *sim.v)
    start = time.perf_counter()
    own_outputs: dict[str, np.ndarray] = {}
    report: Mapping[str, float] = {}
    recorded = None
    for stepping in sim.mode_steppings:
        stepping.before_run(sim, n)
    for stepping in sim.mode_steppings:  # the first owner that records its own outputs takes the run
        recorded = stepping.record_run(sim, n, None if energy_report else lambda: Simulator(scene, kernel=chosen))
        if recorded is not None:
            break
    if recorded is not None:
        xs, own_outputs, report = recorded
    else:
        xs = stepper_slot.kernel().advance(sim, n)  # in the kernel where it can, else step by step
    wall = time.perf_counter() - start
    x = np.vstack([x0, xs])
    t = np.arange(n + 1) * sim.dt  # k·dt, as Simulator.time
    energy, residual, values = state_columns(sim.system, t, x)
    names = output_names(sim.system.elements, sim.q)
    outputs = {**{name: values[:, i] for i, name in enumerate(names)}, **own_outputs}
    if scene.sensors is not None:  # read from the outputs after the run: the dynamics never see them
        outputs.update(SensorBank(scene.sensors, sim.dt).measure(outputs))
    return Trajectory(
        t=t,
        q=np.ascontiguousarray(x[:, :3]),
        v=np.ascontiguousarray(x[:, 3:]),
        energy=energy,
        residual=residual,
        method=sim.method,
        method_reason=sim.method_reason,
        wall_time=wall,
        outputs=outputs,
        error_estimate=sim.error_estimate,
        energy_report=report,
    )
