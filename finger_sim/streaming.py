"""A run written to CSV as it steps: memory stays constant however long the run.

`finger-sim simulate --csv` without `--plot` runs through here, so a long run on purpose
(past the in-memory budget of `finger_sim.budget`) needs no more memory than a short
one. The run goes block by block: BLOCK_STEPS steps through `kernel.runner.advance` (in the
compiled kernel where it can), the block's energy and |Φ| over the block (`state_columns`),
then one formatted write. The file is the one `Trajectory.write_csv` writes for the same
run, byte for byte.
"""

from __future__ import annotations

import math

import time
from dataclasses import dataclass
from pathlib import Path
from typing import TextIO

import numpy as np

from finger_sim.kernel import offline_kernel
from finger_sim.kernel.runner import advance
from finger_sim.kinematics import Vec3
from finger_sim.scene import Scene
from finger_sim.sensors import SensorBank
from finger_sim.simulate import Simulator, Trajectory, output_names, state_columns, summary_line

#: One CSV value, as `Trajectory.write_csv` (np.savetxt, fmt "%.17g") writes it: %.17g round-trips float64.
VALUE_FORMAT = "%.17g"
#: Steps per block: some 100 kB in memory whatever the run's length; the per-block costs
#: (a kernel call, a few numpy calls: ≈ 50 µs) are then ≈ 0.25 µs per step.
BLOCK_STEPS = 200


@dataclass(frozen=True)
class StreamedRun:
    """What is left of a streamed run: its end state and the extremes of its checks."""

    t_end: float  # s
    q_end: Vec3  # rad
    max_residual: float  # m, max |Φ| over the run
    energy_change: float  # J, E(t_end) − E(0)
    steps: int
    method: str
    method_reason: str
    wall_time: float  # s, stepping only
    error_estimate: float = math.nan  # rad, the integrator's estimated θ error at the end (NaN: none)

    def summary(self) -> str:
        """The line `Trajectory.summary` prints for the same run."""
        return summary_line(self.t_end, self.q_end, self.max_residual, self.energy_change, self.method, self.steps,
                            self.wall_time, self.error_estimate)


def stream_csv(scene: Scene, path: str | Path, *, kernel: str = "auto") -> StreamedRun:
    """Run `scene` like `simulate` and write every step to `path` as it goes (header first).

    kernel: as `Simulator`'s; "auto" keeps a short run in Python (`kernel.offline_kernel`).
    """
    steps = scene.step_count
    sim = Simulator(scene, kernel=offline_kernel(kernel, steps, scene))
    names = output_names(sim.system.elements, sim.q)  # the elements' outputs follow the 9 base columns
    drive = sim.scene.drive is not None  # then the drive's outputs follow, taken as the run goes (actuators.record)
    if drive:
        from finger_sim.actuators import record

        names = (*names, *sim.system.output_names())
    bank = None
    if scene.sensors is not None:  # finger_sim.sensors: read from the outputs, block by block in time order
        bank = SensorBank(scene.sensors, sim.dt)
        names = (*names, *bank.column_names())
    row_format = ",".join([VALUE_FORMAT] * (9 + len(names))) + "\n"
    wall, done = 0.0, 0
    with open(path, "w") as file:
        file.write(Trajectory.csv_header(names) + "\n")
        first_energy, energy, max_residual = _write_block(file, sim, row_format, 0, np.array([[*sim.q, *sim.v]]),
                                                          np.array([record.outputs_now(sim)]) if drive else None, bank)
        while done < steps:
            n = min(BLOCK_STEPS, steps - done)
            start = time.perf_counter()
            x, extra = record.steps(sim, n) if drive else (advance(sim, n), None)
            wall += time.perf_counter() - start
            _, energy, residual = _write_block(file, sim, row_format, done + 1, x, extra, bank)
            max_residual = max(max_residual, residual)
            done += n
    return StreamedRun(
        t_end=sim.time, q_end=sim.q, max_residual=max_residual, energy_change=energy - first_energy,
        steps=steps, method=sim.method, method_reason=sim.method_reason, wall_time=wall,
        error_estimate=sim.error_estimate,
    )


def _write_block(file: TextIO, sim: Simulator, row_format: str, k0: int, x: np.ndarray,
                 extra: np.ndarray | None = None, bank: SensorBank | None = None) -> tuple[float, float, float]:
    """Write the states x (n × 6) of steps k0, k0 + 1, … as CSV rows (then `extra` columns: a drive's
    outputs); (first energy, last energy, max |Φ|) of the block. Its rows live only here, so memory
    holds one block at a time."""
    t = np.arange(k0, k0 + len(x)) * sim.dt  # k·dt, as Simulator.time
    energy, residual, values = state_columns(sim.system, t, x)
    columns = [t, x, energy, residual, values, *(() if extra is None else (extra,))]
    if bank is not None:  # the sensors read the block's outputs (elements', then the drive's) by name
        block = np.column_stack(columns[4:])
        names = (*output_names(sim.system.elements, sim.q),
                 *(sim.system.output_names() if extra is not None else ()))  # type: ignore[attr-defined]
        columns += list(bank.measure({n: block[:, i] for i, n in enumerate(names)}).values())
    rows = np.column_stack(columns).tolist()
    file.writelines(map(row_format.__mod__, map(tuple, rows)))
    return float(energy[0]), float(energy[-1]), float(residual.max())
