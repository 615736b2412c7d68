"""A drive scene's run, step by step: the states and the drive's outputs after every step (spec §8).

The mesh mode is discrete state, not a function of (t, q, q'), so the drive's outputs are taken
as the run goes, not recomputed from the states afterwards as the force elements' are.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator, Mapping
from typing import TYPE_CHECKING

import numpy as np

from finger_sim.actuators.drive import STUCK, DrivenSystem
from finger_sim.actuators.stepping import EnergyLedger
from finger_sim.inputs import PIECEWISE_CONSTANT, Constant, steps_on_segment
from finger_sim.kinematics import ZERO

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
    rows = np.empty((n, len(system.output_names())))
    try:
        xs = states(sim, n, rows)
    finally:
        system.drive.ledger = None
    return xs, rows


def states(sim: Simulator, n: int, rows: np.ndarray | None = None) -> np.ndarray:
    """Step `sim` n times under its scene's input, as n calls of `sim.step()`: the (n, 6) states after each step
    (and, into `rows`, the drive's outputs after each); a stretch of steps that hold a stuck mesh where it is
    (`held_steps`) is taken at once."""
    xs = np.empty((n, 6))
    k = 0
    while k < n:
        held = held_steps(sim, n - k)
        if held:
            xs[k:k + held] = (*sim.q, *sim.v)
            if rows is not None:
                rows[k:k + held] = outputs_now(sim)
            k += held
            continue
        state = sim.step()
        xs[k] = (*state.q, *state.v)
        if rows is not None:
            rows[k] = outputs_now(sim)
        k += 1
    return xs


def held_steps(sim: Simulator, n: int) -> int:
    """Take up to n next steps of `sim` that hold its stuck mesh where it is, at once, as `sim.step()` would take
    them one by one; the number taken (0: the next step is `sim.step()`'s).

    A stuck step holds throughout while the holding margin is ≥ 0 at its end (`stepping._release_time`). At a
    fixed q that margin is the same at every t where no element depends on time (`holding_torque_is_steady`) and
    the input is the same: so after a step that held at this q (its end margin, kept in `Drive.margin_cache`,
    ≥ 0), every later step on the same level of a held input holds too (`inputs.steps_on_segment`: none has a
    switch inside), and leaves q, q' = ZERO and the input as they were. Not with the energy ledger (it integrates
    each step), stick–slip friction, an actuator in the slot, a stop's rest mode or L > 0."""
    system: DrivenSystem = sim.system  # type: ignore[assignment]
    drive = system.drive
    profile = sim.scene.torque
    kept = drive.margin_cache
    if (drive.mode != STUCK or kept is None or kept[0] is not sim.q or not kept[2] >= 0.0 or sim.v is not ZERO
            or drive.ledger is not None or drive.inductive or not system.holding_torque_is_steady
            or not system.keeps_holding_torque or sim._resting is not None  # noqa: SLF001
            or not (isinstance(profile, Constant) or profile.kernel_code in PIECEWISE_CONSTANT)):
        return 0
    k, dt = sim.step_index, sim.dt
    count = steps_on_segment(profile, k, dt, n)
    if count == 0 or profile.on_segment(k * dt, (k + 1) * dt)((k + 1) * dt) != kept[1][1]:  # another level
        return 0
    sim.step_index = k + count
    return count


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
