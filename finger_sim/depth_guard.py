"""Geometry that cannot lie: a contact deeper than the phalanx's radius stops the run.

Spec §7's contact law holds while the phalanx's axis stays outside the object: its normal runs
from the object to the closest point p of the axis. Once the axis itself enters the object
(δ > ρ, the phalanx's radius; for a circle also the case of the axis passing its centre, δ > ρ + R)
the normal flips or is undefined and the force pushes the finger through and out, silently.
`DepthGuard.check` is called on every step's end state and raises a one-line
`SimulationDiverged` naming the object, the phalanx, the time and the depth instead.
"""

from __future__ import annotations

from collections.abc import Sequence

from finger_sim.errors import SimulationDiverged
from finger_sim.effects import ForceElement
from finger_sim.kinematics import Vec3

Vec2 = tuple[float, float]

ZERO: Vec3 = (0.0, 0.0, 0.0)
#: Phalanx name of a contact point → index in the scene's phalanx radii (ρ1, ρ3).
PHALANX_INDEX = {"proximal": 0, "distal": 1}


class DepthGuard:
    """Checks the depth of every active contact of the elements that report `contacts` (spec §7)."""

    def __init__(self, elements: Sequence[ForceElement], radii: Vec2) -> None:
        """elements: the system's force elements (those without `contacts` are ignored);
        radii: (ρ1, ρ3) of the proximal and distal phalanx, m."""
        self._contacts = tuple(e for e in elements if hasattr(e, "contacts"))
        self._radii = radii

    def __bool__(self) -> bool:
        return bool(self._contacts)

    def check(self, t: float, q: Vec3, method: str) -> None:
        """SimulationDiverged if at pose q (time t, s) a phalanx's axis is inside an object."""
        for element in self._contacts:
            for cp in element.contacts(t, q, ZERO):  # type: ignore[attr-defined]
                rho = self._radii[PHALANX_INDEX[cp.phalanx]]
                if cp.penetration > rho:
                    raise SimulationDiverged(
                        f"the {cp.phalanx} phalanx went {cp.penetration * 1e3:.3g} mm into object '{cp.object}', "
                        f"past its radius {rho * 1e3:.3g} mm (its axis is inside the object, where the contact "
                        "law no longer holds)", method=method, t=t,
                        hint="a stiffer contact (model.contact.stiffness) or a slower approach keeps it outside")
