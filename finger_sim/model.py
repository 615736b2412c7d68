"""Finger parameters: the paper's geometry and masses plus the spec's assumptions, in SI.

Source: shared/spec/finger_model.md §1-2 (paper Table II). Every value here is a
config value; the defaults are the spec's.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, fields

from finger_sim.errors import ConfigError

#: The paper's ground-link angle θ4 = π − 0.49 rad (equations 2-3).
PAPER_THETA4 = math.pi - 0.49


@dataclass(frozen=True)
class FingerParams:
    """Geometry (m, rad) and masses (kg) of the four-bar finger; inertias follow from them.

    Links are uniform slender rods (spec §2 assumption): I_A = m1 r1²/3 about A,
    I_D = m2 r2²/3 about D, I_G3 = m3 L3²/12 about the distal centre of mass.
    """

    r1: float = 0.046  # proximal link, A→B
    r2: float = 0.0444  # coupler, D→C
    r3: float = 0.0077  # distal short edge, C→B
    r4: float = 0.0085  # ground link, D→A
    theta4: float = PAPER_THETA4  # ground-link angle
    L3: float = 0.0425  # distal phalanx, B→tip
    m1: float = 0.01691
    m2: float = 2 * 0.00086  # two coupler plates
    m3: float = 0.01416

    def __post_init__(self) -> None:
        for f in fields(self):
            value = getattr(self, f.name)
            if f.name == "theta4":
                if not math.isfinite(value):
                    raise ConfigError(f"model.{f.name}", "a finite angle in rad", value)
            elif not (math.isfinite(value) and value > 0.0):
                raise ConfigError(f"model.{f.name}", "a finite value > 0", value)
        # The linkage assembles somewhere iff the D→B distance range meets the
        # coupler dyad's reach |r2 − r3| .. r2 + r3.
        if self.r1 + self.r4 < abs(self.r2 - self.r3) or abs(self.r1 - self.r4) > self.r2 + self.r3:
            raise ConfigError(
                "model.r1..r4",
                f"lengths with which the four-bar assembles (|r1 − r4| ≤ r2 + r3 and "
                f"r1 + r4 ≥ |r2 − r3|)",
                (self.r1, self.r2, self.r3, self.r4),
            )

    @property
    def inertia_A(self) -> float:
        """Proximal link about the fixed pivot A, kg·m²."""
        return self.m1 * self.r1**2 / 3.0

    @property
    def inertia_D(self) -> float:
        """Coupler about the fixed pivot D, kg·m²."""
        return self.m2 * self.r2**2 / 3.0

    @property
    def inertia_G3(self) -> float:
        """Distal link about its centre of mass, kg·m²."""
        return self.m3 * self.L3**2 / 12.0
