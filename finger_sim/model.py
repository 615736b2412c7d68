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
#: Link lengths allowed, m: a finger-sized linkage with wide margins (the paper's are 7.7-46 mm);
#: the bounds keep inertias (m r²) and forces far from float under- and overflow.
LENGTH_RANGE = (1e-4, 1.0)
#: Link masses allowed, kg (the paper's are 0.9-17 g).
MASS_RANGE = (1e-6, 10.0)


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
            value, key = getattr(self, f.name), f"model.geometry.{f.name}"
            if f.name == "theta4":
                if not math.isfinite(value):
                    raise ConfigError(key, "a finite angle in rad", value)
                continue
            lo, hi = MASS_RANGE if f.name.startswith("m") else LENGTH_RANGE
            if not (math.isfinite(value) and value > 0.0):
                raise ConfigError(key, "a finite value > 0", value)
            if not lo <= value <= hi:
                raise ConfigError(key, f"a value in [{lo:g}, {hi:g}] {'kg' if f.name.startswith('m') else 'm'}", value)
        # The model is built around the extended pose θ1 = 0 (spec §1: the distal offset α
        # is taken there), so the coupler dyad r2, r3 must reach B there: the distance D→B
        # must lie strictly between the dyad's folded and stretched lengths.
        reach = self.extension_reach()
        shortest, longest = abs(self.r2 - self.r3), self.r2 + self.r3
        if not shortest < reach < longest:
            limit = f"below the dyad's folded length |r2 − r3| = {shortest * 1e3:.4g} mm" if reach <= shortest else (
                f"beyond the dyad's stretched length r2 + r3 = {longest * 1e3:.4g} mm")
            raise ConfigError(
                "model.geometry",
                "r1, r2, r3, r4, theta4 with |r2 − r3| < |D→B| < r2 + r3 at θ1 = 0",
                {"r1": self.r1, "r2": self.r2, "r3": self.r3, "r4": self.r4, "theta4": self.theta4},
                problem=f"the linkage cannot be assembled: at extension (θ1 = 0) the distance D→B is "
                f"{reach * 1e3:.4g} mm, {limit}",
            )

    def extension_reach(self) -> float:
        """|D→B| at θ1 = 0, m: D = −r4 e(θ4), B = (r1, 0)."""
        return math.hypot(self.r1 + self.r4 * math.cos(self.theta4), self.r4 * math.sin(self.theta4))

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
