"""What the bench's measurements say: Pareto fronts, the recommendation table, hard cases, goals.

Pure functions over lists of `Run`; no timing and no I/O here, so the derivation of the
recommendation (the table `finger_sim.auto` loads, which a full bench run writes) can be
read and tested on its own.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Sequence
from dataclasses import dataclass

from finger_sim.auto import Row, Table
from finger_sim.bench.plan import AUTO_DT, KINDS, RATES, project_methods
from finger_sim.bench.runners import AUTO, AUTO_WHOLE_RUN, FAMILY_MUJOCO, FAMILY_PROJECT, FAMILY_SCIPY, WHOLE_RUN_SUFFIX, Run

#: Not recommended, whatever they measure: the error-controlled methods. `adaptive` restarts
#: scipy's DOP853 at every step (0.2-60 ms per step); `dop853` takes as many internal steps as
#: its tolerance asks, so its cost per step follows the scene and a real-time loop cannot
#: budget it. Both are offline methods, named explicitly.
NOT_RECOMMENDED = ("adaptive", "dop853")

#: Error targets of the recommendation table, rad.
TARGETS = (1e-6, 1e-9)
#: Error at which the project is compared with scipy, rad (goal 2).
SCIPY_TARGET = 1e-8
#: Required advantages (goal 2): CPU time against scipy's best, error against MuJoCo's.
SCIPY_ADVANTAGE = 10.0
MUJOCO_ADVANTAGE = 1000.0
#: Goal 1: the default real-time method on paper_flexion at dt = 1 ms.
REALTIME_DT = 1e-3
REALTIME_ERROR = 1e-9
REALTIME_US_PER_STEP = 30.0

#: Hard-case criteria, at dt = HARD_DT.
HARD_DT = 1e-3
HARD_PHI = 1e-10  # m, for methods that keep the constraints
HARD_ENERGY = 1e-6  # relative |ΔE| / E0 where energy is conserved
HARD_MATCH = 1e-6  # rad, max |θ − θ_ref|
#: On a stiff scene no fixed step of 1 ms resolves the fast mode (period 0.6 ms on
#: stiff_spring); an L-stable method damps it and is judged on where the motion goes:
#: |θ − θ_ref| at the end, after the transient, within this (rad). The transient's
#: error is shown, not judged.
HARD_SETTLED = 1e-9
HARD_PENETRATION = 1e-9  # rad past a joint stop


def pareto(runs: Iterable[Run]) -> list[tuple[float, float]]:
    """(CPU s, error rad) of the successful runs, cheapest first, each more accurate than all cheaper ones."""
    points = sorted((r.cpu, r.error) for r in runs if r.ok and math.isfinite(r.error))
    front: list[tuple[float, float]] = []
    for cpu, err in points:
        if not front or err < front[-1][1]:
            front.append((cpu, err))
    return front


def cost_at(front: Sequence[tuple[float, float]], target: float) -> float:
    """CPU s to reach error ≤ target on a front, log-log interpolated between its points; inf if never."""
    previous = None
    for cpu, err in front:
        if err <= target:
            if previous is None:
                return cpu  # the cheapest run is already accurate enough: no extrapolation
            (c0, e0), (c1, e1) = previous, (cpu, err)
            w = (math.log(target) - math.log(e0)) / (math.log(max(e1, 1e-300)) - math.log(e0))
            return math.exp(math.log(c0) + w * (math.log(c1) - math.log(c0)))
        previous = (cpu, err)
    return math.inf


def error_at(front: Sequence[tuple[float, float]], cpu: float) -> float:
    """Error reached at `cpu` s on a front, log-log interpolated between its points; inf below its cheapest point."""
    if not front or cpu < front[0][0]:
        return math.inf
    for (c0, e0), (c1, e1) in zip(front, front[1:]):
        if c0 <= cpu <= c1:
            w = (math.log(cpu) - math.log(c0)) / (math.log(c1) - math.log(c0)) if c1 > c0 else 1.0
            return math.exp(math.log(max(e0, 1e-300)) + w * (math.log(max(e1, 1e-300)) - math.log(max(e0, 1e-300))))
    return front[-1][1]


# -- the recommendation table ------------------------------------------------------------------


@dataclass(frozen=True)
class Candidate:
    """A project method at one rate on one scene kind: worst error over the kind's scenes, mean cost."""

    method: str
    worst_error: float  # rad
    us_per_step: float  # mean over the kind's scenes


