"""Grasp tasks (finger_sim.tasks) and the objects that test a controller (per-object contact law,
break_force, tip-force spans).

References: metrics hand-computed on a synthetic signal, and recomputed on a real run by plain
loops written here from the metrics' definitions; a per-object stiffness against the same
stiffness given scene-wide; a tip-force span over the whole run against a scene with that
constant tip force; the crush sample against the break force.
"""

from __future__ import annotations

import dataclasses
import json
import math
import re
from pathlib import Path

import numpy as np
import pytest

from finger_sim.cli import main
from finger_sim.effects.contact_geometry import objects_from_list
from finger_sim.errors import ConfigError, FingerSimError
from finger_sim.scene import load_scene, scene_from_dict
from finger_sim.simulate import Simulator, simulate, state_columns
from finger_sim.tasks import metrics
from finger_sim.tasks.controllers import grip_pi, grip_pi_aggressive, load_factory
from finger_sim.tasks.runner import run_task
from finger_sim.tasks.schema import load_task, task_from_dict
from finger_sim.tasks.suite import installed_tasks, parse_controllers

CONFIG = Path(__file__).resolve().parents[2] / "config"
TASKS = CONFIG / "tasks"


# -- metrics on a synthetic signal, by hand --------------------------------------------------
def test_metrics_on_a_synthetic_signal():
    t = np.arange(11) * 0.1  # 0.0 ... 1.0 s
    #              0.0  0.1  0.2   0.3   0.4   0.5   0.6   0.7   0.8   0.9   1.0
    f = np.array([0.0, 0.5, 1.2, 0.94, 1.04, 0.97, 1.02, 1.0, 0.0, 0.0, 0.0])
    setpoints = [(0.0, 1.0), (0.8, 0.0)]
    s = metrics.task_scores(t, f, setpoints, hold_after=0.5, crushed=False)
    # hold segment: samples 0..7; outside the ±5 % band: 0.0, 0.5, 1.2, 0.94 (the last at 0.3 s),
    # so inside from 0.4 s on: settle 0.4 s
    assert s["settle_time"] == pytest.approx(0.4, abs=1e-12)
    assert s["overshoot"] == pytest.approx(20.0, abs=1e-9)  # (1.2 − 1)/1 · 100
    # holding window: t ≥ 0.5 in the segment: 0.97, 1.02, 1.0 → √((0.03² + 0.02² + 0)/3)
    assert s["hold_rms"] == pytest.approx(math.sqrt((0.03**2 + 0.02**2) / 3), abs=1e-12)
    assert s["release_time"] == pytest.approx(0.0, abs=1e-12)  # F = 0 from the change on
    assert s["peak_force"] == 1.2
    assert s["contact_lost"] is False and s["crushed"] is False
    assert s["electrical_energy"] is None and s["motor_work"] is None
    # τ held over each step: 0.1 N·m over +0.2 rad, then −0.05 N·m over −0.1 rad: 0.02 + 0.005 J
    assert metrics.motor_work(np.array([0.1, -0.05, 7.0]), np.array([0.0, 0.2, 0.1])) == pytest.approx(0.025, abs=1e-15)
    assert metrics.judge(s, {"overshoot": 20.0, "settle_time": 0.39, "crushed": False}) == {
        "overshoot": True, "settle_time": False, "crushed": True}


def test_metrics_edge_cases_by_hand():
    t = np.arange(6) * 0.1
    f = np.array([0.0, 0.8, 0.9, 0.0, 0.9, 1.5])  # ends outside the band: never settles
    s = metrics.task_scores(t, f, [(0.0, 1.0)], hold_after=0.2, crushed=True)
    assert s["settle_time"] == math.inf
    assert s["contact_lost"] is True  # F = 0 at 0.3 s, inside the holding window
    # a fall 1.0 → 0.5 N: F starting above is no overshoot; dipping to 0.4 is 20 %
    f2 = np.array([1.0, 1.0, 1.0, 0.8, 0.4, 0.5])
    s2 = metrics.task_scores(t, f2, [(0.0, 1.0), (0.3, 0.5)], hold_after=0.1, crushed=False)
    assert s2["overshoot"] == pytest.approx(20.0, abs=1e-9)
    # electrical energy with a drive's outputs: ∫ u i dt of u = 2 V, i = t A over 0.5 s = 0.25 J
    e = metrics.electrical_energy(t, {"motor_voltage": np.full(6, 2.0), "motor_current": t})
    assert e == pytest.approx(0.25, abs=1e-12)
    assert metrics.judge({"hold_rms": math.nan}, {"hold_rms": 1.0}) == {"hold_rms": False}


