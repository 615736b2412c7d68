"""docs/contact_performance.md: contact (spec §7) against MuJoCo, and what contact costs per step.

`python -m finger_sim.bench.contact_report [--quick] [--out docs]` runs the contact part of
the bench alone, in one process (the full `finger-sim bench` has the same scenes in its
work-precision and hard-case tables, but takes long):

- *Against MuJoCo*: each contact scene by the project (`method: auto` and every fixed method
  at 1 ms) and by the MJCF peer with the scene's objects as geoms (`mujoco_peer`), with
  MuJoCo's default and its tightest stable contact and loop settings, per integrator and
  timestep: the grip force Σ F_n at the end, its spread over the run's last GRIP_WINDOW, the
  final θ1, the error against the scene's reference (`reference.solve_with_events`: `adaptive`
  through `Simulator`, contact onsets and releases located) and the CPU per step.
- *Speed*: `method: auto` at 1 kHz on each contact scene against the free-space paper_flexion,
  per kernel that ran (CPython and the compiled one when numba is installed; a contact scene asked
  for in CPython runs auto's DOP853 with its compiled event step, so it has one row, under the
  compiled kernel, saying so), each against the free scene under the same kernel, every (scene,
  kernel) timed in turn within each repeat so that load on a shared machine hits them alike; medians.
"""

from __future__ import annotations

import argparse
import datetime as _dt
import math
import os
import statistics
import sys
import time
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from finger_sim.bench.markdown import machine_lines
from finger_sim.bench.plan import (
    CONTACT_SCENES,
    MUJOCO_INTEGRATORS,
    MUJOCO_SETTINGS,
    REPEATS,
    SPACING,
    config_dir,
    project_methods,
)
from finger_sim.bench.reference import Reference, build_reference
from finger_sim.bench.runners import (
    AUTO,
    FAMILY_MUJOCO,
    GRIP_WINDOW,
    Run,
    grip_forces,
    mujoco_available,
    run_method,
    run_mujoco_peer,
)
from finger_sim.kernel import PYTHON, compiled_name
from finger_sim.scene import Scene, load_scene
from finger_sim.simulate import Simulator

#: The free-space scene contact is compared with, and the rate of the comparison (s).
FREE_SCENE = "paper_flexion"
SPEED_DT = 1e-3
#: The goal: a contact scene's step costs at most this many free-space steps.
SPEED_GOAL = 2.0
#: Timing repeats of the speed table (median), full run and --quick.
SPEED_REPEATS, SPEED_REPEATS_QUICK = 9, 3
#: The step of the project's rows and MuJoCo's timesteps (s), full run and --quick.
PROJECT_DT = 1e-3
MUJOCO_TIMESTEPS, MUJOCO_TIMESTEPS_QUICK = (1e-3, 1e-4), (1e-3,)
COMPILED = "compiled"


@dataclass(frozen=True)
class SceneComparison:
    """One contact scene: its reference's end state and every run against it."""

    scene: str
    reference_grip: float  # N, Σ F_n at the reference's end
    reference_theta1: float  # rad, θ1 at the reference's end
    floor: float  # rad, the reference's check difference
    runs: tuple[Run, ...]  # the project's rows first, then MuJoCo's


@dataclass(frozen=True)
class SpeedRow:
    """`method: auto` at SPEED_DT on one scene with the kernel that ran: what ran and its median µs/step."""

    scene: str
    kernel: str  # the kernel that ran ("python" or "numba-<version>")
    asked: tuple[str, ...]  # the kernels requested that ran as this one (none: the free scene, for the ratios)
    method: str
    substeps: int
    us_per_step: float  # median over the repeats
    spread: tuple[float, float]  # (min, max) µs/step over the repeats
    ratio: float  # us_per_step over FREE_SCENE's with the same kernel that ran

    @property
    def met(self) -> bool:
        return self.ratio <= SPEED_GOAL

    @property
    def kernel_label(self) -> str:
        """The kernel that ran, and a request it did not honour (auto's DOP853 has compiled stages by construction:
        a contact scene asked for in Python runs the compiled event step)."""
        if self.kernel != PYTHON and PYTHON in self.asked:
            return f"{self.kernel} (requested: {', '.join(self.asked)}; the compiled event step ran)"
        return self.kernel