def candidates(runs: Sequence[Run], kind: str, rate: int) -> list[Candidate]:
    """Project methods that ran (not refused, not diverged) on every scene of `kind` at dt = 1/rate, cheapest first:
    their runs step by step (the node's path, which the table serves), `auto` and the whole runs left out."""
    dt = 1.0 / rate
    scenes = KINDS[kind]
    by_method: dict[str, list[Run]] = {}
    for r in runs:
        if (
            r.family == FAMILY_PROJECT
            and r.method in project_methods()  # not auto, the table's user (run for the goal at its error)
            and r.method not in NOT_RECOMMENDED
            and r.scene in scenes
            and r.knob == "dt"
            and math.isclose(r.value, dt, rel_tol=1e-9)
        ):
            by_method.setdefault(r.method, []).append(r)
    out = []
    for method, rs in by_method.items():
        if len(rs) == len(scenes) and all(r.ok for r in rs):
            out.append(Candidate(method, max(r.error for r in rs), sum(r.us_per_step for r in rs) / len(rs)))
    return sorted(out, key=lambda c: c.us_per_step)


def cheapest(cands: Sequence[Candidate], target: float) -> Candidate | None:
    """The cheapest candidate whose worst error is within target."""
    return next((c for c in cands if c.worst_error <= target), None)


def recommendation(runs: Sequence[Run]) -> Table:
    """kind → rate → (Row(method, worst error rad, µs/step), ...) cheapest first, to 3 digits: auto's table."""
    table: Table = {}
    for kind in KINDS:
        for rate in RATES:
            cands = candidates(runs, kind, rate)
            if cands:
                table.setdefault(kind, {})[rate] = tuple(
                    Row(c.method, float(f"{c.worst_error:.3g}"), float(f"{c.us_per_step:.3g}")) for c in cands
                )
    return table


# -- hard cases ---------------------------------------------------------------------------------


@dataclass(frozen=True)
class HardResult:
    """One method on one hard scene at HARD_DT: each criterion as (passed or None when n/a, text)."""

    scene: str
    method: str
    status: str  # "pass", "fail", "refused", "diverged"
    checks: tuple[tuple[str, bool | None, str], ...]


def hard_case(run: Run, keeps_constraints: bool, *, stiff: bool = False) -> HardResult:
    """Judge one run at HARD_DT against the hard-case criteria (`stiff`: judged settled, see HARD_SETTLED)."""
    if run.status in ("refused", "diverged", "gave up"):
        return HardResult(run.scene, run.method, run.status, ((run.status, None, run.note),))
    checks: list[tuple[str, bool | None, str]] = [("no NaN", True, "finite")]
    if keeps_constraints:
        checks.append(("|Φ|", run.max_phi <= HARD_PHI, f"{run.max_phi:.1e} m"))
    else:
        checks.append(("|Φ|", None, f"{run.max_phi:.1e} m (no constraint control)"))
    if math.isfinite(run.energy_drift):
        checks.append(("energy", run.energy_drift <= HARD_ENERGY, f"{run.energy_drift:.1e}"))
    if stiff:
        checks.append(("transient", None, f"{run.error:.1e} rad (not judged)"))
        checks.append(("settled", run.final_error <= HARD_SETTLED, f"{run.final_error:.1e} rad"))
    else:
        checks.append(("reference", run.error <= HARD_MATCH, f"{run.error:.1e} rad"))
    if math.isfinite(run.penetration):
        checks.append(("stop", run.penetration <= HARD_PENETRATION, f"{run.penetration:.1e} rad"))
    passed = all(ok is not False for _, ok, _ in checks)
    return HardResult(run.scene, run.method, "pass" if passed else "fail", tuple(checks))


# -- goals ---------------------------------------------------------------------------------------


@dataclass(frozen=True)
class ScipyComparison:
    scene: str
    ours: float  # CPU s to reach SCIPY_TARGET
    ours_method: str
    scipy: float
    scipy_method: str

    @property
    def ratio(self) -> float:
        return self.scipy / self.ours if 0 < self.ours < math.inf else math.nan


