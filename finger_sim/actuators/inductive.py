"""A drive with inductance L > 0 (spec §8): the winding current is a state of the step.

L i' = sat(u) − R i − k_e N θ1' is integrated with the linkage by the scene's explicit Runge-Kutta
tableau (rk4, rk6, dop8) on the seven states (q, q', i); the mesh law is the L = 0 one with the
current taken from the state (`DrivenSystem.mesh(..., current=i)`), so a stuck mesh still holds
θ1' = 0 exactly while the current follows its own equation. The driver's limit acts on the state:
where |i| reaches i_max and the winding would push it further, i' = 0 (`drive.current_rate`); its
start and end are events located inside the step, and the current is set to ±i_max exactly there.

The current is the drive's declared slot (`Drive.slots`: i, A, 0 at t = 0), stepped in the flat state
(q, q', i) by `integrators.stateful.StatefulRungeKutta` like any actuator's own state; the Simulator
keeps it on the drive (`Drive.i`), so a scene with L = 0 runs exactly as before. The integrator keeps
the slots of the states it produced (`StatefulRungeKutta.own_of`), so the Simulator's trial steps,
event location and substeps continue each state with its own current.

Methods: an explicit method must resolve the electrical modes at its step (`electrical_root`:
s² + (R/L) s + N² k_t²/(L (c M_eff + N² J_m)) = 0 over the rolling flanks and the MCP range).
`auto` splits each step into `electrical_substeps`; a named method that cannot is refused.
"""

from __future__ import annotations

import cmath
import math
from typing import TYPE_CHECKING


from finger_sim import kinematics, stepper_slot
from finger_sim.actuators.drive import BACK, DRIVE, DrivenSystem, unique
from finger_sim.errors import ConfigError
from finger_sim.integrators.base import Integrator
from finger_sim.integrators.stateful import StatefulRungeKutta

if TYPE_CHECKING:
    from finger_sim.scene import Scene

#: Methods that carry the current: the explicit Runge-Kutta tableaux (their stages take it along).
CARRYING_METHODS = ("rk4", "rk6", "dop8")
#: auto's choice on an inductive drive when its own cannot carry the current.
INDUCTIVE_DEFAULT = "rk4"
#: auto's substep resolves the fastest electrical mode: |s|·h ≤ this (rk4's local error there ≈ 1e-5
#: of the transient; its stability bound on the real axis is 2.79).
ELECTRICAL_RESOLUTION = 0.25
#: Most substeps auto takes per step; beyond that L/R is far below dt and L = 0 is the model to use.
MAX_ELECTRICAL_SUBSTEPS = 1024
#: MCP poses sampled for the linkage's inertia M_eff (as `stability.SAMPLES`), off the toggles by
#: `stability.TOGGLE_MARGIN`.
SAMPLES = 33


def electrical_root(system: DrivenSystem, theta1_range: tuple[float, float]) -> complex:
    """The electromechanical root of largest magnitude, 1/s: s² + (R/L) s + N² k_t²/(L m) = 0 with
    m = c M_eff + N² J_m for each rolling flank's c (1/η_f, η_b; 1 for an ideal gear) where it is
    unique, M_eff (kg·m²) over poses θ1 in theta1_range (rad)."""
    from finger_sim.stability import TOGGLE_MARGIN

    p = system.drive.params
    lo, hi = kinematics.assembly_range(system.params)
    lo, hi = max(theta1_range[0], lo + TOGGLE_MARGIN), min(theta1_range[1], hi - TOGGLE_MARGIN)
    reflected = p.gear_ratio**2 * p.rotor_inertia
    cs = (1.0,) if p.ideal else (system.drive.c(DRIVE), system.drive.c(BACK))
    worst = complex(-p.resistance / p.inductance)
    for k in range(SAMPLES):
        m_eff = system.effective_inertia(kinematics.assemble(system.params, lo + (hi - lo) * k / (SAMPLES - 1)))
        for c in cs:
            if not unique(c, reflected / m_eff):
                continue
            b, c0 = p.resistance / p.inductance, (p.gear_ratio * p.torque_constant) ** 2 / (p.inductance * (c * m_eff + reflected))
            disc = cmath.sqrt(b * b - 4.0 * c0)
            for s in ((-b + disc) / 2.0, (-b - disc) / 2.0):
                if abs(s) > abs(worst):
                    worst = s
    return worst


