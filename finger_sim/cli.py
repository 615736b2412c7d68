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
from finger_sim.atomic_write import atomic_path, check_distinct
from finger_sim.budget import DEFAULT_MAX_STEPS, check_budget
from finger_sim.errors import ConfigError, FingerSimError
from finger_sim.integrators import METHODS
from finger_sim.kernel import KERNELS
from finger_sim.model import FingerParams
from finger_sim.node_command_args import add_parser as add_node_parser
from finger_sim.node_command_args import positive_int as _positive_int
from finger_sim.output_paths import check_output_dir, check_output_file, check_plot_file
from finger_sim.scene import AUTO, Scene, load_scene

#: Exit status of a refused input or a failed command (argparse's own for a usage error).
EXIT_ERROR = 2
#: Exit status of a command whose log was truncated (its intact part was used).
EXIT_TRUNCATED = 3
#: Exit status of `resim` when the re-simulation deviates from the log.
EXIT_DEVIATION = 4
#: Exit status of `resim`/`export` refusing a log's states: none, non-finite, duplicated or out of order.
EXIT_INVALID_LOG = 5
#: Exit status of a command that lost data of a damaged log: `repair` or `--salvage` skipped damaged
#: chunks, or `info` found chunks that fail their CRC.
EXIT_DATA_LOST = 6
#: Exit status of export or resim on a log whose recorder dropped messages (without --accept-incomplete).
EXIT_INCOMPLETE = 7

#: Damaged parts a salvaging read names one by one before it only counts the rest.
MAX_DAMAGE_LINES = 5

#: MCP range of a real finger (the paper's Table I): the range `kinematics` sweeps, rad.
MCP_RANGE = (0.0, math.pi / 2)


def _simulate(args: argparse.Namespace) -> int:
    """Paths and the run's size are checked before it starts; `--csv` without `--plot` streams to the file."""
    from finger_sim.auto import promise_note
    from finger_sim.simulate import simulate
    from finger_sim.streaming import stream_csv

    scene = load_scene(args.scene).with_overrides(method=args.method, dt=args.dt, duration=args.t_end,
                                                  tolerance=getattr(args, "tolerance", None))
    csv = check_output_file(args.csv, argument="--csv") if args.csv else None
    plot = check_plot_file(args.plot, argument="--plot") if args.plot else None
    check_distinct({"SCENE": args.scene}, {"--csv": csv, "--plot": plot})
    streaming = csv is not None and plot is None
    check_budget(scene, max_steps=args.max_steps or DEFAULT_MAX_STEPS, streaming=streaming)
    if args.max_steps and scene.step_count > args.max_steps:  # a streamed run holds nothing: only a cap asked for
        raise ConfigError("--max-steps", f"at least the run's {scene.step_count:,} steps "
                          f"(duration {scene.duration:g} s at dt = {scene.dt:g} s)", args.max_steps)
    if streaming and (args.columns != "paper" or args.every > 1):  # finger_sim.csv_columns
        from finger_sim.csv_columns import write_simulated

        with atomic_path(csv) as part:
            sim = write_simulated(part, scene, columns=args.columns, every=args.every, kernel=args.kernel)
        print(f"t = {sim.time:.4g} s  method = {sim.method}  steps = {sim.step_index}")
        print(f"wrote {csv} ({args.columns} columns, every {args.every} steps)")
        return 0
    if streaming:
        with atomic_path(csv) as part:
            run = stream_csv(scene, part, kernel=args.kernel)
        print(run.summary())
        if run.method_reason:
            print(f"method auto → {run.method}: {run.method_reason}")
        if note := promise_note(scene, run.method, run.error_estimate):
            print(note)
        print(f"wrote {csv}")
        return 0
    traj = simulate(scene, kernel=args.kernel, energy_report=True)  # the summary prints it: one run, not two
    print(traj.summary())
    if traj.method_reason:
        print(f"method auto → {traj.method}: {traj.method_reason}")
    if note := promise_note(scene, traj.method, traj.error_estimate):
        print(note)
    if csv and (args.columns != "paper" or args.every > 1):
        from finger_sim.actuators.drive_outputs import MESH_TORQUE
        from finger_sim.csv_columns import write_paper, write_ros

        with atomic_path(csv) as part:
            if args.columns == "ros":
                efforts = traj.outputs.get(MESH_TORQUE.name, [scene.torque(t) for t in traj.t])  # with a drive: τ_g
                samples = ((t, tuple(q), tuple(v), e) for t, q, v, e in zip(traj.t, traj.q, traj.v, efforts))
                write_ros(part, scene.build_system(), samples, every=args.every, total=len(traj.t))
            else:
                write_paper(part, traj, every=args.every)
        print(f"wrote {csv}")
    elif csv:
        with atomic_path(csv) as part:
            traj.write_csv(part)
        print(f"wrote {csv}")
    if plot:
        from finger_sim.plots import plot_angles

        with atomic_path(plot) as part:
            plot_angles(traj.t, traj.q, part, f"{scene.name}: {traj.method}, dt = {scene.dt:g} s", traj.outputs)
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

        with atomic_path(plot) as part:
            plot_kinematics(p, MCP_RANGE, part)
        print(f"wrote {plot}")
    return 0