def step_of(run: Run) -> float:
    """A project run's step, so output interval (s): its dt, or AUTO_DT for a run over the tolerance grid."""
    return run.value if run.knob == "dt" else AUTO_DT


def _project(runs: Sequence[Run], scene: str, max_dt: float | None, *, whole_run: bool = False) -> list[Run]:
    """The project's runs on a scene; with max_dt, only those whose step (so output interval) is ≤ max_dt.

    Each run timed one `Simulator.step` at a time (the node's path); whole_run: each timed as `simulate` runs
    it where that was measured (WHOLE_RUN_SUFFIX), else step by step (a method stepping in Python, whose whole
    run is the same loop: `plan.WHOLE_RUN_METHODS`)."""
    ours = [r for r in runs if r.scene == scene and r.family == FAMILY_PROJECT
            and (max_dt is None or step_of(r) <= max_dt * (1 + 1e-9))]
    stepped = [r for r in ours if not r.method.endswith(WHOLE_RUN_SUFFIX)]
    if not whole_run:
        return stepped
    whole = [r for r in ours if r.method.endswith(WHOLE_RUN_SUFFIX)]
    timed_whole = {(r.method.removesuffix(WHOLE_RUN_SUFFIX), r.knob, r.value) for r in whole}
    return whole + [r for r in stepped if (r.method, r.knob, r.value) not in timed_whole]


def _best_cost(runs: Sequence[Run], target: float) -> tuple[float, str]:
    """(CPU s, method) of the method that reaches `target` cheapest (interpolated on its own front)."""
    costs = [(cost_at(pareto(r for r in runs if r.method == m), target), m) for m in sorted({r.method for r in runs})]
    return min(costs, default=(math.inf, "—"))


def compare_scipy(runs: Sequence[Run], scene: str, *, max_dt: float | None = None, numpy_rhs: bool = False,
                  whole_run: bool = False) -> ScipyComparison:
    """CPU time to reach SCIPY_TARGET: the project's best method against scipy's best (scalar RHS).

    max_dt: count only project runs with dt ≤ max_dt, i.e. with output at least as dense as
    scipy's (`t_eval` on the 1 ms grid); without it a large-step run is scored at its own steps.
    numpy_rhs: compare with scipy on the naive numpy right-hand side instead of the project's scalar one.
    whole_run: the project's runs timed as `simulate` runs them, as scipy's `solve_ivp` is timed (`_project`);
    else one `Simulator.step` at a time.
    """
    theirs = [r for r in runs if r.scene == scene and r.family == FAMILY_SCIPY and ("numpy" in r.method) == numpy_rhs]
    ours, ours_m = _best_cost(_project(runs, scene, max_dt, whole_run=whole_run), SCIPY_TARGET)
    cost, method = _best_cost(theirs, SCIPY_TARGET)
    return ScipyComparison(scene, ours, ours_m, cost, method)


@dataclass(frozen=True)
class AutoScipyComparison:
    """`auto` at AUTO_DT on one scene against the CPU scipy's best method and the project's cheapest run need
    for the same error: auto's own, or the reference floor where auto is below it (`at`). CPU in s, errors in rad.
    auto is timed two ways: one `Simulator.step` at a time (`auto_cpu`, the node's path) and its whole run as
    `simulate` steps it (`whole_cpu`, what a user running the scene offline gets; NaN where not measured)."""

    scene: str
    pick: str  # what auto ran
    error: float  # auto's error
    at: float  # the error compared at: max(error, the reference floor)
    auto_cpu: float
    whole_cpu: float
    cheapest: float  # the project's cheapest run (any method, any step) to `at`
    cheapest_method: str
    scipy: float  # scipy's best to `at`; where no scipy run reaches it, its most accurate run's CPU
    scipy_method: str
    scipy_reaches: bool  # False: scipy's most accurate run is less accurate than `at`, the ratio a lower bound

    @property
    def ratio(self) -> float:
        """scipy's best CPU over auto's, like for like: over auto's whole run (scipy's is a whole run too), or
        over its step-by-step run where the whole run was not measured."""
        return self.step_ratio if math.isnan(self.whole_cpu) else _over(self.scipy, self.whole_cpu)

    @property
    def step_ratio(self) -> float:
        """scipy's best CPU over auto's stepped one `Simulator.step` at a time."""
        return _over(self.scipy, self.auto_cpu)

    @property
    def cheapest_ratio(self) -> float:
        """scipy's best CPU over the project's cheapest."""
        return _over(self.scipy, self.cheapest)


