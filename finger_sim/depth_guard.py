"""Geometry that cannot lie: a contact as deep as the phalanx's radius is an event that stops the run.

Spec §7's contact law holds while the phalanx's axis stays outside the object: its normal runs
from the object to the closest point p of the axis. Once the axis itself enters the object
(δ > ρ, the phalanx's radius; for a circle this comes before the axis can pass its centre)
the normal flips or is undefined and the force pushes the finger through and out, silently.

`DepthLimit` gives the Simulator one event function per contact candidate, ρ − δ (m, open ≥ 0),
beside the contact's own −δ: the Simulator locates its crossing inside the step as it locates a
contact onset, so a fast impact that would pass through and out within one step is caught too,
and `crossed` raises a one-line `SimulationDiverged` naming the object, the phalanx, the located
time and the depth.
"""

from __future__ import annotations

from collections.abc import Sequence

from finger_sim.effects import ForceElement
from finger_sim.errors import SimulationDiverged
from finger_sim.kinematics import Vec3

Vec2 = tuple[float, float]

#: Phalanx name of a contact candidate → index in the scene's phalanx radii (ρ1, ρ3).
PHALANX_INDEX = {"proximal": 0, "distal": 1}


class DepthLimit:
    """Event functions ρ − δ (m) of every candidate of a contact element (spec §7), in its `gaps`
    order: a gap function like the contact's own, whose crossing ends the run (`crossed`)."""

    smooth = False

    def __init__(self, contact: ForceElement, radii: Vec2) -> None:
        """contact: the system's contact element (it reports `candidates`); radii: (ρ1, ρ3), m."""
        self.contact = contact
        self.labels: tuple[tuple[str, str], ...] = contact.candidates()  # type: ignore[attr-defined]
        #: ρ of each candidate's phalanx, m: the depth gap is the contact gap (−δ) plus it
        self.offsets = tuple(radii[PHALANX_INDEX[phalanx]] for phalanx, _ in self.labels)
        self.time_varying = getattr(contact, "time_varying", False)

    def gaps(self, q: Vec3) -> tuple[float, ...]:
        return tuple(rho + g for rho, g in zip(self.offsets, self.contact.gaps(q)))

    def gaps_at(self, t: float, q: Vec3) -> tuple[float, ...]:
        return tuple(rho + g for rho, g in zip(self.offsets, self.contact.gaps_at(t, q)))  # type: ignore[attr-defined]

    def gap_rates(self, t: float, q: Vec3, v: Vec3) -> tuple[float, ...]:
        return self.contact.gap_rates(t, q, v)  # type: ignore[attr-defined, no-any-return]

    def gap_gradient(self, index: int, q: Vec3) -> Vec3:
        return self.contact.gap_gradient(index, q)

    def impact(self, index: int) -> None:
        """None: a crossing is located like a kink, then `crossed` ends the run."""
        return None

    def crossed(self, index: int, t: float, q: Vec3, v: Vec3, method: str) -> SimulationDiverged:
        """The one-line error of candidate `index` located at (t, q, q') (s, rad, rad/s): its object,
        phalanx, depth and how fast it was going in."""
        phalanx, name = self.labels[index]
        rho = self.offsets[index]
        depth = rho - (self.gaps_at(t, q) if self.time_varying else self.gaps(q))[index]
        n = self.gap_gradient(index, q)
        speed = -(n[0] * v[0] + n[1] * v[1] + n[2] * v[2])  # δ' ≈ −∇gap·q' (a moving object's own speed aside)
        return SimulationDiverged(
            f"the {phalanx} phalanx went {depth * 1e3:.3g} mm into object '{name}', as deep as its radius "
            f"{rho * 1e3:.3g} mm, going in at {speed:.3g} m/s (its axis enters the object, where the contact "
            "law no longer holds)", method=method, t=t,
            hint="a stiffer contact (model.contact.stiffness) or a slower approach keeps it outside")


def depth_limit(elements: Sequence[ForceElement], radii: Vec2) -> DepthLimit | None:
    """The DepthLimit of the system's contact element (the one that reports `candidates`), or None."""
    contacts = [e for e in elements if hasattr(e, "candidates")]
    return DepthLimit(contacts[0], radii) if contacts else None
