"""A drive scene's run, step by step: the states and the drive's outputs after every step (spec §8).

The mesh mode is discrete state, not a function of (t, q, q'), so the drive's outputs are taken
as the run goes, not recomputed from the states afterwards as the force elements' are.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from finger_sim.actuators.drive import DrivenSystem
from finger_sim.actuators.stepping import EnergyLedger

if TYPE_CHECKING:
    from finger_sim.simulate import Simulator


def outputs_now(sim: Simulator) -> list[float]:
    """The drive's outputs at the Simulator's current state, under the input of the step that ended
    there (its left limit at a switch of the input: the mode was decided under it)."""
    system: DrivenSystem = sim.system  # type: ignore[assignment]
    return list(system.motor_outputs(sim.time, sim.q, sim.v, sim.torque).values())


def run(sim: Simulator, n: int, *, ledger: bool = True) -> tuple[np.ndarray, dict[str, np.ndarray], dict[str, float]]:
    """Step `sim` n times: the (n, 6) states after each step, the drive's outputs (n + 1 rows, t = 0
    first) and, with `ledger`, the energy report between the start and the end (`EnergyLedger.report`)."""
    system: DrivenSystem = sim.system  # type: ignore[assignment]
    book = EnergyLedger() if ledger else None
    system.drive.ledger = book  # type: ignore[attr-defined]
    q0, v0 = sim.q, sim.v
    xs = np.empty((n, 6))
    rows = [outputs_now(sim)]
    try:
        for k in range(n):
            state = sim.step()
            xs[k] = (*state.q, *state.v)
            rows.append(outputs_now(sim))
    finally:
        system.drive.ledger = None  # type: ignore[attr-defined]
    values = np.array(rows)
    outputs = {name: values[:, i] for i, name in enumerate(system.output_names())}
    report = book.report(system, q0, v0, sim.q, sim.v) if book is not None else {}
    return xs, outputs, report
