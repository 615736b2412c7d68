"""`finger-sim`: offline runs of scenes, kinematics, and tools over logs and benchmarks."""

from __future__ import annotations

import argparse
import functools
import math
import os
import sys
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import NoReturn

from finger_sim import __version__, kinematics
from finger_sim.budget import DEFAULT_MAX_STEPS, check_budget
from finger_sim.errors import ConfigError, FingerSimError
from finger_sim.integrators import METHODS
from finger_sim.kernel import KERNELS
from finger_sim.model import FingerParams
from finger_sim.output_paths import check_output_dir, check_output_file, check_plot_file
from finger_sim.scene import AUTO, Scene, load_scene

#: Exit status of a refused input or a failed command (argparse's own for a usage error).
EXIT_ERROR = 2
#: Exit status of a command whose log was truncated (its intact part was used).
EXIT_TRUNCATED = 3
#: Exit status of `resim` when the re-simulation deviates from the log.
EXIT_DEVIATION = 4

#: MCP range of a real finger (the paper's Table I): the range `kinematics` sweeps, rad.
MCP_RANGE = (0.0, math.pi / 2)


def _simulate(args: argparse.Namespace) -> int:
    """Paths and the run's size are checked before it starts; `--csv` without `--plot` streams to the file."""
    from finger_sim.simulate import simulate
    from finger_sim.streaming import stream_csv

    scene = load_scene(args.scene).with_overrides(method=args.method, dt=args.dt, duration=args.t_end)
    csv = check_output_file(args.csv, argument="--csv") if args.csv else None
    plot = check_plot_file(args.plot, argument="--plot") if args.plot else None
    streaming = csv is not None and plot is None
    check_budget(scene, max_steps=args.max_steps or DEFAULT_MAX_STEPS, streaming=streaming)
    if args.max_steps and scene.step_count > args.max_steps:  # a streamed run holds nothing: only a cap asked for
        raise ConfigError("--max-steps", f"at least the run's {scene.step_count:,} steps "
                          f"(duration {scene.duration:g} s at dt = {scene.dt:g} s)", args.max_steps)
    if streaming and (args.columns != "paper" or args.every > 1):  # finger_sim.csv_columns
        from finger_sim.csv_columns import write_simulated

        sim = write_simulated(csv, scene, columns=args.columns, every=args.every, kernel=args.kernel)
        print(f"t = {sim.time:.4g} s  method = {sim.method}  steps = {sim.step_index}")
        print(f"wrote {csv} ({args.columns} columns, every {args.every} steps)")
        return 0
    if streaming:
        run = stream_csv(scene, csv, kernel=args.kernel)
        print(run.summary())
        if run.method_reason:
            print(f"method auto → {run.method}: {run.method_reason}")
        print(f"wrote {csv}")
        return 0
    traj = simulate(scene, kernel=args.kernel)
    print(traj.summary())
    if traj.method_reason:
        print(f"method auto → {traj.method}: {traj.method_reason}")
    if csv and (args.columns != "paper" or args.every > 1):
        from finger_sim.csv_columns import write_paper, write_ros

        if args.columns == "ros":
            samples = ((t, tuple(q), tuple(v), scene.torque(t)) for t, q, v in zip(traj.t, traj.q, traj.v))
            write_ros(csv, scene.build_system(), samples, every=args.every, total=len(traj.t))
        else:
            write_paper(csv, traj, every=args.every)
        print(f"wrote {csv}")
    elif csv:
        traj.write_csv(csv)
        print(f"wrote {csv}")
    if plot:
        from finger_sim.plots import plot_angles

        plot_angles(traj.t, traj.q, plot, f"{scene.name}: {traj.method}, dt = {scene.dt:g} s", traj.outputs)
        print(f"wrote {plot}")
    return 0


def _kinematics(args: argparse.Namespace) -> int:
    plot = check_plot_file(args.plot, argument="--plot") if args.plot else None
    p = FingerParams()
    alpha = kinematics.distal_offset(p)
    flex, ext = kinematics.toggle_angles(p)
    ext_pose = kinematics.extended_pose(p)
    pip = [kinematics.pip_angle(kinematics.assemble(p, a), alpha) for a in MCP_RANGE]
    tip = kinematics.fingertip(p, ext_pose, alpha)
    print(f"extended pose θ_ext = ({', '.join(f'{math.degrees(a):.4f}°' for a in ext_pose)})")
    print(f"toggle angles θ1 = {math.degrees(flex):.4f}° (flexion), {math.degrees(ext):.4f}° (extension)")
    print(f"PIP range over MCP {math.degrees(MCP_RANGE[0]):.0f}..{math.degrees(MCP_RANGE[1]):.0f}°: "
          f"{math.degrees(pip[0]):.2f}° .. {math.degrees(pip[1]):.2f}°")
    print(f"fingertip at extension ({tip.x:.4f}, {tip.y:.4f}) m")
    if plot:
        from finger_sim.plots import plot_kinematics

        plot_kinematics(p, MCP_RANGE, plot)
        print(f"wrote {plot}")
    return 0


