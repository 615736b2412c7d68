"""The protocol every force element implements, and the registry that builds them from a scene.

Like Drake's `ForceElement` or MuJoCo's passive forces: the system adds the elements up
without asking what class each one is. Every question the rest of the code has about an
effect (is it affine in q'? smooth? how stiff along the linkage? what energy does it store?
what does it report?) is a member of `ForceElement`. An element exists only when the scene
turns its effect on, so an absent effect costs nothing per step.

Adding an effect takes its module: a class implementing `ForceElement` and a builder decorated with
`@effect("scene_key", ..., parameters, outputs=..., wrenches=...)`, declaring the scene keys it reads (a key that
is no `Scene` field is read through `Scene.effect_value`), the quantities it reports and the bodies it reports a
wrench on; for its compiled form, one `kernel_law(...)` line naming the plain function its `force` calls.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any, ClassVar, Protocol

from finger_sim.kinematics import Vec3

if TYPE_CHECKING:
    from finger_sim.effects.parameters import Parameter
    from finger_sim.scene import Scene


#: Codes of the compiled force laws an element may name as its `kernel_code` (the kernel's force sum computes
#: each from the element's `kernel_params()`). NO_FORCE: an element whose Q is zero (the stops).
NO_FORCE = 0
#: the laws the effects declare with `kernel_law` below (the kernel's lock-step rollout also reads these four)
SPRING = 1
DAMPING = 2
GRAVITY = 3
TIP_FORCE = 4
#: the laws the kernel writes itself (`kernel.numerics`: the contact's candidate loops over its own block)
CONTACT = 5
#: the contact with stick–slip friction (`effects.friction_modes.StickSlipContact`)
STICK_SLIP_CONTACT = 6
KERNEL_RESIDENT = (NO_FORCE, CONTACT, STICK_SLIP_CONTACT)
#: What a compiled law may read after its parameters, by the kernel's names: t (s), q (rad), q' (rad/s).
KERNEL_ARGUMENTS = ("t", "q0", "q1", "q2", "v0", "v1", "v2")


class ForceElement(Protocol):
    """One effect acting on the finger: generalized forces on q = (θ1, θ2, θ3), N·m."""

    #: Q(t, q, q') = Q₀(t, q) + D(q) q': RATTLE's second half is then a linear solve.
    affine_in_velocity: ClassVar[bool]
    #: Q is smooth in t and q over the whole run. False when it has events (a stop, a
    #: contact onset) that a high-order step must not straddle: see `gaps`.
    smooth: ClassVar[bool]

    def force(self, t: float, q: Vec3, v: Vec3) -> Vec3:
        """Generalized force Q(t, q, q'), N·m (rad, rad/s in)."""
        ...

    def potential(self, q: Vec3) -> float:
        """Potential energy stored by the element, J; 0 for a non-conservative one."""
        ...

    def modal(self, q: Vec3, n: Vec3) -> tuple[float, float]:
        """(nᵀKn, nᵀCn) at q along a direction n of q: stiffness N·m and damping N·m·s
        that the element adds to the linkage's one mode (the stability check)."""
        ...

    def gaps(self, q: Vec3) -> tuple[float, ...]:
        """Event functions of q: an event (stop crossing, contact onset or release) lies
        where one changes sign; open ≥ 0, closed < 0. Always the same number, in the same
        order (the Simulator indexes them). () for a smooth element."""
        ...

    def outputs(self, t: float, q: Vec3, v: Vec3) -> Mapping[str, float]:
        """Quantities the element reports, by the names its effect declares (`Effect.outputs`); {} for none."""
        ...

    def wrenches(self, t: float, q: Vec3, v: Vec3) -> tuple[Vec3, ...]:
        """The wrench (Fx, Fy, Mz) on each body its effect declares one on (`Effect.wrenches`), in that order:
        N in the model plane and N·m about the frame origin A (+Z); () for none."""
        ...

    def impact(self, index: int) -> float | None:
        """What happens when gap `index` closes: the restitution coefficient e ∈ [0, 1] of an
        impact (a stop: q' jumps to −e q', and the finger may come to rest on it), or None when
        the crossing only makes Q change non-smoothly (a kink: contact onset or release).

        The Simulator locates every crossing inside a step and ends the step there; only an
        impact changes the velocity. An element with impacts also declares its rest mode:
        `rests(index, q, v_plus, a_free)` and `release_time(index, t, t1, q, free_acceleration)`
        (`effects.stops.JointStops`).
        """
        ...

    def gap_gradient(self, index: int, q: Vec3) -> Vec3:
        """∂gap/∂q of gap `index` at q (gap units per rad), for every gap: the gap's rate ∇gap·q'
        shows a crossing inside a step (Simulator), and the finger resting on a closed impact gap
        stays while its free acceleration a pushes into it (∇gap·a < 0)."""
        ...

    # Optional: `check_clearance(q)`, which refuses a scene whose start q the element forbids (contact: an
    # object overlapping a phalanx), called by the scene loader with a one-line ConfigError.
    # Optional: the compiled form (finger_sim.kernel). An element without these two members, or whose law
    # is not registered, makes the Simulator step its scene in Python.
    #: which compiled force law (a `kernel_law` code, or one of KERNEL_RESIDENT above) computes `force`
    kernel_code: ClassVar[int]

    def kernel_params(self) -> tuple[float, ...]:
        """The numbers the compiled law `kernel_code` reads (pure data, SI), in its order."""
        ...


@dataclass(frozen=True)
class KernelLaw:
    """An element's compiled force law, declared by its effect's module (`kernel_law`).

    `force(p1, …, pn, *state)` is a plain function of floats returning Q = (Q1, Q2, Q3), N·m: the element's
    n `kernel_params()` first, then the kernel arguments named in `state` (KERNEL_ARGUMENTS). The Python
    path calls it as it is; the kernel compiles it (numba) and calls it from its force sum for every element
    whose `kernel_code` is `code` (`finger_sim.kernel.force_laws`). `callees`: plain functions it calls by
    name, compiled with it.
    """

    code: int
    force: Callable[..., Vec3]
    state: tuple[str, ...]
    callees: tuple[Callable[..., Any], ...] = ()

    @property
    def parameters(self) -> int:
        """How many of the element's `kernel_params()` the law reads."""
        return self.force.__code__.co_argcount - len(self.state)


#: code → compiled force law, in registration order.
KERNEL_LAWS: dict[int, KernelLaw] = {}


def kernel_law(force: Callable[..., Vec3], state: tuple[str, ...], *, code: int | None = None,
               callees: tuple[Callable[..., Any], ...] = ()) -> KernelLaw:
    """Register `force` as a compiled force law (`KernelLaw`) under `code` (default: the next free one) and
    return it; an element names it by `kernel_code = <law>.code`."""
    if code is None:
        code = max((*KERNEL_RESIDENT, *KERNEL_LAWS)) + 1
    if code in KERNEL_RESIDENT or code in KERNEL_LAWS:
        raise ValueError(f"compiled force law code {code} registered twice ({force.__qualname__})")
    unknown = [name for name in state if name not in KERNEL_ARGUMENTS]
    if unknown or force.__code__.co_argcount < len(state):
        raise ValueError(f"{force.__qualname__}: state must be trailing arguments among {list(KERNEL_ARGUMENTS)}, "
                         f"got {list(state)}")
    law = KERNEL_LAWS[code] = KernelLaw(code, force, tuple(state), tuple(callees))
    return law


@dataclass(frozen=True)
class Output:
    """One quantity an element or actuator reports at each sample, declared once: `name` is its column in
    CSV, sweep, batch and rollout outputs, its name in plots and in a log's export; `topic` and `message`
    are the finger_node topic that carries it and that topic's ROS message type, where it has one;
    `measurable`: whether a real device's controller could measure it (task runs hand it to the controller)."""

    name: str
    unit: str
    description: str
    topic: str | None = None
    message: str | None = None
    measurable: bool = True


@dataclass(frozen=True)
class Wrench:
    """A wrench an element reports on one body at each sample (`ForceElement.wrenches`), declared once: the
    force (Fx, Fy), N in the model plane, and its moment Mz about the frame origin A, N·m (+Z of the model
    plane). `force`: the two outputs that carry Fx and Fy in tables (an element reporting the wrench reports
    them); their `topic` and `message` are the finger_node topic that carries the whole wrench."""

    body: str
    force: tuple[Output, Output]

    def __post_init__(self) -> None:
        x, y = self.force
        if x.topic is None or (x.topic, x.message) != (y.topic, y.message):
            raise ValueError(f"wrench on '{self.body}': its force outputs must name one topic, "
                             f"got {x.topic!r}, {y.topic!r}")

    @property
    def topic(self) -> str:
        """The finger_node topic that carries the wrench (relative name)."""
        return self.force[0].topic  # type: ignore[return-value]  # checked in __post_init__


#: Builds the element of one effect from a resolved scene, or None when the scene leaves it off.
Builder = Callable[["Scene"], "ForceElement | None"]


@dataclass(frozen=True)
class Effect:
    """A registered effect: its scene key (under `model:`) and its builder."""

    key: str
    build: Builder
    description: str
    #: the scene keys it reads (under `model:`), declared once (`effects.parameters`)
    parameters: Mapping[str, Parameter] = field(default_factory=dict, hash=False, compare=False)
    #: every quantity its element may report (`ForceElement.outputs` returns a subset, in this order)
    outputs: tuple[Output, ...] = ()
    #: the bodies its element reports a wrench on (`ForceElement.wrenches`, in this order)
    wrenches: tuple[Wrench, ...] = ()


#: scene key → effect, in registration order (the order elements are summed in).
EFFECTS: dict[str, Effect] = {}


def effect(key: str, description: str, parameters: Mapping[str, Parameter] | None = None,
           outputs: tuple[Output, ...] = (), wrenches: tuple[Wrench, ...] = ()) -> Callable[[Builder], Builder]:
    """Register the builder of the effect switched on by `model.<key>` in a scene, with the scene
    keys it reads (`parameters`: key → declaration), the quantities its element reports (`outputs`) and
    the bodies it reports a wrench on (`wrenches`, each one's force among `outputs`)."""

    def register(build: Builder) -> Builder:
        if key in EFFECTS:
            raise ValueError(f"effect '{key}' registered twice")
        missing = [o.name for w in wrenches for o in w.force if o not in outputs]
        if missing:
            raise ValueError(f"effect '{key}': its wrenches' force outputs {missing} are not among its outputs")
        EFFECTS[key] = Effect(key, build, description, dict(parameters or {}), tuple(outputs), tuple(wrenches))
        return build

    return register


def declared_parameters() -> dict[str, Parameter]:
    """Every registered effect's scene keys (under `model:`) → their declarations."""
    return {key: p for eff in EFFECTS.values() for key, p in eff.parameters.items()}


def declared_outputs() -> dict[str, Output]:
    """Every registered effect's outputs, by name."""
    return {o.name: o for eff in EFFECTS.values() for o in eff.outputs}


def declared_wrenches() -> tuple[Wrench, ...]:
    """Every registered effect's wrenches, once each, in registration order."""
    return tuple(dict.fromkeys(w for eff in EFFECTS.values() for w in eff.wrenches))


def reported_wrenches(element: ForceElement, q: Vec3) -> tuple[Wrench, ...]:
    """The declared wrenches an element reports, in the order of its `wrenches`: those whose force outputs it
    reports (asked at a pose q, as `outputs` is: an element reports the same names at every state)."""
    names = element.outputs(0.0, q, (0.0, 0.0, 0.0))
    return tuple(w for w in declared_wrenches() if w.force[0].name in names)


def has_kinks(element: ForceElement, q: Vec3) -> bool:
    """Whether the element has events where Q only kinks, without an impact (a contact's onset and release):
    a gap at q whose `impact` is None. What makes a scene one with contact, whatever its effects are."""
    return not element.smooth and any(element.impact(i) is None for i in range(len(element.gaps(q))))


def build_elements(scene: "Scene") -> list[ForceElement]:
    """The elements of every effect the scene turns on, in registration order."""
    return [e for e in (eff.build(scene) for eff in EFFECTS.values()) if e is not None]


NO_OUTPUTS: Mapping[str, Any] = {}


class Smooth:
    """Defaults of the event and report members for an element with no events (`smooth = True`).

    An element class may inherit these instead of writing the five trivial methods;
    `force`, `potential`, `modal` and the class constants stay its own.
    """

    smooth: ClassVar[bool] = True

    def gaps(self, q: Vec3) -> tuple[float, ...]:
        return ()

    def impact(self, index: int) -> float | None:
        raise IndexError(f"{type(self).__name__} has no gaps, got gap index {index}")

    def gap_gradient(self, index: int, q: Vec3) -> Vec3:
        raise IndexError(f"{type(self).__name__} has no gaps, got gap index {index}")

    def outputs(self, t: float, q: Vec3, v: Vec3) -> Mapping[str, float]:
        return NO_OUTPUTS

    def wrenches(self, t: float, q: Vec3, v: Vec3) -> tuple[Vec3, ...]:
        return ()