def _tasks(args: argparse.Namespace) -> int:
    """`finger-sim tasks`: see finger_sim.tasks.suite."""
    from finger_sim.tasks.schema import load_task
    from finger_sim.tasks.suite import chunk_of, installed_tasks, parse_controllers, run_suite, summary_table, write_report

    tasks = [load_task(p) for p in (args.task or installed_tasks())]
    controllers = parse_controllers(args.controller, args.param, args.vary, args.ros_controller)
    runs = run_suite(tasks, chunk_of(controllers, args.chunk), args.out)
    command = "finger-sim tasks " + " ".join(sys.argv[2:]) if sys.argv[1:2] == ["tasks"] else ""
    path = write_report(runs, tasks, args.out, figures=not args.no_figures, command=command.strip())
    print(summary_table(runs))
    print(f"wrote {path} and {args.out / 'metrics.json'}")
    return 0 if all(r.ok for r in runs) else 1


def _log_command(command: Callable[[argparse.Namespace], int]) -> Callable[[argparse.Namespace], int]:
    """A log subcommand: errors of the MCAP library (independent of the core) become one line too."""

    @functools.wraps(command)
    def run(args: argparse.Namespace) -> int:
        from finger_sim.log import LogError
        from finger_sim.run_log_checks import InvalidRunError

        try:
            return command(args)
        except LogError as exc:
            raise FingerSimError(str(exc)) from None
        except InvalidRunError as exc:
            print(f"finger-sim {args.command}: error: {_one_line(str(exc))}", file=sys.stderr)
            return EXIT_INVALID_LOG

    return run


def _open_log(path: Path, *, salvage: bool = False):  # type: ignore[no-untyped-def]
    """A log reader; a truncated log is read up to its intact part, with a warning.
    salvage: damaged chunks are skipped (see `_salvaged`) instead of refused."""
    from finger_sim.log import read_log

    reader = read_log(path, salvage=salvage)
    if reader.truncated:
        print(f"finger-sim: warning: {reader.truncation}; reading the intact part "
              f"(`finger-sim repair {path}` makes a complete copy)", file=sys.stderr)
    return reader


def _incomplete(reader, args: argparse.Namespace) -> bool:  # type: ignore[no-untyped-def]
    """Warn about messages the recorder dropped; True if the command must stop (no --accept-incomplete)."""
    if not reader.dropped:
        return False
    stop = not args.accept_incomplete
    print(f"finger-sim: {'error' if stop else 'warning'}: {args.log}: incomplete log, {reader.dropped} messages were "
          f"dropped while recording" + ("; --accept-incomplete uses what is there" if stop else ""), file=sys.stderr)
    return stop