def _log_command(command: Callable[[argparse.Namespace], int]) -> Callable[[argparse.Namespace], int]:
    """A log subcommand: errors of the MCAP library (independent of the core) become one line too."""

    @functools.wraps(command)
    def run(args: argparse.Namespace) -> int:
        from finger_sim.log import LogError

        try:
            return command(args)
        except LogError as exc:
            raise FingerSimError(str(exc)) from None

    return run


def _open_log(path: Path):  # type: ignore[no-untyped-def]
    """A log reader; a truncated log is read up to its intact part, with a warning."""
    from finger_sim.log import read_log

    reader = read_log(path)
    if reader.truncated:
        print(f"finger-sim: warning: {reader.truncation}; reading the intact part "
              f"(`finger-sim repair {path}` makes a complete copy)", file=sys.stderr)
    return reader


@_log_command
def _info(args: argparse.Namespace) -> int:
    from finger_sim.run_log import FINGER_SIM_METADATA

    reader = _open_log(args.log)
    print(reader.info(FINGER_SIM_METADATA))
    return EXIT_TRUNCATED if reader.truncated else 0


@_log_command
def _export(args: argparse.Namespace) -> int:
    from finger_sim.run_log import load_run, trajectory_from_log

    csv = check_output_file(args.csv, argument="--csv") if args.csv else None
    plot = check_plot_file(args.plot, argument="--plot") if args.plot else None
    reader = _open_log(args.log)
    run = load_run(reader, events=False)
    traj = trajectory_from_log(run)
    print(f"{args.log}: {len(traj.t)} joint states of scene '{run.scene.name}' ({run.torque_source} torque)")
    if len(traj.t):
        print(traj.summary())
    if csv:
        from finger_sim.csv_columns import write_paper, write_ros
        from finger_sim.run_log import logged_samples

        if args.columns == "ros":
            rows = write_ros(csv, run.scene.build_system(), logged_samples(run), every=args.every,
                             total=len(run.joint_states), desc="export")
        else:
            rows = write_paper(csv, traj, every=args.every, desc="export")
        print(f"wrote {csv} ({rows} rows, {args.columns} columns)")
    if plot and len(traj.t):
        from finger_sim.plots import plot_angles

        plot_angles(traj.t, traj.q, plot, f"{run.scene.name}: logged by finger_node ({traj.method})")
        print(f"wrote {plot}")
    return EXIT_TRUNCATED if reader.truncated else 0


@_log_command
def _resim(args: argparse.Namespace) -> int:
    from finger_sim.run_log import load_run, resimulate

    reader = _open_log(args.log)
    result = resimulate(load_run(reader), kernel=args.kernel)
    print(result.summary())
    if reader.truncated:
        return EXIT_TRUNCATED
    return 0 if result.exact else EXIT_DEVIATION


@_log_command
def _repair(args: argparse.Namespace) -> int:
    from finger_sim.log.repair import default_repair_path, repair_log

    out = check_output_file(args.out or default_repair_path(args.log), argument="-o/--out")
    report = repair_log(args.log, out)
    print(report.summary())
    return 0


def _urdf(args: argparse.Namespace) -> int:
    """The URDF of a scene's finger, on stdout or to -o."""
    from finger_sim.urdf import finger_urdf

    scene = load_scene(args.scene)
    out = check_output_file(args.out, argument="-o/--out") if args.out else None
    text = finger_urdf(scene.params, prefix=args.prefix)
    if out is None:
        sys.stdout.write(text)
    else:
        out.write_text(text, encoding="utf-8")
        print(f"wrote {out}")
    return 0


def _sweep(args: argparse.Namespace) -> int:
    """Paths are checked before the first run; refusals name the key or option."""
    from finger_sim.sweep import DEFAULT_MAX_SWEEP_STEPS, sweep

    out = check_output_file(args.out, argument="--out")
    plot = check_plot_file(args.plot, argument="--plot") if args.plot else None
    parquet = check_output_file(args.parquet, argument="--parquet") if args.parquet else None
    print(sweep(args.scene, args.vary, out, plot=plot, chunk=args.chunk, max_steps=args.max_steps or DEFAULT_MAX_SWEEP_STEPS,
                dask=args.dask, parquet=parquet))
    return 0


