"""A located impact on a gap (a stop), and the rest mode it may start: the Simulator's side of both.

The laws are the element's (`effects.stops.JointStops`: `rests`, `release_time`); the mode is its
declared REST_MODE, whose value each run keeps in its `Simulator.mode_values` (`Simulator._resting`
reads it as the closed gap rested on, or None), so that one scene's Simulators share its elements.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from finger_sim.integrators import TorqueFn
from finger_sim.kinematics import ZERO, Vec3
from finger_sim.simulation.crossings import Crossing, Gap

if TYPE_CHECKING:
    from finger_sim.simulation.driver import Simulator

#: The mode an element with impact gaps declares for the rest on them (`effects.stops.REST`).
REST_MODE = "rest"
#: Its values: free, resting on a closed gap.
FREE, RESTING = 0, 1


def impact(sim: Simulator, crossing: Crossing, torque: TorqueFn) -> Vec3:
    """q' just after the impact of a located crossing: −e q', or rest (zero) on the closed gap.

    One degree of freedom: q' lies on the null space of Φ_q, so the impulse along the gap
    scales the whole velocity: v⁺ = −e v⁻. Constraints hold; kinetic energy × e².
    """
    s, qs, vs, gap = crossing
    assert gap.restitution is not None
    sim.impacts += 1
    e = gap.restitution
    v_plus = (-e * vs[0], -e * vs[1], -e * vs[2])
    a_free, _ = sim.system.accelerations(s, qs, ZERO, torque(s))
    if gap.element.rests(gap.index, qs, v_plus, a_free):  # type: ignore[attr-defined]
        sim._resting = gap
        return ZERO
    return v_plus


def release_time(sim: Simulator, gap: Gap, t: float, t1: float, q: Vec3, torque: TorqueFn) -> float | None:
    """When in [t, t1] the finger resting on the closed gap leaves it; None if it stays throughout.
    At rest q is fixed and q' = 0: the free acceleration is a function of time alone."""
    system = sim.system
    return gap.element.release_time(  # type: ignore[attr-defined]
        gap.index, t, t1, q, lambda s: system.accelerations(s, q, ZERO, torque(s))[0])
