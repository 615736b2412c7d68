"""The batch's compiled contact rows (`rollout_loop.run_rows`, `event_checks.kink`) against
`simulate`, bit for bit, on the shipped contact scenes.

The loop steps the fingers itself and hands only a step that may hold a contact event to the
finger's Simulator; its event check carries each step's end gaps and rates into the next step.
Whatever it skips or reuses, every recorded angle and the run's max |Φ| must be the Simulator's
own, to the last bit, and the loop must have taken nearly every step itself.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("numba")
from finger_sim.batch import run_batch  # noqa: E402
from finger_sim.scene import load_scene, scene_from_dict  # noqa: E402
from finger_sim.simulate import simulate  # noqa: E402

CONFIG = Path(__file__).resolve().parents[2] / "config"
#: Steps a run may hand to its Simulator: the onset (and release) steps, not the held contact.
MAX_HANDED = 3


@pytest.mark.parametrize("method", ["rk4", "rk6", "euler"])
@pytest.mark.parametrize("name", ["grasp_cylinder", "press_table", "grasp_impact"])
def test_contact_rows_equal_simulate_bit_for_bit(name, method):
    data = load_scene(CONFIG / f"{name}.yaml").to_dict()
    data["integrator"]["method"] = method
    scene = scene_from_dict(data)
    ref = simulate(scene, kernel="compiled")
    got = run_batch([scene, scene], record=True)
    assert got.compiled.all()
    assert 1 <= got.handed_over[0] <= MAX_HANDED  # the onset went to the Simulator, the rest ran in the loop
    for row in range(2):
        np.testing.assert_array_equal(got.trajectories[row], ref.q)
        assert got.max_residual[row] == ref.residual.max()
    assert got.grip_force is not None and got.grip_force[0] == ref.outputs["grip_force"][-1]
