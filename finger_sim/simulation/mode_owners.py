"""The owners that step their own hybrid modes, and their steppings (`simulation.mode_stepping`): one line each.

A new owner (an actuator with a mode, an element with one) adds its line here: its class, and the function
that returns its stepping for one instance (or None: this one has no modes to step). The first line whose
class the owner is an instance of answers, so a subclass comes before its base.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable
from typing import Any

from finger_sim import stick_slip
from finger_sim.actuators import stepping as drive_stepping
from finger_sim.actuators.base import Actuator
from finger_sim.actuators.drive import Drive
from finger_sim.effects.friction_modes import StickSlipContact
from finger_sim.simulation import actuated_events
from finger_sim.simulation.mode_stepping import ModeStepping

#: (owner class, its stepping of an instance), subclasses first.
OWNERS: list[tuple[type, Callable[[Any], ModeStepping | None]]] = [
    (Drive, drive_stepping.stepping_of),
    (StickSlipContact, stick_slip.FrictionStepping),
    (Actuator, actuated_events.ActuatorStepping),
]


def steppings(owners: Iterable[object]) -> tuple[ModeStepping, ...]:
    """The steppings of `owners` (force elements, the actuator; None skipped), in their order."""
    found = []
    for owner in owners:
        make = next((make for cls, make in OWNERS if isinstance(owner, cls)), None)
        stepping = None if make is None else make(owner)
        if stepping is not None:
            found.append(stepping)
    return tuple(found)
