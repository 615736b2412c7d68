"""`finger-sim`: offline runs of scenes, kinematics, and tools over logs and benchmarks."""

from __future__ import annotations

import argparse
import math
import os
import sys
from collections.abc import Sequence
from pathlib import Path

from finger_sim import __version__, kinematics
from finger_sim.errors import FingerSimError
from finger_sim.integrators import METHODS
from finger_sim.model import FingerParams
from finger_sim.scene import AUTO, load_scene

#: Exit status of a command whose log was truncated (its intact part was used).
EXIT_TRUNCATED = 3
#: Exit status of `resim` when the re-simulation deviates from the log.
EXIT_DEVIATION = 4

#: MCP range of a real finger (the paper's Table I): the range `kinematics` sweeps, rad.
MCP_RANGE = (0.0, math.pi / 2)


def _simulate(args: argparse.Namespace) -> int:
    from finger_sim.simulate import simulate

    scene = load_scene(args.scene).with_overrides(method=args.method, dt=args.dt, duration=args.t_end)
    traj = simulate(scene)
    print(traj.summary())
    if traj.method_reason:
        print(f"method auto → {traj.method}: {traj.method_reason}")
    if args.csv:
        traj.write_csv(args.csv)
        print(f"wrote {args.csv}")
    if args.plot:
        from finger_sim.plots import plot_angles

        plot_angles(traj.t, traj.q, args.plot, f"{scene.name}: {traj.method}, dt = {scene.dt:g} s")
        print(f"wrote {args.plot}")
    return 0


def _kinematics(args: argparse.Namespace) -> int:
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
    if args.plot:
        from finger_sim.plots import plot_kinematics

        plot_kinematics(p, MCP_RANGE, args.plot)
        print(f"wrote {args.plot}")
    return 0


def _open_log(path: Path):  # type: ignore[no-untyped-def]
    """A log reader; a truncated log is read up to its intact part, with a warning."""
    from finger_sim.log import read_log

    reader = read_log(path)
    if reader.truncated:
        print(f"finger-sim: warning: {reader.truncation}; reading the intact part", file=sys.stderr)
    return reader


def _info(args: argparse.Namespace) -> int:
    reader = _open_log(args.log)
    print(reader.info())
    return EXIT_TRUNCATED if reader.truncated else 0


def _export(args: argparse.Namespace) -> int:
    from finger_sim.log.tools import load_run, trajectory_from_log

    reader = _open_log(args.log)
    run = load_run(reader)
    traj = trajectory_from_log(run)
    print(f"{args.log}: {len(traj.t)} joint states of scene '{run.scene.name}' ({run.torque_source} torque)")
    if len(traj.t):
        print(traj.summary())
    if args.csv:
        traj.write_csv(args.csv)
        print(f"wrote {args.csv}")
    if args.plot and len(traj.t):
        from finger_sim.plots import plot_angles

        plot_angles(traj.t, traj.q, args.plot, f"{run.scene.name}: logged by finger_node ({traj.method})")
        print(f"wrote {args.plot}")
    return EXIT_TRUNCATED if reader.truncated else 0


def _resim(args: argparse.Namespace) -> int:
    from finger_sim.log.tools import load_run, resimulate

    reader = _open_log(args.log)
    result = resimulate(load_run(reader))
    print(result.summary())
    if reader.truncated:
        return EXIT_TRUNCATED
    return 0 if result.exact else EXIT_DEVIATION


def _bench(args: argparse.Namespace) -> int:
    from finger_sim.bench.report import run_bench

    return run_bench(quick=args.quick, out=args.out, argv=sys.argv)


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="finger-sim", description=__doc__)
    parser.add_argument("--version", action="version", version=f"finger-sim {__version__}")
    sub = parser.add_subparsers(dest="command", required=True)

    sim = sub.add_parser("simulate", help="run a scene offline; CSV and plot of the angles")
    sim.add_argument("scene", type=Path, help="scene YAML file (see config/)")
    sim.add_argument("--method", choices=sorted(METHODS) + [AUTO], help="override the scene's integrator")
    sim.add_argument("--dt", type=float, help="override the step, s")
    sim.add_argument("--t-end", type=float, help="override the duration, s")
    sim.add_argument("--csv", type=Path, help="write every step: " + "t,theta1,...,constraint_residual")
    sim.add_argument("--plot", type=Path, help="write a PNG of θ1, θ2, θ3 against time")
    sim.set_defaults(func=_simulate)

    kin = sub.add_parser("kinematics", help="fingertip trajectory, postures, toggle angles, PIP range")
    kin.add_argument("--plot", type=Path, help="write a PNG of the trajectory and postures")
    kin.set_defaults(func=_kinematics)

    info = sub.add_parser("info", help="topics, counts, duration and scene of a node's MCAP log (like ros2 bag info)")
    info.add_argument("log", type=Path)
    info.set_defaults(func=_info)

    export = sub.add_parser("export", help="a node's MCAP log as the simulate CSV and plot")
    export.add_argument("log", type=Path)
    export.add_argument("--csv", type=Path, help="write the logged joint states in the paper's coordinates")
    export.add_argument("--plot", type=Path, help="write a PNG of θ1, θ2, θ3 against time")
    export.set_defaults(func=_export)

    resim = sub.add_parser("resim", help="re-simulate a node's MCAP log and report the deviation from it")
    resim.add_argument("log", type=Path)
    resim.set_defaults(func=_resim)

    bench = sub.add_parser("bench", help="work-precision and hard-case report with peers, written to docs/")
    bench.add_argument("--quick", action="store_true", help="a reduced grid for CI (under two minutes)")
    bench.add_argument("--out", type=Path, default=Path("docs"), help="folder for performance.md and figures")
    bench.set_defaults(func=_bench)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    try:
        return args.func(args)
    except FingerSimError as exc:
        print(f"finger-sim {args.command}: error: {exc}", file=sys.stderr)
        return 2
    except BrokenPipeError:  # the reader of our output went away (`| head`): stop quietly
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return 0


if __name__ == "__main__":
    sys.exit(main())
