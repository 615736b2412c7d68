"""`finger-sim bench`: the work-precision report, with peers measured side by side in one run.

Everything runs in this one process, one configuration after another, so that the ratios
between methods are honest on a shared machine: the project's integrators over a grid of
dt, scipy's solve_ivp over rtol on the same index-1 equations (and the same scalar
right-hand side), MuJoCo's integrators over timestep on the MJCF peer. Each run is scored
against the scene's reference (`finger_sim.bench.reference`). The report, written to
`<out>/performance.md` with one work-precision figure per scene (`<out>/wp_<scene>.png`),
holds: the machine and the exact command, per-scene tables, the hard-case pass/fail
table, the recommendation table (and the literal `finger_sim.auto` uses), and the goals.
"""

from __future__ import annotations

import datetime as _dt
import math
import os
import platform
import sys
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from tqdm import tqdm

import finger_sim
from finger_sim import auto
from finger_sim.bench import analysis as an
from finger_sim.bench.reference import Reference, build_reference
from finger_sim.bench.runners import (
    FAMILY_MUJOCO,
    FAMILY_PROJECT,
    FAMILY_SCIPY,
    LONG_RUN_SECONDS,
    MAX_SCIPY_EVALUATIONS,
    Run,
    mujoco_available,
    run_method,
    run_mujoco_peer,
    run_scipy,
)
from finger_sim.integrators import METHODS
from finger_sim.scene import Scene, load_scene

#: Scenes with a work-precision figure (peers included), then the scenes measured for the
#: recommendation and hard cases only.
WP_SCENES = ("paper_flexion", "toggle_passage", "free_swing", "bang_bang", "stiff_spring")
ALL_SCENES = WP_SCENES + ("paper_to_stop",)
#: Errors are measured on this grid (s), or on a method's own coarser step grid.
SPACING = 1e-3
#: Timing repeats (median); runs longer than LONG_RUN_SECONDS are timed once.
REPEATS = 3

_COARSE = (1e-1, 5e-2, 2e-2)
_DECADES = (1e-2, 5e-3, 2e-3, 1e-3, 5e-4, 2e-4, 1e-4)
_FINE = (5e-5, 2e-5, 1e-5)
#: dt grid per project method (full run). Each dt divides every scene's duration and is
#: a multiple or a divisor of SPACING. Cheap methods go down to 1e-5 s; the order-6 and
#: order-8 methods and the implicit ones stop at 1e-4 s, where they are at the reference
#: floor or their cost per run exceeds seconds; `adaptive` steps internally, its dt is only
#: the output rate.
FULL_DT: dict[str, tuple[float, ...]] = {
    "euler": _DECADES + _FINE,
    "rk4": _COARSE[1:] + _DECADES + _FINE,
    "rk6": _COARSE + _DECADES,
    "dop8": _COARSE + _DECADES,
    "rattle": _DECADES,
    "radau": _COARSE + _DECADES,
    "adaptive": (1e-2, 1e-3),
}
QUICK_DT = (1e-2, 1e-3)
FULL_RTOL = tuple(10.0**-k for k in range(3, 13))
QUICK_RTOL = (1e-4, 1e-8)
SCIPY_METHODS = ("RK45", "DOP853", "Radau", "LSODA")
#: The naive numpy right-hand side is shown on the paper's run only, with DOP853.
NUMPY_RHS_SCENE, NUMPY_RHS_METHOD = "paper_flexion", "DOP853"
FULL_TIMESTEPS = (1e-3, 1e-4, 1e-5)
QUICK_TIMESTEPS = (1e-3,)
MUJOCO_INTEGRATORS = ("Euler", "RK4", "implicitfast")
MUJOCO_SETTINGS = ("default", "tight")

#: Errors are floored here on log axes (an exact match would otherwise vanish).
_PLOT_FLOOR = 1e-16


