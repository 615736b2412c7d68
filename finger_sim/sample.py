"""`finger-sim sample`: Monte Carlo over toleranced scene values, with Sobol sensitivity indices.

    finger-sim sample config/paper_flexion.yaml --dist model.geometry.r1=normal(0.046,0.00005) \
        --dist model.geometry.L3=normal(0.0425,0.00005) -n 256 --seed 1 [--at 0.2] [--out runs.csv] \
        [--parquet runs.parquet] [--plot envelope.png]

Each `--dist KEY=normal(mean,sd)` or `KEY=uniform(low,high)` names a dotted scene key (as
`sweep --vary` takes it) and its distribution (SI units). The parameter sets are SALib's
Saltelli design for Sobol indices (a scrambled Sobol sequence, seeded, so a seed gives the
same draws everywhere): n·(D + 2) runs for D keys, n a power of two. They run on
`finger_sim.rollout` in chunks of CHUNK rows (the compiled loop on every core), and each run
is reduced to a few outputs, so memory stays flat whatever n:

- theta1, theta2, theta3 at time `at` (default: the scene's end), rad;
- tip_x, tip_y at `at`, m; tip_deviation, the largest distance of the fingertip from the
  nominal scene's fingertip at the same time over the whole run, m (the path envelope's width);
- grip_force at `at`, N, on a scene with contact.

The report gives each output's mean, standard deviation and 1 %/99 % quantiles, and its first-
order and total Sobol indices per key (SALib's `sobol.analyze`, 95 % confidence half-widths).
The envelope plot shows the nominal fingertip path and the band the sampled paths fill.
"""

from __future__ import annotations

import math
import re
import textwrap
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from finger_sim import kinematics
from finger_sim.errors import ConfigError
from finger_sim.rollouts import rollout
from finger_sim.scene import Scene, load_scene

#: Runs per rollout call: the compiled loop's grain; memory is CHUNK × steps × 48 B.
CHUNK = 1024
#: Most runs one `sample` may take (n·(D + 2)) unless split across seeds.
MAX_RUNS = 2**20
#: The quantiles the report gives of each output.
QUANTILES = (0.01, 0.99)
#: Fingertip paths drawn in the envelope plot (a random subset of the runs).
PLOTTED_PATHS = 200
#: The plotted paths' deviation from the nominal path is drawn this many times larger (tolerances
#: of a tenth of a millimetre would not show on a path of centimetres).
MAGNIFY = 20.0
#: Characters per line of the envelope plot's title.
TITLE_WIDTH = 150
_DIST = re.compile(r"^\s*([A-Za-z0-9_.]+)\s*=\s*(normal|uniform)\s*\(\s*([^,()]+)\s*,\s*([^,()]+)\s*\)\s*$")
#: SALib's names of the distributions; its "norm" bounds are (mean, sd), "unif" (low, high).
SALIB_DISTS = {"normal": "norm", "uniform": "unif"}


@dataclass(frozen=True)
class Dist:
    """One `--dist`: a dotted scene key, its distribution and its two parameters (SI)."""

    key: str
    kind: str  # "normal" (mean, sd) or "uniform" (low, high)
    a: float
    b: float


def parse_dist(text: str) -> Dist:
    """`KEY=normal(mean,sd)` or `KEY=uniform(low,high)`; ConfigError naming --dist and the problem."""
    match = _DIST.match(text)
    if match is None:
        raise ConfigError("--dist", "KEY=normal(mean,sd) or KEY=uniform(low,high)", text)
    key, kind, a_text, b_text = match.groups()
    try:
        a, b = float(a_text), float(b_text)
    except ValueError:
        raise ConfigError(f"--dist {key}", "two numbers in the parentheses", text) from None
    if not (math.isfinite(a) and math.isfinite(b)):
        raise ConfigError(f"--dist {key}", "finite numbers", text)
    if kind == "normal" and not b > 0.0:
        raise ConfigError(f"--dist {key}", "a standard deviation > 0", b)
    if kind == "uniform" and not b > a:
        raise ConfigError(f"--dist {key}", "low < high", f"({a}, {b})")
    return Dist(key, kind, a, b)


@dataclass(frozen=True)
class SampleResult:
    """Every run's drawn values and outputs, and the Sobol indices of each output per key."""

    keys: list[str]
    draws: np.ndarray  # (runs, D), SI
    outputs: dict[str, np.ndarray]  # name → (runs,)
    sobol: dict[str, dict[str, np.ndarray]]  # output → {"S1", "S1_conf", "ST", "ST_conf"} each (D,)
    at: float  # s
    t: np.ndarray  # (steps + 1,) s
    nominal_tip: np.ndarray  # (steps + 1, 2) m
    deviation_max: np.ndarray  # (steps + 1,) m: the largest fingertip distance from the nominal one over the runs
    deviation_rms: np.ndarray  # (steps + 1,) m: its root mean square over the runs
    tip_paths: np.ndarray  # (≤ PLOTTED_PATHS, steps + 1, 2) m

    @property
    def header(self) -> list[str]:
        return [*self.keys, *self.outputs]

    def rows(self) -> list[dict[str, Any]]:
        cols = [*self.draws.T, *self.outputs.values()]
        return [dict(zip(self.header, map(float, values))) for values in zip(*cols)]