# -- metrics on a real run, recomputed by plain loops ----------------------------------------
def test_metrics_on_a_real_run_match_a_recomputation():
    task = load_task(TASKS / "staircase.yaml")
    run = run_task(task, grip_pi, label="pi")
    t, f = run.samples["t"].tolist(), run.samples["grip_force"].tolist()
    worst_settle = worst_over = worst_rms = 0.0
    changes = list(run.setpoints)
    for i, (t0, value) in enumerate(changes):
        end = changes[i + 1][0] if i + 1 < len(changes) else math.inf
        idx = [k for k in range(len(t)) if t0 - 1e-12 <= t[k] < end - 1e-12] if end < math.inf else \
              [k for k in range(len(t)) if t[k] >= t0 - 1e-12]
        settle = 0.0
        for k in idx:  # the sample after the last one outside the band
            if abs(f[k] - value) > 0.05 * value:
                settle = t[k + 1] - t0
        prev = changes[i - 1][1] if i else 0.0
        over = (max(f[k] for k in idx) - value if value >= prev else value - min(f[k] for k in idx)) / value * 100
        window = [f[k] for k in idx if t[k] >= t0 + task.hold_after - 1e-12]
        rms = math.sqrt(sum((x - value) ** 2 for x in window) / len(window))
        worst_settle, worst_over, worst_rms = max(worst_settle, settle), max(worst_over, over), max(worst_rms, rms)
    assert run.scores["settle_time"] == pytest.approx(worst_settle, abs=1e-12)
    assert run.scores["overshoot"] == pytest.approx(max(worst_over, 0.0), abs=1e-9)
    assert run.scores["hold_rms"] == pytest.approx(worst_rms, rel=1e-9)
    assert run.scores["peak_force"] == max(f)
    # the values themselves: settles in 0.368 s (closing onto the cup), holds to < 1e-2 N
    assert 0.3 < run.scores["settle_time"] < 0.5 and run.scores["hold_rms"] < 5e-3


def test_release_time_and_contact_lost_on_real_runs_match_a_recomputation():
    task = load_task(TASKS / "release_reopen.yaml")
    run = run_task(task, grip_pi)
    t, f = run.samples["t"].tolist(), run.samples["grip_force"].tolist()
    (t_release, _), (t_regrasp, _) = run.setpoints[1], run.setpoints[2]
    touching = [k for k in range(len(t)) if t_release - 1e-12 <= t[k] < t_regrasp - 1e-12 and f[k] != 0.0]
    assert run.scores["release_time"] == pytest.approx(t[touching[-1] + 1] - t_release, abs=1e-12)
    assert 0.0 < run.scores["release_time"] < 0.1  # the opening torque lifts off within a few steps
    # an oscillating controller bounces off the cup inside the holding window
    hot = run_task(load_task(TASKS / "hold_cup.yaml"), grip_pi_aggressive)
    t, f = hot.samples["t"].tolist(), hot.samples["grip_force"].tolist()
    lost = [k for k in range(len(t)) if t[k] >= 0.6 - 1e-12 and f[k] == 0.0]
    assert hot.scores["contact_lost"] is bool(lost) is True
    assert run.scores["contact_lost"] is False and min(f_ for t_, f_ in zip(run.samples["t"], run.samples["grip_force"])
                                                       if 0.6 <= t_ < 1.0) > 0.0