@dataclass(frozen=True)
class ContactReport:
    """Everything the contact report shows, as data."""

    comparisons: tuple[SceneComparison, ...]
    speed: tuple[SpeedRow, ...]
    repeats: int
    command: str
    started: _dt.datetime
    wall: float  # s

    def comparison(self, scene: str) -> SceneComparison:
        return next(c for c in self.comparisons if c.scene == scene)


def kernels() -> tuple[str, ...]:
    """The kernels to time: CPython always, the compiled one when numba is installed."""
    return (PYTHON, COMPILED) if compiled_name() else (PYTHON,)


def compare(scene: Scene, ref: Reference, *, quick: bool) -> SceneComparison:
    """The project's rows (auto, then every fixed method, at PROJECT_DT) and MuJoCo's, against `ref`."""
    kw = {"spacing": SPACING, "repeats": REPEATS}
    runs = [run_method(scene, m, PROJECT_DT, ref, kernel=PYTHON, **kw) for m in [AUTO, *project_methods()]]
    for integrator in MUJOCO_INTEGRATORS:
        for setting in MUJOCO_SETTINGS:
            for ts in MUJOCO_TIMESTEPS_QUICK if quick else MUJOCO_TIMESTEPS:
                runs.append(run_mujoco_peer(scene, integrator, ts, setting, ref, **kw))
    end = np.array([scene.duration])
    state = ref.solution.states(end)
    grip = float(grip_forces(scene, end, state[:, :3], state[:, 3:])[0])
    return SceneComparison(scene.name, grip, float(state[0, 0]), ref.check_difference, tuple(runs))


def measure_speed(scenes: dict[str, Scene], kernel_names: Sequence[str], repeats: int) -> tuple[SpeedRow, ...]:
    """µs/step of `method: auto` at SPEED_DT, each (scene, kernel that ran) in turn within every repeat; medians.
    A scene asked for under several kernels that run as one is timed once; FREE_SCENE is timed under every kernel
    that ran, so that each ratio divides by the free step of the same kernel."""
    sims: dict[tuple[str, str], Simulator] = {}
    asked: dict[tuple[str, str], list[str]] = {}
    for name, scene in scenes.items():
        for kernel in kernel_names:
            sim = Simulator(scene.with_overrides(method="auto", dt=SPEED_DT), kernel=kernel)
            sims.setdefault((name, sim.kernel), sim)
            asked.setdefault((name, sim.kernel), []).append(kernel)
    free = scenes[FREE_SCENE].with_overrides(method="auto", dt=SPEED_DT)
    for ran in sorted({kernel for _, kernel in sims} - {kernel for name, kernel in sims if name == FREE_SCENE}):
        sims[FREE_SCENE, ran] = sim = Simulator(free, kernel=ran)
        if sim.kernel != ran:
            raise ValueError(f"kernel: {FREE_SCENE} cannot run under {ran!r} (it runs {sim.kernel!r})")
    samples: dict[tuple[str, str], list[float]] = {key: [] for key in sims}
    for k in range(repeats + 1):  # the first round warms up (caches, a compiled kernel's first call)
        for key, sim in sims.items():
            sim.reset()
            n = sim.scene.step_count
            step = sim.step
            start = time.process_time()
            for _ in range(n):
                step()
            if k:
                samples[key].append(1e6 * (time.process_time() - start) / n)
    rows = []
    for (name, kernel), sim in sims.items():
        median = statistics.median(samples[name, kernel])
        spread = (min(samples[name, kernel]), max(samples[name, kernel]))
        rows.append(SpeedRow(name, kernel, tuple(asked.get((name, kernel), ())), sim.method, sim.substeps, median,
                             spread, median / statistics.median(samples[FREE_SCENE, kernel])))
    return tuple(rows)


