"""The modes' one home per run (`state_layout.ModeValues`, `Simulator.mode_values`): a new element that
declares a mode, defined in this file alone, gets it stored in the run's home, reset and reported without
a line of the Simulator naming it, and its run matches an independent tight solve of the switched law
(test/reference.py's equations in numpy), under DOP853 too (which restarts its solution when the mode changes). The shipped owners (the stops' rest, friction's lock) keep
their values there too."""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass
from typing import ClassVar

import numpy as np
import pytest
import reference as ref

from finger_sim.effects import EFFECTS, Smooth
from finger_sim.effects.base import Vec3, effect
from finger_sim.effects.parameters import scalar
from finger_sim.scene import Scene, load_scene, scene_from_dict
from finger_sim.simulate import Simulator
from finger_sim.state_layout import ModeSet, OwnModes

KEY = "mcp_clutch_stiffness"
#: The clutch's mode: open (no torque) or engaged (the MCP spring acts); a controller's command switches it.
CLUTCH = ModeSet("clutch", ("open", "engaged"), ("command",))
OPEN, ENGAGED = 0, 1
STIFFNESS = 0.02  # N·m/rad
#: A free swing from θ1 = 0.4 rad; the clutch engages after ENGAGE_AT steps.
SCENE = {"model": {KEY: STIFFNESS, "spring_stiffness": 0.0}, "input": {"torque": {"type": "constant", "value": 0.0}},
         "initial": {"theta1": 0.4}, "duration": 0.05, "integrator": {"method": "rk4", "dt": 1e-3}}
ENGAGE_AT, STEPS = 20, 50
#: The reference's initial state (q, q') of SCENE.
Y0 = [*ref.assemble(SCENE["initial"]["theta1"]), 0.0, 0.0, 0.0]
#: rk4 at 1 ms over 50 ms against the tight solve, rad (the MCP spring's own test measures 6.5e-11 on
#: the same swing; engaging at 20 ms moves θ1(50 ms) by ≈ 1e-3 rad from the free swing)
REFERENCE_TOLERANCE = 1e-8
#: our DOP853 (rtol 1e-10, atol 1e-12) over the same swing against the tight solve, rad
DOP853_TOLERANCE = 1e-9


class McpClutch(OwnModes, Smooth):
    """A torsional MCP spring behind a clutch: Q = (−k θ1, 0, 0) while engaged, none while open. Its mode
    is read by its law from the run's home (`OwnModes.mode`) and switched between steps by a command."""

    affine_in_velocity: ClassVar[bool] = True
    modes: ClassVar[tuple[ModeSet, ...]] = (CLUTCH,)

    def __init__(self, stiffness: float) -> None:
        self.stiffness = stiffness  # N·m/rad
        self.own_modes()

    def force(self, t: float, q: Vec3, v: Vec3) -> Vec3:
        return (-self.stiffness * q[0], 0.0, 0.0) if self.mode == ENGAGED else (0.0, 0.0, 0.0)

    def potential(self, q: Vec3) -> float:
        return 0.5 * self.stiffness * q[0] ** 2 if self.mode == ENGAGED else 0.0

    def modal(self, q: Vec3, n: Vec3) -> tuple[float, float]:
        return (self.stiffness * n[0] ** 2, 0.0)  # the stiffest mode: engaged


def build(scene: Scene) -> McpClutch | None:
    k = scene.effect_value(KEY)
    return McpClutch(k) if k else None


@pytest.fixture(autouse=True)
def registered() -> Iterator[None]:
    """The effect's registry line, for this module's tests only."""
    effect(KEY, "MCP spring behind a clutch, N·m/rad", {KEY: scalar(0.0, "N·m/rad", "clutch spring stiffness",
                                                                     minimum=0.0, maximum=1.0)})(build)
    yield
    del EFFECTS[KEY]


def clutch_of(sim: Simulator) -> McpClutch:
    return next(e for e in sim.system.elements if isinstance(e, McpClutch))


def run(sim: Simulator) -> tuple[np.ndarray, list[tuple[str, ...]]]:
    """θ of STEPS steps with the clutch engaged (by its owner) after ENGAGE_AT, and the reported modes."""
    thetas, modes = [sim.q], [sim.modes]
    for k in range(STEPS):
        if k == ENGAGE_AT:
            clutch_of(sim).mode = ENGAGED
        thetas.append(sim.step().q)
        modes.append(sim.modes)
    return np.array(thetas), modes


@dataclass(frozen=True)
class ClutchReference(ref.Effects):
    """The reference's force elements plus the engaged spring, written again: Q1 −= k θ1."""

    mcp: float = 0.0  # N·m/rad

    def force(self, q, v, tau):  # type: ignore[no-untyped-def]
        return super().force(q, v, tau) - np.array([self.mcp * q[0], 0.0, 0.0])


def switched_reference() -> np.ndarray:
    """θ (rad) at the STEPS + 1 output times of `run` from the tight solve: free to the command, the engaged
    spring from then on."""
    dt, t_on = SCENE["integrator"]["dt"], ENGAGE_AT * SCENE["integrator"]["dt"]
    free = ref.solve(lambda a, b: ref.constant(0.0), [], Y0, t_on, ClutchReference(k=0.0))
    engaged = ref.solve(lambda a, b: ref.constant(0.0), [], free.y(t_on), SCENE["duration"] - t_on,
                        ClutchReference(k=0.0, mcp=STIFFNESS))
    t = dt * np.arange(STEPS + 1)
    return np.vstack([free.y(t[:ENGAGE_AT + 1])[:3].T, engaged.y(t[ENGAGE_AT + 1:] - t_on)[:3].T])