def config_dir() -> Path:
    """The scenes folder: `config/` beside the package (a source checkout), else under the cwd."""
    for candidate in (Path(finger_sim.__file__).resolve().parent.parent / "config", Path.cwd() / "config"):
        if (candidate / "paper_flexion.yaml").is_file():
            return candidate
    raise FileNotFoundError("finger-sim bench: no config/ folder with the scenes beside the package or in the cwd")


@dataclass(frozen=True)
class Task:
    """One measurement: a label for the progress bar and the call that makes the Run."""

    label: str
    call: Callable[[], Run]


def project_methods() -> list[str]:
    """Every integrator `METHODS` has, in the report's order (the paper's Euler first)."""
    order = ["euler", "rk4", "rk6", "dop8", "rattle", "radau", "adaptive"]
    return [m for m in order if m in METHODS] + sorted(set(METHODS) - set(order))


def plan(scenes: dict[str, Scene], refs: dict[str, Reference], *, quick: bool) -> list[Task]:
    """The measurements, in the order they run."""
    tasks: list[Task] = []
    kw = {"spacing": SPACING, "repeats": REPEATS}
    for name, scene in scenes.items():
        ref = refs[name]
        for method in project_methods():
            grid = QUICK_DT if quick else FULL_DT.get(method, _DECADES)
            for dt in grid:
                tasks.append(Task(f"{name} {method} dt={dt:g}", lambda s=scene, m=method, d=dt, r=ref: run_method(s, m, d, r, **kw)))
        if name not in WP_SCENES:
            continue
        for method in SCIPY_METHODS:
            for rtol in QUICK_RTOL if quick else FULL_RTOL:
                tasks.append(Task(f"{name} scipy {method} rtol={rtol:g}", lambda s=scene, m=method, t=rtol, r=ref: run_scipy(s, m, t, r, **kw)))
        if name == NUMPY_RHS_SCENE:
            for rtol in QUICK_RTOL if quick else FULL_RTOL[1::2]:
                tasks.append(
                    Task(
                        f"{name} scipy {NUMPY_RHS_METHOD} numpy rtol={rtol:g}",
                        lambda s=scene, t=rtol, r=ref: run_scipy(s, NUMPY_RHS_METHOD, t, r, rhs="numpy", **kw),
                    )
                )
        for integrator in MUJOCO_INTEGRATORS:
            for setting in MUJOCO_SETTINGS:
                for ts in QUICK_TIMESTEPS if quick else FULL_TIMESTEPS:
                    tasks.append(
                        Task(
                            f"{name} MuJoCo {integrator} {setting} h={ts:g}",
                            lambda s=scene, i=integrator, g=setting, h=ts, r=ref: run_mujoco_peer(s, i, h, g, r, **kw),
                        )
                    )
    return tasks


def run_bench(*, quick: bool, out: Path, argv: list[str]) -> int:
    """Measure everything, write `<out>/performance.md` and the figures; 0 on success."""
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    started = _dt.datetime.now(_dt.timezone.utc)
    wall0, cpu0, load0 = time.perf_counter(), time.process_time(), os.getloadavg()
    folder = config_dir()
    scenes = {name: load_scene(folder / f"{name}.yaml") for name in ALL_SCENES}
    refs: dict[str, Reference] = {}
    for name in tqdm(ALL_SCENES, desc="references", file=sys.stderr, leave=False):
        refs[name] = build_reference(scenes[name], quick=quick, spacing=SPACING)
    tasks = plan(scenes, refs, quick=quick)
    runs: list[Run] = []
    with tqdm(total=len(tasks), desc="bench", file=sys.stderr, unit="run") as bar:
        for task in tasks:
            bar.set_postfix_str(task.label, refresh=False)
            runs.append(task.call())
            bar.update()
    meta = {
        "started": started,
        "wall": time.perf_counter() - wall0,
        "cpu": time.process_time() - cpu0,
        "load": (load0, os.getloadavg()),
        # the program by its name, not the venv path it was started from
        "command": " ".join([Path(argv[0]).name, *argv[1:]]) if argv else "finger-sim bench" + (" --quick" if quick else ""),
        "quick": quick,
    }
    figures = {name: write_figure(name, [r for r in runs if r.scene == name], refs[name], out) for name in ALL_SCENES}
    text = render(scenes, refs, runs, figures, meta)
    (out / "performance.md").write_text(text)
    print(f"wrote {out / 'performance.md'} and {len(figures)} figures in {meta['wall']:.0f} s", file=sys.stderr)
    return 0


