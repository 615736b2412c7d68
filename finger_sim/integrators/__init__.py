"""Integrators sharing one step interface; `METHODS` maps scene names to classes."""

from finger_sim.integrators.adaptive import AdaptiveReference
from finger_sim.integrators.base import HeldTorque, Integrator, TorqueFn
from finger_sim.integrators.dop853 import DormandPrince853
from finger_sim.integrators.explicit import RK4, ExplicitRungeKutta, PaperEuler
from finger_sim.integrators.high_order import ButcherRK6, DormandPrince8
from finger_sim.integrators.radau import RadauIIA
from finger_sim.integrators.rattle import Rattle

METHODS: dict[str, type[Integrator]] = {
    cls.name: cls for cls in (PaperEuler, RK4, ButcherRK6, DormandPrince8, Rattle, RadauIIA, AdaptiveReference,
                          DormandPrince853)
}

__all__ = [
    "METHODS",
    "AdaptiveReference",
    "ButcherRK6",
    "DormandPrince8",
    "DormandPrince853",
    "ExplicitRungeKutta",
    "HeldTorque",
    "Integrator",
    "PaperEuler",
    "RK4",
    "RadauIIA",
    "Rattle",
    "TorqueFn",
]