def test_motor_work_balances_the_energy_of_a_lossless_run(tmp_path):
    """No damping anywhere: the energy T + V + V_c gained is the work of the held torques. The
    commands paired with the step before or after give a work 2 % off (measured)."""
    data = load_scene(CONFIG / "grasp_cylinder.yaml").to_dict()
    data["model"]["damping"] = 0.0
    data["model"]["contact"]["damping"] = 0.0
    (tmp_path / "lossless.yaml").write_text(scene_from_dict(data).to_yaml())
    task = task_from_dict({"scene": "lossless.yaml", "duration": 0.6, "setpoints": [{"t": 0.0, "value": 0.5}],
                           "controller": {"sample_steps": 2, "delay_steps": 3}}, base=tmp_path)

    def two_levels(sample_period, **_):  # closes, then presses harder from 0.25 s
        return lambda t, setpoint, measured: 0.01 if t < 0.25 else 0.02

    run = run_task(task, two_levels)
    sim = Simulator(task.scene)  # the same run again, to read the core's energy column at both ends
    x0 = np.array([[*sim.q, *sim.v]])
    for tau in run.samples["command"][:-1]:
        sim.step(float(tau))
    assert sim.q[0] == run.samples["theta1"][-1]  # bit for bit the task's run
    e0 = state_columns(sim.system, np.array([0.0]), x0)[0][0]
    e1 = state_columns(sim.system, np.array([sim.time]), np.array([[*sim.q, *sim.v]]))[0][0]
    assert run.scores["motor_work"] > 2e-3 and run.samples["grip_force"].max() > 0.5  # it pressed the cup
    assert e1 - e0 == pytest.approx(run.scores["motor_work"], rel=1e-4)


# -- the suite -------------------------------------------------------------------------------
def test_the_shipped_grip_controller_passes_the_suite():
    failed = {}
    for path in installed_tasks():
        task = load_task(path)
        if task.input != "torque":  # the drive task: grip_voltage's (test_tasks_drive)
            continue
        run = run_task(task, grip_pi, label="grip_pi")
        if not run.ok:
            failed[run.task] = {k: run.scores[k] for k, ok in run.passed.items() if not ok}
    assert not failed
    assert {p.stem for p in installed_tasks()} >= {"hold_cup", "hold_soft", "hold_rigid", "fragile", "staircase",
                                                    "tip_pull", "release_reopen", "push_while_holding"}


def test_an_overshooting_controller_crushes_the_fragile_object_and_fails():
    task = load_task(TASKS / "fragile.yaml")
    run = run_task(task, grip_pi_aggressive, label="aggressive")
    assert not run.ok and run.passed["crushed"] is False and run.scores["crushed"] is True
    (crush,) = run.crushes
    f = run.samples["grip_force"]
    k = crush.step
    assert crush.force > 0.6 and f[k] == crush.force  # the crushing sample keeps its force
    assert np.all(f[:k] <= 0.6)  # the first sample beyond the break force
    assert np.all(f[k + 1:] == 0.0)  # removed: it pushes no more
    assert run.samples["crushed"][k] == 1 and run.samples["crushed"][k - 1] == 0
    # the finger closes through where the egg was, past the angle it touched it at
    assert run.samples["theta1"][-1] > run.samples["theta1"][k] + 0.1


# -- objects: their own contact law -----------------------------------------------------------
def _cup_scene(obj_keys: dict, contact: dict | None = None):
    data = load_scene(CONFIG / "grasp_cylinder.yaml").to_dict()
    data["objects"] = [{"name": "cup", "type": "circle", "center": [0.065, 0.040], "radius": 0.012, **obj_keys}]
    if contact:
        data["model"]["contact"].update(contact)
    return scene_from_dict(data)