def test_a_new_elements_mode_is_stored_in_the_run_reset_and_reported() -> None:
    sim = Simulator(scene_from_dict(SCENE), kernel="python")
    assert [(owner, m) for owner, m in sim.layout.modes] == [("McpClutch", CLUTCH)]
    thetas, modes = run(sim)
    # reported: open up to the command, engaged from then on
    assert modes == [("open",)] * (ENGAGE_AT + 1) + [("engaged",)] * (STEPS - ENGAGE_AT)
    # stored in the run's home, which the element's law reads: writing the home switches the element
    assert sim.mode_values.values == [ENGAGED] and clutch_of(sim).mode == ENGAGED
    sim.mode_values.values[0] = OPEN
    assert clutch_of(sim).mode == OPEN and sim.modes == ("open",)
    # against the tight solve: free to the command, the spring from then on (engaging moves θ1 by ≈ 1e-3 rad)
    assert np.max(np.abs(thetas - switched_reference())) < REFERENCE_TOLERANCE
    never = ref.solve(lambda a, b: ref.constant(0.0), [], Y0, SCENE["duration"], ClutchReference(k=0.0))
    assert abs(never.y(SCENE["duration"])[0] - thetas[-1, 0]) > 1e-4  # the engaged law made the difference
    # reset: the mode back to its declared initial value, and the same run again, bit for bit
    clutch_of(sim).mode = ENGAGED
    sim.reset()
    assert sim.modes == ("open",) and clutch_of(sim).mode == OPEN
    again, modes_again = run(sim)
    assert np.array_equal(again, thetas) and modes_again == modes


def test_each_run_of_a_scene_has_its_own_home() -> None:
    """Two Simulators of one scene: engaging one's clutch leaves the other's open (its element is its own)."""
    scene = scene_from_dict(SCENE)
    first, second = Simulator(scene, kernel="python"), Simulator(scene, kernel="python")
    assert clutch_of(first) is not clutch_of(second)
    clutch_of(first).mode = ENGAGED
    assert first.modes == ("engaged",) and second.modes == ("open",)
    for _ in range(5):
        first.step(), second.step()
    free = Simulator(scene_from_dict({**SCENE, "model": {"spring_stiffness": 0.0}}), kernel="python")
    for _ in range(5):
        free.step()
    assert second.q == free.q and first.q[0] < free.q[0] - 1e-6  # open: no torque; engaged: pulled back


def test_the_stops_rest_mode_lives_in_the_runs_home() -> None:
    """paper_to_stop comes to rest on its upper stop: the home's `rest` entry reads resting there (1),
    free (0) after a reset; the frozen stops element is shared by the scene's runs and holds no value."""
    scene = load_scene(ref.CONFIG / "paper_to_stop.yaml")
    sim, other = Simulator(scene), Simulator(scene)
    assert [m.name for _, m in sim.layout.modes] == ["rest"]
    for _ in range(scene.step_count):
        sim.step()
    assert sim.mode_values.values == [1] and sim.modes == ("resting",) and sim.v == (0.0, 0.0, 0.0)
    assert other.mode_values.values == [0] and other.modes == ("free",)
    sim.reset()
    assert sim.mode_values.values == [0] and sim.modes == ("free",)


def test_friction_lock_lives_in_the_runs_home() -> None:
    """hold_table locks at its first turning point and stays there after the torque drops (μ_s = 2 holds
    it, the scene's claim): the home's `friction` entry reads locked exactly on the steps that end at
    rest, q does not move after them, and the contact element's law reads the same entry."""
    scene = load_scene(ref.CONFIG / "friction" / "hold_table.yaml")
    sim = Simulator(scene)
    position = [m.name for _, m in sim.layout.modes].index("friction")
    element = next(e for e in sim.system.elements if isinstance(e, OwnModes))
    locked, still, moved = [], [], []
    for _ in range(scene.step_count):
        q = sim.q
        sim.step()
        assert element.mode == sim.mode_values.values[position]
        locked.append(sim.modes[position] == "locked")
        still.append(sim.v == (0.0, 0.0, 0.0))
        moved.append(sim.q != q)
    assert locked == still  # locked exactly where the step ends at rest
    assert not any(m for m, was_locked in zip(moved[1:], locked) if was_locked)  # and it stays where it locked
    assert all(locked[len(locked) // 2:]) and not all(locked)  # through the torque drop at 0.5 s


def test_dop853_restarts_its_solution_when_a_new_elements_mode_changes() -> None:
    """Our DOP853 keeps its internal solution across output steps; the clutch, declared in this file alone,
    switches its law between two of them. The integrator restarts from the output where the system's mode
    key (`FingerSystem.mode_key`, the clutch's `OwnModes.mode_key`) changed, as it does for the drive and
    stick–slip friction, with no line naming the clutch: the run then matches the tight solve of the
    switched law to the integrator's own tolerance. (Continuing the open-clutch solution past the switch
    misses it by 0.06 rad.)"""
    scene = scene_from_dict({**SCENE, "integrator": {"method": "dop853", "dt": 1e-3}})
    sim = Simulator(scene)
    assert sim.method == "dop853" and len(sim.system.mode_owners) == 1
    thetas, _ = run(sim)
    assert np.max(np.abs(thetas - switched_reference())) < DOP853_TOLERANCE
