"""The Simulator's compiled common step on scenes with events (`simulation.event_step`, `kernel.event_step`).

A step it takes skips Python's DOP853 driver and gap check; every other step goes to Python as
before (the same code that locates a crossing). The reference is that Python path alone
(`_event_step` switched off: main's path), run side by side: every state, torque and error estimate
bit for bit, on every shipped scene with stops or contact, under the scene's torque and under
commands held step by step as the node sends them, across resets and a state set from outside.
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("numba")
from finger_sim.errors import SimulationDiverged  # noqa: E402
from helpers import EVENT_PROFILES as PROFILES, EVENT_SCENES, event_scene, with_profile  # noqa: E402
from finger_sim.scene import load_scene  # noqa: E402
from finger_sim.simulate import Simulator  # noqa: E402

CONFIG = Path(__file__).resolve().parents[2] / "config"
#: Least share of the steps of a contact scene under its constant torque the kernel takes by itself.
MIN_TAKEN = 0.9

Command = Callable[[int, Simulator], "float | None"]


def run(scene, compiled: bool, command: Command = lambda k, sim: None,
        between: Callable[[int, Simulator], None] = lambda k, sim: None) -> tuple[np.ndarray, str, float]:
    """Every step's (q, q', torque, error estimate) under command(k, sim) (None: the scene's torque),
    with `between(k, sim)` before each step; the error that ended the run ("" if none); the share of
    steps the kernel took."""
    sim = Simulator(scene)
    if not compiled:
        sim._event_step = None  # the Python step alone
    rows, error = [], ""
    try:
        for k in range(scene.step_count):
            between(k, sim)
            state = sim.step(command(k, sim))
            rows.append((*state.q, *state.v, sim.torque, sim.error_estimate))
    except SimulationDiverged as exc:
        error = str(exc)
    share = sim._event_step.taken / scene.step_count if compiled else 0.0
    return np.array(rows), error, share


def assert_same(scene, command: Command = lambda k, sim: None,
                between: Callable[[int, Simulator], None] = lambda k, sim: None) -> float:
    """The compiled and the Python runs agree bit for bit; the kernel's share of the steps."""
    rows, error, share = run(scene, True, command, between)
    reference, reference_error = run(scene, False, command, between)[:2]
    np.testing.assert_array_equal(rows, reference)
    assert error == reference_error
    return share


@pytest.mark.parametrize("name", EVENT_SCENES)
def test_runs_under_the_scene_torque_equal_the_python_step_bit_for_bit(name):
    scene = event_scene(name)
    assert Simulator(scene)._event_step is not None
    share = assert_same(scene)
    if name in ("grasp_cylinder", "press_table", "grasp_impact", "grasp_rigid"):
        assert share >= MIN_TAKEN  # the common contact step no longer enters Python


@pytest.mark.parametrize("name", ["finger_default", "grasp_cylinder", "hard/grasp_release", "paper_to_stop"])
def test_held_commands_as_the_node_sends_them_equal_the_python_step(name):
    scene = event_scene(name)
    rng = np.random.default_rng(7)
    # runs of one held value (the solution continues) and a new value at every step (it restarts)
    values = np.repeat(rng.uniform(-0.03, 0.05, 40), rng.integers(1, 40, 40))
    assert assert_same(scene, lambda k, sim: float(values[k % len(values)])) > 0.5


def test_a_closed_loop_command_every_step_equals_the_python_step():
    scene = event_scene("finger_default").with_overrides(duration=0.6)

    def pd(k, sim):  # towards θ1 = 0.9 rad and back: the stops are reached
        goal = 0.9 if k < 300 else -0.2
        return 0.2 * (goal - sim.q[0]) - 0.01 * sim.v[0]

    assert assert_same(scene, pd) > 0.5


def test_resets_a_state_set_from_outside_and_mixed_torques_equal_the_python_step():
    scene = load_scene(CONFIG / "grasp_cylinder.yaml")

    def command(k, sim):  # the scene's constant, then held values, then the scene's again
        return None if k < 150 or k >= 330 else (0.02 if k < 250 else 0.03)

    def between(k, sim):
        if k == 200:
            sim.reset()  # a new integrator: the kernel starts over from Python's first step
        if k == 300:
            sim.q, sim.v = sim.q, (sim.v[0] * 0.5, sim.v[1] * 0.5, sim.v[2] * 0.5)  # not on the constraint: as main

    assert assert_same(scene, command, between) > 0.5


def test_the_common_steps_shortcut_gives_way_to_every_change_between_steps():
    """`EventStep.step` continues its last output at once when nothing changed since; each change below
    (the location switched off and on, a held value as another number type, the same value, the scene's
    torque again, a state set from outside) takes the full preparation, as the Python step would see it."""
    scene = load_scene(CONFIG / "grasp_impact.yaml")

    def command(k, sim):
        if k % 10 == 3:
            return np.float64(0.001)  # not a float: the held value is converted, as `Simulator.step` does
        if k % 10 in (4, 5):
            return 0.001  # the same held value: its function object is kept
        return None

    located = []  # the compiled run's (whether the kernel may locate, the crossings it located so far) before each step

    def between(k, sim):
        events = sim._event_step
        if events is not None:
            events.locates = k % 25 < 20  # crossings handed over to Python for 5 steps in 25
            located.append((events.locates, events.settled))
        if k == 70:
            sim.q, sim.v = tuple(list(sim.q)), tuple(list(sim.v))  # equal values, not the kernel's output objects

    assert assert_same(scene, command, between) > 0.5
    assert all(after == before for (may, before), (_, after) in zip(located, located[1:]) if not may)
    assert located[-1][1] > 0  # and it located crossings itself where it might


#: Torque profiles stepped by the kernel: smooth ones evaluated at every stage, piecewise-constant ones
#: held on each segment (switches inside a step go to Python). Levels near each scene's own torque.
@pytest.mark.parametrize("profile", sorted(PROFILES))
@pytest.mark.parametrize("name", ["paper_to_stop", "grasp_cylinder", "press_table", "hard/stops_elastic"])
def test_torque_profiles_on_stop_and_contact_scenes_equal_the_python_step_bit_for_bit(name, profile):
    share = assert_same(with_profile(name, PROFILES[profile]))
    assert share >= 0.3  # the kernel takes the profile's steps but those near a crossing, a switch or a release


@pytest.mark.parametrize("name", ["paper_to_stop", "hard/chatter_wall", "hard/grasp_release", "hard/stops_elastic"])
def test_the_shipped_profile_scenes_step_in_the_kernel(name):
    scene = event_scene(name)
    rows, error, share = run(scene, True)
    assert not error and share >= 0.5
    if name == "paper_to_stop":  # the ramp onto the stop and the rest on it (from ~0.43 s): all but the located impact
        assert share >= 0.99
    # τ after each step is the profile's at the step's end, as the Python step reports it
    reference = np.array([scene.torque.on_segment((k - 1) * scene.dt, k * scene.dt)(k * scene.dt)
                          for k in range(1, scene.step_count + 1)])
    np.testing.assert_array_equal(rows[:, 6], reference)