def test_an_objects_stiffness_and_damping_act_as_the_scenes_would():
    own = _cup_scene({"stiffness": 1.0e6, "damping": 0.5})
    shared = _cup_scene({}, {"stiffness": 1.0e6, "damping": 0.5})
    # auto steps the compilable scene with the error-controlled dop853 and the other with a fixed
    # step: one named method for both (at a step that resolves the contact mode) compares the laws alone
    own, shared = (s.with_overrides(method="rk4", dt=2e-4) for s in (own, shared))
    a, b = simulate(own, kernel="python"), simulate(shared, kernel="python")
    assert np.array_equal(a.q, b.q) and np.array_equal(a.outputs["grip_force"], b.outputs["grip_force"])
    assert a.outputs["grip_force"][-1] > 0.1  # it did press the cup
    # the compiled law has one stiffness, here the object's (its only law): compiled, the same run
    assert Simulator(own).kernel.startswith("numba-")
    c, d = simulate(own, kernel="compiled"), simulate(shared, kernel="compiled")
    assert np.array_equal(c.q, d.q) and np.array_equal(c.outputs["grip_force"], d.outputs["grip_force"])


def test_object_keys_round_trip_and_are_refused_with_their_key():
    scene = _cup_scene({"stiffness": 1.0e3, "break_force": 0.6})
    assert scene_from_dict(scene.to_dict()) == scene
    with pytest.raises(ConfigError, match=r"objects\[0\]\.break_force"):
        objects_from_list([{"name": "c", "type": "circle", "center": [0, 1], "radius": 0.1, "break_force": -1}])
    with pytest.raises(ConfigError, match=r"objects\[0\]\.stiffness"):
        objects_from_list([{"name": "c", "type": "circle", "center": [0, 1], "radius": 0.1, "stiffness": 0}])
    with pytest.raises(ConfigError, match=r"objects\[0\]\.stiffness"):
        _cup_scene({"stiffness": 1e13})


# -- script: tip force spans, sampling and delay ---------------------------------------------
def test_a_tip_force_span_over_the_whole_run_equals_the_constant_tip_force():
    base = {"scene": "../grasp_cylinder.yaml", "duration": 0.4, "setpoints": [{"t": 0.0, "value": 0.5}]}
    span = task_from_dict({**base, "disturbances": [{"type": "tip_force", "start": 0.0, "end": 0.4,
                                                     "force": [0.0, -0.2]}]}, base=TASKS)
    plain = task_from_dict(base, base=TASKS)
    plain = dataclasses.replace(plain, scene=dataclasses.replace(plain.scene, tip_force=(0.0, -0.2)))
    a, b = run_task(span, grip_pi), run_task(plain, grip_pi)
    for name in ("grip_force", "theta1", "command"):
        assert np.array_equal(a.samples[name][:-1], b.samples[name][:-1])