# -- figures ---------------------------------------------------------------------------------


def write_figure(name: str, runs: Sequence[Run], ref: Reference, out: Path) -> str:
    """Error and loop violation against CPU time, log-log, every method and peer: wp_<scene>.png."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, (ax_err, ax_phi) = plt.subplots(1, 2, figsize=(13.5, 5.8), sharex=True)
    labels = sorted({r.method for r in runs}, key=lambda m: _row_order(next(r for r in runs if r.method == m)))
    handles = []
    for label in labels:
        rs = sorted((r for r in runs if r.method == label and r.ok), key=lambda r: r.cpu)
        if not rs:
            continue
        kw = _line_style(label, rs[0].family)
        cpu = [r.cpu for r in rs]
        (line,) = ax_err.plot(cpu, [max(r.error, _PLOT_FLOOR) for r in rs], label=label, **kw)
        ax_phi.plot(cpu, [max(r.max_phi, _PLOT_FLOOR) for r in rs], **kw)
        handles.append(line)
    for target in an.TARGETS:
        ax_err.axhline(target, color="grey", lw=0.7, alpha=0.6)
    floor = ax_err.axhspan(_PLOT_FLOOR, max(ref.check_difference, _PLOT_FLOOR), color="grey", alpha=0.15, label="reference floor")
    handles.append(floor)
    ax_err.set_ylabel("max |θ − θ_ref| (rad)")
    ax_phi.set_ylabel("max |Φ| (m): loop violation")
    for ax in (ax_err, ax_phi):
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.set_xlabel("CPU time of the run (s)")
        ax.grid(True, which="both", alpha=0.25)
    ax_err.set_title(f"{name}: error against CPU time (targets 1e-6, 1e-9 rad)")
    ax_phi.set_title(f"{name}: loop closure")
    fig.tight_layout(rect=(0.0, 0.0, 0.85, 1.0))
    fig.legend(handles=handles, loc="center left", bbox_to_anchor=(0.85, 0.5), fontsize=7.5, frameon=False)
    path = out / f"wp_{name}.png"
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path.name


#: Colours: the project's methods in strong colours, scipy's in a muted set, MuJoCo's by integrator.
_PROJECT_COLORS = ("#d62728", "#1f77b4", "#2ca02c", "#000000", "#9467bd", "#ff7f0e", "#8c564b", "#e377c2")
_SCIPY_COLORS = {"RK45": "#7f7f7f", "DOP853": "#17becf", "Radau": "#393b79", "LSODA": "#6baed6"}
_MUJOCO_COLORS = {"Euler": "#8c6d31", "RK4": "#e6550d", "implicitfast": "#bcbd22"}


def _line_style(label: str, family: str) -> dict:
    if family == FAMILY_PROJECT:
        methods = project_methods()
        color = _PROJECT_COLORS[methods.index(label) % len(_PROJECT_COLORS)] if label in methods else "k"
        return {"color": color, "linestyle": "-", "marker": "o", "ms": 4, "lw": 1.6}
    if family == FAMILY_SCIPY:
        key = label.split()[1]
        numpy = "numpy" in label
        return {"color": _SCIPY_COLORS.get(key, "grey"), "linestyle": ":" if numpy else "--", "marker": "s", "ms": 3.5, "lw": 1.2}
    _, integrator, setting = label.split()
    return {"color": _MUJOCO_COLORS.get(integrator, "grey"), "linestyle": ":" if setting == "tight" else "-.", "marker": "^" if setting == "tight" else "v", "ms": 4, "lw": 1.2}


# -- markdown ---------------------------------------------------------------------------------


def _g(x: float, digits: int = 2) -> str:
    """A number for a table: 3 significant digits in e-notation, '—' for NaN."""
    if x is None or (isinstance(x, float) and math.isnan(x)):
        return "—"
    if math.isinf(x):
        return "∞"
    return f"{x:.{digits}e}"


def _f(x: float, fmt: str) -> str:
    return "—" if x is None or not math.isfinite(x) else format(x, fmt)


def _machine() -> list[str]:
    cpu = platform.processor() or "?"
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                cpu = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    import matplotlib
    import scipy

    versions = [f"finger_sim {finger_sim.__version__}", f"Python {platform.python_version()}", f"numpy {np.__version__}", f"scipy {scipy.__version__}"]
    try:
        import mujoco

        versions.append(f"mujoco {mujoco.__version__}")
    except ImportError:
        versions.append("mujoco not installed")
    versions.append(f"matplotlib {matplotlib.__version__}")
    return [f"- CPU: {cpu}, {os.cpu_count()} logical cores (shared with other work)", f"- OS: {platform.platform()}", f"- {', '.join(versions)}"]


def render(scenes: dict[str, Scene], refs: dict[str, Reference], runs: list[Run], figures: dict[str, str], meta: dict) -> str:
    """The whole performance.md."""
    quick = meta["quick"]
    lines: list[str] = []
    add = lines.append
    (l0, l1) = meta["load"]
    add("# Performance: speed against error")
    add("")
    add("Generated by `finger-sim bench`" + (" --quick (reduced grids)" if quick else "") + "; do not edit by hand.")
    add("")
    add(f"- Command: `{meta['command']}`")
    add(f"- Date: {meta['started']:%Y-%m-%d %H:%M} UTC; the bench took {meta['wall']:.0f} s wall, {meta['cpu']:.0f} s CPU")
    lines.extend(_machine())
    add(f"- Load average (1, 5, 15 min) at start {l0[0]:.2f}, {l0[1]:.2f}, {l0[2]:.2f}; at end {l1[0]:.2f}, {l1[1]:.2f}, {l1[2]:.2f}")
    add("")
    add("## How it is measured")
    add("")
    add(
        f"- **Error**: max over the run of |θ − θ_ref| on the three angles (rad), sampled every {SPACING * 1e3:g} ms "
        "(at every step for dt > 1 ms: such a run is judged only where it gives output, so a very coarse run on a "
        "scene with a fast transient can look better than a finer one). θ_ref: scipy DOP853 (the scheme of the `adaptive` method) at its tightest "
        "tolerance on the index-1 equations, restarted at every torque switch and joint-stop impact, checked against "
        "a second, independent solution (Radau IIA; LSODA on the stiff scene). Their difference, the *reference floor*, "
        "is listed per scene: errors near it are the reference's, not the method's."
    )
    add(
        f"- **CPU time**: `time.process_time` of the stepping loop alone (no setup, no model compile), median of "
        f"{REPEATS} repeats; a run whose first repeat takes over {LONG_RUN_SECONDS:g} s is timed once. "
        "µs/step = CPU / steps; real-time factor (RTF) = simulated s / CPU s."
    )
    add(
        "- **The project's methods** step through `finger_sim.simulate.Simulator`, the node's path (time grid, torque "
        "switches, stops, checks included). `euler` is the paper's method, equations (6)-(7)."
    )
    add(
        "- **scipy** `solve_ivp` gets the *same* index-1 equations and the *same* fast scalar right-hand side "
        "(`FingerSystem.accelerations`): integrator against integrator. atol = 1e-2·rtol, output on the 1 ms grid via "
        "`t_eval` (what a script would ask for), restarted at each torque switch like the others. Its CPU includes "
        f"an evaluation counter (under 2 % of an evaluation) that gives a run up after {MAX_SCIPY_EVALUATIONS:,} "
        "evaluations. `scipy DOP853 (numpy RHS)` on the paper's run is the right-hand side a user would write first "
        "(numpy arrays, a 5×5 `np.linalg.solve`). µs/step for scipy is per accepted step."
    )
    add(
        "- **MuJoCo**: the MJCF peer (`finger_sim.bench.mujoco_peer`): the four-bar as a tree plus a soft `connect` "
        "closing the loop. *default*: MuJoCo's default solref/solimp; *tight*: the stiffest loop that stays stable "
        "(`tight_equality`: timeconst 2·timestep, impedance 0.9999). The torque is held over each step. Its |Φ| column "
        "is the loop violation |C_coupler − C_distal| in m."
    )
    available, note = mujoco_available()
    if not available:
        add(f"- **{note}**")
    add("")

    # -- goals first: the headline
    add("## Goals")
    add("")
    lines.extend(render_goals(scenes, refs, runs))
    add("")

    # -- recommendation
    add("## Recommendation: the cheapest method that reaches a target error")
    add("")
    lines.extend(render_recommendation(runs, quick))
    add("")

    # -- hard cases
    add(f"## Hard cases at dt = {an.HARD_DT * 1e3:g} ms")
    add("")
    lines.extend(render_hard_cases(scenes, runs))
    add("")

    # -- per scene
    add("## Work-precision per scene")
    add("")
    for name in ALL_SCENES:
        scene = scenes[name]
        ref = refs[name]
        add(f"### {name}")
        add("")
        add(f"{scene.description} — {scene.duration:g} s simulated.")
        sol, chk = ref.solution, ref.check
        add(
            f"Reference: {sol.method} rtol {sol.rtol:g} ({sol.nfev} evaluations, {sol.cpu_time:.2f} s); check: "
            f"{chk.method} rtol {chk.rtol:g}; reference floor {ref.check_difference:.1e} rad."
        )
        add("")
        add(f"![{name}]({figures[name]})")
        add("")
        add("| family | method | knob | status | error (rad) | max \\|Φ\\| (m) | energy drift | µs/step | CPU (ms) | RTF | note |")
        add("|---|---|---|---|---|---|---|---|---|---|---|")
        for r in sorted((r for r in runs if r.scene == name), key=_row_order):
            add(
                f"| {r.family} | {r.method} | {r.knob} {r.value:g} | {r.status} | {_g(r.error)} | {_g(r.max_phi)} | "
                f"{_g(r.energy_drift)} | {_f(r.us_per_step, '.1f')} | {_f(r.cpu * 1e3, '.3g')} | "
                f"{_f(r.realtime_factor, '.3g')} | {_note(r, ref)} |"
            )
        add("")
    return "\n".join(lines) + "\n"


def _note(r: Run, ref: Reference) -> str:
    """A row's note for a table cell (pipes escaped), flagging a peer run identical to the reference."""
    note = r.note
    if r.family == FAMILY_SCIPY and r.method == f"scipy {ref.solution.method}" and math.isclose(r.value, ref.solution.rtol):
        note = "the reference's own solver and tolerance: error 0 by construction"
    return note[:170].replace("|", "\\|")


