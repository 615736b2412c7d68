"""`finger-sim sweep`: one scene run over the Cartesian product of varied scene keys.

    finger-sim sweep config/paper_flexion.yaml --vary model.spring_stiffness=0.0005,0.001 \
        --vary input.torque.slope=0.01,0.02,0.03 --out results.csv [--plot tips.png] [--chunk 2/4]

A `--vary KEY=V1,V2,...` names a dotted key of the scene schema (`model.geometry.r1`,
`input.torque.slope`, `initial.theta1`; a list element by its index, `model.gravity.1`) and
values read as YAML 1.2 (`1e-3` is a number; `[0, 1.5]` a list). Each combination is set into
the resolved scene and validated by `scene_from_dict`, so every value gets the scene's checks
and a refusal names the key. The runs go through `finger_sim.batch.run_batch`.

A sweep is a list of independent chunks: `run_chunk(scene, vary, index, count)` runs the
index-th of count contiguous slices of the combinations (1-based) and returns its rows; the
chunks' rows in order are the whole sweep's. docs/sweep_performance.md shows Dask and Ray
spreading them over machines.
"""

from __future__ import annotations

import csv
import itertools
import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from finger_sim.atomic_write import atomic_path
from finger_sim.batch import BatchResult, run_batch
from finger_sim.effects.contact_outputs import GRIP_FORCE
from finger_sim.errors import ConfigError
from finger_sim.scene import Scene, load_scene, scene_from_dict
from finger_sim.scene_yaml import parse_scene_text
from finger_sim.simulate import Trajectory
from finger_sim.sweep_plan import Progress, check_values, combination, scene_block, sweep_steps

#: The final-state columns, named as in `finger-sim simulate`'s CSV.
STATE_COLUMNS = tuple(Trajectory.CSV_HEADER.split(",")[1:7])
RESULT_COLUMNS = (*STATE_COLUMNS, "max_constraint_residual", "energy_change")
GRIP_COLUMN = GRIP_FORCE.name
#: Finger-steps a sweep may take unless the user raises the limit: about a minute of CPU for the
#: compiled batch (0.27–0.34 µs of CPU per rk6 finger-step, 2026-11-27, docs/sweep_performance.md),
#: half a minute on two cores; hours in Python.
DEFAULT_MAX_SWEEP_STEPS = 200_000_000
#: Finger-steps whose angles `--plot` may hold (24 B each, measured: ≈ 480 MB).
MAX_PLOT_STEPS = 20_000_000
#: Bytes per held finger-step of a plotted sweep (three float64 angles).
PLOT_BYTES_PER_STEP = 24
#: Runs handed to the batch at once: the progress bar's grain; large enough to keep both cores busy.
BLOCK = 512


@dataclass(frozen=True)
class Vary:
    """One `--vary`: a dotted scene key, exactly as given, and its values (as YAML read them)."""

    key: str
    values: tuple[Any, ...]
    texts: tuple[str, ...]  # each value as written, for the CSV


def parse_vary(text: str) -> Vary:
    """`KEY=V1,V2,...` as a Vary; ConfigError naming the option and the key."""
    key, sep, rhs = text.partition("=")
    key = key.strip()
    if not sep or not key or not rhs.strip():
        raise ConfigError("--vary", "KEY=V1,V2,... (a dotted scene key and at least one value)", text)
    try:
        values = parse_scene_text(f"[{rhs}]", f"--vary {key}")
    except ConfigError as exc:
        raise ConfigError(f"--vary {key}", "comma-separated YAML values", rhs, problem=str(exc)) from None
    if not isinstance(values, list) or not values or any(v is None for v in values):
        raise ConfigError(f"--vary {key}", "comma-separated values, none empty", rhs)
    texts = tuple(_split_values(rhs))
    if len(texts) != len(values):  # a value with a comma inside brackets: keep YAML's reading
        texts = tuple(str(v) for v in values)
    return Vary(key, tuple(values), texts)


def _split_values(rhs: str) -> list[str]:
    """The comma-separated items of rhs, commas inside brackets kept."""
    items, depth, current = [], 0, ""
    for ch in rhs:
        depth += ch in "[{"
        depth -= ch in "]}"
        if ch == "," and depth == 0:
            items.append(current.strip())
            current = ""
        else:
            current += ch
    items.append(current.strip())
    return items


