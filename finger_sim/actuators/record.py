"""A drive scene's run, step by step: the states and the drive's outputs after every step (spec §8).

The mesh mode is discrete state, not a function of (t, q, q'), so the drive's outputs are taken
as the run goes, not recomputed from the states afterwards as the force elements' are.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator, Mapping
from typing import TYPE_CHECKING

import numpy as np

from finger_sim.actuators.drive import DrivenSystem
from finger_sim.actuators.stepping import EnergyLedger

if TYPE_CHECKING:
    from finger_sim.simulation.driver import Simulator


def outputs_now(sim: Simulator) -> list[float]:
    """The drive's outputs at the Simulator's current state, under the input of the step that ended
    there (its left limit at a switch of the input: the mode was decided under it)."""
    system: DrivenSystem = sim.system  # type: ignore[assignment]
    return list(system.motor_outputs(sim.time, sim.q, sim.v, sim.torque).values())


def steps(sim: Simulator, n: int, ledger: EnergyLedger | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Step `sim` n times: the (n, 6) states and the (n, outputs) drive outputs after each step;
    with `ledger`, the steps' energy integrals are added to it."""
    system: DrivenSystem = sim.system  # type: ignore[assignment]
    system.drive.ledger = ledger
    xs = np.empty((n, 6))
    rows = np.empty((n, len(system.output_names())))
    try:
        for k in range(n):
            state = sim.step()
            xs[k] = (*state.q, *state.v)
            rows[k] = outputs_now(sim)
    finally:
        system.drive.ledger = None
    return xs, rows


class EnergyReport(Mapping[str, float]):
    """A run's energy balance (`EnergyLedger.report`, J), computed on its first read by `compute`: the
    ledger's quadrature costs about as much as the run, so a run whose report nobody reads skips it."""

    def __init__(self, compute: Callable[[], dict[str, float]]) -> None:
        self._compute: Callable[[], dict[str, float]] | None = compute
        self._values: dict[str, float] = {}

    def _filled(self) -> dict[str, float]:
        if self._compute is not None:
            self._values, self._compute = self._compute(), None
        return self._values

    def __getitem__(self, key: str) -> float:
        return self._filled()[key]

    def __iter__(self) -> Iterator[str]:
        return iter(self._filled())

    def __len__(self) -> int:
        return len(self._filled())

    def __repr__(self) -> str:
        return repr(self._filled())


def run(sim: Simulator, n: int, again: Callable[[], Simulator] | None = None,
        ) -> tuple[np.ndarray, dict[str, np.ndarray], Mapping[str, float]]:
    """Step `sim` n times from its state: the (n, 6) states after each step, the drive's outputs
    (n + 1 rows, the start first) and the energy report between start and end (`EnergyLedger.report`).
    With `again` (a fresh Simulator of the same run, at the same start) the run goes without the ledger
    and the report is that second run's, made when first read (`EnergyReport`): the ledger leaves the
    steps as they are, so both runs take the same states, bit for bit."""
    system: DrivenSystem = sim.system  # type: ignore[assignment]
    first = outputs_now(sim)
    if again is None:
        xs, rows, report = _ledger_run(sim, n)
    else:
        xs, rows = steps(sim, n)
        report = EnergyReport(lambda: _ledger_run(again(), n)[2])
    values = np.vstack([first, rows])
    outputs = {name: values[:, i] for i, name in enumerate(system.output_names())}
    return xs, outputs, report


def _ledger_run(sim: Simulator, n: int) -> tuple[np.ndarray, np.ndarray, dict[str, float]]:
    """`steps` with the ledger: (states, output rows, energy report)."""
    system: DrivenSystem = sim.system  # type: ignore[assignment]
    book = EnergyLedger()
    q0, v0, i0 = sim.q, sim.v, system.drive.i
    xs, rows = steps(sim, n, book)
    currents = (i0, system.drive.i) if system.drive.inductive else None
    return xs, rows, book.report(system, q0, v0, sim.q, sim.v, currents)