def measure(*, quick: bool, command: str) -> ContactReport:
    """The references, the comparisons and the speed table, one after another in this process."""
    started = _dt.datetime.now(_dt.timezone.utc)
    wall0 = time.perf_counter()
    folder = config_dir()
    scenes = {name: load_scene(folder / f"{name}.yaml") for name in (FREE_SCENE, *CONTACT_SCENES)}
    comparisons = []
    for name in CONTACT_SCENES:
        print(f"contact report: {name}", file=sys.stderr)
        ref = build_reference(scenes[name], quick=quick, spacing=SPACING)
        comparisons.append(compare(scenes[name], ref, quick=quick))
    repeats = SPEED_REPEATS_QUICK if quick else SPEED_REPEATS
    print("contact report: speed", file=sys.stderr)
    speed = measure_speed(scenes, kernels(), repeats)
    return ContactReport(tuple(comparisons), speed, repeats, command, started, time.perf_counter() - wall0)


# -- Markdown ----------------------------------------------------------------------------------


def _f(x: float, fmt: str) -> str:
    return "—" if not math.isfinite(x) else format(x, fmt)


def _row_label(r: Run) -> str:
    if r.family == FAMILY_MUJOCO:
        return f"{r.method} @ {r.value * 1e3:g} ms"
    return f"finger_sim {r.method}" + (f" ({r.note})" if r.method == AUTO and r.ok else "") + f" @ {r.value * 1e3:g} ms"


def render_comparison(c: SceneComparison) -> list[str]:
    """One scene's table: the reference, then every run."""
    out = [
        f"### {c.scene}",
        "",
        f"Reference: `adaptive` (DOP853, rtol 1e-12) through `Simulator`, contact events located; checked by "
        f"scipy Radau at rtol 1e-12 (1e-10 with --quick): difference {c.floor:.1e} rad.",
        "",
        "| run | status | grip force at end (N) | spread, last 10 % (N) | final θ1 (rad) | final θ1 − ref (rad) "
        "| max \\|θ − θ_ref\\| (rad) | max \\|Φ\\| (m) | µs/step | note |",
        "|---|---|---|---|---|---|---|---|---|---|",
        f"| reference | ok | {c.reference_grip:.6f} | — | {c.reference_theta1:.9f} | 0 | — | — | — | |",
    ]
    for r in c.runs:
        note = "" if r.ok else r.note[:120].replace("|", "\\|")
        out.append(
            f"| {_row_label(r)} | {r.status} | {_f(r.grip_force, '.6f')} | {_f(r.grip_spread, '.1e')} | "
            f"{_f(r.final_theta1, '.9f')} | {_f(r.final_theta1 - c.reference_theta1, '+.1e')} | {_f(r.error, '.1e')} | "
            f"{_f(r.max_phi, '.1e')} | {_f(r.us_per_step, '.1f')} | {note} |"
        )
    out.append("")
    return out


