"""`finger-sim bench --quick`: every method and peer has a row with finite numbers; the analysis is right.

The bench runs once (module fixture, ~30 s); nothing here is timed. The MuJoCo rows are
present when `mujoco` imports, and skipped with a note saying how to install it when not.
"""

from __future__ import annotations

import math
import re
from pathlib import Path

import pytest

from finger_sim.bench import analysis as an
from finger_sim.bench import runners
from finger_sim.bench.reference import build_reference
from finger_sim.bench.report import MUJOCO_INTEGRATORS, MUJOCO_SETTINGS, SCIPY_METHODS, WP_SCENES, ALL_SCENES, project_methods, run_bench
from finger_sim.bench.runners import Run
from finger_sim.integrators import METHODS
from finger_sim.scene import load_scene

CONFIG = Path(__file__).resolve().parent.parent / "config"
ROW = re.compile(r"^\| (finger_sim|scipy|MuJoCo) \| ([^|]+) \| (dt|rtol|timestep) (\S+) \| ([^|]+) \|(.*)$")

try:
    import mujoco  # noqa: F401

    HAVE_MUJOCO = True
except ImportError:
    HAVE_MUJOCO = False


@pytest.fixture(scope="module")
def bench(tmp_path_factory):
    out = tmp_path_factory.mktemp("bench")
    code = run_bench(quick=True, out=out, argv=["finger-sim", "bench", "--quick", "--out", str(out)])
    assert code == 0
    return out, (out / "performance.md").read_text()


def scene_rows(text: str, scene: str) -> list[dict]:
    """The rows of one scene's work-precision table."""
    section = text.split(f"\n### {scene}\n", 1)[1].split("\n### ", 1)[0]
    rows = []
    for line in section.splitlines():
        m = ROW.match(line)
        if m:
            cells = [c.strip() for c in m.group(6).split("|")]
            rows.append(
                {
                    "family": m.group(1),
                    "method": m.group(2).strip(),
                    "knob": m.group(3),
                    "value": float(m.group(4)),
                    "status": m.group(5).strip(),
                    "error": cells[0],
                    "phi": cells[1],
                    "drift": cells[2],
                    "us": cells[3],
                    "cpu": cells[4],
                    "rtf": cells[5],
                    "note": cells[6],
                }
            )
    return rows


def test_report_has_the_command_machine_and_date(bench):
    out, text = bench
    assert f"- Command: `finger-sim bench --quick --out {out}`" in text
    assert re.search(r"- Date: \d{4}-\d\d-\d\d \d\d:\d\d UTC", text)
    assert "- CPU: " in text and "logical cores" in text and "Python 3." in text
    for name in ALL_SCENES:
        assert (out / f"wp_{name}.png").stat().st_size > 10_000
        assert f"![{name}](wp_{name}.png)" in text


@pytest.mark.parametrize("scene", ALL_SCENES)
def test_every_project_method_has_rows_with_finite_numbers(bench, scene):
    rows = [r for r in scene_rows(bench[1], scene) if r["family"] == "finger_sim"]
    assert {r["method"] for r in rows} == set(project_methods()) == set(METHODS)
    for r in rows:
        assert r["status"] in ("ok", "refused", "diverged"), r
        if r["status"] == "ok":
            for key in ("error", "phi", "us", "cpu", "rtf"):
                assert math.isfinite(float(r[key])), (key, r)
        else:
            assert r["note"], r  # a refusal or divergence says why
    # at 1 ms every method is either measured or refused by the stability check
    at_1ms = {r["method"]: r["status"] for r in rows if r["value"] == 1e-3}
    assert set(at_1ms) == set(METHODS)
    if scene == "stiff_spring":
        assert at_1ms["rk4"] == at_1ms["euler"] == "refused" and at_1ms["radau"] == "ok"
    else:
        assert all(s == "ok" for s in at_1ms.values()), at_1ms


@pytest.mark.parametrize("scene", WP_SCENES)
def test_every_peer_has_rows(bench, scene):
    rows = scene_rows(bench[1], scene)
    scipy_rows = [r for r in rows if r["family"] == "scipy"]
    assert {r["method"] for r in scipy_rows} >= {f"scipy {m}" for m in SCIPY_METHODS}
    for r in scipy_rows:
        assert r["status"] in ("ok", "gave up"), r
        if r["status"] == "ok":
            assert all(math.isfinite(float(r[k])) for k in ("error", "phi", "us", "cpu", "rtf")), r
    assert any(r["status"] == "ok" for r in scipy_rows)
    mj = [r for r in rows if r["family"] == "MuJoCo"]
    assert {r["method"] for r in mj} == {f"MuJoCo {i} {s}" for i in MUJOCO_INTEGRATORS for s in MUJOCO_SETTINGS}
    for r in mj:
        if not HAVE_MUJOCO:
            assert r["status"] == "skipped" and "pip install" in r["note"], r
        elif r["status"] == "ok":
            assert all(math.isfinite(float(r[k])) for k in ("error", "phi", "us", "cpu", "rtf")), r
        else:
            assert r["status"] == "diverged" and r["note"], r
    if HAVE_MUJOCO and scene == "paper_flexion":
        # the peer runs the paper's case with every integrator and setting
        assert all(r["status"] == "ok" for r in mj)


def test_numpy_rhs_variant_is_shown_on_the_paper_run(bench):
    rows = scene_rows(bench[1], "paper_flexion")
    naive = [r for r in rows if r["method"] == "scipy DOP853 (numpy RHS)"]
    fast = {r["value"]: r for r in rows if r["method"] == "scipy DOP853"}
    assert naive and all(r["status"] == "ok" for r in naive)
    for r in naive:  # the same equations and steps: the same error, only slower
        assert float(r["error"]) == pytest.approx(float(fast[r["value"]]["error"]), rel=1e-3)