def set_key(data: dict[str, Any], key: str, value: Any) -> None:
    """Set a dotted key (list elements by index) in a scene mapping, in place.

    Every segment but the last must exist in the resolved scene; the last may be new (e.g.
    `model.joint_limits.mcp` of a scene without stops), and `scene_from_dict` then checks it.
    """
    parts = key.split(".")
    node: Any = data
    for depth, part in enumerate(parts):
        last = depth == len(parts) - 1
        where = ".".join(parts[:depth]) or "the scene"
        if isinstance(node, list):
            if not part.isdigit() or int(part) >= len(node):
                raise ConfigError(f"--vary {key}", f"an index below {len(node)} of the list {where}", part)
            index: int | str = int(part)
        elif isinstance(node, dict):
            if part not in node and not last:
                raise ConfigError(f"--vary {key}", f"a scene key: one of {sorted(node)} under {where}", part)
            index = part
        else:
            raise ConfigError(f"--vary {key}", f"a key inside a mapping or list, but {where} is a value", key)
        if last:
            node[index] = value
        else:
            node = node[index]


def sweep_scenes(base: Scene, vary: Sequence[Vary], start: int = 0, stop: int | None = None) -> list[Scene]:
    """The validated scenes of combinations start..stop of the product (the last key varies fastest)."""
    scenes = []
    combos = itertools.islice(itertools.product(*(v.values for v in vary)), start, stop)
    for combo in combos:
        data = base.to_dict()
        for v, value in zip(vary, combo):
            set_key(data, v.key, value)
        try:
            scenes.append(scene_from_dict(data))
        except ConfigError as exc:
            given = ", ".join(f"{v.key}={value!r}" for v, value in zip(vary, combo))
            raise ConfigError(f"--vary ({given}): {exc.key}", exc.allowed, exc.got, problem=exc.problem) from None
    return scenes


def combination_count(vary: Sequence[Vary]) -> int:
    return math.prod(len(v.values) for v in vary)


def chunk_range(total: int, index: int, count: int) -> tuple[int, int]:
    """Combinations [start, stop) of chunk `index` (1-based) of `count` contiguous chunks."""
    if count < 1 or not 1 <= index <= count:
        raise ConfigError("--chunk", "i/n with 1 ≤ i ≤ n", f"{index}/{count}")
    return total * (index - 1) // count, total * index // count


def parse_chunk(text: str) -> tuple[int, int]:
    """`i/n` as (i, n)."""
    i, sep, n = text.partition("/")
    if not sep or not i.strip().isdigit() or not n.strip().isdigit():
        raise ConfigError("--chunk", "i/n: run the i-th of n chunks (1 ≤ i ≤ n)", text)
    index, count = int(i), int(n)
    chunk_range(0, index, count)
    return index, count


def check_sweep_budget(scenes: Sequence[Scene], *, max_steps: int, plot: bool) -> int:
    """Refuse (ConfigError) a sweep of more than max_steps finger-steps, or a plotted one that
    would hold more than MAX_PLOT_STEPS; the finger-step count otherwise."""
    return check_step_count(sum(s.step_count for s in scenes), len(scenes), max_steps=max_steps, plot=plot)


def check_step_count(steps: int, runs: int, *, max_steps: int, plot: bool) -> int:
    """check_sweep_budget from the counts alone (finger_sim.sweep_plan.sweep_steps): no scene built."""
    if steps > max_steps:
        raise ConfigError("sweep", f"at most {max_steps:,} finger-steps in all (pass --max-steps {steps} to go ahead "
                          "on purpose, or split the sweep with --chunk i/n)", f"{runs:,} runs, {steps:,} steps")
    if plot and steps > MAX_PLOT_STEPS:
        raise ConfigError("--plot", f"a sweep of at most {MAX_PLOT_STEPS:,} finger-steps: it holds every run's angles "
                          f"(drop --plot or split the sweep with --chunk i/n)",
                          f"{steps:,} steps, about {steps * PLOT_BYTES_PER_STEP / 1e9:.3g} GB")
    return steps


