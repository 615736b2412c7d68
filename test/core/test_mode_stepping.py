"""An owner that steps its own hybrid mode plugs into the Simulator through `simulation.mode_stepping` alone.

test_mode_values' clutch (an MCP spring Q1 = −k θ1 behind a clutch, declared in that test file) gets a latch
here: its stepping and its registry line (`simulation.mode_owners.OWNERS`, added by a fixture). While open
nothing acts; where θ1 first reaches THETA_L, located inside the step as a guard (`locate.first_guard_crossing`),
the clutch engages (a jump of k θ_L in the torque at the switch). No line of the Simulator, its set-up or
`simulate` names it. Its run matches an independent tight
solve (scipy's solve_ivp on test/reference.py's equations, the switch a terminal event) to rk4's accuracy;
switching the mode at the step's end instead (no location) misses it by far more. The precedence between
two owners is declared (`carries`), not written as an if-chain: the shipped pairs lead as before and an
undeclared pair is refused in one line.
"""

from __future__ import annotations

from collections.abc import Iterator

import numpy as np
import pytest
import reference as ref
from scipy.integrate import solve_ivp

from finger_sim.actuators.stepping import DriveStepping, InductiveDriveStepping
from finger_sim.effects import EFFECTS
from finger_sim.effects.base import Vec3, effect
from finger_sim.effects.parameters import scalar
from finger_sim.errors import ConfigError
from finger_sim.integrators import TorqueFn
from finger_sim.scene import scene_from_dict
from finger_sim.simulate import Simulator, simulate
from finger_sim.simulation import mode_owners
from finger_sim.simulation.locate import first_guard_crossing
from finger_sim.simulation.mode_stepping import ModeStepping, leader
from finger_sim.stick_slip import FrictionStepping
from test_mode_values import CLUTCH, ENGAGED, KEY, OPEN, STIFFNESS, McpClutch, build

THETA_L = 0.2  # rad: where the latch engages the clutch
TORQUE = 0.02  # N·m, constant: θ1 reaches THETA_L at ≈ 54 ms
SCENE = {"model": {KEY: STIFFNESS, "spring_stiffness": 0.0}, "input": {"torque": {"type": "constant", "value": TORQUE}},
         "duration": 0.12, "integrator": {"method": "rk4", "dt": 1e-3}}
#: rk4 at 1 ms against the tight solve, rad (measured 1.0e-10; switched at the step's end instead: 5.5e-4)
TOLERANCE = 1e-8


class LatchStepping(ModeStepping):
    """The clutch's latch: one integrator step; while open, its guard θ_L − θ1 located inside it, the clutch
    engaged there and the step finished under the engaged law."""

    name = "latch"

    def __init__(self, latch: McpClutch) -> None:
        self.latch = latch

    def advance(self, sim: Simulator, t0: float, t1: float, u: TorqueFn) -> None:
        q, v = sim.q, sim.v
        q1, v1 = sim.integrator.step(t0, q, v, t1 - t0, u)
        if self.latch.mode == OPEN:
            def at(_: int, s: float) -> tuple[float, tuple[Vec3, Vec3]]:
                qs, vs = sim.integrator.step(t0, q, v, s - t0, u)
                return THETA_L - qs[0], (qs, vs)

            event = first_guard_crossing((False,), (THETA_L - q[0],), (THETA_L - q1[0],), at, t0, t1, (q1, v1))
            if event is not None:
                self.latch.mode = ENGAGED
                (qe, ve), t = event.state, event.t
                q1, v1 = (qe, ve) if t >= t1 else sim.integrator.step(t, qe, ve, t1 - t, u)
        sim.q, sim.v = q1, v1


class UnlocatedStepping(LatchStepping):
    """The same mode switched at the step's end where the guard crossed (no location): the control."""

    def advance(self, sim: Simulator, t0: float, t1: float, u: TorqueFn) -> None:
        sim.q, sim.v = sim.integrator.step(t0, sim.q, sim.v, t1 - t0, u)
        if self.latch.mode == OPEN and sim.q[0] >= THETA_L:
            self.latch.mode = ENGAGED


@pytest.fixture
def registered(request: pytest.FixtureRequest) -> Iterator[None]:
    """The clutch's effect line (as test_mode_values registers it) and the latch's line in `mode_owners.OWNERS`."""
    effect(KEY, "MCP spring behind a clutch, N·m/rad", {KEY: scalar(0.0, "N·m/rad", "clutch spring stiffness",
                                                                     minimum=0.0, maximum=1.0)})(build)
    line = (McpClutch, getattr(request, "param", LatchStepping))
    mode_owners.OWNERS.insert(0, line)
    yield
    mode_owners.OWNERS.remove(line)
    del EFFECTS[KEY]