def test_mujoco_rows_are_skipped_with_a_note_when_it_is_missing(monkeypatch):
    scene = load_scene(CONFIG / "paper_flexion.yaml").with_overrides(duration=0.01)
    ref = build_reference(scene, quick=True, spacing=1e-3)
    note = "MuJoCo rows skipped: No module named 'mujoco' (install with `pip install .[bench]` or `pip install mujoco`)"
    monkeypatch.setattr(runners, "mujoco_available", lambda: (False, note))
    run = runners.run_mujoco_peer(scene, "RK4", 1e-3, "tight", ref, spacing=1e-3, repeats=1)
    assert run.status == "skipped" and run.note == note and math.isnan(run.error)


def test_sections_goals_hard_cases_and_recommendation(bench):
    text = bench[1]
    for heading in ("## Goals", "## Recommendation", "## Hard cases at dt = 1 ms", "### The table behind `method: auto`"):
        assert heading in text
    hard = text.split("## Hard cases at dt = 1 ms", 1)[1].split("\n## ", 1)[0]
    for name in an.HARD_SCENES:
        line = next(l for l in hard.splitlines() if l.startswith(f"| {name} |"))
        assert "**pass**" in line  # at least one method passes each hard case
    stiff = next(l for l in hard.splitlines() if l.startswith("| stiff_spring |"))
    assert "refused" in stiff and "| radau |" in stiff  # explicit methods refused, auto picks radau
    rec = text.split("## Recommendation", 1)[1].split("\n## ", 1)[0]
    for kind in an.KINDS:
        assert f"| {kind} | 1000 Hz | " in rec
    assert "RECOMMENDATION: dict[str, dict[int, tuple[tuple[str, float, float], ...]]] = {" in rec


# -- the analysis on known numbers -----------------------------------------------------------


def fake(method: str, cpu: float, error: float, *, scene: str = "s", family: str = "finger_sim", value: float = 1e-3, steps: int = 100) -> Run:
    return Run(scene, family, method, "dt", value, 0.1, error=error, cpu=cpu, steps=steps, repeats=3)


def test_pareto_keeps_only_improving_points():
    runs = [fake("a", 1.0, 1e-3), fake("a", 2.0, 1e-2), fake("a", 3.0, 1e-6), fake("a", 0.5, math.nan)]
    assert an.pareto(runs) == [(1.0, 1e-3), (3.0, 1e-6)]


def test_cost_at_interpolates_log_log_and_never_extrapolates():
    front = [(1e-3, 1e-4), (1e-1, 1e-8)]
    assert an.cost_at(front, 1e-6) == pytest.approx(1e-2, rel=1e-12)  # halfway in log
    assert an.cost_at(front, 1e-3) == 1e-3  # the cheapest already reaches it
    assert an.cost_at(front, 1e-9) == math.inf
    assert an.error_at(front, 1e-2) == pytest.approx(1e-6, rel=1e-12)
    assert an.error_at(front, 1e-4) == math.inf  # cheaper than any run: no estimate
    assert an.error_at(front, 1.0) == 1e-8


def test_recommendation_takes_the_worst_scene_of_a_kind_and_the_cheapest_method():
    smooth = an.KINDS["smooth"]
    runs = []
    for scene in smooth:
        runs.append(fake("rk4", 1.0, 1e-7 if scene != "toggle_passage" else 1e-5, scene=scene, steps=1000))
        runs.append(fake("rk6", 2.0, 1e-8, scene=scene, steps=1000))
        runs.append(fake("adaptive", 0.1, 1e-14, scene=scene, steps=1000))  # never recommended
    cands = an.candidates(runs, "smooth", 1000)
    assert [c.method for c in cands] == ["rk4", "rk6"]
    assert cands[0].worst_error == 1e-5 and cands[0].us_per_step == pytest.approx(1000.0)
    assert an.cheapest(cands, 1e-6).method == "rk6"
    assert an.cheapest(cands, 1e-4).method == "rk4"
    assert an.cheapest(cands, 1e-9) is None
    # a scene of the kind missing or refused: the method is not a candidate
    runs[0] = Run(smooth[0], "finger_sim", "rk4", "dt", 1e-3, 0.3, status="refused")
    assert [c.method for c in an.candidates(runs, "smooth", 1000)] == ["rk6"]


def test_hard_case_verdicts():
    ok = Run("paper_to_stop", "finger_sim", "rk4", "dt", 1e-3, 0.6, error=1e-9, max_phi=1e-15, penetration=0.0, cpu=1.0, steps=600)
    assert an.hard_case(ok, True).status == "pass"
    drift = Run("free_swing", "finger_sim", "euler", "dt", 1e-3, 2.0, error=0.1, max_phi=1e-4, energy_drift=0.04, cpu=1.0, steps=2000)
    result = an.hard_case(drift, False)
    assert result.status == "fail"
    assert ("|Φ|", None, "1.0e-04 m (no constraint control)") in result.checks  # shown, not judged
    refused = Run("stiff_spring", "finger_sim", "rk4", "dt", 1e-3, 0.1, status="refused", note="unstable")
    assert an.hard_case(refused, True).status == "refused"
    stiff = Run("stiff_spring", "finger_sim", "radau", "dt", 1e-3, 0.1, error=1.2e-6, final_error=1e-13, max_phi=1e-16, cpu=1.0, steps=100)
    assert an.hard_case(stiff, True, stiff=True).status == "pass"
    assert an.hard_case(stiff, True).status == "fail"