def rows_of(vary: Sequence[Vary], start: int, result: BatchResult, grip: bool) -> list[dict[str, Any]]:
    """One row per run: the varied keys (their values as written), then the results."""
    rows = []
    for j in range(len(result.methods)):
        texts = combination([Vary(v.key, v.texts, v.texts) for v in vary], start + j)
        row: dict[str, Any] = {v.key: text for v, text in zip(vary, texts)}
        row.update(zip(STATE_COLUMNS, [*result.q[j].tolist(), *result.v[j].tolist()]))
        row["max_constraint_residual"] = float(result.max_residual[j])
        row["energy_change"] = float(result.energy_change[j])
        if grip:
            row[GRIP_COLUMN] = float(result.grip_force[j]) if result.grip_force is not None else 0.0
        row.update({name: float(values[j]) for name, values in result.measured.items()})  # the sensors' last readings
        rows.append(row)
    return rows


def columns(vary: Sequence[Vary], base: Scene) -> list[str]:
    """The CSV header: the varied keys as given, the results, grip_force for a contact scene, and the
    last reading of each scene sensor (`<sensor>_measured`, finger_sim.sensors)."""
    sensors = [f"{name}_measured" for name in base.sensors.models] if base.sensors is not None else []
    return [*(v.key for v in vary), *RESULT_COLUMNS, *([GRIP_COLUMN] if base.objects else []), *sensors]


@dataclass(frozen=True)
class Chunk:
    """The rows of one chunk in combination order, its CSV header, and when recorded its scenes
    and each run's (steps + 1) × 3 angles."""

    header: list[str]
    rows: list[dict[str, Any]]
    scenes: list[Scene]
    trajectories: list[np.ndarray]


def run_chunk(scene: str | Path | Scene, vary: Sequence[str | Vary], index: int = 1, count: int = 1, *,
              max_steps: int = DEFAULT_MAX_SWEEP_STEPS, record: bool = False,
              progress: Callable[[int], None] | None = None) -> Chunk:
    """Run chunk `index` (1-based) of `count` of a sweep.

    scene: a scene file or a Scene; vary: `KEY=V1,V2,...` texts or Vary. The arguments are plain
    data, so Dask or Ray can ship the call to another worker or machine. progress: called with
    the number of runs done, as blocks of runs finish.
    """
    base = scene if isinstance(scene, Scene) else load_scene(scene)
    varies = [v if isinstance(v, Vary) else parse_vary(v) for v in vary]
    _check_distinct(varies)
    start, stop = chunk_range(combination_count(varies), index, count)
    check_values(base, varies)  # each value once, then the counts: nothing of the product is built yet
    check_step_count(sweep_steps(base, varies, start, stop), stop - start, max_steps=max_steps, plot=record)
    grip = bool(base.objects)
    rows: list[dict[str, Any]] = []
    paths: list[np.ndarray] = []
    kept: list[Scene] = []
    for lo in range(start, stop, BLOCK):
        scenes = scene_block(base, varies, lo, min(lo + BLOCK, stop))  # built as the batch needs them
        result = run_batch(scenes, record=record)
        rows += rows_of(varies, lo, result, grip)
        paths += result.trajectories or []
        kept += scenes if record else []
        if progress is not None:
            progress(len(result.methods))
    return Chunk(columns(varies, base), rows, kept, paths)


def _check_distinct(varies: Sequence[Vary]) -> None:
    keys = [v.key for v in varies]
    for key in keys:
        if keys.count(key) > 1:
            raise ConfigError(f"--vary {key}", "each key varied once", f"{keys.count(key)} times")


def write_rows(path: Path, header: Sequence[str], rows: Sequence[dict[str, Any]]) -> None:
    """The rows as CSV (floats with 17 significant digits, as `simulate`'s CSV), written atomically."""
    with atomic_path(path) as part, part.open("w", newline="", encoding="utf-8") as f:
        writer = csv.writer(f)
        writer.writerow(header)
        for row in rows:
            writer.writerow([f"{row[c]:.17g}" if isinstance(row[c], float) else row[c] for c in header])


