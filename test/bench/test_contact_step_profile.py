"""finger_sim.bench.contact_step_profile's accounting against the Python step: its event steps are the steps
where the Python DOP853 step (the kernel's event step switched off) locates a crossing, and its count of
DOP853 internal steps in the kernel's steps is the integrator's own count over the same steps."""

from __future__ import annotations

import pytest

from finger_sim.bench import contact_step_profile, event_attempts
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


def counters_by_step(name: str) -> tuple[dict[int, tuple[int, int]], dict[int, int]]:
    """The integrator's own accepted and rejected counts of every step of Python's counted loop, and for each
    step with a cut at a kink the accepted internal steps its pass 1 took past the straddling one (those the
    cut deletes from the history)."""
    sim = Simulator(load_scene(config_dir() / f"{name}.yaml"))
    sim._event_step, sim.integrator._steps = None, None  # noqa: SLF001  (every attempt counted)
    integ, past = sim.integrator, {}
    cut_at = integ.cut_at

    def counted_cut(s, *args):  # type: ignore[no-untyped-def]
        starts = list(integ._history_starts)  # noqa: SLF001
        straddling = max(i for i, start in enumerate(starts) if start < s)
        ended = cut_at(s, *args)
        past[sim.step_index] = len(starts) - straddling - 1 if ended is not None else 0  # none dropped without a cut
        return ended

    integ.cut_at = counted_cut
    counts = {}
    for k in range(sim.scene.step_count):
        before = (integ.accepted, integ.rejected)
        sim.step()
        counts[k] = (integ.accepted - before[0], integ.rejected - before[1])
    return counts, past


@pytest.mark.parametrize("name", ["grasp_impact", "grasp_rigid"])
def test_event_attempts_by_phase_add_up_to_the_integrators_own_counts(name):
    located, _, _ = python_reference(name)
    counts, past = counters_by_step(name)
    steps, accepted, rejected = event_attempts.count_scene(name)
    assert set(steps) == located
    assert (accepted, rejected) == (sum(a for a, _ in counts.values()), sum(r for _, r in counts.values()))
    for k, attempts in steps.items():
        phases = attempts.by_phase()
        assert (sum(a for a, _ in phases.values()), sum(r for _, r in phases.values())) == counts[k]
        assert phases["pass 1 past the kink"][0] == past[k]  # the cut dropped exactly those accepted steps
        assert phases["pass 1 to the kink"][0] >= 1