def test_sample_period_and_delay_in_whole_steps():
    seen = []

    def factory(sample_period, **_):
        def control(t, setpoint, measured):
            seen.append((t, sample_period, set(measured) >= {"grip_force", "theta1", "theta1_dot"}))
            return 0.001 * len(seen)  # the n-th command
        return control

    task = task_from_dict({"scene": "../grasp_cylinder.yaml", "duration": 0.02, "setpoints": [{"t": 0.0, "value": 0.5}],
                           "controller": {"sample_steps": 4, "delay_steps": 3}}, base=TASKS)
    run = run_task(task, factory)
    assert [round(t, 12) for t, _, _ in seen] == [0.0, 0.004, 0.008, 0.012, 0.016]
    assert all(p == pytest.approx(0.004) and ok for _, p, ok in seen)
    # command n (computed at step 4n) acts from step 4n + 3: steps 0-2 hold 0
    expected = [0.0] * 3 + [0.001 * (1 + (k - 3) // 4) for k in range(3, 20)]
    assert np.allclose(run.samples["command"][:20], expected, rtol=0, atol=1e-15)


def test_bad_tasks_are_refused_naming_the_key(tmp_path):
    with pytest.raises(ConfigError, match="controller.delay_steps"):
        task_from_dict({"scene": "../grasp_cylinder.yaml", "setpoints": [{"t": 0, "value": 1}],
                        "controller": {"delay_steps": 1.5}}, base=TASKS)
    with pytest.raises(ConfigError, match=r"setpoints\[1\]\.t"):
        task_from_dict({"scene": "../grasp_cylinder.yaml", "setpoints": [{"t": 0, "value": 1}, {"t": 0, "value": 2}]},
                       base=TASKS)
    with pytest.raises(ConfigError, match="limits"):
        task_from_dict({"scene": "../grasp_cylinder.yaml", "setpoints": [{"t": 0, "value": 1}],
                        "limits": {"speed": 1}}, base=TASKS)
    with pytest.raises(ConfigError, match="--controller"):
        load_factory("finger_sim.tasks.controllers:nothing")
    with pytest.raises(ConfigError, match="--param"):
        parse_controllers([], ["nobody.kp=1"], [])
    with pytest.raises(FingerSimError, match=r"controller 'nan' returned nan at t = 0 s"):
        run_task(load_task(TASKS / "hold_cup.yaml"), lambda sample_period: lambda t, sp, m: math.nan, label="nan")


# -- the command -------------------------------------------------------------------------------
def test_tasks_command_writes_report_and_json_and_exits_by_the_result(tmp_path, capsys):
    out = tmp_path / "r"
    code = main(["tasks", str(TASKS / "fragile.yaml"), "--out", str(out), "--no-figures",
                 "--controller", "pi=finger_sim.tasks.controllers:grip_pi",
                 "--controller", "hot=finger_sim.tasks.controllers:grip_pi_aggressive"])
    assert code == 1  # hot fails
    data = json.loads((out / "metrics.json").read_text())
    assert [(d["controller"], d["passed"]) for d in data] == [("pi", True), ("hot", False)]
    assert data[1]["scores"]["crushed"] is True and data[1]["crushes"][0]["object"] == "egg"
    assert data[1]["scores"]["settle_time"] == "inf"
    text = (out / "report.md").read_text()
    assert "| crushed | = no | no ✔ | yes ✘ |" in text
    assert main(["tasks", str(TASKS / "fragile.yaml"), "--out", str(out), "--no-figures"]
                + ["--controller", "pi=finger_sim.tasks.controllers:grip_pi"]) == 0
    # a gain sweep: one column per value, scored the same way
    assert main(["tasks", str(TASKS / "hold_cup.yaml"), "--out", str(out), "--no-figures", "--vary", "ki=2,4"]) == 0
    data = json.loads((out / "metrics.json").read_text())
    assert [d["controller"] for d in data] == ["grip_pi[ki=2]", "grip_pi[ki=4]"]
    # the same sweep in two chunks: the second chunk's run is the whole sweep's second, bit for bit
    whole = data
    assert main(["tasks", str(TASKS / "hold_cup.yaml"), "--out", str(out), "--no-figures", "--vary", "ki=2,4",
                 "--chunk", "2/2"]) == 0
    assert json.loads((out / "metrics.json").read_text()) == whole[1:]
    capsys.readouterr()
    assert main(["tasks", str(TASKS / "fragile.yaml"), "--controller", "x=no_such_module:f"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "--controller" in err


def test_a_run_pressed_through_its_object_fails_as_not_completed(caplog):
    """The aggressive PI drives the distal phalanx into the foam cup (k_c = 1e3) past its radius ρ3:
    the run stops inside that step and the task fails as `completed`; the shipped PI completes."""
    task = load_task(TASKS / "hold_soft.yaml")
    run = run_task(task, grip_pi_aggressive, label="aggressive")
    assert run.passed["completed"] is False and not all(run.passed.values())
    t_end = run.samples["t"][-1]
    assert t_end < task.scene.duration - task.scene.dt  # it stopped early, at the step that went too deep
    depth_mm = float(re.search(r"went ([0-9.]+) mm into object 'foam_cup'", caplog.text).group(1))
    assert depth_mm == pytest.approx(1e3 * task.scene.phalanx_radius[1], rel=1e-3)  # located where it reaches ρ3
    t_stop = float(re.search(r"at t = ([0-9.]+) s", caplog.text).group(1))
    assert t_end < t_stop <= t_end + task.scene.dt  # inside the step that went too deep
    assert "completed" not in run_task(task, grip_pi, label="pi").passed