def method_for(method: str, reason: str, auto: bool) -> tuple[str, str]:
    """(method, reason) on a drive with L > 0: a method that carries the current (CARRYING_METHODS),
    auto's own or INDUCTIVE_DEFAULT; a named one that cannot is refused (ConfigError)."""
    if method in CARRYING_METHODS:
        return method, reason
    if auto:
        return INDUCTIVE_DEFAULT, (f"{reason}; {method} cannot carry the winding current (L > 0): {INDUCTIVE_DEFAULT} "
                                   "instead, in substeps that resolve L/R")
    raise ConfigError("integrator.method", f"a method that carries the winding current ({', '.join(CARRYING_METHODS)}"
                      " or auto) for a drive with inductance > 0", method)


def electrical_substeps(scene: Scene, system: DrivenSystem, method: type[Integrator], auto: bool) -> int:
    """Substeps per step that resolve the electrical modes: auto's ceil(|s| dt / ELECTRICAL_RESOLUTION);
    a named method takes 1 and is refused (ConfigError) where it is unstable on the mode at dt."""
    from finger_sim.stability import largest_stable_dt, mcp_range, stable_at

    root = electrical_root(system, mcp_range(scene))
    p = system.drive.params
    if auto:
        n = max(1, math.ceil(abs(root) * scene.dt / ELECTRICAL_RESOLUTION))
        if n > MAX_ELECTRICAL_SUBSTEPS:
            raise ConfigError("model.drive.inductance", f"an L/R that a step of dt = {scene.dt:g} s resolves in at most "
                              f"{MAX_ELECTRICAL_SUBSTEPS} substeps, or 0 H (the current follows the voltage at once)",
                              p.inductance, problem=f"L/R = {p.inductance / p.resistance:.3g} s, fastest electrical "
                              f"mode |s| = {abs(root):.4g} 1/s")
        return n
    if not stable_at(method, root, scene.dt):
        raise ConfigError("integrator.method", f"auto, or dt ≤ {largest_stable_dt(method, root, scene.dt):.3g} s",
                          method.name, problem=f"{method.name} does not resolve the winding at dt = {scene.dt:g} s "
                          f"(L/R = {p.inductance / p.resistance:.3g} s, fastest electrical mode |s| = {abs(root):.4g} 1/s)")
    return 1


class InductiveRungeKutta(StatefulRungeKutta):
    """`StatefulRungeKutta` with the drive as the actuator: the flat state (q, q', i), the mesh's q'' in
    the drive's mode at the stage's current, and i' from `Drive.current_rate`."""

    def __init__(self, system: DrivenSystem) -> None:  # type: ignore[override]
        super().__init__(system, system.drive)


def kernel_note(kernel: str, gaps: bool) -> str:
    """What the method's reason says of the kernel that steps the current (`kernel`: the Setup's name,
    "python" or "numba-…"); gaps: the scene has stops or contact."""
    if kernel == "python":
        return "; the Python path carries the current"
    if gaps:
        return (f"; {kernel} carries the current in its substeps, the events (mesh modes, current limit, stops, "
                "contact) located in Python")
    return (f"; {kernel} carries the current: each rolling step (input, substeps, guards) is one compiled call, "
            "a step with an event is located in Python")


def integrator_class(integrator_cls: type[Integrator], substeps: int) -> type[Integrator]:
    """The class that steps an inductive drive with the method of `integrator_cls` (a Python
    ExplicitRungeKutta or its compiled twin, `kernel.integrators.CompiledRungeKutta`)."""
    compiled = hasattr(integrator_cls, "step_plan")
    base = stepper_slot.kernel().compiled_inductive() if compiled else InductiveRungeKutta
    return base.of(integrator_cls, substeps)