def render_speed(report: ContactReport) -> list[str]:
    out = [
        f"| scene | kernel | auto runs | substeps in contact | µs/step (median of {report.repeats}) | min – max | "
        f"× {FREE_SCENE} | goal ≤ {SPEED_GOAL:g}× |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for r in report.speed:
        goal = "—" if r.scene == FREE_SCENE else ("met" if r.met else "NOT met")
        out.append(
            f"| {r.scene} | {r.kernel_label} | {r.method} | {r.substeps} | {r.us_per_step:.1f} | "
            f"{r.spread[0]:.1f} – {r.spread[1]:.1f} | {r.ratio:.2f}× | {goal} |"
        )
    return out


def render(report: ContactReport, limits: Sequence[str] = ()) -> str:
    """The whole contact_performance.md; `limits`: the hand-written lines (`hand_written`)."""
    available, note = mujoco_available()
    lines = [
        "# Contact: against MuJoCo, and its cost per step",
        "",
        "Generated by the command below, except the part between the *written by hand* markers (kept when the "
        "file is regenerated).",
        "",
        f"- Command: `{report.command}`",
        f"- Date: {report.started:%Y-%m-%d %H:%M} UTC; the run took {report.wall:.0f} s wall",
        *machine_lines(),
        f"- Load average (1, 5, 15 min) at the end: {', '.join(f'{x:.2f}' for x in os.getloadavg())}",
        "",
        "## Speed: a contact step against a free-space step",
        "",
        f"`method: auto` at {1 / SPEED_DT:g} Hz through `Simulator.step` (the node's path), whole scenes, CPU time "
        "(`time.process_time`) per step. Every (scene, kernel) is timed in turn within each repeat, in one process, "
        "after one warm-up round. A contact scene's average includes its steps out of contact (before the finger "
        "reaches the object).",
        "",
        *render_speed(report),
        "",
        *limits,
        "",
        "## Against MuJoCo",
        "",
        "The MJCF peer (`finger_sim.bench.mujoco_peer`) gains the scene's objects: a circle is a `cylinder` geom "
        "along z, a plane a `plane` geom, the phalanges collision capsules of the spec's radii (ρ1 = 8 mm, "
        "ρ3 = 7 mm); contype/conaffinity let a phalanx touch only the objects, frictionless (condim 1) as the "
        "scenes are. MuJoCo's grip force is Σ of the normal forces `mj_contactForce` reports for the "
        "phalanx–object contacts. *default*: MuJoCo's default solref/solimp on the contacts and on the "
        "loop-closing connect; *tight*: its stiffest stable settings, the loop at timeconst 2 steps "
        "(`tight_equality`) and the contacts at 3 steps (`tight_contact`: 2 chatters at 0.1 ms), impedance 0.9999. "
        f"Grip force at the run's end and its spread (max − min) over the last {GRIP_WINDOW:.0%} of the run "
        "(sampled every 1 ms): a run at rest has none. Errors are against the reference, sampled every 1 ms.",
        "",
        "MuJoCo's contact is its own soft-constraint law, not Hunt–Crossley: at rest its grip force is set by "
        "the statics (the torque balanced through the linkage), so it matches ours closely, but its penetration, "
        "and so its final pose, differs from ours by the difference in compliance. With the default connect the "
        "loop itself opens by millimetres under the grip, which moves the whole pose. On the impacts "
        "(grasp_impact, grasp_rigid) MuJoCo's critically damped contact takes nearly all the energy: the finger "
        "stays at the cup (θ1 ≈ 0.17 rad at the end) where ours, with Hunt–Crossley damping, bounces back towards "
        "extension (θ1 ≈ 0.02–0.04 rad): a different contact law, not an integration error. MuJoCo's µs/step is "
        "per its own step (a 0.1 ms run takes 10× the steps of a 1 ms one).",
        "",
        "The node's real-time factor in contact is measured in docs/auto_accuracy.md (every shipped scene under "
        "`auto` at 1 kHz).",
        "",
    ]
    if not available:
        lines += [f"**{note}**", ""]
    for c in report.comparisons:
        lines += render_comparison(c)
    return "\n".join(lines) + "\n"


#: The hand-written part of contact_performance.md (what limits the speed, from profiles) sits
#: between these markers; `write` keeps it from the file it replaces.
HAND_BEGIN, HAND_END = "<!-- written by hand: begin -->", "<!-- written by hand: end -->"
NO_HAND_TEXT = ("### What limits the speed", "", "Not written yet: profile the contact step and say here what bounds it.")


def hand_written(path: Path) -> tuple[str, ...]:
    """The lines between HAND_BEGIN and HAND_END in the report at `path`, markers included
    (NO_HAND_TEXT within markers when the file or its markers are missing)."""
    text = path.read_text() if path.exists() else ""
    if HAND_BEGIN in text and HAND_END in text.split(HAND_BEGIN, 1)[1]:
        inner = text.split(HAND_BEGIN, 1)[1].split(HAND_END, 1)[0]
        return (HAND_BEGIN, *inner.strip("\n").split("\n"), HAND_END)
    return (HAND_BEGIN, *NO_HAND_TEXT, HAND_END)


def write(report: ContactReport, out: Path) -> Path:
    out.mkdir(parents=True, exist_ok=True)
    path = out / "contact_performance.md"
    path.write_text(render(report, hand_written(path)))
    return path


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m finger_sim.bench.contact_report", description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="fewer timesteps and repeats (for tests)")
    parser.add_argument("--out", type=Path, default=Path("docs"), help="folder for contact_performance.md")
    args = parser.parse_args(argv)
    words = ["python -m finger_sim.bench.contact_report", *(sys.argv[1:] if argv is None else argv)]
    report = measure(quick=args.quick, command=" ".join(words))
    path = write(report, args.out)
    print(f"wrote {path} in {report.wall:.0f} s", file=sys.stderr)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
