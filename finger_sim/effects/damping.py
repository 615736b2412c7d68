"""Viscous joint damping (scene key `damping`, N·m·s/rad at each joint; 0 removes it). Spec §3."""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, ClassVar

from finger_sim.effects.base import DAMPING, Smooth, Vec3, effect, kernel_law
from finger_sim.effects.parameters import scalar

if TYPE_CHECKING:
    from finger_sim.scene import Scene


@dataclass(frozen=True)
class JointDamping(Smooth):
    """Viscous damping at the MCP, coupler and PIP joints: R = ½ c (θ1'² + θ2'² + β'²)."""

    coefficient: float  # N·m·s/rad

    affine_in_velocity: ClassVar[bool] = True
    kernel_code: ClassVar[int] = DAMPING

    def kernel_params(self) -> tuple[float, ...]:
        return (self.coefficient,)

    def force(self, t: float, q: Vec3, v: Vec3) -> Vec3:
        return damping_force(self.coefficient, v[0], v[1], v[2])

    def potential(self, q: Vec3) -> float:
        return 0.0

    def modal(self, q: Vec3, n: Vec3) -> tuple[float, float]:
        """(0, c (n1² + n2² + (n3 − n1)²)): the damping along n, N·m·s; no stiffness."""
        return (0.0, self.coefficient * (n[0] ** 2 + n[1] ** 2 + (n[2] - n[0]) ** 2))


def damping_force(c: float, w1: float, w2: float, w3: float) -> Vec3:
    """Q = −∂R/∂q', N·m, of R = ½ c (θ1'² + θ2'² + β'²), β' = θ3' − θ1' (c in N·m·s/rad, rates in rad/s):
    the damping's one law, which the compiled kernel compiles."""
    beta_dot = w3 - w1
    return (-c * w1 + c * beta_dot, -c * w2, -c * beta_dot)


kernel_law(damping_force, ("v0", "v1", "v2"), code=DAMPING)


#: Largest coefficient, N·m·s/rad: keeps the modal arithmetic (C²) finite.
MAX_DAMPING = 1e3
PARAMETERS = {"damping": scalar(0.0, "N·m·s/rad", "viscous damping c at the MCP, coupler and PIP joints; 0 removes it",
                                minimum=0.0, maximum=MAX_DAMPING)}


@effect("damping", "viscous damping at each joint, N·m·s/rad", PARAMETERS)
def build(scene: Scene) -> JointDamping | None:
    return JointDamping(scene.damping) if scene.damping else None
