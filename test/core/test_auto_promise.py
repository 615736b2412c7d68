"""`method: auto` keeps its accuracy promise on the hard scenes of issue 22 (config/hard/).

Each scene's run is held against test/hybrid_reference.py: the spec's equations written again
(rigid-body mass matrix, dense KKT solve, spec §7 contact, spec §3 stops), solved by scipy DOP853 at
rtol 1e-11 and restarted at every event; nothing of finger_sim in it. Energies are computed by
test/reference.py and the reference's contact potential, not by the core.
"""

from __future__ import annotations

import logging
import math
from pathlib import Path

import numpy as np
import pytest
import yaml

import hybrid_reference as hybrid
import reference as ref
from finger_sim import auto
from finger_sim.errors import ConfigError, SimulationDiverged
from finger_sim.scene import load_scene
from finger_sim.simulate import Simulator, simulate

HARD = Path(__file__).resolve().parents[2] / "config" / "hard"
#: issue 22's table: the six scenes where the table's fixed-step choice missed 1e-6 rad by up to 400×
SIX = ("elastic_impact", "chatter_wall", "grasp_release", "friction_table", "rigid_fast", "stops_elastic")
#: An estimate is an estimate: the run's estimated error is at least its true error / ESTIMATE_FACTOR (an
#: optimistic estimate hides an error: this side is the promise) and at most PESSIMISM × its true error (a
#: pessimistic one only warns early). It is a sum of local errors, without their cancelling, growth or decay
#: along the flow; since a located contact onset or release ends an internal step (`DormandPrince853.cut_at`)
#: the true error fell up to 11× on the hard scenes while the sum kept or grew (measured 0.7-14×:
#: friction_table's estimate 1.15e-9 → 1.14e-9 rad while its error fell 1.8e-10 → 9.5e-11; grasp_release's
#: 1.0e-8 → 2.1e-8, the steps ending at its releases each adding their own local estimate, while its error
#: fell 2.0e-8 → 1.8e-9).
ESTIMATE_FACTOR = 10.0
PESSIMISM = 100.0


def data(name: str) -> dict:
    return yaml.safe_load((HARD / f"{name}.yaml").read_text(encoding="utf-8"))


@pytest.fixture(scope="module")
def references() -> dict[str, hybrid.HybridReference]:
    return {}


def reference_of(references, name: str) -> hybrid.HybridReference:
    if name not in references:
        references[name] = hybrid.solve(data(name))
    return references[name]


def theta_error(run, reference: hybrid.HybridReference) -> float:
    return float(np.max(np.abs(run.q - reference.states(run.t)[:3].T)))


@pytest.mark.parametrize("name", SIX)
def test_auto_is_within_its_tolerance_on_the_hard_scenes(name, references):
    scene = load_scene(HARD / f"{name}.yaml")
    assert scene.tolerance == auto.AUTO_TARGET == 1e-6
    run = simulate(scene)
    error = theta_error(run, reference_of(references, name))
    assert error <= scene.tolerance, (name, run.method, error)
    # the run reports its own estimate, and it is an honest one
    assert math.isfinite(run.error_estimate) and run.error_estimate <= scene.tolerance
    assert error / ESTIMATE_FACTOR <= run.error_estimate <= error * PESSIMISM, (error, run.error_estimate)
    assert f"est. error = {run.error_estimate:.1e} rad" in run.summary()


def test_a_tighter_tolerance_is_kept_too(references):
    scene = load_scene(HARD / "stops_elastic.yaml").with_overrides(tolerance=1e-8)
    run = simulate(scene)
    assert theta_error(run, reference_of(references, "stops_elastic")) <= 1e-8
    assert "for 1e-08 rad on θ" in run.method_reason


def test_the_old_table_choice_misses_the_tolerance_where_auto_now_keeps_it(references):
    # the regression: the table's rk4 with contact substeps (today's path) on the elastic impact
    scene = load_scene(HARD / "elastic_impact.yaml").with_overrides(method="rk4", dt=1e-3 / 9)
    run = simulate(scene.with_overrides(duration=0.2))
    assert theta_error(run, reference_of(references, "elastic_impact")) > 10 * scene.tolerance


def energy(q, v, d: dict) -> float:
    """T + V + V_c by the independent formulas (J)."""
    model = d["model"]
    fx = ref.Effects(k=model.get("spring_stiffness", ref.K_PAPER), c=model.get("damping", 0.0))
    c = model["contact"]
    law = hybrid.ContactLaw(c["stiffness"], c["exponent"], c["damping"], c["friction"], c["slip_velocity"],
                            tuple(model["phalanx_radius"]))
    return ref.energy(q, v, fx) + hybrid.contact_energy(q, d["objects"], law)


def test_energy_never_increases_in_a_damped_contact_scene():
    # the cup with Hunt–Crossley damping and no torque: T + V + V_c can only fall
    d = yaml.safe_load((HARD.parent / "grasp_impact.yaml").read_text(encoding="utf-8"))
    run = simulate(load_scene(HARD.parent / "grasp_impact.yaml"))
    e = np.array([energy(q, v, d) for q, v in zip(run.q, run.v)])
    # up to the integration error: rtol = 1e-9 of the error control (auto at 1e-6 rad), over the whole run
    assert np.max(e - np.minimum.accumulate(e)) <= 1e-9 * e[0]
    assert e[-1] < 0.9 * e[0]  # the impact took energy out