def _row_order(r: Run) -> tuple:
    fam = [FAMILY_PROJECT, FAMILY_SCIPY, FAMILY_MUJOCO].index(r.family)
    methods = project_methods()
    rank = methods.index(r.method) if r.method in methods else 99
    return (fam, rank, r.method, -r.value)


def render_goals(scenes: dict[str, Scene], refs: dict[str, Reference], runs: list[Run]) -> list[str]:
    out: list[str] = []
    add = out.append
    # goal 1
    scene = scenes["paper_flexion"].with_overrides(method="auto", dt=an.REALTIME_DT)
    method, reason = auto.choose_method(scene)
    run = next((r for r in runs if r.scene == "paper_flexion" and r.method == method and math.isclose(r.value, an.REALTIME_DT)), None)
    if run is None or not run.ok:
        add(f"1. **Default real-time method** (`auto` on paper_flexion at 1 ms → {method}): not measured.")
    else:
        met = run.error <= an.REALTIME_ERROR and run.us_per_step <= an.REALTIME_US_PER_STEP
        add(
            f"1. **Default real-time method: {'met' if met else 'NOT met'}.** `auto` picks **{method}** for paper_flexion at "
            f"dt = 1 ms: error {run.error:.1e} rad (goal ≤ {an.REALTIME_ERROR:g}) at {run.us_per_step:.1f} µs/step "
            f"(goal ≤ {an.REALTIME_US_PER_STEP:g}), real-time factor {run.realtime_factor:.0f}. Why: {reason}."
        )
    # goal 2: scipy
    smooth = an.KINDS["smooth"]
    add(
        f"2. **Against scipy** — CPU time to reach {an.SCIPY_TARGET:g} rad, log-log interpolated on each method's "
        f"work-precision front; goal: the project's best ≥ {an.SCIPY_ADVANTAGE:g}× cheaper than scipy's best. "
        "*Any step*: every project run counts, a large-step run scored at its own steps (few outputs); "
        "*1 ms output*: only project runs with dt ≤ 1 ms, i.e. with output as dense as scipy's `t_eval` on the 1 ms grid "
        "(scipy's dense output decouples its steps from its output; a fixed-rate method's output is its steps)."
    )
    add("")
    add("   | scene | scipy's best | CPU (ms) | project, any step | CPU (ms) | ratio | goal | project, 1 ms output | CPU (ms) | ratio |")
    add("   |---|---|---|---|---|---|---|---|---|---|")
    for name in smooth:
        c = an.compare_scipy(runs, name)
        d = an.compare_scipy(runs, name, max_dt=SPACING)
        ok = c.ratio >= an.SCIPY_ADVANTAGE
        add(
            f"   | {name} | {c.scipy_method} | {_f(c.scipy * 1e3, '.3g')} | {c.ours_method} | {_f(c.ours * 1e3, '.3g')} | "
            f"{_f(c.ratio, '.2g')}× | {'met' if ok else 'NOT met'} | {d.ours_method} | {_f(d.ours * 1e3, '.3g')} | "
            f"{_f(d.ratio, '.2g')}× |".replace("—×", "—")
        )
    naive = an.compare_scipy(runs, NUMPY_RHS_SCENE, numpy_rhs=True)
    add("")
    add(
        f"   Against the naive numpy right-hand side (scipy {NUMPY_RHS_METHOD} on {NUMPY_RHS_SCENE}): "
        f"{_f(naive.scipy * 1e3, '.3g')} ms to {an.SCIPY_TARGET:g} rad, {_f(naive.ratio, '.2g')}× the project's best."
    )
    add("")
    add(
        f"3. **Against MuJoCo with its tightest stable loop** — every successful *tight* run against the project's "
        f"error at the same CPU time, log-log interpolated on the project's work-precision front (every run; one with "
        f"dt > 1 ms gives output less often than MuJoCo's 1 ms samples); goal: ≥ {an.MUJOCO_ADVANTAGE:g}× more "
        "accurate. Where the project's error is within 10× the reference floor the ratio is only a lower bound "
        f"(*floor*). *Same rate*: the project's cheapest method at dt = MuJoCo's timestep that is "
        f"≥ {an.MUJOCO_ADVANTAGE:g}× more accurate, and its CPU time over MuJoCo's."
    )
    add("")
    if not mujoco_available()[0]:
        add(f"   Skipped: {mujoco_available()[1]}")
    else:
        add("   | scene | MuJoCo run | its error (rad) | its CPU (ms) | project at that CPU (rad) | ratio | goal | same rate: method, error, CPU × MuJoCo's |")
        add("   |---|---|---|---|---|---|---|---|")
        for name in smooth:
            comps = an.compare_mujoco(runs, name, refs[name].check_difference)
            if not comps:
                add(f"   | {name} | no tight MuJoCo run succeeded | | | | | | |")
            for c in comps:
                if math.isnan(c.ratio):
                    verdict = "n/a"
                elif c.ratio >= an.MUJOCO_ADVANTAGE:
                    verdict = "met"
                else:
                    verdict = "floor" if c.at_floor else "NOT met"
                same = c.same_rate
                same_text = f"{same.method}, {same.error:.1e} rad, {same.cpu / c.mujoco_cpu:.2g}×" if same else "none"
                ratio = f"{c.ratio:.3g}×" if math.isfinite(c.ratio) else "—"
                add(
                    f"   | {name} | {c.label} | {c.mujoco_error:.1e} | {c.mujoco_cpu * 1e3:.3g} | {_g(c.ours_error, 1)} | "
                    f"{ratio} | {verdict} | {same_text} |"
                )
    add("")
    # goal 4: hard cases
    verdicts = []
    for name in an.HARD_SCENES:
        passing = [h.method for h in _hard_results(runs, name) if h.status == "pass"]
        pick, _ = auto.choose_method(scenes[name].with_overrides(method="auto", dt=an.HARD_DT))
        verdicts.append((name, passing, pick, pick in passing))
    all_ok = all(p and ok for _, p, _, ok in verdicts)
    add(
        f"4. **Hard cases: {'met' if all_ok else 'NOT met'}.** At dt = 1 ms: "
        + "; ".join(f"{n}: {len(p)} passing, auto → {pick} ({'passes' if ok else 'FAILS'})" for n, p, pick, ok in verdicts)
        + "."
    )
    return out


