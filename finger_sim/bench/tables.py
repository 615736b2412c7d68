"""The report's tables as data: what `markdown` writes and the tests read.

Built once from the measurements (`build_tables`); each table is a list of frozen rows, in
the report's order. The judgements come from `analysis` and, for what `method: auto` does,
from `finger_sim.auto` itself (`auto.choose_method`, `auto.pick`), so the report states
what auto does, by auto's own rule.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

from finger_sim import auto
from finger_sim.bench import analysis as an
from finger_sim.bench.plan import HARD_SCENES, KINDS, NUMPY_RHS_SCENE, RATES, SHIPPED_SCENES, SPACING, project_methods
from finger_sim.bench.runners import AUTO, FAMILY_MUJOCO, FAMILY_PROJECT, FAMILY_SCIPY, Run
from finger_sim.integrators import METHODS
from finger_sim.scene import Scene

#: A mode every method is stable on: `auto.pick` with it chooses from a row of the table stability aside.
RESOLVED_MODE = 0j
#: The verdicts of a MuJoCo comparison.
MET, NOT_MET, AT_FLOOR, NOT_APPLICABLE = "met", "NOT met", "floor", "n/a"


def row_order(r: Run) -> tuple:
    """Sort key of a scene's rows: project, scipy, MuJoCo; the project's methods in plan order; larger knob first."""
    fam = [FAMILY_PROJECT, FAMILY_SCIPY, FAMILY_MUJOCO].index(r.family)
    methods = project_methods()
    rank = methods.index(r.method) if r.method in methods else len(methods)
    return (fam, rank, r.method, -r.value)


def scene_rows(runs: Sequence[Run], scene: str) -> list[Run]:
    """The rows of one scene's work-precision table, in the report's order."""
    return sorted((r for r in runs if r.scene == scene), key=row_order)


def auto_pick(rows: Sequence[auto.Row], rate: int) -> str:
    """What `auto.pick` takes from one kind-and-rate row of a table, stability aside ('—' for an empty row)."""
    return auto.pick(rows, RESOLVED_MODE, 1.0 / rate)[0] if rows else "—"


def shipped_pick(kind: str, rate: int) -> str:
    """What `auto` takes from its own (shipped) table at this kind and rate, stability aside."""
    return auto_pick(auto.RECOMMENDATION.get(kind, {}).get(rate, ()), rate)


def same_choices(a: auto.Table, b: auto.Table) -> bool:
    """Whether two tables have the same kinds and rates and lead `auto.pick` to the same method at each."""
    if {k: set(v) for k, v in a.items()} != {k: set(v) for k, v in b.items()}:
        return False
    return all(auto_pick(rows, rate) == auto_pick(b[kind][rate], rate) for kind, by_rate in a.items() for rate, rows in by_rate.items())


# -- hard cases ----------------------------------------------------------------------------------


@dataclass(frozen=True)
class HardRow:
    """One hard scene at HARD_DT: auto's pick and each measured project method's verdict."""

    scene: str
    auto_pick: str
    results: dict[str, an.HardResult]  # method → verdict, in project_methods() order; unmeasured absent
    #: the verdict of the `method: auto` run itself, where it was measured (contact scenes: auto
    #: adds substeps in contact, so its run is not the picked method's plain run)
    auto_result: an.HardResult | None = None

    @property
    def passing(self) -> list[str]:
        return [m for m, h in self.results.items() if h.status == "pass"]

    @property
    def auto_passes(self) -> bool:
        if self.auto_result is not None:
            return self.auto_result.status == "pass"
        return self.auto_pick in self.passing


def hard_rows(scenes: dict[str, Scene], runs: Sequence[Run]) -> list[HardRow]:
    """The hard-case table: every HARD_SCENES scene, judged at HARD_DT."""
    out = []
    for name in HARD_SCENES:
        results = {}
        stiff = name in KINDS["stiff"]
        for method in project_methods():
            run = next((r for r in runs if r.scene == name and r.method == method and math.isclose(r.value, an.HARD_DT)), None)
            if run is not None:
                results[method] = an.hard_case(run, METHODS[method].keeps_constraints, stiff=stiff)
        pick, _ = auto.choose_method(scenes[name].with_overrides(method="auto", dt=an.HARD_DT))
        auto_run = next((r for r in runs if r.scene == name and r.method == AUTO and math.isclose(r.value, an.HARD_DT)), None)
        auto_result = None
        if auto_run is not None:
            auto_result = an.hard_case(auto_run, METHODS[pick].keeps_constraints, stiff=stiff)
            pick = auto_run.note if auto_run.ok else pick  # what ran: the method and its substeps
        out.append(HardRow(name, pick, results, auto_result))
    return out


# -- the recommendation ----------------------------------------------------------------------------


@dataclass(frozen=True)
class RecommendationRow:
    """One kind and rate: the cheapest candidate per target (None: none reached it), the most accurate, auto's pick."""

    kind: str
    rate: int  # Hz
    cheapest: tuple[an.Candidate | None, ...]  # per analysis.TARGETS; () when the rate was not measured
    most_accurate: an.Candidate | None
    auto_pick: str  # from the shipped table

    @property
    def measured(self) -> bool:
        return self.most_accurate is not None


