"""`method: auto`: the kind and rate of a scene, the table's pick, stability, and the stated reason."""

from __future__ import annotations

import logging
from pathlib import Path

import pytest

from finger_sim import auto
from finger_sim.errors import StabilityError
from finger_sim.integrators import METHODS
from finger_sim.scene import load_scene
from finger_sim.simulate import Simulator, simulate
from finger_sim.stability import fastest_mode, mcp_range, stable_at

CONFIG = Path(__file__).resolve().parents[2] / "config"
SHIPPED = sorted(p.stem for p in CONFIG.glob("*.yaml") if p.stem != "finger_node")


def scene(name: str, **overrides):
    return load_scene(CONFIG / f"{name}.yaml").with_overrides(method="auto", **overrides)


def root_of(s) -> complex:
    return fastest_mode(s.build_system(), mcp_range(s))


def test_stiff_spring_at_1ms_gets_the_error_controlled_method():
    # issue 17 item 5: not the Python radau (125-146 µs/step) but the compiled dop853, stable there by its error control
    method, reason = auto.choose_method(scene("stiff_spring", dt=1e-3))
    assert method == auto.ERROR_CONTROLLED == "dop853"
    assert METHODS[method].is_stable(complex(-1e6, 1e6))  # error control shrinks its step on any mode
    assert reason.startswith("stiff scene (fastest mode |s|·dt = 10.8 > 1, not resolved by the step)")
    assert "rtol = atol = 1e-09 for 1e-06 rad on θ" in reason


def test_paper_flexion_at_1ms_gets_an_explicit_method_within_the_target():
    method, reason = auto.choose_method(scene("paper_flexion", dt=1e-3))
    assert not METHODS[method].implicit
    assert reason.startswith("smooth scene (smooth ramp torque, no stops, fastest mode |s|·dt = 0.0108)")
    # the table's method is trusted on a scene without events only TABLE_MARGIN inside the tolerance
    assert f"at 1000 Hz the bench measured {method} as the cheapest method within 1e-07 rad" in reason
    row = dict((m, e) for m, e, _ in auto.RECOMMENDATION["smooth"][1000])
    assert row[method] <= auto.AUTO_TARGET / auto.TABLE_MARGIN


def test_the_simulator_stores_and_the_run_reports_the_reason(caplog):
    s = scene("paper_flexion", dt=1e-3, duration=0.01)
    method, reason = auto.choose_method(s)
    with caplog.at_level(logging.INFO, logger="finger_sim.auto"):
        sim = Simulator(s)
    assert sim.method == method and sim.method_reason == reason
    assert f"method auto → {method}: {reason}" in caplog.text
    traj = simulate(s)
    assert traj.method == method and traj.method_reason == reason


def test_a_named_method_has_no_reason():
    sim = Simulator(scene("paper_flexion").with_overrides(method="rk4"))
    assert sim.method == "rk4" and sim.method_reason == ""


@pytest.mark.parametrize("name", SHIPPED)
@pytest.mark.parametrize("dt", [1e-2, 1e-3, 1e-4])
def test_auto_always_picks_a_method_the_stability_check_accepts(name, dt):
    s = scene(name, dt=dt)
    method, reason = auto.choose_method(s)
    # at its step: dt, or dt/m while in contact (auto substeps a contact scene)
    assert stable_at(METHODS[method], root_of(s), dt / auto.contact_substeps(s))
    Simulator(s)  # no StabilityError
    assert method in reason


def test_scene_kinds():
    assert auto.scene_kind(scene("bang_bang"), root_of(scene("bang_bang")))[0] == "discontinuous"
    assert auto.scene_kind(scene("paper_to_stop"), root_of(scene("paper_to_stop")))[0] == "stops"
    assert auto.scene_kind(scene("toggle_passage"), root_of(scene("toggle_passage")))[0] == "smooth"
    # the same spring is resolved by a step of 10 µs (|s|·dt = 0.108): no longer stiff
    fine = scene("stiff_spring", dt=1e-5)
    kind, why = auto.scene_kind(fine, root_of(fine))
    assert kind == "smooth" and "0.108" in why


def test_rate_row_is_the_tabulated_rate_at_or_below_the_scene_rate():
    assert auto.table_rate([100, 1000, 10000], 1e-3) == (1000, "1000 Hz")
    assert auto.table_rate([100, 1000, 10000], 3e-3)[0] == 100  # accuracy measured at a larger step
    assert auto.table_rate([100, 1000, 10000], 5e-4)[0] == 1000
    rate, text = auto.table_rate([100, 1000], 0.05)
    assert rate == 100 and "slower than any measured rate" in text


def test_the_table_is_bench_data_auto_can_use():
    assert set(auto.RECOMMENDATION) == {"smooth", "discontinuous", "stiff", "stops"}
    for kind, rows in auto.RECOMMENDATION.items():
        assert 1000 in rows, kind
        for rate, cands in rows.items():
            assert all(m in METHODS for m, _, _ in cands), (kind, rate)
            costs = [c for _, _, c in cands]
            assert costs == sorted(costs), (kind, rate)  # cheapest first
            assert all(e >= 0.0 for _, e, _ in cands)