def _hard_results(runs: list[Run], scene: str) -> list[an.HardResult]:
    results = []
    for method in project_methods():
        run = next((r for r in runs if r.scene == scene and r.method == method and math.isclose(r.value, an.HARD_DT)), None)
        if run is not None:
            results.append(an.hard_case(run, METHODS[method].keeps_constraints, stiff=scene in an.KINDS["stiff"]))
    return results


def render_hard_cases(scenes: dict[str, Scene], runs: list[Run]) -> list[str]:
    out = [
        f"Criteria: no NaN; |Φ| ≤ {an.HARD_PHI:g} m for the methods that keep the constraints (the paper's Euler does "
        f"not: shown, not judged); relative energy drift ≤ {an.HARD_ENERGY:g} where energy is conserved (free_swing); "
        f"max |θ − θ_ref| ≤ {an.HARD_MATCH:g} rad; penetration past the MCP stop ≤ {an.HARD_PENETRATION:g} rad "
        f"(paper_to_stop). On the stiff scene no 1 ms step resolves the fast mode (period 0.6 ms): an L-stable method "
        f"damps it, so the transient's error is shown, not judged, and the run must settle where the reference does, "
        f"|θ − θ_ref| ≤ {an.HARD_SETTLED:g} rad at the end. An explicit method the stability check refuses "
        "(StabilityError) is *refused*, not a crash.",
        "",
        "| scene | auto picks | " + " | ".join(project_methods()) + " |",
        "|---|---|" + "---|" * len(project_methods()),
    ]
    for name in an.HARD_SCENES:
        results = {h.method: h for h in _hard_results(runs, name)}
        pick, _ = auto.choose_method(scenes[name].with_overrides(method="auto", dt=an.HARD_DT))
        cells = []
        for m in project_methods():
            h = results.get(m)
            if h is None:
                cells.append("—")
                continue
            mark = {"pass": "**pass**", "fail": "FAIL", "refused": "refused", "diverged": "DIVERGED", "gave up": "gave up"}[h.status]
            detail = "; ".join(
                f"{label} {text}" + ("" if ok is not False else " ✗") for label, ok, text in h.checks if label != "no NaN"
            )
            detail = detail.replace("|", "\\|")
            cells.append(f"{mark}<br>{detail}" if h.status in ("pass", "fail") else mark)
        out.append(f"| {name} | {pick} | " + " | ".join(cells) + " |")
    return out