def recommendation_rows(runs: Sequence[Run]) -> list[RecommendationRow]:
    """The recommendation table, every kind and rate (unmeasured ones included, empty)."""
    out = []
    for kind in KINDS:
        for rate in RATES:
            cands = an.candidates(runs, kind, rate)
            cheapest = tuple(an.cheapest(cands, target) for target in an.TARGETS) if cands else ()
            best = min(cands, key=lambda c: c.worst_error) if cands else None
            out.append(RecommendationRow(kind, rate, cheapest, best, shipped_pick(kind, rate)))
    return out


# -- goals ---------------------------------------------------------------------------------------


@dataclass(frozen=True)
class RealtimeGoal:
    """Goal 1: auto's method on paper_flexion at REALTIME_DT and its run (None: not measured)."""

    method: str
    reason: str
    run: Run | None

    @property
    def met(self) -> bool:
        r = self.run
        return r is not None and r.ok and r.error <= an.REALTIME_ERROR and r.us_per_step <= an.REALTIME_US_PER_STEP


def realtime_goal(scenes: dict[str, Scene], runs: Sequence[Run]) -> RealtimeGoal:
    scene = scenes["paper_flexion"].with_overrides(method="auto", dt=an.REALTIME_DT)
    method, reason = auto.choose_method(scene)
    run = next((r for r in runs if r.scene == "paper_flexion" and r.method == method and math.isclose(r.value, an.REALTIME_DT)), None)
    return RealtimeGoal(method, reason, run)


@dataclass(frozen=True)
class ScipyGoalRow:
    """Goal 2 on one shipped scene: every project run counted, and only those with output as dense as scipy's;
    each with the project's runs timed whole, as `simulate` runs them (scipy's `solve_ivp` is timed whole: the
    goal's comparison), and step by step, one `Simulator.step` at a time (the node's path)."""

    scene: str
    any_step: an.ScipyComparison  # whole runs
    dense: an.ScipyComparison  # whole runs with dt ≤ SPACING
    stepped: an.ScipyComparison  # step by step
    stepped_dense: an.ScipyComparison  # step by step with dt ≤ SPACING

    @property
    def met(self) -> bool:
        return self.any_step.ratio >= an.SCIPY_ADVANTAGE


def scipy_goal(runs: Sequence[Run]) -> list[ScipyGoalRow]:
    """Goal 2 at SCIPY_TARGET on every shipped scene with scipy rows."""
    return [
        ScipyGoalRow(name, an.compare_scipy(runs, name, whole_run=True),
                     an.compare_scipy(runs, name, max_dt=SPACING, whole_run=True),
                     an.compare_scipy(runs, name), an.compare_scipy(runs, name, max_dt=SPACING))
        for name in SHIPPED_SCENES if any(r.scene == name and r.family == FAMILY_SCIPY for r in runs)
    ]


def auto_goal(runs: Sequence[Run], floors: dict[str, float]) -> list[an.AutoScipyComparison]:
    """Goal 2 at auto's own error, on every shipped scene measured (`analysis.compare_auto`)."""
    out = [an.compare_auto(runs, name, floors[name]) for name in SHIPPED_SCENES if name in floors]
    return [c for c in out if c is not None]


def mujoco_verdict(c: an.MujocoComparison) -> str:
    """MET, NOT_MET, AT_FLOOR (short of the goal, but the project's error is at the reference floor) or NOT_APPLICABLE."""
    if math.isnan(c.ratio):
        return NOT_APPLICABLE
    if c.ratio >= an.MUJOCO_ADVANTAGE:
        return MET
    return AT_FLOOR if c.at_floor else NOT_MET


@dataclass(frozen=True)
class Tables:
    """Every table of the report, as data."""

    scenes: dict[str, list[Run]]  # scene → its work-precision rows
    realtime: RealtimeGoal
    scipy: list[ScipyGoalRow]
    auto_scipy: list[an.AutoScipyComparison]  # auto at its own error against scipy, every shipped scene
    naive_scipy: an.ScipyComparison  # scipy on the naive numpy RHS against the project's best whole run
    mujoco: dict[str, list[an.MujocoComparison]]  # smooth scene → its tight MuJoCo runs compared
    hard: list[HardRow]
    recommendation: list[RecommendationRow]
    table: auto.Table  # this run's data for `auto` (analysis.recommendation)
    matches_shipped: bool  # whether `table` leads auto to the same choices as the shipped one

    @property
    def hard_met(self) -> bool:
        return all(row.passing and row.auto_passes for row in self.hard)


def build_tables(scenes: dict[str, Scene], floors: dict[str, float], runs: Sequence[Run]) -> Tables:
    """Every table of the report from the runs; floors: scene → its reference floor (rad)."""
    table = an.recommendation(runs)
    return Tables(
        scenes={name: scene_rows(runs, name) for name in scenes},
        realtime=realtime_goal(scenes, runs),
        scipy=scipy_goal(runs),
        auto_scipy=auto_goal(runs, floors),
        naive_scipy=an.compare_scipy(runs, NUMPY_RHS_SCENE, numpy_rhs=True, whole_run=True),
        mujoco={name: an.compare_mujoco(runs, name, floors[name]) for name in KINDS["smooth"]},
        hard=hard_rows(scenes, runs),
        recommendation=recommendation_rows(runs),
        table=table,
        matches_shipped=same_choices(table, auto.RECOMMENDATION),
    )
