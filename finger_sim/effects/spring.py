"""The PIP spring (scene key `spring_stiffness`, N·m/rad; 0 removes it). Spec §3."""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, ClassVar

from finger_sim.effects.base import SPRING, Smooth, Vec3, effect, kernel_law
from finger_sim.effects.parameters import scalar
from finger_sim.kinematics import distal_offset

if TYPE_CHECKING:
    from finger_sim.scene import Scene


@dataclass(frozen=True)
class PipSpring(Smooth):
    """Torsional PIP spring, V = ½ k β², β = θ3 + α − θ1; Q = (kβ, 0, −kβ) (spec §3, energy-consistent sign)."""

    stiffness: float  # N·m/rad
    alpha: float  # rad, distal offset

    affine_in_velocity: ClassVar[bool] = True
    kernel_code: ClassVar[int] = SPRING

    def kernel_params(self) -> tuple[float, ...]:
        return (self.stiffness, self.alpha)

    def force(self, t: float, q: Vec3, v: Vec3) -> Vec3:
        return spring_force(self.stiffness, self.alpha, q[0], q[2])

    def potential(self, q: Vec3) -> float:
        beta = q[2] + self.alpha - q[0]
        return 0.5 * self.stiffness * beta * beta

    def modal(self, q: Vec3, n: Vec3) -> tuple[float, float]:
        """(k (n3 − n1)², 0): the spring's stiffness along n, N·m; no damping."""
        return (self.stiffness * (n[2] - n[0]) ** 2, 0.0)


def spring_force(stiffness: float, alpha: float, t1: float, t3: float) -> Vec3:
    """Q = (kβ, 0, −kβ), N·m, β = θ3 + α − θ1 (rad): the spring's one law, which the compiled kernel
    compiles and the node's pip_joint effort (−kβ) reads. k in N·m/rad, angles in rad."""
    kb = stiffness * (t3 + alpha - t1)
    return (kb, 0.0, -kb)


kernel_law(spring_force, ("q0", "q2"), code=SPRING)


#: Largest stiffness, N·m/rad: far beyond any finger (the paper's spring is 1e-3, the stiff scene's
#: 1e3), and small enough that the modal arithmetic (K·I) stays finite.
MAX_SPRING_STIFFNESS = 1e6
PARAMETERS = {"spring_stiffness": scalar(0.001, "N·m/rad", "stiffness k of the torsional PIP spring (spec §3); 0 removes it",
                                         minimum=0.0, maximum=MAX_SPRING_STIFFNESS)}


@effect("spring_stiffness", "torsional PIP spring, N·m/rad (spec §3)", PARAMETERS)
def build(scene: Scene) -> PipSpring | None:
    if not scene.spring_stiffness:
        return None
    return PipSpring(scene.spring_stiffness, distal_offset(scene.params))
