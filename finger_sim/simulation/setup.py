"""The set-up of a Simulator: what it needs of a scene before its first step, kept per scene.

The method (auto resolved), the stability check, the integrator class on the chosen kernel, the
non-smooth elements' gaps (`simulation.crossings.Gap`) and the compiled fast path; a frozen value,
so one scene's Simulators share it (`setup_for`, an LRU cache: a node's resets, a rollout's rows).
A system that holds run state (an owner of modes, `FingerSystem.mode_owners`) is built anew for each
Simulator (`for_simulator`), the rest of the set-up kept. Owners that step their own modes impose their
method and integrator through their declared stepping (`simulation.mode_stepping`).
"""

from __future__ import annotations

import functools
from typing import NamedTuple

from finger_sim import stepper_slot
from finger_sim.auto import (ERROR_CONTROLLED, PYTHON_STAGES_NOTE, choose_method, contact_substeps,
                             integrator_options, warn_unresolved_contact)
from finger_sim.depth_guard import depth_limit
from finger_sim.dynamics import FingerSystem
from finger_sim.effects import Effect, ForceElement
from finger_sim.errors import StabilityError
from finger_sim.integrators import METHODS, Integrator
from finger_sim.scene import AUTO, Scene
from finger_sim.simulation import mode_owners
from finger_sim.simulation.crossings import Gap
from finger_sim.simulation.mode_stepping import leader
from finger_sim.stability import CONTACT_RESOLUTION, fastest_mode, has_contact, largest_stable_dt, mcp_range, stable_at

#: Scenes whose Simulator set-up is kept (`setup_for`): a node's resets, a rollout's rows, a test's reruns.
SETUP_CACHE_SIZE = 256


class Setup(NamedTuple):
    """What a Simulator of one scene needs before its first step; immutable, shared by its Simulators."""

    system: FingerSystem
    method: str
    reason: str
    substeps: int
    options: dict[str, float]
    method_cls: type[Integrator]
    integrator_cls: type[Integrator]
    kernel: str
    gaps: tuple[Gap, ...]
    kinks: tuple[Gap, ...]
    gap_elements: tuple[tuple[ForceElement, tuple[int, ...]], ...]
    depth_sources: tuple[tuple[int, float], ...]
    fast_stepper: object  # kernel.integrators.FastStepper | None
    #: the system holds run state (an owner of modes): each Simulator builds its own
    own_system: bool
    #: what the first Simulator's start found at the scene's initial state (a function of the scene alone:
    #: an owner's rule for its modes at rest), by its owner's module;
    #: filled once, read by the next Simulators' `reset`
    kept_start: dict[str, tuple[object, ...]]


def for_simulator(scene: Scene, kernel: str, effects: tuple[Effect, ...]) -> Setup:
    """The set-up of one Simulator of `scene`: the kept one (`setup_for`), with a system of its own
    where the system holds run state (`rebound`); built whole for a scene that cannot key the cache."""
    try:
        setup = setup_for(scene, kernel, effects)
    except TypeError:  # a scene holding a mutable value cannot key the cache (hashing it once: ~2 µs)
        return setup_for.__wrapped__(scene, kernel, effects)
    return rebound(setup, scene) if setup.own_system else setup


def rebound(setup: Setup, scene: Scene) -> Setup:
    """`setup` on a fresh system of `scene`: its gaps, gap groups and depth gaps on the new elements
    (each at its position in `system.elements`), the method, checks and classes kept."""
    system = scene.build_system()
    old = {id(e): k for k, e in enumerate(setup.system.elements)}
    depth = depth_limit(system.elements, scene.phalanx_radius) if setup.depth_sources else None

    def moved(gap: Gap) -> Gap:
        k = old.get(id(gap.element))
        return Gap(depth if k is None else system.elements[k], gap.index, gap.restitution)  # type: ignore[arg-type]

    gaps = tuple(map(moved, setup.gaps))
    kinks = tuple(gap for gap in gaps if gap.restitution is None) if setup.kinks else ()
    gap_elements = tuple((system.elements[old[id(e)]], indices) for e, indices in setup.gap_elements)
    fast_stepper = setup.fast_stepper
    if fast_stepper is not None:  # bound to the system it was planned on
        fast_stepper = stepper_slot.kernel().fast_stepper(setup.integrator_cls(system), scene.dt, scene.torque)
    return setup._replace(system=system, gaps=gaps, kinks=kinks, gap_elements=gap_elements, fast_stepper=fast_stepper)