def _sample(args: argparse.Namespace) -> int:
    """Paths are checked before the first run; refusals name the key or option."""
    from finger_sim.sample import sample

    out = check_output_file(args.out, argument="--out") if args.out else None
    parquet = check_output_file(args.parquet, argument="--parquet") if args.parquet else None
    plot = check_plot_file(args.plot, argument="--plot") if args.plot else None
    print(sample(args.scene, args.dist, args.n, args.seed, at=args.at, out=out, parquet=parquet, plot=plot))
    return 0


def _bench(args: argparse.Namespace) -> int:
    from finger_sim.bench.report import run_bench

    return run_bench(quick=args.quick, out=check_output_dir(args.out, argument="--out"), argv=sys.argv)


class _Parser(argparse.ArgumentParser):
    """argparse with a usage error on one line (`finger-sim simulate: error: ...`), exit status 2."""

    def error(self, message: str) -> NoReturn:
        self.exit(EXIT_ERROR, f"{self.prog}: error: {_one_line(message)}\n")


def _positive_int(text: str) -> int:
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected an integer > 0, got {text!r}") from None
    if value <= 0:
        raise argparse.ArgumentTypeError(f"expected an integer > 0, got {value}")
    return value


def _csv_options(parser: argparse.ArgumentParser) -> None:
    """--columns and --every, shared by simulate and export (finger_sim.csv_columns)."""
    parser.add_argument("--columns", choices=("paper", "ros"), default="paper",
                        help="CSV columns: 'paper' (t, θ1..θ3, rates, energy, residual) or 'ros' (spec §6 joints: "
                             "mcp/coupler/pip position, velocity, effort, torque, tip pose in finger_base; "
                             "units in a '# units:' first line)")
    parser.add_argument("--every", type=_positive_int, default=1, metavar="N",
                        help="write every N-th sample (the first, then N, 2N, ...) to thin long runs")