def problem(dists: Sequence[Dist]) -> dict[str, Any]:
    """SALib's problem description of the distributions."""
    return {"num_vars": len(dists), "names": [d.key for d in dists], "bounds": [[d.a, d.b] for d in dists],
            "dists": [SALIB_DISTS[d.kind] for d in dists]}


def draw(dists: Sequence[Dist], n: int, seed: int) -> np.ndarray:
    """The Saltelli design, (n·(D + 2), D): SALib's scrambled Sobol sequence under `seed`."""
    from SALib.sample import sobol as sobol_sample

    if n < 2 or n & (n - 1):
        raise ConfigError("-n", "a power of two ≥ 2 (the Sobol sequence's balance)", n)
    if n * (len(dists) + 2) > MAX_RUNS:
        raise ConfigError("-n", f"at most {MAX_RUNS:,} runs in all (n·(D + 2), D = {len(dists)})", n)
    return sobol_sample.sample(problem(dists), n, calc_second_order=False, seed=seed)


def _tips(scene: Scene, q: np.ndarray) -> np.ndarray:
    """Fingertip (x, y), m, of states q (..., 3): `kinematics.fingertip`, over arrays."""
    p, alpha = scene.params, kinematics.distal_offset(scene.params)
    psi = q[..., 2] + alpha
    return np.stack([p.r1 * np.cos(q[..., 0]) + p.L3 * np.cos(psi), p.r1 * np.sin(q[..., 0]) + p.L3 * np.sin(psi)], -1)


def run_sample(scene: str | Path | Scene, dists: Sequence[str | Dist], n: int, seed: int, *,
               at: float | None = None) -> SampleResult:
    """Draw, run on `rollout` in chunks, reduce, and analyse; see the module docstring."""
    from SALib.analyze import sobol as sobol_analyze

    base = scene if isinstance(scene, Scene) else load_scene(scene)
    parsed = [d if isinstance(d, Dist) else parse_dist(d) for d in dists]
    if not parsed:
        raise ConfigError("--dist", "at least one KEY=normal(mean,sd) or KEY=uniform(low,high)", "none")
    keys = [d.key for d in parsed]
    if len(set(keys)) != len(keys):
        raise ConfigError("--dist", "each key once", keys)
    t_at = base.step_count * base.dt if at is None else at
    index = round(t_at / base.dt)
    if not (0 <= index <= base.step_count and math.isclose(index * base.dt, t_at, rel_tol=0, abs_tol=1e-9 * base.dt)):
        raise ConfigError("--at", f"a time on the step grid k·{base.dt:g} s within [0, {base.step_count * base.dt:g}] s", at)
    draws = draw(parsed, n, seed)
    nominal = rollout(base)
    nominal_tip = _tips(base, nominal.q[0])
    names = ["theta1", "theta2", "theta3", "tip_x", "tip_y", "tip_deviation", *nominal.outputs]
    outputs = {name: np.empty(len(draws)) for name in names}
    dev_max, dev_sq = np.zeros(len(nominal_tip)), np.zeros(len(nominal_tip))
    rng = np.random.default_rng(seed)
    shown = set(rng.choice(len(draws), min(PLOTTED_PATHS, len(draws)), replace=False).tolist())
    paths = []
    for lo in range(0, len(draws), CHUNK):
        block = draws[lo: lo + CHUNK]
        res = rollout(base, params={k: block[:, j] for j, k in enumerate(keys)}, nstep=base.step_count)
        for r in range(len(block)):
            tip = _tips(res.scenes[r], res.q[r])
            i = lo + r
            outputs["theta1"][i], outputs["theta2"][i], outputs["theta3"][i] = res.q[r, index]
            outputs["tip_x"][i], outputs["tip_y"][i] = tip[index]
            distance = np.hypot(*(tip - nominal_tip).T)
            outputs["tip_deviation"][i] = float(distance.max())
            np.maximum(dev_max, distance, out=dev_max)
            dev_sq += distance**2
            if i in shown:
                paths.append(tip)
        for name, values in res.outputs.items():
            outputs[name][lo: lo + len(block)] = values[:, index]
    sobol = {}
    for name, y in outputs.items():
        if np.ptp(y) == 0.0:  # no spread: every index is zero (SALib would divide by zero)
            zeros = np.zeros(len(keys))
            sobol[name] = {"S1": zeros, "S1_conf": zeros, "ST": zeros, "ST_conf": zeros}
            continue
        s = sobol_analyze.analyze(problem(parsed), y, calc_second_order=False, seed=seed)
        sobol[name] = {k: np.asarray(s[k]) for k in ("S1", "S1_conf", "ST", "ST_conf")}
    return SampleResult(keys, draws, outputs, sobol, t_at, nominal.t, nominal_tip, dev_max,
                        np.sqrt(dev_sq / len(draws)), np.array(paths))


