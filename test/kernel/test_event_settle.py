"""A step with a contact onset or release taken whole in the kernel (`kernel.event_step._settle`,
`kernel.event_crossing`, whose gap loop is Python's guard loop compiled: `locate.guard_loop`, `locate.gap_guard`).

The kernel locates the crossing on its internal steps' dense output and continues or restarts the
solution from it, as Python's step does after the hand-over. Two references, stepped side by side:
the Python step alone (`_event_step` off: main's path before the compiled step) and the hand-over path
(`EventStep.locates` off: Python locates what the kernel hands over). After every step the states,
torque, error estimate and impact count are equal bit for bit, and so is the end of the run (a phalanx
axis in the object raises the same error); on the contact scenes every onset and release is taken here.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
import pytest

pytest.importorskip("numba")
from finger_sim.errors import SimulationDiverged  # noqa: E402
from finger_sim.simulate import Simulator  # noqa: E402
from helpers import EVENT_PROFILES, EVENT_SCENES, event_scene, with_profile  # noqa: E402

#: The contact scenes: their onsets and releases are all taken by the kernel, no crossing located by Python.
CONTACT_SCENES = ("grasp_cylinder", "press_table", "grasp_impact", "grasp_rigid")


def located_in_python(sim: Simulator) -> list:
    """The steps at which `sim`'s Python event loop locates a crossing (its `_locate`, observed)."""
    steps: list = []
    locate = sim._locate

    def observed(*args):  # type: ignore[no-untyped-def]
        steps.append(sim.step_index)
        return locate(*args)

    sim._locate = observed
    return steps


def record(sim: Simulator, command: float | None):
    """The state, torque, error estimate and impacts after a step, or the error that ended the run."""
    try:
        state = sim.step(command)
    except SimulationDiverged as exc:
        return str(exc)
    return state, sim.torque, sim.error_estimate, sim.impacts


def run_side_by_side(scene, command: Callable[[int], float | None] = lambda k: None) -> tuple[int, int, list, list]:
    """Steps the kernel's Simulator, the Python step's and the hand-over's together, comparing after every
    step; (steps settled in the kernel, steps the kernel took, steps where it located in Python, steps where
    the reference did)."""
    kernel, python, handed = Simulator(scene), Simulator(scene), Simulator(scene)
    assert kernel._event_step is not None and kernel._event_step.locates
    python._event_step = None
    handed._event_step.locates = False
    in_python, reference = located_in_python(kernel), located_in_python(python)
    for k in range(scene.step_count):
        a = record(kernel, command(k))
        assert a == record(python, command(k)), k
        assert a == record(handed, command(k)), k
        if isinstance(a, str):
            break
    return kernel._event_step.settled, kernel._event_step.taken, in_python, reference


@pytest.mark.parametrize("name", EVENT_SCENES)
def test_settled_steps_equal_the_python_step_bit_for_bit(name: str) -> None:
    settled, taken, in_python, reference = run_side_by_side(event_scene(name))
    if name in CONTACT_SCENES:
        assert settled >= 1 and not in_python  # every onset and release taken whole by the kernel
        assert settled == len(set(reference))  # one settled step per step the reference located in
        # every step in the kernel: the one after a crossing that ended its step too (it restarts from that output)
        assert taken == event_scene(name).step_count


@pytest.mark.parametrize("profile", ["ramp", "sine"])
@pytest.mark.parametrize("name", ["grasp_impact", "grasp_rigid"])
def test_settled_steps_under_smooth_inputs(name: str, profile: str) -> None:
    settled, _, in_python, reference = run_side_by_side(with_profile(name, EVENT_PROFILES[profile]))
    assert reference and settled >= 1


def test_held_commands_onto_the_cup_and_away() -> None:
    """Commands held as the node sends them: onsets and releases under held values, restarts between them."""
    scene = event_scene("grasp_impact").with_overrides(duration=0.3)
    values = np.repeat([0.0, 0.02, -0.01, 0.03], 75)
    settled, _, in_python, reference = run_side_by_side(scene, lambda k: float(values[k]))
    assert reference and settled >= 1 and not in_python