def build_parser() -> argparse.ArgumentParser:
    parser = _Parser(prog="finger-sim", description=__doc__)
    parser.add_argument("--version", action="version", version=f"finger-sim {__version__}")
    sub = parser.add_subparsers(dest="command", required=True)

    sim = sub.add_parser("simulate", help="run a scene offline; CSV and plot of the angles")
    sim.add_argument("scene", type=Path, help="scene YAML file (see config/)")
    sim.add_argument("--method", choices=sorted(METHODS) + [AUTO],
                     help=f"override the scene's integrator (a scene that names none uses {Scene.method})")
    sim.add_argument("--dt", type=float, help="override the step, s")
    sim.add_argument("--t-end", type=float, help="override the duration, s")
    sim.add_argument("--max-steps", type=_positive_int, metavar="N",
                     help=f"refuse a run longer than N steps (default: {DEFAULT_MAX_STEPS:,} for a run held in "
                          "memory, none for --csv without --plot, which streams the run to the file)")
    sim.add_argument("--csv", type=Path, help="write every step: " + "t,theta1,...,constraint_residual"
                     + " (then grip_force, contact_force_{proximal,distal}_{x,y} when the scene has objects)"
                     + "; alone (no --plot), written as the run goes, in constant memory")
    _csv_options(sim)
    sim.add_argument("--plot", type=Path, help="write a figure of θ1, θ2, θ3 (and contact forces) against time (.png, .pdf, .svg, ...)")
    sim.add_argument("--kernel", choices=KERNELS, default="auto",
                     help="stepping kernel: compiled (numba), python, or auto (compiled where it pays; default)")
    sim.set_defaults(func=_simulate)

    kin = sub.add_parser("kinematics", help="fingertip trajectory, postures, toggle angles, PIP range")
    kin.add_argument("--plot", type=Path, help="write a figure of the trajectory and postures (.png, .pdf, .svg, ...)")
    kin.set_defaults(func=_kinematics)

    info = sub.add_parser("info", help="topics, counts, duration and scene of a node's MCAP log (like ros2 bag info)")
    info.add_argument("log", type=Path)
    info.set_defaults(func=_info)

    export = sub.add_parser("export", help="a node's MCAP log as the simulate CSV and plot")
    export.add_argument("log", type=Path)
    export.add_argument("--csv", type=Path, help="write the logged joint states (columns: see --columns)")
    _csv_options(export)
    export.add_argument("--plot", type=Path, help="write a PNG of θ1, θ2, θ3 against time")
    export.set_defaults(func=_export)

    resim = sub.add_parser("resim", help="re-simulate a node's MCAP log and report the deviation from it")
    resim.add_argument("log", type=Path)
    resim.add_argument("--kernel", choices=KERNELS,
                       help="step with this kernel instead of the one the log records (its metadata 'kernel')")
    resim.set_defaults(func=_resim)

    repair = sub.add_parser("repair", help="rewrite the readable part of a cut log (kill -9, full disk) as a "
                                           "complete, indexed MCAP (like `mcap recover`)")
    repair.add_argument("log", type=Path)
    repair.add_argument("-o", "--out", type=Path, help="the repaired log (default: <stem>.repaired.mcap next to LOG)")
    repair.set_defaults(func=_repair)

    urdf = sub.add_parser("urdf", help="the URDF of a scene's finger (links, joints, masses, capsules; spec §6)")
    urdf.add_argument("scene", type=Path, help="scene YAML file (see config/); its model.geometry sets the URDF")
    urdf.add_argument("-o", "--out", type=Path, help="write the URDF to this file (default: stdout)")
    urdf.add_argument("--prefix", default="", help="prepended to every link and joint name (finger_node's frame_prefix)")
    urdf.set_defaults(func=_urdf)

    sweep = sub.add_parser("sweep", help="a scene over the Cartesian product of varied keys, run as one "
                                         "compiled batch; one CSV row per run")
    sweep.add_argument("scene", type=Path, help="scene YAML file (see config/)")
    sweep.add_argument("--vary", action="append", required=True, metavar="KEY=V1,V2,...",
                       help="a dotted scene key (model.spring_stiffness, input.torque.slope, model.geometry.r1, "
                            "initial.theta1, model.gravity.1, ...) and its values; repeat for a product")
    sweep.add_argument("--out", type=Path, required=True, help="the CSV: the varied keys, then theta1..theta3_dot, "
                       "max_constraint_residual, energy_change (and grip_force for a contact scene) at the end")
    sweep.add_argument("--plot", type=Path, help="write the fingertip paths of the runs overlaid (.png, .pdf, .svg, ...)")
    sweep.add_argument("--chunk", default="1/1", metavar="i/n",
                       help="run only the i-th of n equal slices of the combinations (their CSVs' rows in order "
                            "are the whole sweep's); default 1/1")
    sweep.add_argument("--max-steps", type=_positive_int, metavar="N",
                       help="refuse a sweep of more than N finger-steps in all (default: 200,000,000)")
    sweep.add_argument("--dask", metavar="ADDRESS", help="run the chunks on the Dask scheduler at ADDRESS "
                       "(tcp://host:8786; workers need finger_sim installed, not the scene file)")
    sweep.add_argument("--parquet", type=Path, help="write the rows as Parquet too (pyarrow)")
    sweep.set_defaults(func=_sweep)

    sample = sub.add_parser("sample", help="Monte Carlo over toleranced scene values: the spread of the outputs and "
                                           "their Sobol sensitivity indices (SALib)")
    sample.add_argument("scene", type=Path, help="scene YAML file (see config/)")
    sample.add_argument("--dist", action="append", required=True, metavar="KEY=normal(mean,sd)",
                        help="a dotted scene key and its distribution, normal(mean,sd) or uniform(low,high), SI; "
                             "repeat for more keys")
    sample.add_argument("-n", type=_positive_int, required=True,
                        help="base sample size, a power of two: n·(keys + 2) runs (Saltelli's design)")
    sample.add_argument("--seed", type=int, default=0, help="seed of the draws (default 0): same seed, same runs")
    sample.add_argument("--at", type=float, help="time of the θ, fingertip and grip outputs, s (default: the end)")
    sample.add_argument("--out", type=Path, help="write one CSV row per run: the drawn values and the outputs")
    sample.add_argument("--parquet", type=Path, help="the same rows as Parquet (pyarrow)")
    sample.add_argument("--plot", type=Path, help="write the fingertip-path envelope (.png, .pdf, .svg, ...)")
    sample.set_defaults(func=_sample)

    bench = sub.add_parser("bench", help="work-precision and hard-case report with peers, written to docs/")
    bench.add_argument("--quick", action="store_true", help="a reduced grid for CI (under two minutes)")
    bench.add_argument("--out", type=Path, default=Path("docs"), help="folder for performance.md and figures")
    bench.set_defaults(func=_bench)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Run one command; every refusal or failure is one line on stderr and a non-zero exit status."""
    args = build_parser().parse_args(argv)
    try:
        return args.func(args)
    except BrokenPipeError:  # the reader of our output went away (`| head`): stop quietly
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return 0
    except (FingerSimError, OSError, UnicodeError) as exc:  # UnicodeError: a file or name not in UTF-8
        problem = str(exc)
    except RecursionError:
        problem = "input nested too deeply to process"
    except MemoryError:
        problem = "out of memory"
    print(f"finger-sim {args.command}: error: {_one_line(problem)}", file=sys.stderr)
    return EXIT_ERROR


def _one_line(text: str) -> str:
    """A message that may span lines (a YAML parser's, an OS error's) joined into one."""
    return "; ".join(line.strip() for line in text.splitlines() if line.strip())


if __name__ == "__main__":
    sys.exit(main())