def _salvaged(reader, command: str) -> bool:  # type: ignore[no-untyped-def]
    """Warn (one line each, at most a few) of the damaged parts a salvaging read skipped; whether any were."""
    for damage in reader.damage[:MAX_DAMAGE_LINES]:
        print(f"finger-sim {command}: warning: skipped {_one_line(str(damage.error))} "
              f"({damage.messages} messages by its index)", file=sys.stderr)
    if len(reader.damage) > MAX_DAMAGE_LINES:
        print(f"finger-sim {command}: warning: skipped {len(reader.damage) - MAX_DAMAGE_LINES} more damaged parts",
              file=sys.stderr)
    return bool(reader.damage)


@_log_command
def _info(args: argparse.Namespace) -> int:
    from finger_sim.run_log import FINGER_SIM_METADATA, crush_lines

    reader = _open_log(args.log, salvage=True)
    print(reader.info(FINGER_SIM_METADATA))
    crushes = crush_lines(reader)  # objects the run crushed (finger_sim.runtime.crushing)
    if crushes is not None:
        print("Crushed:  " + ("\n          ".join(crushes) if crushes else "none"))
    if args.no_verify:
        print("Chunks:   not verified (--no-verify)")
    else:
        damage = reader.verify()
        lost = sum(d.messages for d in damage)
        print(f"Chunks:   {reader.chunk_count - len(damage)} of {reader.chunk_count} pass their CRC"
              + (f"; {len(damage)} DAMAGED, holding {lost} messages (`finger-sim repair` keeps the rest)" if damage else ""))
    if _salvaged(reader, "info"):  # also damage met while scanning a log without a summary
        return EXIT_DATA_LOST
    return EXIT_TRUNCATED if reader.truncated else 0


def _per_finger(path: Path, finger: str, fingers: list[str]) -> Path:
    """An output path of one finger: `path` itself for a one-finger export, else <stem>_<finger><suffix>."""
    return path if len(fingers) == 1 else path.with_name(f"{path.stem}_{finger}{path.suffix}")


@_log_command
def _export(args: argparse.Namespace) -> int:
    from finger_sim.run_log import select_fingers

    reader = _open_log(args.log, salvage=args.salvage)
    if _incomplete(reader, args):
        return EXIT_INCOMPLETE
    fingers = select_fingers(reader, args.finger)
    outputs = [(f, check_output_file(_per_finger(args.csv, f, fingers), argument="--csv") if args.csv else None,
                check_plot_file(_per_finger(args.plot, f, fingers), argument="--plot") if args.plot else None)
               for f in fingers]
    label = (lambda option, f: option) if len(fingers) == 1 else (lambda option, f: f"{option} ({f})")
    check_distinct({"LOG": args.log}, {label("--csv", f): c for f, c, _ in outputs} | {label("--plot", f): p for f, _, p in outputs})
    for finger, csv, plot in outputs:
        _export_finger(args, reader, finger, csv, plot)
    if _salvaged(reader, "export"):
        return EXIT_DATA_LOST
    return EXIT_TRUNCATED if reader.truncated else 0


def _export_finger(args: argparse.Namespace, reader, finger: str, csv: Path | None, plot: Path | None) -> None:  # type: ignore[no-untyped-def]
    """One finger of a log ('' for finger_node's) as CSV and plot; its states checked first (run_log_checks)."""
    from finger_sim.run_log import load_run, logged_outputs, trajectory_from_log
    from finger_sim.run_log_checks import check_states

    run = load_run(reader, finger=finger)  # with its events: a reset may repeat a stamp (run_log_checks)
    check_states(run, args.log)
    traj = trajectory_from_log(run)
    traj.outputs = logged_outputs(reader, run, finger)  # a contact scene's forces, as simulate writes them
    who = f" finger '{finger}'" if finger else ""
    print(f"{args.log}:{who} {len(traj.t)} joint states of scene '{run.scene.name}' ({run.torque_source} torque)")
    if len(traj.t):
        print(traj.summary())
    if csv:
        from finger_sim.csv_columns import write_paper, write_ros
        from finger_sim.run_log import logged_samples

        with atomic_path(csv) as part:
            if args.columns == "ros":
                rows = write_ros(part, run.scene.build_system(), logged_samples(run), every=args.every,
                                 total=len(run.joint_states), desc="export")
            else:
                rows = write_paper(part, traj, every=args.every, desc="export")
        print(f"wrote {csv} ({rows} rows, {args.columns} columns)")
    if plot and len(traj.t):
        from finger_sim.plots import plot_angles

        with atomic_path(plot) as part:
            plot_angles(traj.t, traj.q, part, f"{run.scene.name}{who}: logged by finger_node ({traj.method})", traj.outputs)
        print(f"wrote {plot}")