def plot_tips(scenes: Sequence[Scene], paths: Sequence, labels: Sequence[str], path: Path, title: str) -> None:
    """The fingertip trajectories of the runs overlaid (like the paper's Fig. 4), m → mm."""
    from finger_sim import kinematics
    from finger_sim.plots import plt

    from matplotlib.collections import LineCollection

    fig, ax = plt.subplots(figsize=(7, 6))
    lines = []
    for scene, q in zip(scenes, paths):
        alpha = kinematics.distal_offset(scene.params)
        tips = [kinematics.fingertip(scene.params, tuple(x), alpha) for x in q.tolist()]
        lines.append([(1e3 * t.x, 1e3 * t.y) for t in tips])
    collection = LineCollection(lines, cmap="viridis", linewidths=1.0, alpha=max(0.15, min(1.0, 20 / max(1, len(lines)))))
    collection.set_array(list(range(len(lines))))
    ax.add_collection(collection)
    ax.autoscale()
    ax.set_aspect("equal")
    ax.set_xlabel("X (mm)")
    ax.set_ylabel("Y (mm)")
    ax.set_title(title, fontsize=9)
    ax.grid(True, alpha=0.3)
    ends = [line[-1] for line in lines]
    ax.scatter([e[0] for e in ends], [e[1] for e in ends], c=list(range(len(ends))), cmap="viridis", s=12, zorder=3,
               label="end of each run")
    if labels:
        ax.legend(loc="lower left", fontsize=7, title=f"first: {labels[0]}\nlast: {labels[-1]}", title_fontsize=7)
    fig.colorbar(collection, ax=ax, label="run (combination order)")
    fig.tight_layout()
    with atomic_path(path) as part:
        fig.savefig(part, dpi=120)
    plt.close(fig)


def sweep(scene: Path, vary: Sequence[str], out: Path, *, plot: Path | None = None, chunk: str = "1/1",
          max_steps: int = DEFAULT_MAX_SWEEP_STEPS, dask: str | None = None, parquet: Path | None = None) -> str:
    """The `finger-sim sweep` command: run a chunk, write its CSV (and plot); a one-line summary.
    A progress bar (tqdm) is drawn on stderr when it is a terminal. dask: a scheduler address,
    the whole sweep's chunks run there (`finger_sim.cluster`); parquet: the rows as Parquet too."""
    index, count = parse_chunk(chunk)
    varies = [parse_vary(v) for v in vary]
    start, stop = chunk_range(combination_count(varies), index, count)
    if dask is not None:
        return _sweep_on_dask(scene, vary, out, dask, chunk=chunk, plot=plot, max_steps=max_steps, parquet=parquet)
    bar = Progress(stop - start)  # a bar on a terminal, a line per quarter otherwise
    try:
        result = run_chunk(scene, varies, index, count, max_steps=max_steps, record=plot is not None,
                           progress=bar.update)
    finally:
        bar.close()
    write_rows(out, result.header, result.rows)
    if parquet is not None:
        from finger_sim.parquet_rows import write_parquet

        write_parquet(parquet, result.header, result.rows)
    if plot is not None:
        labels = [", ".join(f"{v.key}={r[v.key]}" for v in varies) for r in result.rows]
        plot_tips(result.scenes, result.trajectories, labels, plot,
                  f"{Path(scene).name}: fingertip paths of {len(result.rows)} runs ({', '.join(v.key for v in varies)})")
    part = f" (chunk {index}/{count}: runs {start + 1}..{stop} of {combination_count(varies)})" if count > 1 else ""
    return f"{len(result.rows)} runs{part}; wrote {out}" + (f" and {plot}" if plot is not None else "")


def _sweep_on_dask(scene: Path, vary: Sequence[str], out: Path, address: str, *, chunk: str, plot: Path | None,
                   max_steps: int, parquet: Path | None) -> str:
    """`finger-sim sweep … --dask ADDRESS`: every chunk on the cluster, the rows to CSV (and Parquet)."""
    from finger_sim.cluster import sweep_on_dask
    from finger_sim.parquet_rows import write_parquet

    if chunk != "1/1":
        raise ConfigError("--chunk", "1/1 with --dask (the cluster runs every chunk)", chunk)
    if plot is not None:
        raise ConfigError("--plot", "no --plot with --dask (a plot holds every run's angles in this process)", str(plot))
    result = sweep_on_dask(scene, vary, address, max_steps=max_steps)
    write_rows(out, result.header, result.rows)
    if parquet is not None:
        write_parquet(parquet, result.header, result.rows)
    return f"{len(result.rows)} runs on the Dask cluster at {address}; wrote {out}" + (f" and {parquet}" if parquet else "")
