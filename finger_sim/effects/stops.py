"""Hard MCP stops (scene keys `joint_limits: {mcp: [lower, upper]}` rad and `restitution`).

No force: a stop acts only when θ1 reaches a limit. Its two gaps (θ1 − lower, upper − θ1)
are event functions; the Simulator locates their crossing inside a step and applies the
impact there (q' → −e q', or rest on the stop). Spec §3.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import TYPE_CHECKING, ClassVar

from finger_sim.effects.base import NO_FORCE, NO_OUTPUTS, Vec3, effect
from finger_sim.effects.parameters import scalar

if TYPE_CHECKING:
    from finger_sim.scene import Scene

ZERO: Vec3 = (0.0, 0.0, 0.0)
#: ∂gap/∂q of the lower gap θ1 − lower and of the upper gap upper − θ1.
_GRADIENTS: tuple[Vec3, Vec3] = ((1.0, 0.0, 0.0), (-1.0, 0.0, 0.0))


@dataclass(frozen=True)
class JointStops:
    """MCP stops at lower ≤ θ1 ≤ upper (rad), with restitution coefficient e ∈ [0, 1]."""

    lower: float  # rad
    upper: float  # rad
    restitution: float

    affine_in_velocity: ClassVar[bool] = True
    smooth: ClassVar[bool] = False
    kernel_code: ClassVar[int] = NO_FORCE  # Q = 0: the Simulator handles the stops as events

    def kernel_params(self) -> tuple[float, ...]:
        return ()

    def force(self, t: float, q: Vec3, v: Vec3) -> Vec3:
        return ZERO

    def potential(self, q: Vec3) -> float:
        return 0.0

    def modal(self, q: Vec3, n: Vec3) -> tuple[float, float]:
        return (0.0, 0.0)

    def gaps(self, q: Vec3) -> tuple[float, float]:
        """(θ1 − lower, upper − θ1), rad: both ≥ 0 between the stops."""
        return (q[0] - self.lower, self.upper - q[0])

    def impact(self, index: int) -> float:
        return self.restitution

    def gap_gradient(self, index: int, q: Vec3) -> Vec3:
        return _GRADIENTS[index]

    def outputs(self, t: float, q: Vec3, v: Vec3) -> Mapping[str, float]:
        return NO_OUTPUTS

    @property
    def mcp_range(self) -> tuple[float, float]:
        """(lower, upper), rad: the MCP angles the finger can reach."""
        return (self.lower, self.upper)


#: `restitution` (the `joint_limits` mapping is read by the scene, which checks it against the linkage's range).
PARAMETERS = {"restitution": scalar(0.0, "1", "restitution coefficient e of the MCP stops: q' → −e q' at impact",
                                    minimum=0.0, maximum=1.0)}


@effect("joint_limits", "hard MCP stops, [lower, upper] rad, with `restitution`", PARAMETERS)
def build(scene: Scene) -> JointStops | None:
    if scene.mcp_limits is None:
        return None
    return JointStops(*scene.mcp_limits, scene.restitution)