@functools.lru_cache(maxsize=SETUP_CACHE_SIZE)
def setup_for(scene: Scene, kernel: str, effects: tuple[Effect, ...]) -> Setup:
    """The set-up of a Simulator of `scene` on `kernel`: method (auto resolved), stability check,
    integrator class, the non-smooth elements' gaps and the compiled fast path. Kept per scene
    (a frozen value) and registry of effects (`effects.EFFECTS`, what builds the system), so a
    scene seen before costs a dictionary look-up."""
    system = scene.build_system()
    # the owners that step their own modes (`simulation.mode_stepping`) impose their method and integrator
    steppings = mode_owners.steppings((*system.elements, system.actuator))
    lead = leader(steppings)
    pick = lead.auto_method(scene) if lead is not None and scene.method == AUTO else None
    method, reason = (scene.method, "") if pick is None else (pick.method, pick.reason)
    substeps = 1
    options: dict[str, float] = {}
    if method == AUTO:
        method, reason = choose_method(scene)
        if (method == ERROR_CONTROLLED and system.actuator is None
                and stepper_slot.kernel().model_array(system) is None):
            reason += PYTHON_STAGES_NOTE
    for stepping in steppings:
        method, reason = stepping.method_for(scene, method, reason, lambda name: stable_under_auto(scene, system, name))
    if pick is not None:
        options, substeps = pick.options, pick.substeps
    elif scene.method == AUTO:
        options = integrator_options(scene, method)
        if method != ERROR_CONTROLLED:  # its error control resolves the contact mode itself
            substeps = contact_substeps(scene, METHODS[method].implicit)
    method_cls = METHODS[method]
    check_stability(scene, system, method_cls, substeps)
    depth = depth_limit(system.elements, scene.phalanx_radius)
    if depth is not None and scene.method != AUTO and method_cls.implicit:
        warn_unresolved_contact(scene, method_cls)
    integrator_cls, kernel_name = stepper_slot.kernel().select(method_cls, system, kernel)
    q0, _ = scene.initial_state()
    # every gap of every non-smooth element; empty on a smooth scene, which then pays nothing
    gaps = tuple(Gap(e, i, e.impact(i)) for e in system.elements if not e.smooth for i in range(len(e.gaps(q0))))
    kinks = tuple(gap for gap in gaps if gap.restitution is None) if substeps > 1 else ()
    # the gaps grouped by element, in `gaps` order: each element's gaps are evaluated once per state
    gap_elements = tuple((e, tuple(g.index for g in gaps if g.element is e))
                         for e in dict.fromkeys(g.element for g in gaps))
    depth_sources: tuple[tuple[int, float], ...] = ()
    if depth is not None:  # a depth gap ρ − δ per contact candidate, after every other gap
        depth_sources = tuple((next(p for p, g in enumerate(gaps) if g.element is depth.contact and g.index == i), rho)
                              for i, rho in enumerate(depth.offsets))
        gaps += tuple(Gap(depth, i, None) for i in range(len(depth.offsets)))  # type: ignore[arg-type]
    for stepping in steppings:  # an owner with its own slots steps them with the method (a winding current)
        integrator_cls, note = stepping.integrator_for(scene, system, method_cls, integrator_cls, kernel_name, bool(gaps))
        reason += note
    fast_stepper = None
    if hasattr(integrator_cls, "step_plan") and not gaps and not steppings:  # a stepping brings its own lean path
        fast_stepper = stepper_slot.kernel().fast_stepper(integrator_cls(system), scene.dt, scene.torque)
    own_system = bool(system.mode_owners)  # an owner of modes holds run state
    return Setup(system, method, reason, substeps, options, method_cls, integrator_cls, kernel_name, gaps, kinks,
                 gap_elements, depth_sources, fast_stepper, own_system, {})


def stable_under_auto(scene: Scene, system: FingerSystem, name: str) -> bool:
    """Whether method `name` is stable on the scene's fastest mode at auto's (sub)step for it."""
    cls = METHODS[name]
    return stable_at(cls, fastest_mode(system, mcp_range(scene)), scene.dt / contact_substeps(scene, cls.implicit), False)


def check_stability(scene: Scene, system: FingerSystem, cls: type[Integrator], substeps: int) -> None:
    """StabilityError unless `cls` is stable on the scene's fastest mode at its (sub)step; a named
    method on a scene with contact must also resolve that mode (`stability.stable_at`). auto
    resolves the contact mode by its substeps (auto.CONTACT_SUBSTEP_MODE_DT)."""
    root = fastest_mode(system, mcp_range(scene))
    contact = scene.method != AUTO and has_contact(system, scene.initial_state()[0])
    if not stable_at(cls, root, scene.dt / substeps, contact):
        raise StabilityError(cls.name, scene.name, scene.dt, root, largest_stable_dt(cls, root, scene.dt, contact),
                             f"a method with a bounded stability region must resolve the contact mode, |s|·dt ≤ {CONTACT_RESOLUTION:g}"
                             if contact and stable_at(cls, root, scene.dt) else "")
