"""A drive with inductance L > 0 (spec §8): the winding current is a state of the step.

L i' = sat(u) − R i − k_e N θ1' is integrated with the linkage by the scene's explicit Runge-Kutta
tableau (rk4, rk6, dop8) on the seven states (q, q', i); the mesh law is the L = 0 one with the
current taken from the state (`DrivenSystem.mesh(..., current=i)`), so a stuck mesh still holds
θ1' = 0 exactly while the current follows its own equation. The driver's limit acts on the state:
where |i| reaches i_max and the winding would push it further, i' = 0 (`drive.current_rate`); its
start and end are events located inside the step, and the current is set to ±i_max exactly there.

The current is the actuator's own state (`Drive.i`, A, 0 at t = 0), not a seventh entry of the
Simulator's state: a scene with L = 0 runs exactly as before. The integrator keeps the current of
the states it produced (`InductiveRungeKutta.current_of`), so the Simulator's trial steps, event
location and substeps continue each state with its own current.

Methods: an explicit method must resolve the electrical modes at its step (`electrical_root`:
s² + (R/L) s + N² k_t²/(L (c M_eff + N² J_m)) = 0 over the rolling flanks and the MCP range).
`auto` splits each step into `electrical_substeps`; a named method that cannot is refused.
"""

from __future__ import annotations

import cmath
import math
from collections import deque
from typing import TYPE_CHECKING, ClassVar


from finger_sim import kinematics, stepper_slot
from finger_sim.actuators.drive import BACK, DRIVE, DrivenSystem, unique
from finger_sim.errors import ConfigError
from finger_sim.integrators.base import Integrator, TorqueFn
from finger_sim.integrators.explicit import ExplicitRungeKutta
from finger_sim.kinematics import Vec3
from finger_sim.projection import project

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
#: States the integrator remembers the current of (event location tries ≤ 2 × 60 per step).
MEMORY = 256


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


class InductiveRungeKutta(Integrator):
    """An explicit Runge-Kutta method (`reference`) on (q, q', i), `substeps` per step, projected after
    each. `current` (A) is the current of a state it did not produce (set by the caller); the states it
    produced continue with their own (`current_of`)."""

    reference: ClassVar[type[ExplicitRungeKutta]]
    substeps: ClassVar[int] = 1

    def __init__(self, system: DrivenSystem) -> None:  # type: ignore[override]
        super().__init__(system)
        ref = self.reference
        self._stages = tuple(
            (c, tuple((j, a) for j, a in enumerate(row) if a != 0.0)) for c, row in zip(ref.C, ref.A)
        )
        self._weights = tuple((j, b) for j, b in enumerate(ref.B) if b != 0.0)
        self.current = 0.0
        self._memory: deque[tuple[Vec3, Vec3, float]] = deque(maxlen=MEMORY)

    @classmethod
    def of(cls, reference: type[Integrator], substeps: int) -> type[InductiveRungeKutta]:
        return type(f"Inductive{reference.__name__}", (cls,), {
            "reference": getattr(reference, "reference", reference), "substeps": substeps, "name": reference.name,
            "order": reference.order, "keeps_constraints": reference.keeps_constraints, "implicit": False,
            "__doc__": f"{reference.name} on (q, q', i): {(reference.__doc__ or '').splitlines()[0]}",
        })

    def begin(self, q: Vec3, v: Vec3, i: float) -> None:
        """The state (q, q') the next steps start from has the current i (A), whatever it had when this
        integrator produced it (the current limit sets i = ±i_max at a located event)."""
        self.current = i
        self._memory.append((q, v, i))

    def current_of(self, q: Vec3, v: Vec3) -> float:
        """The current (A) of the state (q, q') (the same objects) this integrator produced or was told
        of last (`begin`), else `current`."""
        for qs, vs, i in reversed(self._memory):
            if qs is q and vs is v:
                return i
        return self.current

    def step(self, t: float, q: Vec3, v: Vec3, dt: float, torque: TorqueFn) -> tuple[Vec3, Vec3]:
        q, v, i = self.advance(t, q, v, self.current_of(q, v), dt, torque, self.substeps)
        self._memory.append((q, v, i))
        return q, v

    def advance(self, t: float, q: Vec3, v: Vec3, i: float, dt: float, torque: TorqueFn,
                n: int) -> tuple[Vec3, Vec3, float]:
        """(q, q', i) at t + dt from (q, q', i) at t in n substeps, remembering nothing."""
        h = dt / n
        for k in range(n):
            q, v, i = self._substep(t + k * h, q, v, i, h, torque)
        return q, v, i

    def _substep(self, t: float, q: Vec3, v: Vec3, i: float, dt: float, torque: TorqueFn) -> tuple[Vec3, Vec3, float]:
        """`ExplicitRungeKutta.step` with the current as a seventh state (same order of operations)."""
        system: DrivenSystem = self.system  # type: ignore[assignment]
        drive = system.drive
        mode = drive.mode
        kq: list[Vec3] = []
        kv: list[Vec3] = []
        ki: list[float] = []
        q0, q1, q2 = q
        v0, v1, v2 = v
        for c, row in self._stages:
            x0, x1, x2, w0, w1, w2, c6 = q0, q1, q2, v0, v1, v2, i
            for j, a in row:
                ha = dt * a
                dq, dv = kq[j], kv[j]
                x0 += ha * dq[0]
                x1 += ha * dq[1]
                x2 += ha * dq[2]
                w0 += ha * dv[0]
                w1 += ha * dv[1]
                w2 += ha * dv[2]
                c6 += ha * ki[j]
            ts = t + c * dt
            u = torque(ts)
            kq.append((w0, w1, w2))
            kv.append(system.mesh(ts, (x0, x1, x2), (w0, w1, w2), u, mode, c6)[2])
            ki.append(drive.current_rate(u, c6, w0))
        for j, b in self._weights:
            hb = dt * b
            dq, dv = kq[j], kv[j]
            q0 += hb * dq[0]
            q1 += hb * dq[1]
            q2 += hb * dq[2]
            v0 += hb * dv[0]
            v1 += hb * dv[1]
            v2 += hb * dv[2]
            i += hb * ki[j]
        q1_, v1_ = project(system.params, (q0, q1, q2), (v0, v1, v2))
        return q1_, v1_, i

    @classmethod
    def is_stable(cls, z: complex) -> bool:
        return cls.reference.is_stable(z / cls.substeps)


def integrator_class(integrator_cls: type[Integrator], substeps: int) -> type[Integrator]:
    """The class that steps an inductive drive with the method of `integrator_cls` (a Python
    ExplicitRungeKutta or its compiled twin, `kernel.integrators.CompiledRungeKutta`)."""
    compiled = hasattr(integrator_cls, "step_plan")
    base = stepper_slot.kernel().compiled_inductive() if compiled else InductiveRungeKutta
    return base.of(integrator_cls, substeps)
