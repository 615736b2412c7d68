"""The CSV columns of `finger-sim simulate --csv` and `finger-sim export --csv`, in one place.

Two sets (`--columns`):
- `paper` (the default): t, θ1..θ3, θ1'..θ3', energy, constraint residual and the force
  elements' outputs (`Trajectory.csv_header`), the paper's coordinates.
- `ros`: the ROS joints of spec §6 (finger_sim.joints), as `joint_states` and
  `fingertip_pose` carry them, one column per value; ROS_COLUMNS names them with units.
  Efforts: motor τ at mcp_joint, the PIP spring −kβ at pip_joint, 0 at coupler_joint;
  `torque` is the motor torque again under its own name. The tip is in `finger_base`
  (REP 103: x along the extended finger, z dorsal) with the distal phalanx's orientation as a
  quaternion (a rotation by ψ about +y) and as the pitch ψ itself.

A `ros` file starts with one comment line `# units: s, rad, ...` (one unit per column, in
column order), then the header: `pandas.read_csv(path, comment="#")` reads it as it is.
`--every N` keeps the first sample and every N-th after it (samples 0, N, 2N, ...). Long
writes draw a tqdm progress bar on stderr when stderr is a terminal, and nothing otherwise.
"""

from __future__ import annotations

import math
import sys
from collections.abc import Callable, Iterable, Iterator, Sequence
from pathlib import Path
from typing import TextIO

import numpy as np

from finger_sim import kinematics
from finger_sim.actuators import record
from finger_sim.actuators.drive_outputs import MESH_TORQUE
from finger_sim.dynamics import FingerSystem
from finger_sim.effects.spring import spring_force
from finger_sim.joints import joint_positions, joint_velocities, pip_stiffness
from finger_sim.kernel import offline_kernel
from finger_sim.kinematics import Vec3
from finger_sim.scene import Scene
from finger_sim.simulate import Simulator, Trajectory, output_names, output_values

COLUMN_SETS = ("paper", "ros")
#: The `ros` columns: (name, unit).
ROS_COLUMNS: tuple[tuple[str, str], ...] = (
    ("t", "s"),
    ("mcp_position", "rad"), ("coupler_position", "rad"), ("pip_position", "rad"),
    ("mcp_velocity", "rad/s"), ("coupler_velocity", "rad/s"), ("pip_velocity", "rad/s"),
    ("mcp_effort", "N·m"), ("coupler_effort", "N·m"), ("pip_effort", "N·m"),
    ("torque", "N·m"),
    ("tip_x", "m"), ("tip_y", "m"), ("tip_z", "m"),
    ("tip_qx", "1"), ("tip_qy", "1"), ("tip_qz", "1"), ("tip_qw", "1"),
    ("tip_pitch", "rad"),
)
#: One CSV value: %.17g round-trips float64 (as Trajectory.write_csv).
VALUE_FORMAT = "%.17g"
#: Samples from which a write draws a progress bar (on a terminal).
PROGRESS_MIN_SAMPLES = 100_000
class RosRow:
    """Builds `ros` rows of one finger: `row(t, q, v, torque)` from the paper's coordinates."""

    def __init__(self, system: FingerSystem) -> None:
        self._params = system.params
        self._q_ext = kinematics.extended_pose(system.params)
        self._alpha = kinematics.distal_offset(system.params)
        self._k = pip_stiffness(system)  # N·m/rad

    def row(self, t: float, q: Vec3, v: Vec3, torque: float) -> tuple[float, ...]:
        """t (s), q (rad), v (rad/s), torque (N·m, the motor's) → the ROS_COLUMNS values."""
        pos = joint_positions(q, self._q_ext, self._alpha)
        tip = kinematics.fingertip(self._params, q, self._alpha)
        half = 0.5 * tip.psi
        pip_effort = spring_force(self._k, self._alpha, q[0], q[2])[2]  # −kβ
        return (t, *pos, *joint_velocities(v), torque, 0.0, pip_effort, torque,
                tip.x, 0.0, -tip.y, 0.0, math.sin(half), 0.0, math.cos(half), tip.psi)


def units_comment() -> str:
    """The `# units:` line of a `ros` file (no newline)."""
    return "# units: " + ", ".join(unit for _, unit in ROS_COLUMNS)