@_log_command
def _resim(args: argparse.Namespace) -> int:
    from finger_sim.run_log import load_run, resimulate, select_fingers
    from finger_sim.run_log_checks import check_states

    reader = _open_log(args.log, salvage=args.salvage)
    if _incomplete(reader, args):
        return EXIT_INCOMPLETE
    exact = True
    for finger in select_fingers(reader, args.finger):
        run = load_run(reader, finger=finger)
        check_states(run, args.log)
        result = resimulate(run, kernel=args.kernel, max_steps=args.max_steps)
        print((f"{finger}: " if finger else "") + result.summary())
        exact = exact and result.exact
    if not exact:
        return EXIT_DEVIATION
    if _salvaged(reader, "resim"):
        return EXIT_DATA_LOST
    return EXIT_TRUNCATED if reader.truncated else 0


@_log_command
def _repair(args: argparse.Namespace) -> int:
    from finger_sim.log.repair import default_repair_path, repair_log

    out = check_output_file(args.out or default_repair_path(args.log), argument="-o/--out")
    check_distinct({"LOG": args.log}, {"-o/--out": out})
    report = repair_log(args.log, out)
    print(report.summary())
    return EXIT_DATA_LOST if report.lost else 0


@_log_command
def _view(args: argparse.Namespace) -> int:
    """The HTML viewer of a log or CSV (finger_sim.view); paths checked before reading."""
    from finger_sim.view import write_view

    out = check_output_file(args.out or args.run.with_suffix(".html"), argument="-o/--out")
    print(write_view(args.run, out, scene=args.scene))
    return 0


def _urdf(args: argparse.Namespace) -> int:
    """The URDF of a scene's finger, on stdout or to -o."""
    from finger_sim.urdf import finger_urdf

    scene = load_scene(args.scene)
    out = check_output_file(args.out, argument="-o/--out") if args.out else None
    check_distinct({"SCENE": args.scene}, {"-o/--out": out})
    text = finger_urdf(scene.params, prefix=args.prefix, mcp_limits=scene.mcp_limits, drive=scene.drive)
    if out is None:
        sys.stdout.write(text)
    else:
        with atomic_path(out) as part:
            part.write_text(text, encoding="utf-8")
        print(f"wrote {out}")
    return 0


def _schema(args: argparse.Namespace) -> int:
    """The JSON Schema of scene (or hand, or task) files, on stdout or to -o (for an editor's YAML language server)."""
    from finger_sim.runtime.hand_schema import hand_schema
    from finger_sim.scene_schema import scene_schema, schema_text
    from finger_sim.tasks.task_schema import task_schema

    text = schema_text(hand_schema() if args.hand else task_schema() if args.task else scene_schema())
    if args.out is None:
        sys.stdout.write(text)
        return 0
    out = check_output_file(args.out, argument="-o/--out")
    with atomic_path(out) as part:
        part.write_text(text, encoding="utf-8")
    print(f"wrote {out}")
    return 0


def _sweep(args: argparse.Namespace) -> int:
    """Paths are checked before the first run; refusals name the key or option."""
    from finger_sim.sweep import DEFAULT_MAX_SWEEP_STEPS, sweep

    out = check_output_file(args.out, argument="--out")
    plot = check_plot_file(args.plot, argument="--plot") if args.plot else None
    parquet = check_output_file(args.parquet, argument="--parquet") if args.parquet else None
    check_distinct({"SCENE": args.scene}, {"--out": out, "--plot": plot, "--parquet": parquet})
    print(sweep(args.scene, args.vary, out, plot=plot, chunk=args.chunk, max_steps=args.max_steps or DEFAULT_MAX_SWEEP_STEPS,
                dask=args.dask, parquet=parquet))
    return 0


