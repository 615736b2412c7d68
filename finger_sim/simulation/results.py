"""What a run gives back: the recorded trajectory (`Trajectory`), its CSV and summary line, and the
per-state columns (energy, |Φ|, the elements' outputs) that `simulate` and `stream_csv` both write."""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from finger_sim.dynamics import FingerSystem
from finger_sim.effects import ForceElement
from finger_sim.kinematics import ZERO, Vec3



def output_names(elements: Sequence[ForceElement], q: Vec3) -> tuple[str, ...]:
    """The names of every element's `outputs` (e.g. contact's grip_force, N), in element order:
    the extra columns of a run's CSV. Asked at a pose q; an element reports the same names at every state."""
    return tuple(name for e in elements for name in e.outputs(0.0, q, ZERO))


def output_values(elements: Sequence[ForceElement], t: float, q: Vec3, v: Vec3) -> tuple[float, ...]:
    """Every element's `outputs` at (t, q, q'), in the order of `output_names`."""
    return tuple(value for e in elements for value in e.outputs(t, q, v).values())


def state_columns(system: FingerSystem, t: np.ndarray, x: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A block of states' checks and outputs: energy (J), |Φ| (m), and the elements' outputs
    (one column per `output_names`), for states x = (q, q') (n × 6) at times t (s).

    The kinetic energy and Φ are evaluated over the block with numpy in the same order of
    operations as `FingerSystem.kinetic_energy` and `kinematics.constraint` (|Φ| by math.hypot);
    the elements' potentials and outputs row by row. Used by `simulate` and `stream_csv` alike,
    so both write the same bytes.
    """
    p, alpha = system.params, system.alpha
    q0, q1, q2, v0, v1, v2 = x.T
    # FingerSystem's mass-matrix entries, the same expressions
    m11, m22, m33 = p.inertia_A + p.m3 * p.r1**2, p.inertia_D, p.inertia_G3 + p.m3 * p.L3**2 / 4.0
    b = p.m3 * p.r1 * p.L3 / 2.0 * np.cos(q0 - q2 - alpha)
    energy = 0.5 * (m11 * v0**2 + m22 * v1**2 + m33 * v2**2) + b * v0 * v2
    rows = x.tolist()
    elements = system.elements
    if elements:
        # an element that moves with time (a moving object's contact) stores V at (t, q)
        energy = energy + np.array([sum(e.potential_at(s, (r[0], r[1], r[2])) if getattr(e, "time_varying", False)
                                        else e.potential((r[0], r[1], r[2])) for e in elements)
                                    for s, r in zip(t.tolist(), rows)])
    k1, k2 = p.r4 * math.cos(p.theta4), p.r4 * math.sin(p.theta4)
    f1 = p.r1 * np.cos(q0) + k1 - p.r2 * np.cos(q1) - p.r3 * np.cos(q2)
    f2 = p.r1 * np.sin(q0) + k2 - p.r2 * np.sin(q1) - p.r3 * np.sin(q2)
    residual = np.array(list(map(math.hypot, f1.tolist(), f2.tolist())))
    names = output_names(elements, (0.0, 0.0, 0.0))
    outputs = np.array([output_values(elements, s, (r[0], r[1], r[2]), (r[3], r[4], r[5]))
                        for s, r in zip(t.tolist(), rows)] if names else np.empty((len(rows), 0)))
    return energy, residual, outputs.reshape(len(rows), len(names))


@dataclass
class Trajectory:
    """A run sampled at every step, t = 0 included. Angles rad, rates rad/s, energy J, |Φ| m;
    `outputs`: what the force elements report (name → one value per sample, e.g. grip_force, N)."""

    t: np.ndarray
    q: np.ndarray  # (N, 3)
    v: np.ndarray  # (N, 3)
    energy: np.ndarray
    residual: np.ndarray
    method: str
    method_reason: str
    wall_time: float  # s, stepping only
    outputs: dict[str, np.ndarray] = field(default_factory=dict)
    #: the integrator's estimate of the θ error at the end (rad; NaN: a fixed-step method, none)
    error_estimate: float = math.nan
    #: a drive scene's energy balance, J (`finger_sim.actuators.stepping.EnergyLedger.report`); else empty
    energy_report: Mapping[str, float] = field(default_factory=dict)

    #: The columns every run has; the elements' outputs follow them (`csv_header`).
    CSV_HEADER = "t,theta1,theta2,theta3,theta1_dot,theta2_dot,theta3_dot,energy,constraint_residual"

    @staticmethod
    def csv_header(output_columns: Sequence[str] = ()) -> str:
        """The CSV header: CSV_HEADER, then the elements' output names."""
        return ",".join([Trajectory.CSV_HEADER, *output_columns])

    def write_csv(self, path: str | Path) -> None:
        data = np.column_stack([self.t, self.q, self.v, self.energy, self.residual, *self.outputs.values()])
        np.savetxt(path, data, delimiter=",", header=self.csv_header(list(self.outputs)), comments="", fmt="%.17g")

    def summary(self) -> str:
        line = summary_line(self.t[-1], self.q[-1], float(self.residual.max()), self.energy[-1] - self.energy[0],
                            self.method, len(self.t) - 1, self.wall_time, self.error_estimate)
        if self.energy_report:
            from finger_sim.actuators.report import energy_line

            line += "\n" + energy_line(self.energy_report)
        return line


def summary_line(t_end: float, q_end: Sequence[float], max_residual: float, energy_change: float, method: str,
                 steps: int, wall_time: float, error_estimate: float = math.nan) -> str:
    """The one-line run summary `finger-sim simulate` prints (s, rad, m, J; wall s, NaN for none;
    error_estimate: the integrator's estimated θ error, rad, NaN for none)."""
    deg = np.degrees(q_end)
    return (
        f"t = {t_end:.4g} s  θ = ({deg[0]:.2f}°, {deg[1]:.2f}°, {deg[2]:.2f}°)  "
        f"max|Φ| = {max_residual:.2e} m  ΔE = {energy_change:+.3e} J  "
        f"method = {method}  steps = {steps}"
        + (f"  est. error = {error_estimate:.1e} rad" if math.isfinite(error_estimate) else "")
        + (f"  wall = {wall_time:.3f} s" if math.isfinite(wall_time) else "")
    )