def render_recommendation(runs: list[Run], quick: bool) -> list[str]:
    table = an.recommendation(runs)
    out = [
        "For each scene kind and step rate: the cheapest of the project's methods (mean µs/step over the kind's scenes) "
        "whose worst error over those scenes is within the target, measured in this run at dt = 1/rate "
        f"({', '.join(an.NOT_RECOMMENDED)} left out: scipy restarted every step, the reference's scheme, not a "
        "fixed-rate method). "
        "Kinds: " + "; ".join(f"*{k}*: {', '.join(v)}" for k, v in an.KINDS.items()) + ".",
        "",
        "| kind | rate | ≤ 1e-6 rad | ≤ 1e-9 rad | most accurate | auto picks |",
        "|---|---|---|---|---|---|",
    ]
    for kind in an.KINDS:
        for rate in an.RATES:
            cands = an.candidates(runs, kind, rate)
            if not cands:
                out.append(f"| {kind} | {rate:g} Hz | not measured{' (--quick)' if quick else ''} | | | |")
                continue
            cells = []
            for target in an.TARGETS:
                c = an.cheapest(cands, target)
                cells.append(f"**{c.method}** ({c.worst_error:.1e} rad, {c.us_per_step:.0f} µs/step)" if c else "none")
            best = min(cands, key=lambda c: c.worst_error)
            cells.append(f"{best.method} ({best.worst_error:.1e} rad)")
            out.append(f"| {kind} | {rate:g} Hz | " + " | ".join(cells) + f" | {_auto_pick(kind, rate)} |")
    out += [
        "",
        "### The table behind `method: auto`",
        "",
        f"`finger_sim.auto` picks, for a scene's kind and rate, the cheapest method of this table within "
        f"{auto.AUTO_TARGET:g} rad that is stable at the scene's dt (see its docstring). This run's table "
        + ("**matches** the one in finger_sim/auto.py." if _same_choices(table, auto.RECOMMENDATION) else
           "**differs** from the one in finger_sim/auto.py (to regenerate: paste the block below over "
           "`RECOMMENDATION` there" + (", from a full run" if quick else "") + ")."),
        "",
        "```python",
        *format_table(table),
        "```",
    ]
    return out


