"""finger_sim.bench.contact_step_profile's accounting against the Python step: its event steps are the steps
where the Python DOP853 step (the kernel's event step switched off) locates a crossing, and its count of
DOP853 internal steps in the kernel's steps is the integrator's own count over the same steps."""

from __future__ import annotations

import pytest

from finger_sim.bench import contact_step_profile
from finger_sim.bench.plan import config_dir
from finger_sim.scene import load_scene
from finger_sim.simulate import Simulator


def python_reference(name: str) -> tuple[set[int], int, int]:
    """(the steps with a located crossing, accepted internal steps over the other steps but the first,
    the step count) of one run with the Python DOP853 step."""
    sim = Simulator(load_scene(config_dir() / f"{name}.yaml"))
    sim._event_step = None  # noqa: SLF001  (the Python step with the compiled gap check)
    located: set[int] = set()
    locate = sim._locate  # noqa: SLF001

    def counted(*args):  # type: ignore[no-untyped-def]
        located.add(sim.step_index)
        return locate(*args)

    sim._locate = counted  # noqa: SLF001
    accepted = 0
    for k in range(sim.scene.step_count):
        before = sim.integrator.accepted
        sim.step()
        if k and k not in located:
            accepted += sim.integrator.accepted - before
    return located, accepted, sim.scene.step_count


@pytest.mark.parametrize("name", ["grasp_impact", "grasp_rigid"])
def test_event_steps_and_internal_steps_are_those_of_the_python_step(name):
    located, accepted, steps = python_reference(name)
    profile = contact_step_profile.profile_scene(name, runs=1)
    assert len(located) == 2  # the onset and the release
    assert profile["steps"] == steps
    assert profile["n event"] == len(located)
    assert profile["n kernel"] == steps - 1 - len(located)
    assert profile["internal"] == accepted
    parts = profile["first"] + profile["kernel"] + profile["event"]
    assert profile["whole"] == pytest.approx(parts, rel=1e-12)
    assert profile["kernel call"] > 0.0  # timed in other runs than the steps: no order between the two under load