def write_rows(path: str | Path, header: str, rows: Iterable[Sequence[float]], *, comment: str = "",
               every: int = 1, total: int | None = None, desc: str = "csv") -> int:
    """Write `comment` (if any), `header`, then every `every`-th row (from the first) to `path`;
    returns the rows written. `total`: the number of rows expected, for the progress bar."""
    with open(path, "w") as file:
        if comment:
            file.write(comment + "\n")
        file.write(header + "\n")
        return _write(file, thinned(rows, every), every, total, desc)


def thinned(rows: Iterable[Sequence[float]], every: int) -> Iterator[Sequence[float]]:
    """Rows 0, every, 2·every, ..."""
    for i, row in enumerate(rows):
        if i % every == 0:
            yield row


def _write(file: TextIO, rows: Iterator[Sequence[float]], every: int, total: int | None, desc: str) -> int:
    written, row_format = 0, None
    update = _progress(total, desc)
    try:
        for row in rows:
            if row_format is None:
                row_format = ",".join([VALUE_FORMAT] * len(row)) + "\n"
            file.write(row_format % tuple(row))
            written += 1
            update(every)
    finally:
        update(0, close=True)
    return written


def _progress(total: int | None, desc: str) -> Callable[..., None]:
    """update(n, close=False): a tqdm bar on stderr for `total` samples when stderr is a
    terminal and the write is long; a no-op otherwise."""
    if total is None or total < PROGRESS_MIN_SAMPLES or not sys.stderr.isatty():
        return lambda n, close=False: None
    from tqdm import tqdm

    bar = tqdm(total=total, unit="sample", unit_scale=True, desc=desc, file=sys.stderr, mininterval=0.5)

    def update(n: int, close: bool = False) -> None:
        if close:
            bar.close()
        else:
            bar.update(n)

    return update


Sample = tuple[float, Vec3, Vec3, float]  # t (s), q (rad), q' (rad/s), motor torque (N·m)


def ros_header() -> str:
    return ",".join(name for name, _ in ROS_COLUMNS)


def write_ros(path: str | Path, system: FingerSystem, samples: Iterable[Sample], *, every: int = 1,
              total: int | None = None, desc: str = "csv") -> int:
    """A `ros` CSV of `samples`; returns the rows written."""
    rows = RosRow(system)
    return write_rows(path, ros_header(), (rows.row(*s) for s in samples), comment=units_comment(),
                      every=every, total=total, desc=desc)


def write_paper(path: str | Path, traj: Trajectory, *, every: int = 1, desc: str = "csv") -> int:
    """A `paper` CSV of a Trajectory, every `every`-th sample (every 1: `Trajectory.write_csv`'s file)."""
    data = np.column_stack([traj.t, traj.q, traj.v, traj.energy, traj.residual, *traj.outputs.values()])
    return write_rows(path, Trajectory.csv_header(list(traj.outputs)), data.tolist(), every=every,
                      total=len(data), desc=desc)


def write_simulated(path: str | Path, scene: Scene, *, columns: str, every: int = 1, kernel: str = "auto") -> Simulator:
    """Run `scene` and write its CSV as it steps (memory stays flat); returns the Simulator at the end.

    ros: the torque column is the scene's profile τ(t) at each state's time (with a drive: the mesh
    torque on link 1). A drive's outputs are taken as the run goes (`actuators.record`).
    """
    sim = Simulator(scene, kernel=offline_kernel(kernel, scene.step_count, scene))
    system = sim.system
    drive = scene.drive is not None

    def states() -> Iterator[tuple[float, Vec3, Vec3, list[float]]]:
        s = sim.state
        yield s.t, s.q, s.v, record.outputs_now(sim) if drive else []
        for _ in range(scene.step_count):
            s = sim.step()
            yield s.t, s.q, s.v, record.outputs_now(sim) if drive else []

    total, desc = scene.step_count + 1, f"simulate {scene.name}"
    if columns == "ros":
        effort = system.output_names().index(MESH_TORQUE.name) if drive else None  # type: ignore[attr-defined]
        write_ros(path, system, ((t, q, v, scene.torque(t) if effort is None else extra[effort])
                                 for t, q, v, extra in states()), every=every, total=total, desc=desc)
        return sim
    p = scene.params
    names = output_names(system.elements, sim.q) + (system.output_names() if drive else ())  # type: ignore[attr-defined]
    rows = ((t, *q, *v, system.energy(q, v), kinematics.constraint_norm(p, q), *output_values(system.elements, t, q, v),
             *extra) for t, q, v, extra in states())
    write_rows(path, Trajectory.csv_header(names), rows, every=every, total=total, desc=desc)
    return sim
