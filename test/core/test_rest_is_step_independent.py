"""The stop's rest does not depend on the output step (issue 22, config/hard/grasp_release.yaml).

Spec §3 defines the stops by their impacts alone (q' → −e q'); with e < 1 and a push into the stop
the impacts form a Zeno series, and the finger's rest is its limit. The reference
(test/hybrid_reference.py: scipy DOP853 at rtol 1e-11, restarted at every impact, nothing of
finger_sim) follows the series 1000× further down than the project does (rebounds to 1e-14 rad),
so it stands for the model itself. Before the fix the project rested after any rebound shorter than
one output step, and θ moved with dt: 1.5e-4 rad off at 1 ms, 1.3e-5 at 0.5 ms.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import yaml

import hybrid_reference as hybrid
from finger_sim.scene import load_scene
from finger_sim.simulate import simulate

SCENE = Path(__file__).resolve().parents[2] / "config" / "hard" / "grasp_release.yaml"
#: The reference's rest: rebounds followed down to this height (rad), far below the project's cut.
REFERENCE_REST_HEIGHT = 1e-14


@pytest.fixture(scope="module")
def reference() -> hybrid.HybridReference:
    return hybrid.solve(yaml.safe_load(SCENE.read_text(encoding="utf-8")), rest_height=REFERENCE_REST_HEIGHT)


@pytest.mark.parametrize("dt", [1e-2, 1e-3, 5e-4])
def test_auto_meets_the_model_at_every_output_step(dt, reference):
    scene = load_scene(SCENE).with_overrides(dt=dt)
    run = simulate(scene)
    error = float(np.max(np.abs(run.q - reference.states(run.t)[:3].T)))
    assert error <= scene.tolerance, (dt, run.method, error)
