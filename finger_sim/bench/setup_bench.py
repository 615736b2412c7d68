"""The slow corners' costs, side by side in one run: building a Simulator, importing the simulator.

    python -m finger_sim.bench.setup_bench [--repeats 200] [--scenes all | NAME ...] [--no-import]

- `Simulator(scene)` of a scene seen before (its set-up kept: `simulation.setup.setup_for`) against one
  never seen (a new spring stiffness each time: method choice, fastest mode, stability check,
  compiled plan), per scene (names under config/ without .yaml, e.g. `friction/hold_table`; `all`:
  every shipped scene); medians, µs of CPU.
- `import finger_sim.simulate` in a fresh interpreter, and the same followed by
  `import scipy.integrate` (what it imported before), medians of 5, ms of wall time.
"""

from __future__ import annotations

import argparse
import statistics
import subprocess
import sys
import time
from pathlib import Path

from finger_sim.scene import load_scene
from finger_sim.simulate import Simulator
from finger_sim.sweep import set_key

CONFIG = Path(__file__).resolve().parents[2] / "config"
SCENES = ("paper_flexion", "paper_to_stop", "grasp_cylinder", "stiff_spring")
#: The folders of shipped scenes (config/finger_node.yaml holds the node's parameters, not a scene).
SCENE_DIRS = (".", "hard", "friction")
NOT_SCENES = frozenset({"finger_node"})
IMPORT_REPEATS = 5
#: Relative change of the spring that makes each "never seen" scene new.
SPRING_STEP = 1e-9


def _cpu_us(make, repeats: int) -> float:  # type: ignore[no-untyped-def]
    samples = []
    for i in range(repeats):
        start = time.process_time()
        make(i)
        samples.append(time.process_time() - start)
    return 1e6 * statistics.median(samples)


def _import_ms(code: str) -> float:
    samples = []
    for _ in range(IMPORT_REPEATS):
        out = subprocess.run([sys.executable, "-c", f"import time; t = time.perf_counter(); {code}; "
                              "print(time.perf_counter() - t)"], capture_output=True, text=True, check=True)
        samples.append(float(out.stdout))
    return 1e3 * statistics.median(samples)


def shipped_scenes() -> tuple[str, ...]:
    """Every shipped scene's name, relative to config/ without .yaml (`hard/chatter_wall`)."""
    return tuple(str((CONFIG / d / path.name).relative_to(CONFIG).with_suffix(""))
                 for d in SCENE_DIRS for path in sorted((CONFIG / d).glob("*.yaml")) if path.stem not in NOT_SCENES)


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeats", type=int, default=200)
    ap.add_argument("--scenes", nargs="+", default=list(SCENES), help="names under config/, or all")
    ap.add_argument("--no-import", action="store_true", help="leave out the import timings")
    args = ap.parse_args(argv)
    names = shipped_scenes() if args.scenes == ["all"] else args.scenes
    print(f"# {time.strftime('%Y-%m-%d %H:%M UTC', time.gmtime())}; medians of {args.repeats}")
    print("| scene | `Simulator(scene)` never seen, µs CPU | seen before, µs CPU | ratio |")
    print("|---|---:|---:|---:|")
    for name in names:
        scene = load_scene(CONFIG / f"{name}.yaml")
        Simulator(scene)
        data = scene.to_dict()
        fresh = []
        for i in range(args.repeats // 4):
            set_key(data, "model.spring_stiffness", scene.spring_stiffness * (1.0 + SPRING_STEP * (i + 1)))
            fresh.append(type(scene)(**{**scene.__dict__, "spring_stiffness": data["model"]["spring_stiffness"]}))
        new = _cpu_us(lambda i: Simulator(fresh[i]), len(fresh))
        seen = _cpu_us(lambda i: Simulator(scene), args.repeats)
        print(f"| {name} | {new:.0f} | {seen:.1f} | {new / seen:.0f}× |")
    if args.no_import:
        return
    lean = _import_ms("import finger_sim.simulate")
    full = _import_ms("import finger_sim.simulate; import scipy.integrate")
    print(f"\n`import finger_sim.simulate`: {lean:.0f} ms; with `import scipy.integrate` after it: {full:.0f} ms "
          f"(medians of {IMPORT_REPEATS} fresh interpreters, wall)")


if __name__ == "__main__":
    main()