@pytest.mark.parametrize("name", ["grasp_impact", "grasp_rigid", "paper_to_stop", "hard/stops_elastic"])
def test_whole_runs_of_simulate_equal_step_by_step(name: str) -> None:
    """`simulate`'s stretches (`kernel.run_stretch`) take settled steps too, stop impacts included: every state
    and the impact count as the Python step's."""
    from finger_sim.kernel import run_stretch

    scene = event_scene(name)
    kernel, python = Simulator(scene), Simulator(scene)
    python._event_step = None
    in_python = located_in_python(kernel)
    xs = run_stretch.advance(kernel, scene.step_count)
    reference = np.array([(*s.q, *s.v) for s in (python.step() for _ in range(scene.step_count))])
    np.testing.assert_array_equal(xs, reference)
    assert kernel.impacts == python.impacts
    assert not in_python, name


#: The scenes with MCP stops: their impacts (bounces, the start of a rest) are applied in the kernel.
STOP_SCENES = ("paper_to_stop", "hard/stops_elastic")  # (finger_default's first seconds start on the stop: no
# impact; grasp_release's square input is a new function at every step, which the kernel does not locate under;
# both are stepped side by side in EVENT_SCENES)


@pytest.mark.parametrize("name", STOP_SCENES)
def test_stop_impacts_in_the_kernel_equal_the_python_step(name: str) -> None:
    """Every stop impact the reference applies (its only crossings) is applied in the kernel (`event_step._impact`):
    states, estimates and impact counts bit for bit (`run_side_by_side`), no crossing located in Python."""
    settled, _, in_python, reference = run_side_by_side(event_scene(name))
    assert reference and settled == len(set(reference)) and not in_python


def test_the_kernels_gap_loop_is_the_python_guard_loop() -> None:
    """`event_crossing.first_crossing` runs `locate.guard_loop` and `locate.gap_guard` compiled from their own
    code objects (not copies); the side-by-side runs above hold its answers to Python's bit for bit."""
    from finger_sim.kernel import event_crossing
    from finger_sim.simulation import locate

    assert event_crossing._guard_loop.py_func.__code__ is locate.guard_loop.__code__
    assert event_crossing._gap_guard.py_func.__code__ is locate.gap_guard.__code__


def test_the_kernels_rest_test_is_the_stops_rest_verdict() -> None:
    """The impact's rest test in the kernel (`event_step._impact`) is `stops.rest_verdict` compiled from its
    own code object, and `JointStops.rests` asks the same function with no slack: the spec's rule (the free
    acceleration closes the gap and the rebound rises no higher than REST_HEIGHT, h = ṙ² / 2|a|) at states
    on either side of each edge, and the kernel's margin turning them UNSURE."""
    from finger_sim.effects import stops
    from finger_sim.kernel import event_step

    assert event_step.rest_verdict.py_func.__code__ is stops.rest_verdict.__code__
    joint_stops, a = stops.JointStops(0.0, 1.0, 0.0), 2.0  # a: |free acceleration into the upper gap|, rad/s²
    edge = (2.0 * stops.REST_HEIGHT * a) ** 0.5  # the rebound rate that rises exactly REST_HEIGHT, rad/s
    for rate, rests in ((0.0, True), (0.99 * edge, True), (1.01 * edge, False)):
        v_plus = (-rate, 0.0, 0.0)  # leaving the upper gap (upper − θ1) at gap' = rate
        assert joint_stops.rests(1, (1.0, 0.0, 0.0), v_plus, (a, 0.0, 0.0)) is rests
        assert joint_stops.rests(1, (1.0, 0.0, 0.0), v_plus, (-a, 0.0, 0.0)) is False  # pulled off the stop
        verdict = stops.RESTS if rests else stops.BOUNCES
        assert event_step.rest_verdict(-a, rate, 0.0) == stops.rest_verdict(-a, rate, 0.0) == verdict
    assert event_step.rest_verdict(-a, 0.999 * edge, 0.01 * a) == stops.UNSURE  # within the margin of the edge
    assert event_step.rest_verdict(-1e-12, 0.0, 1e-9) == stops.UNSURE