def _sample(args: argparse.Namespace) -> int:
    """Paths are checked before the first run; refusals name the key or option."""
    from finger_sim.sample import sample

    out = check_output_file(args.out, argument="--out") if args.out else None
    parquet = check_output_file(args.parquet, argument="--parquet") if args.parquet else None
    plot = check_plot_file(args.plot, argument="--plot") if args.plot else None
    check_distinct({"SCENE": args.scene}, {"--out": out, "--parquet": parquet, "--plot": plot})
    print(sample(args.scene, args.dist, args.n, args.seed, at=args.at, out=out, parquet=parquet, plot=plot))
    return 0


#: Where `bench` writes without --out: the full grid into docs/ (its committed results), a
#: --quick run into out/ (ignored by git), so that a quick check never replaces the full results.
BENCH_OUT, QUICK_BENCH_OUT = Path("docs"), Path("out") / "bench_quick"


def bench_out(args: argparse.Namespace) -> Path:
    """The folder `bench` writes to: --out, else BENCH_OUT or, with --quick, QUICK_BENCH_OUT."""
    if args.out is not None:
        return args.out
    return QUICK_BENCH_OUT if args.quick else BENCH_OUT


def _bench(args: argparse.Namespace) -> int:
    from finger_sim.bench.report import run_bench

    return run_bench(quick=args.quick, out=check_output_dir(bench_out(args), argument="--out"), argv=sys.argv)


def _node(args: argparse.Namespace) -> int:
    """`finger-sim node ...` (finger_sim.ros.node_command): rclpy is imported only when it runs."""
    from finger_sim.ros.node_command import run

    return run(args)


