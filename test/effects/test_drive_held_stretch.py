"""A stuck mesh's held stretch taken at once (`actuators.record.held_steps`) is the same run as `Simulator.step`
one step at a time: every state and every drive output, bit for bit, on both kernels; and the stretch is taken."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

import reference as ref
from finger_sim import stepper_slot
from finger_sim.actuators import record
from finger_sim.actuators.drive import STUCK
from finger_sim.inputs import Square
from finger_sim.scene import load_scene
from finger_sim.simulate import Simulator, simulate


def scenes():
    grasp = load_scene(ref.CONFIG / "drive_grasp.yaml")
    back = load_scene(ref.CONFIG / "drive_grasp_backdrivable.yaml")
    # a square voltage: grasp, stuck hold, back-driven opening, grasp again (several held stretches, each ended
    # by a switch of the input or by the mesh breaking free)
    square = dataclasses.replace(grasp, torque=Square(amplitude=6.0, frequency=2.0), duration=1.0, name="square")
    return [grasp, back, square]


def one_by_one(scene, kernel):
    """(states, drive outputs) of `Simulator.step` called once per step, the outputs read after each."""
    sim = Simulator(scene, kernel=kernel)
    rows = [record.outputs_now(sim)]
    xs = [(*sim.q, *sim.v)]
    for _ in range(scene.step_count):
        s = sim.step()
        xs.append((*s.q, *s.v))
        rows.append(record.outputs_now(sim))
    return np.array(xs), np.array(rows)


@pytest.mark.parametrize("kernel", ["python", "compiled"])
@pytest.mark.parametrize("scene", scenes(), ids=lambda s: s.name)
def test_held_stretches_give_the_states_and_outputs_of_one_step_at_a_time(scene, kernel):
    xs, rows = one_by_one(scene, kernel)
    run = simulate(scene, kernel=kernel)
    assert np.array_equal(np.hstack([run.q, run.v]).view(np.uint64), xs.view(np.uint64))
    names = Simulator(scene, kernel=kernel).system.output_names()
    for i, name in enumerate(names):
        assert np.array_equal(run.outputs[name].view(np.uint64), rows[:, i].view(np.uint64)), name
    sim = Simulator(scene, kernel=kernel)  # the bench's whole run (`kernel.advance`): the same states
    assert np.array_equal(stepper_slot.kernel().advance(sim, scene.step_count).view(np.uint64), xs[1:].view(np.uint64))


def test_a_self_locked_hold_is_taken_in_one_stretch_per_level_of_the_input():
    scene = load_scene(ref.CONFIG / "drive_grasp.yaml")  # 6 V until 0.3 s, then 0 V: stuck on the cup from ~0.05 s
    sim = Simulator(scene, kernel="compiled")
    while sim.system.drive.mode != STUCK:  # the step that sticks holds for the rest of it: its end margin is known
        sim.step()
    k = sim.step_index
    taken = record.held_steps(sim, 10_000)
    assert taken > 200 and sim.step_index == k + taken == 299  # up to the last step before the switch at 0.3 s
    assert record.held_steps(sim, 10_000) == 0  # the step that ends on the switch goes through `Simulator.step`
    sim.step()
    assert record.held_steps(sim, 10_000) == 0  # the new level (0 V): its first step decides in `Simulator.step`
    sim.step()
    rest = scene.step_count - sim.step_index
    assert record.held_steps(sim, rest) == rest and sim.system.drive.mode == STUCK  # the self-locked hold at 0 V