def _over(scipy: float, ours: float) -> float:
    """scipy's CPU over ours; NaN where either is missing (inf, NaN) or ours is 0."""
    return scipy / ours if 0 < ours < math.inf and scipy < math.inf else math.nan


def compare_auto(runs: Sequence[Run], scene: str, floor: float) -> AutoScipyComparison | None:
    """`auto`'s run at AUTO_DT on `scene` against scipy's best and the project's cheapest at its error; None
    when auto's run or every scipy run is missing or failed. floor: the scene's reference floor, rad."""
    mine = next((r for r in runs if r.scene == scene and r.family == FAMILY_PROJECT and r.method == AUTO
                 and math.isclose(r.value, AUTO_DT) and r.ok), None)
    whole = next((r for r in runs if r.scene == scene and r.family == FAMILY_PROJECT
                  and r.method == AUTO_WHOLE_RUN and math.isclose(r.value, AUTO_DT) and r.ok), None)
    theirs = [r for r in runs if r.scene == scene and r.family == FAMILY_SCIPY and "numpy" not in r.method and r.ok]
    if mine is None or not theirs:
        return None
    at = max(mine.error, floor)
    cheapest, cheapest_method = _best_cost(_project(runs, scene, None), at)
    cost, method = _best_cost(theirs, at)
    reaches = math.isfinite(cost)
    if not reaches:  # a lower bound: the CPU of scipy's most accurate run, still short of `at`
        best = min(theirs, key=lambda r: (r.error, r.cpu))
        cost, method = best.cpu, best.method
    return AutoScipyComparison(scene, mine.note, mine.error, at, mine.cpu, math.nan if whole is None else whole.cpu,
                               cheapest, cheapest_method, cost, method, reaches)


@dataclass(frozen=True)
class MujocoComparison:
    scene: str
    label: str  # the MuJoCo run compared
    mujoco_error: float
    mujoco_cpu: float
    ours_error: float  # the project's front at the same CPU time (inf: no project run that cheap)
    floor: float  # the reference's own error bound
    same_rate: Run | None  # the project's cheapest run at dt = MuJoCo's timestep that is MUJOCO_ADVANTAGE× more accurate

    @property
    def at_floor(self) -> bool:
        """The project's error is within 10× the reference floor: the ratio is then only a lower bound."""
        return self.ours_error <= 10.0 * self.floor

    @property
    def ratio(self) -> float:
        """MuJoCo's error over ours (ours floored at the reference floor); NaN when no project run is that cheap."""
        if not math.isfinite(self.ours_error):
            return math.nan
        return self.mujoco_error / max(self.ours_error, self.floor)


def compare_mujoco(runs: Sequence[Run], scene: str, floor: float, *, max_dt: float | None = None) -> list[MujocoComparison]:
    """Every successful MuJoCo run with the tight loop setting against the project's error at its CPU time.

    The project's error there is log-log interpolated on the Pareto front of all its runs
    on the scene (with max_dt, of those with dt ≤ max_dt only). Also, at the same rate:
    the cheapest project run at dt = the MuJoCo timestep that is MUJOCO_ADVANTAGE× more accurate.
    """
    ours = _project(runs, scene, max_dt)
    front = pareto(ours)
    out = []
    for r in runs:
        if r.scene == scene and r.family == FAMILY_MUJOCO and r.method.endswith("tight") and r.ok:
            better = [
                o
                for o in ours
                if o.ok and math.isclose(step_of(o), r.value) and max(o.error, floor) * MUJOCO_ADVANTAGE <= r.error
            ]
            same = min(better, key=lambda o: o.cpu, default=None)
            out.append(MujocoComparison(scene, f"{r.method} @ {r.value:g} s", r.error, r.cpu, error_at(front, r.cpu), floor, same))
    return out