def test_the_table_is_package_data_that_round_trips(tmp_path):
    assert auto.RECOMMENDATION_FILE.parent.name == "data"
    path = tmp_path / "recommendation.json"
    auto.save_recommendation(auto.RECOMMENDATION, "test", path)
    assert auto.load_recommendation(path) == auto.load_recommendation() == auto.RECOMMENDATION


def test_pick_is_the_cheapest_stable_row_within_the_target():
    rows = (("rk4", 7.5e-6, 15.0), ("rk6", 9e-9, 25.0), ("radau", 1e-8, 190.0))
    slow, fast = -10j, -1e4 + 0j  # a slow oscillation; a mode no explicit method resolves at 1 ms
    assert auto.pick(rows, slow, 1e-3)[0] == "rk6"
    assert "cheaper rk4 missed it" in auto.pick(rows, slow, 1e-3)[1]
    assert auto.pick(rows, fast, 1e-3)[0] == "radau"  # the explicit ones are unstable there
    assert auto.pick((("rk4", 1e-3, 15.0),), slow, 1e-3)[0] == "rk4"  # none within: the most accurate
    assert auto.pick((("rk4", 1e-9, 15.0),), fast, 1e-3) == (auto.FALLBACK, f"no tabulated method is stable; unstable here: rk4: {auto.FALLBACK}, L-stable")


def test_pick_takes_the_most_accurate_row_among_those_as_cheap_within_timing_noise():
    """issue 17 item 5: a pick is never dearer than another stable row at the same or better error, and a
    difference of cost below COST_MARGIN (the spread of one row between bench runs) does not decide it."""
    slow = -10j
    # the discontinuous row at 100 Hz of two full bench runs: rk4 and rk6 swapped places by 12 %
    run_a = (("rk4", 6.95e-08, 2.03), ("rk6", 7.11e-11, 2.28), ("dop8", 5.13e-14, 2.83))
    run_b = (("rk6", 7.11e-11, 2.72), ("dop8", 5.13e-14, 3.2), ("rk4", 6.95e-08, 3.55))
    assert auto.pick(run_a, slow, 1e-2)[0] == auto.pick(run_b, slow, 1e-2)[0] == "rk6"
    reason = auto.pick(run_a, slow, 1e-2)[1]
    assert "rk4 as cheap within timing noise (2.03 µs/step) but less accurate (6.9e-08 rad)" in reason
    # beyond the margin the cheaper one within the target wins: 2.03 × 1.15 < 2.4
    assert auto.pick((("rk4", 6.95e-08, 2.03), ("rk6", 7.11e-11, 2.4)), slow, 1e-2)[0] == "rk4"
    # a row both cheaper and more accurate than another is picked over it, whatever their order
    assert auto.pick((("dop8", 1e-12, 3.0), ("rk6", 1e-9, 3.1)), slow, 1e-3)[0] == "dop8"
    # equal error: the cheaper
    assert auto.pick((("rk6", 1e-12, 2.0), ("dop8", 1e-12, 2.2)), slow, 1e-3)[0] == "rk6"


def test_no_pick_of_the_shipped_table_is_dominated_by_another_stable_row():
    for kind, by_rate in auto.RECOMMENDATION.items():
        for rate, rows in by_rate.items():
            for target in (auto.AUTO_TARGET, auto.AUTO_TARGET / auto.TABLE_MARGIN):
                method = auto.pick(rows, -10j, 1.0 / rate, target)[0]
                chosen = next(auto.Row(*r) for r in rows if r[0] == method)
                if chosen.error > target:
                    continue  # none within the target: the most accurate
                assert not [r for r in map(auto.Row._make, rows) if r.error <= chosen.error and r.cost <= chosen.cost
                            and (r.error, r.cost) != (chosen.error, chosen.cost)
                            and stable_at(METHODS[r.method], -10j, 1.0 / rate)], (kind, rate, target)


def test_explicit_methods_stay_refused_where_auto_is_not_used():
    with pytest.raises(StabilityError) as info:
        Simulator(scene("stiff_spring", dt=1e-3).with_overrides(method="rk4"))
    err = info.value
    assert (err.method, err.scene, err.dt) == ("rk4", "stiff_spring", 1e-3)
    assert abs(err.mode) * err.dt > 2.8 and stable_at(METHODS["rk4"], err.mode, err.safe_dt)
    assert f"or dt ≤ {err.safe_dt:.3g} s" in str(err)


def test_a_contact_scene_is_called_one():
    """issue 19, item 11: the reason names a contact scene as such (it uses the stops row)."""
    _, reason = auto.choose_method(scene("grasp_cylinder"))
    assert reason.startswith("contact scene (events of model.contact")
    assert auto.choose_method(scene("paper_to_stop"))[1].startswith("stops scene (")