def test_an_elastic_impact_keeps_its_energy_under_auto_and_radau_by_hand_is_warned_about(caplog):
    d = data("elastic_impact")
    scene = load_scene(HARD / "elastic_impact.yaml")
    run = simulate(scene)
    e0 = energy(run.q[0], run.v[0], d)
    assert abs(energy(run.q[-1], run.v[-1], d) - e0) <= 1e-6 * e0  # d_c = 0, μ = 0: conserved
    with caplog.at_level(logging.WARNING, logger="finger_sim.auto"):
        stiff = simulate(scene.with_overrides(method="radau"))
    assert "radau at dt = 0.001 s does not resolve the contact mode" in caplog.text
    assert "% of the energy out of every contact" in caplog.text
    lost = 1.0 - energy(stiff.q[-1], stiff.v[-1], d) / e0
    assert lost > 0.005  # the warning is warranted: radau damps the unresolved contact mode


def test_a_phalanx_axis_inside_an_object_stops_the_run_at_that_depth():
    scene = load_scene(HARD / "soft_pass_through.yaml")
    reference = hybrid.solve(data("soft_pass_through") | {"duration": 0.02})
    law = hybrid.ContactLaw(1e3, 1.5, 0.0)
    ts = np.arange(0, 0.02, 1e-5)
    depth = [max(dd for dd, _, _ in hybrid._candidates(reference.states(np.array([t]))[:3, 0], data("soft_pass_through")["objects"], law.rho))
             for t in ts]
    crossing = ts[np.argmax(np.array(depth) > 0.007)]  # the distal axis reaches the cup (ρ3 = 7 mm)
    with pytest.raises(SimulationDiverged) as info:
        simulate(scene)
    message = str(info.value)
    assert "\n" not in message and "'cup'" in message and "distal phalanx" in message and "as deep as its radius 7 mm" in message
    assert crossing - 1e-5 <= info.value.t <= crossing  # located inside the step (test_depth_event.py: to 1e-7 s)


def test_the_same_inputs_give_the_same_steps_bit_for_bit():
    # resim: a fresh Simulator and a reset one step the same held torques to identical states
    scene = load_scene(HARD / "grasp_release.yaml")
    torques = [0.05 * math.sin(40.0 * k * scene.dt) for k in range(400)]
    runs = []
    sim = Simulator(scene)
    for _ in range(2):
        runs.append([sim.step(tau) for tau in torques])
        sim.reset()
    runs.append([Simulator(scene).step(tau) for tau in torques[:1]])
    assert runs[0] == runs[1] and runs[0][:1] == runs[2]


@pytest.mark.parametrize("value", [0.0, -1e-6, 1e-11, 0.1, "1e-6"])
def test_the_tolerance_key_is_checked(value):
    d = data("elastic_impact")
    d["integrator"]["tolerance"] = value
    from finger_sim.scene import scene_from_dict

    with pytest.raises(ConfigError, match="integrator.tolerance"):
        scene_from_dict(d)


def test_a_log_made_before_auto_changed_its_choice_resimulates_with_the_method_that_made_it():
    from finger_sim.run_log import _recorded_method

    scene = load_scene(HARD.parent / "paper_to_stop.yaml")  # auto chose rk4 here before issue 22
    old = simulate(scene.with_overrides(method="rk4"))
    again = simulate(_recorded_method(scene, "rk4"))
    assert again.method == "rk4" and np.array_equal(again.q, old.q)  # bit for bit, as resim compares
    assert _recorded_method(scene, "dop853") is scene  # a log of today's choice: the scene as it is


def test_a_scene_auto_cannot_step_in_real_time_is_named_at_start_up(caplog):
    # a mode of 1e6 rad/s at 1 ms: DOP853 settles at |s|·h ≈ 6, about 167 internal steps per step
    scene = load_scene(HARD / "rigid_fast.yaml")
    with caplog.at_level(logging.WARNING, logger="finger_sim.auto"):
        note = auto.realtime_note(scene, complex(-1e6, 0.0))
    attempts = 1e6 * 1e-3 / auto.DOP853_STABILITY
    cost = auto.ATTEMPT_US * attempts + auto.EVENT_STEP_US
    assert f"about {attempts:.0f} internal steps per step, about {cost:.0f} µs of CPU against 500 µs" in note
    assert f"a realtime_factor ≤ {500 / cost:.2g} holds it" in note and note in caplog.text
    # every shipped scene with objects or stops is predicted to hold real time at 1 kHz (docs/auto_accuracy.md)
    for name in ("grasp_rigid", "grasp_impact", "stiff_spring", "finger_default"):
        assert "cannot hold" not in auto.choose_method(load_scene(HARD.parent / f"{name}.yaml"))[1]