def reference(t: np.ndarray) -> tuple[np.ndarray, float]:
    """θ1 (rad) at times t and the switch time (s): solve_ivp of §4 under the torque, the latch a terminal event."""
    fx = ref.Effects(k=0.0)

    def rhs(engaged: bool):  # type: ignore[no-untyped-def]
        def f(_: float, y: np.ndarray) -> np.ndarray:
            tau = TORQUE - (STIFFNESS * y[0] if engaged else 0.0)
            return np.concatenate([y[3:], ref.kkt(y[:3], y[3:], tau, fx)[0]])
        return f

    def reaches(_: float, y: np.ndarray) -> float:
        return y[0] - THETA_L

    reaches.terminal = True  # type: ignore[attr-defined]
    q0 = ref.assemble(0.0)
    y0 = [*q0, 0.0, 0.0, 0.0]
    end = SCENE["duration"]
    free = solve_ivp(rhs(False), (0.0, end), y0, method="DOP853", rtol=ref.RTOL, atol=ref.ATOL, events=reaches,
                     dense_output=True)
    t_on = free.t_events[0][0]
    engaged = solve_ivp(rhs(True), (t_on, end), free.y_events[0][0], method="DOP853", rtol=ref.RTOL, atol=ref.ATOL,
                        dense_output=True)
    return np.where(t < t_on, free.sol(np.minimum(t, t_on))[0], engaged.sol(np.maximum(t, t_on))[0]), t_on


@pytest.mark.usefixtures("registered")
def test_an_owner_with_its_own_stepping_runs_through_the_protocol_alone() -> None:
    scene = scene_from_dict(SCENE)
    sim = Simulator(scene, kernel="python")
    assert [type(s) for s in sim.mode_steppings] == [LatchStepping] and sim.layout.modes == (("McpClutch", CLUTCH),)
    modes = [sim.modes]
    thetas = [sim.q[0]]
    for _ in range(scene.step_count):
        thetas.append(sim.step().q[0])
        modes.append(sim.modes)
    t = scene.dt * np.arange(scene.step_count + 1)
    theta_ref, t_on = reference(t)
    switched = modes.index(("engaged",))
    assert 0.02 < t_on < 0.1 and t[switched - 1] < t_on <= t[switched]  # the step that holds the switch
    assert all(m == ("open",) for m in modes[:switched]) and all(m == ("engaged",) for m in modes[switched:])
    error = np.max(np.abs(np.array(thetas) - theta_ref))
    assert error < TOLERANCE
    # `simulate` runs it the same way, bit for bit; a reset starts the latch open again
    traj = simulate(scene, kernel="python")
    assert np.array_equal(traj.q[:, 0], thetas)
    sim.reset()
    assert sim.modes == ("open",)


@pytest.mark.parametrize("registered", [UnlocatedStepping], indirect=True)
@pytest.mark.usefixtures("registered")
def test_the_switch_unlocated_misses_the_reference() -> None:
    """The control: the same mode switched at the end of the step that crossed misses by > 100× TOLERANCE, so
    the test above holds the location inside the step, not only the mode's bookkeeping."""
    scene = scene_from_dict(SCENE)
    traj = simulate(scene, kernel="python")
    assert np.max(np.abs(traj.q[:, 0] - reference(traj.t)[0])) > 100 * TOLERANCE


def test_the_precedence_between_two_owners_is_declared() -> None:
    """Stick–slip friction carries the drive's mesh (L = 0); the drive with L > 0 carries the friction; an
    owner that no one carries with another is refused in one line naming both."""
    friction = FrictionStepping(None)  # type: ignore[arg-type]
    drive, inductive = DriveStepping(None), InductiveDriveStepping(None)  # type: ignore[arg-type]
    assert leader([friction, drive]) is friction and leader([drive, friction]) is friction
    assert leader([friction, inductive]) is inductive
    assert leader([drive]) is drive and leader([]) is None
    with pytest.raises(ConfigError) as caught:
        leader([LatchStepping(None), friction])  # type: ignore[arg-type]
    assert "\n" not in str(caught.value) and "latch and stick_slip" in str(caught.value)