class _Parser(argparse.ArgumentParser):
    """argparse with a usage error on one line (`finger-sim simulate: error: ...`), exit status 2."""

    def error(self, message: str) -> NoReturn:
        self.exit(EXIT_ERROR, f"{self.prog}: error: {_one_line(message)}\n")


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
    sim.add_argument("--tolerance", type=float, metavar="RAD",
                     help="override integrator.tolerance: the global error on θ that method auto delivers (default 1e-6 rad)")
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
    info.add_argument("--no-verify", action="store_true",
                      help="skip reading every chunk to check its CRC (the summary alone is shown)")
    info.set_defaults(func=_info)

    export = sub.add_parser("export", help="a node's MCAP log as the simulate CSV and plot")
    export.add_argument("log", type=Path)
    export.add_argument("--csv", type=Path, help="write the logged joint states (columns: see --columns)")
    _csv_options(export)
    export.add_argument("--plot", type=Path, help="write a PNG of θ1, θ2, θ3 against time")
    export.add_argument("--accept-incomplete", action="store_true",
                        help="export a log whose recorder dropped messages (else exit 7)")
    export.add_argument("--salvage", action="store_true",
                        help="read past damaged chunks (each named on stderr; exit status 6)")
    export.add_argument("--finger", metavar="NAME", help="one finger of a finger_hand log (default: every finger, "
                        "each to <stem>_<finger><suffix> of --csv and --plot)")
    export.set_defaults(func=_export)

    resim = sub.add_parser("resim", help="re-simulate a node's MCAP log and report the deviation from it")
    resim.add_argument("log", type=Path)
    resim.add_argument("--kernel", choices=KERNELS,
                       help="step with this kernel instead of the one the log records (its metadata 'kernel')")
    resim.add_argument("--accept-incomplete", action="store_true",
                       help="re-simulate a log whose recorder dropped messages (else exit 7)")
    resim.add_argument("--max-steps", type=_positive_int, metavar="N",
                       help=f"refuse a re-simulation of more than N steps in all (default: {DEFAULT_MAX_STEPS:,})")
    resim.add_argument("--salvage", action="store_true",
                       help="read past damaged chunks (each named on stderr; exit status 6)")
    resim.add_argument("--finger", metavar="NAME", help="one finger of a finger_hand log (default: every finger)")
    resim.set_defaults(func=_resim)

    repair = sub.add_parser("repair", help="rewrite the readable part of a cut log (kill -9, full disk) as a "
                                           "complete, indexed MCAP (like `mcap recover`)")
    repair.add_argument("log", type=Path)
    repair.add_argument("-o", "--out", type=Path, help="the repaired log (default: <stem>.repaired.mcap next to LOG)")
    repair.set_defaults(func=_repair)

    view = sub.add_parser("view", help="a self-contained HTML viewer of a run: the linkage to scale over a time "
                                       "slider, plots of every signal under a shared cursor")
    view.add_argument("run", type=Path, help="a finger_node or finger_hand MCAP log, or a simulate/export CSV")
    view.add_argument("-o", "--out", type=Path, help="the HTML file (default: RUN with the suffix .html)")
    view.add_argument("--scene", type=Path, help="the scene of a CSV (geometry, objects, scripted torque); "
                                                 "a log holds its own")
    view.set_defaults(func=_view)

    urdf = sub.add_parser("urdf", help="the URDF of a scene's finger (links, joints, masses, capsules, the scene's "
                                       "MCP stops as limits; spec §6)")
    urdf.add_argument("scene", type=Path, help="scene YAML file (see config/); its model.geometry sets the URDF")
    urdf.add_argument("-o", "--out", type=Path, help="write the URDF to this file (default: stdout)")
    urdf.add_argument("--prefix", default="", help="prepended to every link and joint name (finger_node's frame_prefix)")
    urdf.set_defaults(func=_urdf)

    schema = sub.add_parser("schema", help="the JSON Schema of scene files, which editors complete and check "
                                           "scenes with (README: YAML language server)")
    schema.add_argument("-o", "--out", type=Path, help="write the schema to this file (default: stdout)")
    kind = schema.add_mutually_exclusive_group()
    kind.add_argument("--hand", action="store_true", help="the schema of finger_hand's hand files (config/hands/)")
    kind.add_argument("--task", action="store_true", help="the schema of grasp task files (config/tasks/)")
    schema.set_defaults(func=_schema)

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

    tasks = sub.add_parser("tasks", help="grade grip controllers on the grasp tasks (config/tasks/): "
                                         "Markdown report, figures, JSON; exit 1 when a controller fails a task")
    tasks.add_argument("task", nargs="*", type=Path, help="task YAML files (default: the installed suite)")
    tasks.add_argument("--controller", action="append", default=[], metavar="LABEL=module:callable",
                       help="a controller factory (repeat; default: the shipped grip_pi and grip_pi_aggressive)")
    tasks.add_argument("--ros-controller", action="append", default=[], metavar="LABEL=EXECUTABLE",
                       help="a ROS 2 controller node (e.g. finger_grip_controller, or module:callable run as a node) "
                            "run through finger_node in lockstep on ROS_DOMAIN_ID, loopback only (repeatable)")
    tasks.add_argument("--param", action="append", default=[], metavar="LABEL.key=value",
                       help="a keyword argument of a controller's factory, e.g. grip_pi.kp=0.01")
    tasks.add_argument("--vary", action="append", default=[], metavar="key=v1,v2,...",
                       help="run the first controller over the product of these parameter values (a gain sweep); "
                            "scene.KEY sets a dotted scene key of the tasks (e.g. scene.objects.0.break_force)")
    tasks.add_argument("--chunk", default="1/1", metavar="i/n",
                       help="run only the i-th of n equal slices of the controllers (as `sweep --chunk`); default 1/1")
    tasks.add_argument("--out", type=Path, default=Path("out/tasks"), help="folder for report.md, metrics.json, figures")
    tasks.add_argument("--no-figures", action="store_true", help="skip the figures")
    tasks.set_defaults(func=_tasks)

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
    bench.add_argument("--out", type=Path, help="folder for performance.md and figures (default: docs/, "
                       "with --quick out/bench_quick/)")
    bench.set_defaults(func=_bench)
    add_node_parser(sub, _node)
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
