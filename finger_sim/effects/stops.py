"""Hard MCP stops (scene keys `joint_limits: {mcp: [lower, upper]}` rad and `restitution`).

No force: a stop acts only when θ1 reaches a limit. Its two gaps (θ1 − lower, upper − θ1)
are event functions; the Simulator locates their crossing inside a step and applies the
impact there (q' → −e q', or rest on the stop). Spec §3.

The stop owns one discrete mode, resting: after an impact whose rebound would rise
no higher than REST_HEIGHT (`rests`) q stays fixed and q' = 0 until the free acceleration pulls it off the
stop (`release_time`, the mode's guard). The mode's value is kept in each run's home
(`Simulator.mode_values`): one scene's Simulators share this frozen element.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import TYPE_CHECKING, ClassVar

from finger_sim.effects.base import NO_FORCE, NO_OUTPUTS, Vec3, effect
from finger_sim.effects.parameters import scalar
from finger_sim.kinematics import ZERO
from finger_sim.state_layout import ModeSet

if TYPE_CHECKING:
    from finger_sim.scene import Scene

#: The finger rests on a stop after an impact whose rebound would rise no higher than this (rad): the
#: rest cuts the rest of the impacts' Zeno series (heights × e² each), so θ departs from the model's
#: (spec §3: impacts alone) by at most this much, 10× below the smallest `integrator.tolerance`, and the
#: rule does not depend on the step (a rest after a rebound shorter than a step made θ depend on dt
#: by ≈ |θ1''| dt²/2: 1.5e-4 rad at 1 ms on config/hard/grasp_release.yaml).
REST_HEIGHT = 1e-11
#: The release from a stop is located to this fraction of the step.
RELEASE_TOLERANCE = 1e-12
#: brentq's relative tolerance on the release time: four units in the last place.
RELEASE_RTOL = 4 * 2.0**-52
#: The stops' discrete mode: free, or resting on the lower or upper stop; its guards are the impact
#: (a gap's crossing with a rebound no higher than REST_HEIGHT) and the release (the free acceleration
#: pulls q off the stop).
REST = ModeSet("rest", ("free", "resting"), ("impact", "release"))
#: ∂gap/∂q of the lower gap θ1 − lower and of the upper gap upper − θ1.
_GRADIENTS: tuple[Vec3, Vec3] = ((1.0, 0.0, 0.0), (-1.0, 0.0, 0.0))
#: `rest_verdict`'s answers.
BOUNCES, RESTS, UNSURE = 0, 1, 2


def rest_verdict(closing: float, rate: float, slack: float) -> int:
    """The rest test after an impact: RESTS when the free acceleration into the gap at q' = 0, `closing`
    (d²gap/dt², rad/s²), closes it and the rebound's gap rate `rate` (rad/s) would rise no higher than
    REST_HEIGHT; BOUNCES when either fails; UNSURE when either lies within `slack` (rad/s²) of its edge.
    `JointStops.rests` asks with slack 0; the kernel's impact (`kernel.event_step._impact`) with a margin
    for its own round-off, and leaves UNSURE to the Simulator."""
    lift = rate * rate - 2.0 * REST_HEIGHT * -closing  # ≤ 0: the rebound rises no higher than REST_HEIGHT
    if closing > slack or lift > 2.0 * REST_HEIGHT * slack:
        return BOUNCES
    if closing >= -slack or lift >= -2.0 * REST_HEIGHT * slack:
        return UNSURE
    return RESTS


@dataclass(frozen=True)
class JointStops:
    """MCP stops at lower ≤ θ1 ≤ upper (rad), with restitution coefficient e ∈ [0, 1]."""

    lower: float  # rad
    upper: float  # rad
    restitution: float

    affine_in_velocity: ClassVar[bool] = True
    smooth: ClassVar[bool] = False
    kernel_code: ClassVar[int] = NO_FORCE  # Q = 0: the Simulator handles the stops as events
    #: the declared rest mode (`state_layout`): entered at an impact that `rests`, left at `release_time`
    modes: ClassVar[tuple[ModeSet, ...]] = (REST,)

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

    def wrenches(self, t: float, q: Vec3, v: Vec3) -> tuple[Vec3, ...]:
        return ()

    # -- the resting mode -----------------------------------------------------------------
    def rests(self, index: int, q: Vec3, v_plus: Vec3, a_free: Vec3) -> bool:
        """Whether the finger, leaving gap `index` at q with q' = v_plus (rad/s) after an impact, rests
        on it instead: its free acceleration a_free (rad/s², at q' = 0) closes the gap and the rebound
        would rise no higher than REST_HEIGHT (rad)."""
        n = _GRADIENTS[index]
        closing = n[0] * a_free[0] + n[1] * a_free[1] + n[2] * a_free[2]  # d²gap/dt² at rest
        rate = n[0] * v_plus[0] + n[1] * v_plus[1] + n[2] * v_plus[2]
        return rest_verdict(closing, rate, 0.0) == RESTS

    def release_time(self, index: int, t: float, t1: float, q: Vec3,
                     free_acceleration: Callable[[float], Vec3]) -> float | None:
        """When in [t, t1] (s) the finger resting on gap `index` at q leaves it; None if it stays
        throughout. At rest q is fixed and q' = 0, so the free acceleration (rad/s², a function of the
        time alone) decides: the release is the root of its component into the gap, found by brentq."""
        n = _GRADIENTS[index]

        def push(s: float) -> float:
            a = free_acceleration(s)
            return -(n[0] * a[0] + n[1] * a[1] + n[2] * a[2])

        if push(t) <= 0.0:
            return t
        if push(t1) > 0.0:
            return None
        from scipy.optimize import brentq  # here: a release from a stop is rare, scipy.optimize costs ≈ 0.15 s to import

        return brentq(push, t, t1, xtol=RELEASE_TOLERANCE * (t1 - t), rtol=RELEASE_RTOL)

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