def format_table(table: dict[str, dict[int, tuple[tuple[str, float, float], ...]]]) -> list[str]:
    """The table as the Python literal of `finger_sim.auto.RECOMMENDATION`, one candidate per line."""
    out = ["RECOMMENDATION: dict[str, dict[int, tuple[tuple[str, float, float], ...]]] = {"]
    for kind, rows in table.items():
        out.append(f'    "{kind}": {{')
        for rate, cands in rows.items():
            out.append(f"        {rate}: (")
            out.extend(f'            ("{m}", {e!r}, {c!r}),' for m, e, c in cands)
            out.append("        ),")
        out.append("    },")
    out.append("}")
    return out


def _auto_pick(kind: str, rate: int) -> str:
    """What `auto` takes from its own (shipped) table at this kind and rate, ignoring stability."""
    rows = auto.RECOMMENDATION.get(kind, {}).get(rate)
    if not rows:
        return "—"
    within = [r for r in rows if r[1] <= auto.AUTO_TARGET]
    return (within[0] if within else min(rows, key=lambda r: r[1]))[0]


def _same_choices(a: dict, b: dict) -> bool:
    """Whether two tables lead auto to the same method for every kind and rate they both have (and have the same keys)."""
    if {k: set(v) for k, v in a.items()} != {k: set(v) for k, v in b.items()}:
        return False
    for kind, rows in a.items():
        for rate, cands in rows.items():
            pick = lambda rs: next((r[0] for r in rs if r[1] <= auto.AUTO_TARGET), min(rs, key=lambda r: r[1])[0])  # noqa: E731
            if pick(cands) != pick(b[kind][rate]):
                return False
    return True
