"""finger_node's real-time factor on every shipped scene with `method: auto`, a short run each.

    python -m finger_sim.bench.node_scenes_bench [--duration 5] [--command-hz 100] [--scenes ...] [--out FILE]

--scenes takes names under config/ (paper_flexion, friction/hold_table, hard/grasp_release) or scene
files; by default every scene of config/ itself (not its friction/ and hard/ folders).

Each scene runs in its own finger_node process (physics and publishing at 1 kHz, realtime_factor 1,
torque from the topic), driven by this client as `node_bench` drives it (small alternating torques
at --command-hz, each held until the next, so the node's integrator restarts at every command):
the real-time factor from the joint_states stamps against the client's wall clock, the node's CPU
as a fraction of one core, their ratio (the node's CPU seconds per simulated second: below 1, one
free core holds real time, whatever else loads the machine), and its overruns from /diagnostics. A drive scene takes voltage, not
torque: the commands are refused (logged) and it runs at 0 V.
"""

from __future__ import annotations

import argparse
import os
import sys
import tempfile
from datetime import datetime, timezone
from pathlib import Path

from finger_sim.bench import node_bench
from finger_sim.bench.processes import ROOT, isolate_dds, machine
from finger_sim.errors import ConfigError

SCENES = tuple(sorted(p.stem for p in (ROOT / "config").glob("*.yaml") if p.stem != "finger_node"))


def scene_file(name: str) -> Path:
    """A --scenes entry → its scene file: a name under config/ ('hard/grasp_release') or a file's path.

    The node is given the file's absolute path, which it takes as it is (`scene_paths.resolve_scene`);
    a subfolder name alone would be read as a path relative to the working directory."""
    shipped = ROOT / "config" / f"{name}.yaml"
    for path in (shipped, Path(name).expanduser()):
        if path.suffix == ".yaml" and path.is_file():
            return path.resolve()
    raise ConfigError("--scenes", f"a scene file or a name under config/ (e.g. {SCENES[0]}, hard/grasp_release)", name)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="node_scenes_bench", description=__doc__.split("\n\n")[0])
    parser.add_argument("--duration", type=float, default=5.0, help="measured run per scene, s")
    parser.add_argument("--command-hz", type=float, default=node_bench.COMMAND_HZ, help="torque commands per second")
    parser.add_argument("--scenes", nargs="*", default=list(SCENES))
    parser.add_argument("--domain-id", type=int, default=node_bench.DEFAULT_DOMAIN_ID)
    parser.add_argument("--out", type=Path, help="write the Markdown table here")
    args = parser.parse_args(argv)
    try:
        files = {name: scene_file(name) for name in args.scenes}
    except ConfigError as exc:
        parser.error(str(exc))
    isolate_dds(args.domain_id)
    from finger_sim.scene import load_scene
    from finger_sim.simulate import Simulator

    rows = ["| scene | auto's method | real-time factor | node CPU (cores) | CPU s per simulated s | overruns |",
            "|---|---|---|---|---|---|"]
    with tempfile.TemporaryDirectory(prefix="node_scenes_") as tmp:
        for name in args.scenes:
            method = Simulator(load_scene(files[name])).method
            run = node_bench.measure(1.0, args.duration, args.domain_id, Path(tmp), commands=True,
                                     scene=str(files[name]), command_hz=args.command_hz)
            overruns = run.diagnostics[-1].get("overruns", "?") if run.diagnostics else "?"
            per_sim_s = run.cpu_cores / run.rtf if run.rtf else float("nan")
            rows.append(f"| {name} | {method} | {run.rtf:.3f} | {run.cpu_cores:.2f} | {per_sim_s:.2f} | {overruns} |")
            print(rows[-1], flush=True)
    command = "python -m finger_sim.bench.node_scenes_bench " + " ".join(argv if argv is not None else sys.argv[1:])
    text = (f"Measured {datetime.now(timezone.utc):%Y-%m-%d %H:%M} UTC on {machine()['cpu']} ({os.cpu_count()} cores), load average "
            f"{os.getloadavg()[0]:.1f}; `{command.strip()}`\n\n" + "\n".join(rows) + "\n")
    if args.out:
        args.out.write_text(text, encoding="utf-8")
    print(text)
    return 0


if __name__ == "__main__":
    sys.exit(main())
