"""`finger-sim bench`: the work-precision report, with peers measured side by side in one run.

Everything runs in this one process, one configuration after another, so that the ratios
between methods are honest on a shared machine (what runs: `plan`). Each run is scored
against the scene's reference (`reference`). From the runs: the report's tables as data
(`tables`), one work-precision figure per scene (`figures`, `<out>/wp_<scene>.png`), and
`<out>/performance.md` (`markdown`). A full run also writes the recommendation table that
`method: auto` loads (`finger_sim.auto`'s data file); a --quick run measures too little for it.
"""

from __future__ import annotations

import datetime as _dt
import os
import sys
import time
from dataclasses import dataclass
from pathlib import Path

from tqdm import tqdm

from finger_sim import auto
from finger_sim.bench.figures import write_figure
from finger_sim.bench.markdown import RunInfo, render
from finger_sim.bench.plan import ALL_SCENES, SPACING, scene_file, tasks
from finger_sim.bench.reference import Reference, build_reference
from finger_sim.bench.runners import Run
from finger_sim.bench.tables import Tables, build_tables
from finger_sim.scene import Scene, load_scene


@dataclass(frozen=True)
class Measurements:
    """Everything one bench run measured: the scenes, their references, the runs, and how it ran."""

    scenes: dict[str, Scene]
    refs: dict[str, Reference]
    runs: list[Run]
    info: RunInfo

    def tables(self) -> Tables:
        return build_tables(self.scenes, {name: ref.floor for name, ref in self.refs.items()}, self.runs)


def measure(*, quick: bool, argv: list[str]) -> Measurements:
    """Build every scene's reference, then run the plan's tasks one after another (progress on stderr)."""
    started = _dt.datetime.now(_dt.timezone.utc)
    wall0, cpu0, load0 = time.perf_counter(), time.process_time(), os.getloadavg()
    scenes = {name: load_scene(scene_file(name)) for name in ALL_SCENES}
    refs: dict[str, Reference] = {}
    # disable=None: no bar unless stderr is a terminal (a CI log or a pipe gets no flood of updates)
    for name in tqdm(ALL_SCENES, desc="references", file=sys.stderr, leave=False, disable=None):
        refs[name] = build_reference(scenes[name], quick=quick, spacing=SPACING)
    todo = tasks(scenes, refs, quick=quick)
    runs: list[Run] = []
    with tqdm(total=len(todo), desc="bench", file=sys.stderr, unit="run", disable=None) as bar:
        for task in todo:
            bar.set_postfix_str(task.label, refresh=False)
            runs.append(task.call())
            bar.update()
    info = RunInfo(
        started=started,
        wall=time.perf_counter() - wall0,
        cpu=time.process_time() - cpu0,
        load=(load0, os.getloadavg()),
        # the program by its name, not the venv path it was started from
        command=" ".join([Path(argv[0]).name, *argv[1:]]) if argv else "finger-sim bench" + (" --quick" if quick else ""),
        quick=quick,
    )
    return Measurements(scenes, refs, runs, info)


def write_report(measured: Measurements, out: Path, *, recommendation_file: Path = auto.RECOMMENDATION_FILE) -> Tables:
    """The figures and performance.md in `out`; on a full run, also the table `auto` loads, to `recommendation_file`."""
    out.mkdir(parents=True, exist_ok=True)
    tables = measured.tables()
    figures = {
        name: write_figure(name, [r for r in measured.runs if r.scene == name], measured.refs[name], out) for name in ALL_SCENES
    }
    (out / "performance.md").write_text(render(tables, measured.scenes, measured.refs, figures, measured.info))
    if not measured.info.quick:
        auto.save_recommendation(tables.table, recommendation_about(measured.info, out), recommendation_file)
    return tables


def recommendation_about(info: RunInfo, out: Path) -> str:
    """The data file's note on what it holds and which bench run wrote it."""
    return (
        "kind → rate (Hz) → [[method, worst error over the kind's bench scenes (rad), µs per step], ...], cheapest "
        f"first; written by `finger-sim bench` (full run of {info.started:%Y-%m-%d %H:%M} UTC, "
        f"{(out / 'performance.md').as_posix()}) and loaded by finger_sim.auto. Fixed-step methods only."
    )


def run_bench(*, quick: bool, out: Path, argv: list[str]) -> int:
    """Measure everything, write `<out>/performance.md` and the figures (and, full run, auto's table); 0 on success."""
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    measured = measure(quick=quick, argv=argv)
    write_report(measured, out)
    written = f"{out / 'performance.md'} and {len(ALL_SCENES)} figures"
    if not quick:
        written += f" and {auto.RECOMMENDATION_FILE}"
    print(f"wrote {written} in {measured.info.wall:.0f} s", file=sys.stderr)
    return 0