def report(result: SampleResult, scene_name: str, n: int, seed: int) -> str:
    """The spread and Sobol indices of every output, as Markdown tables."""
    lines = [f"{scene_name}: {len(result.draws)} runs (n = {n}, seed {seed}), outputs at t = {result.at:g} s", "",
             "| output | mean | sd | q01 | q99 |", "|---|---:|---:|---:|---:|"]
    for name, y in result.outputs.items():
        q_lo, q_hi = np.quantile(y, QUANTILES)
        lines.append(f"| {name} | {y.mean():.6g} | {y.std(ddof=1):.3g} | {q_lo:.6g} | {q_hi:.6g} |")
    lines += ["", "Sobol indices, first order S1 and total ST (± 95 % confidence):", "",
              "| output | " + " | ".join(f"{k} S1 | {k} ST" for k in result.keys) + " |",
              "|---|" + "---:|---:|" * len(result.keys)]
    for name, s in result.sobol.items():
        cells = [f"{s['S1'][j]:.3f} ± {s['S1_conf'][j]:.3f} | {s['ST'][j]:.3f} ± {s['ST_conf'][j]:.3f}"
                 for j in range(len(result.keys))]
        lines.append(f"| {name} | " + " | ".join(cells) + " |")
    return "\n".join(lines)


def plot_envelope(result: SampleResult, path: Path, title: str) -> None:
    """The fingertip-path envelope: the sampled paths around the nominal one with their deviation
    magnified MAGNIFY×; the distance from the nominal fingertip against time (largest and RMS over
    the runs); and the histogram of each run's largest distance. mm."""
    from finger_sim.plots import plt

    fig, (ax, ax_t, ax_h) = plt.subplots(1, 3, figsize=(14, 4.8))
    nominal = 1e3 * result.nominal_tip
    for tip in result.tip_paths:
        shown = nominal + MAGNIFY * (1e3 * tip - nominal)
        ax.plot(shown[:, 0], shown[:, 1], color="tab:blue", alpha=0.1, lw=0.8)
    ax.plot(nominal[:, 0], nominal[:, 1], color="k", lw=1.2, label="nominal")
    ax.plot([], [], color="tab:blue", label=f"{len(result.tip_paths)} sampled runs, deviation ×{MAGNIFY:g}")
    ax.set_aspect("equal")
    ax.set_xlabel("X (mm)")
    ax.set_ylabel("Y (mm)")
    ax.grid(True, alpha=0.3)
    ax.legend(fontsize=7, loc="lower left")
    ax.set_title("fingertip paths", fontsize=9)
    ax_t.plot(result.t, 1e3 * result.deviation_max, color="tab:red", label=f"largest of {len(result.draws)} runs")
    ax_t.plot(result.t, 1e3 * result.deviation_rms, color="tab:blue", label="RMS over the runs")
    ax_t.set_xlabel("t (s)")
    ax_t.set_ylabel("fingertip distance from nominal (mm)")
    ax_t.grid(True, alpha=0.3)
    ax_t.legend(fontsize=7)
    ax_t.set_title("envelope width against time", fontsize=9)
    ax_h.hist(1e3 * result.outputs["tip_deviation"], bins=40, color="tab:blue")
    ax_h.set_xlabel("each run's largest distance from the nominal path (mm)")
    ax_h.set_ylabel("runs")
    ax_h.grid(True, alpha=0.3)
    fig.suptitle("\n".join(textwrap.wrap(title, TITLE_WIDTH)), fontsize=9)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def sample(scene: Path, dists: Sequence[str], n: int, seed: int, *, at: float | None = None, out: Path | None = None,
           parquet: Path | None = None, plot: Path | None = None) -> str:
    """The `finger-sim sample` command: run, write what was asked, and return the report."""
    from finger_sim.sweep import write_rows

    result = run_sample(scene, dists, n, seed, at=at)
    if out is not None:
        write_rows(out, result.header, result.rows())
    if parquet is not None:
        from finger_sim.parquet_rows import write_parquet

        write_parquet(parquet, result.header, result.rows())
    if plot is not None:
        plot_envelope(result, plot, f"{Path(scene).name}: {len(result.draws)} runs (n = {n}, seed {seed}); "
                                    + "; ".join(dists))
    return report(result, Path(scene).name, n, seed)
