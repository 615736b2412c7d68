"""A phalanx's axis reaching an object (δ = ρ, spec §7) is an event located inside the step.

Reference: test/hybrid_reference.py (the spec's equations written again, scipy DOP853 at rtol 1e-11,
restarted at the contact onset) solves the soft impact of config/hard/soft_pass_through.yaml; the
crossing time t* is the root of its own event function ρ3 − δ(cup, distal) on that dense solution
(brentq to 1e-14 s). Nothing of finger_sim computes t*. Every stepping path must stop there with
the one-line error naming the object, the phalanx and the depth.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import yaml
from scipy.optimize import brentq

import hybrid_reference as hybrid
from finger_sim.batch import run_batch
from finger_sim.errors import SimulationDiverged
from finger_sim.rollouts import rollout
from finger_sim.scene import load_scene, scene_from_dict
from finger_sim.simulate import Simulator, simulate

HARD = Path(__file__).resolve().parents[2] / "config" / "hard"
RHO3 = 0.007  # m, the distal capsule of the scene
#: The crossing's time on auto's error-controlled path (its θ error ≤ 1e-6 rad at δ' ≈ 0.8 m/s,
#: about a lever of 0.08 m: ≈ 1e-7 s) and on rk4 at 0.1 ms (its θ error there ≈ 1e-6 rad).
AUTO_TIME_TOLERANCE = 1e-7
RK4_TIME_TOLERANCE = 1e-6


def soft_impact(**overrides) -> dict:
    data = yaml.safe_load((HARD / "soft_pass_through.yaml").read_text(encoding="utf-8"))
    data["name"] = "soft_pass_through"
    data.update(overrides)
    return data


def depth_crossing(data: dict, candidate: int) -> float:
    """t* where candidate `candidate` of the reference reaches ρ3 (s): the reference's own event function."""
    reference = hybrid.solve(data | {"duration": 0.03})
    law = hybrid.ContactLaw(rho=tuple(data["model"]["phalanx_radius"]))

    def event(t: float) -> float:
        q = reference.states(np.array([t]))[:3, 0]
        return hybrid._candidates(q, data["objects"], law.rho)[candidate][0] - RHO3

    ts = np.linspace(0.0, 0.03, 3001)
    values = np.array([event(t) for t in ts])
    first = int(np.argmax(values > 0.0))
    assert first > 0, "the reference never reaches the depth"
    return brentq(event, ts[first - 1], ts[first], xtol=1e-14, rtol=1e-15)


@pytest.fixture(scope="module")
def crossing() -> float:
    return depth_crossing(soft_impact(), 1)  # the cup's distal candidate (hybrid_reference's order)


def check(info: pytest.ExceptionInfo, expected: float, tolerance: float) -> None:
    message = str(info.value)
    assert "\n" not in message and "distal phalanx went 7 mm into object 'cup'" in message, message
    assert "as deep as its radius 7 mm" in message and f"t = {info.value.t:.6f} s" in message
    assert abs(info.value.t - expected) <= tolerance, (info.value.t, expected)


def test_auto_stops_at_the_located_crossing(crossing):
    scene = scene_from_dict(soft_impact())
    with pytest.raises(SimulationDiverged) as info:
        simulate(scene)
    check(info, crossing, AUTO_TIME_TOLERANCE)
    assert info.value.method == "dop853"


@pytest.mark.parametrize("kernel", ["python", "compiled"])
def test_a_fixed_step_method_stops_at_the_located_crossing(crossing, kernel):
    scene = scene_from_dict(soft_impact(integrator={"method": "rk4", "dt": 1e-4}))
    sim = Simulator(scene, kernel=kernel)
    with pytest.raises(SimulationDiverged) as info:
        for _ in range(scene.step_count):
            sim.step()
    check(info, crossing, RK4_TIME_TOLERANCE)


def test_a_batch_and_a_rollout_stop_there_too(crossing):
    scene = scene_from_dict(soft_impact(integrator={"method": "rk4", "dt": 1e-4}))
    with pytest.raises(SimulationDiverged) as info:
        run_batch([scene, scene])
    check(info, crossing, RK4_TIME_TOLERANCE)
    with pytest.raises(SimulationDiverged) as info:
        rollout(scene_from_dict(soft_impact()), nstep=30)
    check(info, crossing, AUTO_TIME_TOLERANCE)


def test_an_object_passed_through_within_one_step_is_caught():
    # a thin rod (R 1 mm) on the distal axis's path at 1 ms steps: the axis is in and out of it
    # within one step, so no step's end shows it (the old end-of-step check passed it silently)
    rod = {"name": "cup", "type": "circle", "center": [0.0626, 0.0228], "radius": 0.001}
    data = soft_impact(objects=[rod], integrator={"method": "rk4", "dt": 1e-3})
    expected = depth_crossing(data, 1)
    reference = hybrid.solve(data | {"duration": 0.03})
    k = int(expected / 1e-3)
    ends = reference.states(np.array([k * 1e-3, (k + 1) * 1e-3]))[:3].T
    law = hybrid.ContactLaw(rho=(0.008, RHO3))
    assert all(hybrid._candidates(q, [rod], law.rho)[1][0] < RHO3 for q in ends)  # neither end is that deep
    with pytest.raises(SimulationDiverged) as info:
        simulate(scene_from_dict(data))
    check(info, expected, RK4_TIME_TOLERANCE)
