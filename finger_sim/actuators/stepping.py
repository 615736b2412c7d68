"""The drive's mode changes located inside the step (spec §8), beside the Simulator's gap events.

A rolling mesh (drive or back) has three guards, each evaluated at the ends of an integrator step
and located by Illinois regula falsi on the step's length when one crosses:
- turn: direction·θ1' < 0, the finger turns (or stops). There the holding test decides: the mesh
  sticks (θ1' = 0 exactly from then on) or rolls on in the direction sgn(N τ_a − τ_h);
- flank: direction·τ_g changes sign against the flank (drive ↔ back), at τ_a = 0;
- limit: the current limit starts or stops acting (a kink of the force, no mode change).
A stuck mesh holds q fixed and q' = 0; the holding margin is then a function of time alone, and
its root (brentq) is where the mesh breaks free. An ideal gear has only the limit guard.

With `Drive.ledger` set, each smooth piece's powers are integrated by 3-point Gauss–Legendre
quadrature (states at the nodes by the same integrator step from the piece's start), so that the
energy report (`EnergyLedger`) closes to the integrator's accuracy.
"""

from __future__ import annotations

from collections.abc import Callable

import math
from contextlib import nullcontext
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
from scipy.optimize import brentq

from finger_sim import stepper_slot
from finger_sim.actuators.drive import BACK, DRIVE, STUCK, DrivenSystem, holding_margin
from finger_sim.errors import ConfigError, SimulationDiverged
from finger_sim.integrators.base import TorqueFn
from finger_sim.kinematics import ZERO, Vec3
from finger_sim.simulation.locate import GUARD_TOLERANCE  # noqa: F401  (read here by the compiled guards' tests)
from finger_sim.simulation.locate import LOCATE_TOLERANCE, GuardCrossing, first_guard_crossing
from finger_sim.simulation.mode_stepping import ModeStepping

if TYPE_CHECKING:
    from finger_sim.dynamics import FingerSystem
    from finger_sim.scene import Scene
    from finger_sim.actuators.drive import Drive
    from finger_sim.integrators import Integrator
    from finger_sim.simulation.driver import Simulator

#: Events (mode changes, kinks, impacts) allowed within one step before it is declared chattering.
MAX_EVENTS_PER_STEP = 64  # room for a stop's Zeno series down to its rest (effects.stops.REST_HEIGHT)
#: 3-point Gauss–Legendre nodes and weights on [0, 1] (exact for polynomials of degree 5).
GAUSS_NODES = (0.5 - math.sqrt(15.0) / 10.0, 0.5, 0.5 + math.sqrt(15.0) / 10.0)
GAUSS_WEIGHTS = (5.0 / 18.0, 8.0 / 18.0, 5.0 / 18.0)
TURN, FLANK, LIMIT = 0, 1, 2
#: The rolling mesh's guards by index, declared for `locate.first_guard_crossing`: turn and flank are
#: one-sided (the mode's conditions), the current limit two-sided (a kink, no mode change).
GUARDS_TWO_SIDED = tuple(k == LIMIT for k in (TURN, FLANK, LIMIT))
#: Methods that cannot step a drive scene: rattle takes Q and M apart (not the mesh's accelerations).
UNSUPPORTED_METHODS = ("rattle",)
#: auto's choices on a drive scene when its own is unsupported, in order: explicit (the table's usual
#: pick), then L-stable where the explicit one is unstable at the step (a stiff scene at a coarse dt).
DRIVE_FALLBACKS = ("rk4", "radau")


@dataclass
class EnergyLedger:
    """The drive's energy integrals over a run, J (spec §8's power balance):
    v i = R i² + d/dt ½ J_m ω_m² + mesh loss + τ_g θ1'."""

    electrical_work: float = 0.0  # ∫ v i dt
    copper_loss: float = 0.0  # ∫ R i² dt
    mesh_loss: float = 0.0  # ∫ (τ_a ω_m − τ_g θ1') dt
    element_work: float = 0.0  # ∫ Σ Q_elements · q' dt (springs, damping, contact, ...)
    impact_loss: float = 0.0  # kinetic energy (linkage and rotor) taken by stop impacts

    def report(self, system: DrivenSystem, q0: Vec3, v0: Vec3, q1: Vec3, v1: Vec3,
               currents: tuple[float, float] | None = None) -> dict[str, float]:
        """The balance between two states: each term (J) and `residual`, which closes to the
        integrator's accuracy: W − copper − mesh − Δ½J_m ω_m² − Δ(T + V) − dissipated − impacts;
        with L > 0 (`currents`: i at both states, A) also − Δ½L i² (`magnetic_energy_change`)."""
        rotor = system.rotor_energy(v1) - system.rotor_energy(v0)
        link = system.energy(q1, v1) - system.energy(q0, v0)
        dissipated = -self.element_work - (system.potential_energy(q1) - system.potential_energy(q0))
        residual = (self.electrical_work - self.copper_loss - self.mesh_loss - rotor - link - dissipated
                    - self.impact_loss)
        out = {"electrical_work": self.electrical_work, "copper_loss": self.copper_loss, "mesh_loss": self.mesh_loss,
               "rotor_energy_change": rotor, "linkage_energy_change": link, "dissipated": dissipated,
               "impact_loss": self.impact_loss, "residual": residual}
        if currents is not None:
            magnetic = system.magnetic_energy(currents[1]) - system.magnetic_energy(currents[0])
            out["magnetic_energy_change"], out["residual"] = magnetic, residual - magnetic
        return out


_compiled_guards = None  # finger_sim.kernel.drive.drive_guards, once a compiled Simulator starts


def drive_method(method: str, reason: str, auto: bool, stable: Callable[[str], bool],
                 inductive: bool = False) -> tuple[str, str]:
    """(method, reason) for a drive scene: auto's choice, or where it cannot step the drive the first of
    DRIVE_FALLBACKS that is `stable` at the scene's step (auto's substeps included); a named method that
    cannot is refused (ConfigError naming integrator.method). `inductive` (L > 0): a method that carries
    the current (`inductive.method_for`)."""
    if inductive:
        from finger_sim.actuators.inductive import method_for

        return method_for(method, reason, auto)
    if method not in UNSUPPORTED_METHODS:
        return method, reason
    if auto:
        fallback = next((m for m in DRIVE_FALLBACKS if stable(m)), DRIVE_FALLBACKS[-1])
        return fallback, f"{reason}; {method} cannot step the drive, {fallback} instead"
    raise ConfigError("integrator.method", f"a method that steps the drive (not {', '.join(UNSUPPORTED_METHODS)})",
                      method)


def start(sim: Simulator) -> None:
    """The mesh mode of the scene's initial state: at rest, the turning-point rule; moving, the flank."""
    global _compiled_guards
    system: DrivenSystem = sim.system  # type: ignore[assignment]
    model = getattr(sim.integrator, "model", None)  # a compiled integrator's model: its guards are compiled
    if model is None and sim.requested_kernel != "python":  # our DOP853's compiled stages: its guards too
        model = getattr(sim.integrator, "guard_model", None)
    system.drive.kernel_model, system.drive.guard_cache, system.drive.margin_cache = model, None, None
    # τ_h may be kept where no other owner carries a state of its own (stick–slip friction's modes)
    system.keeps_holding_torque, system._held = len(sim.mode_steppings) == 1, None
    system.holding_torque_is_steady = all(_steady(e) for e in system.elements)
    if model is not None:
        _compiled_guards = stepper_slot.kernel().compiled_drive().drive_guards
        _compiled_guards(model, 0.0, *ZERO, *ZERO, 0.0, 1.0)  # load it now, not at the first event of a paced step
    if system.drive.inductive:  # L > 0: the current is a state (actuators.inductive_stepping)
        from finger_sim.actuators import inductive_stepping

        inductive_stepping.start(sim)
        return
    u = sim.scene.torque(0.0)
    if sim.v[0] == 0.0:
        kept = sim.kept_start.get(__name__)  # the rule's outcome depends on the scene alone
        if kept is None:
            sim.v = _turn(system, 0.0, sim.q, u)
            sim.kept_start[__name__] = (system.drive.mode, system.drive.direction)
        else:
            (system.drive.mode, system.drive.direction), sim.v = kept, ZERO
    else:
        _roll(system, 0.0, sim.q, sim.v, u, math.copysign(1.0, sim.v[0]))


def _steady(element: object) -> bool:
    """Whether a force element's force at (q, q') is the same at every t: the ones known to be (a contact
    only with objects that do not move); an element not listed counts as depending on time."""
    from finger_sim.effects.contact import Contact
    from finger_sim.effects.damping import JointDamping
    from finger_sim.effects.gravity import Gravity
    from finger_sim.effects.spring import PipSpring
    from finger_sim.effects.stops import JointStops

    if isinstance(element, Contact):
        return type(element) is Contact and not element.time_varying
    return type(element) in (PipSpring, JointDamping, Gravity, JointStops)


def fast_stepper(sim: Simulator) -> object | None:
    """The lean compiled path of a drive scene's `Simulator.step` (`kernel.drive.DrivenFastStepper`):
    a compiled fixed-step method on a scene without gaps (stops, contact); else None. With L > 0 the
    compiled inductive step's (`kernel.inductive.InductiveFastStepper`)."""
    if sim._gaps:
        return None
    if sim.system.drive.inductive and hasattr(sim.integrator, "model"):  # type: ignore[attr-defined]
        return stepper_slot.kernel().inductive_fast_stepper(sim.integrator, sim.dt, sim.scene.torque,
                                                            sim.system.drive)  # type: ignore[attr-defined]
    if not hasattr(sim.integrator, "step_plan"):
        return None
    driven = stepper_slot.kernel().compiled_drive()  # numba is loaded by now
    return driven.DrivenFastStepper(sim.integrator, sim.dt, sim.scene.torque, sim.system.drive)  # type: ignore[arg-type,attr-defined]


def advance(sim: Simulator, t0: float, t1: float, u_fn: TorqueFn) -> None:
    """Integrate [t0, t1] of a drive scene (L = 0; L > 0: `inductive_stepping.advance`) under a smooth
    voltage u(s), splitting it at every mode change, current-limit kink and gap event (stops, contact)."""
    system: DrivenSystem = sim.system  # type: ignore[assignment]
    drive = system.drive
    ledger: EnergyLedger | None = drive.ledger
    t, q, v = t0, sim.q, sim.v
    for _ in range(MAX_EVENTS_PER_STEP):
        if drive.mode == STUCK:
            release = _release_time(system, t, t1, q, u_fn)
            end = t1 if release is None else release
            if ledger is not None and end > t:
                _integrate(ledger, system, t, end, lambda s: (q, ZERO), u_fn)
            if release is None:
                sim.q, sim.v = q, ZERO
                return
            t, v = release, ZERO
            _roll(system, t, q, v, u_fn(t), _break_direction(system, t, q, u_fn(t)))
            if t >= t1:  # freed on the step's end: no zero-length step (as stick–slip friction's advance)
                sim.q, sim.v = q, v
                return
        q1, v1 = sim._step(t, q, v, t1 - t, u_fn)
        event = _first_event(sim, system, t, q, v, t1, q1, v1, u_fn)
        end, qe, ve = (t1, q1, v1) if event is None else (event.t, *event.state)
        crossing = sim._first_crossing(t, q, v, end, qe, ve, u_fn) if sim._gaps else None
        if crossing is not None:  # a stop or a contact change first: the mode guards are checked again after it
            end, qe, ve = crossing.t, crossing.q, crossing.v
        if ledger is not None:
            t_, q_, v_ = t, q, v
            with getattr(sim.integrator, "aside", nullcontext)():  # dop853 continues as without the quadrature
                _integrate(ledger, system, t, end, lambda s: sim._step(t_, q_, v_, s - t_, u_fn), u_fn)
        t, q, v = end, qe, ve
        if crossing is not None:
            if crossing.gap.restitution is not None:
                before = system.kinetic_energy(q, v) + system.rotor_energy(v)
                v = sim._impact(crossing, u_fn)
                if ledger is not None:
                    ledger.impact_loss += before - system.kinetic_energy(q, v) - system.rotor_energy(v)
                if sim._resting is not None:  # at rest on the stop: the mesh may hold it
                    v = _turn(system, t, q, u_fn(t))
                    if drive.mode == STUCK:
                        sim._resting = None
        elif event is not None:
            u = u_fn(t)
            if event.guard == TURN:
                v = _turn(system, t, q, u)
            elif event.guard == FLANK:
                drive.mode = BACK if drive.mode == DRIVE else DRIVE
        else:
            sim.q, sim.v = q1, v1
            return
        if sim._resting is not None:
            release = sim._release_time(sim._resting, t, t1, q, u_fn)
            if release is None:
                sim.q, sim.v = q, ZERO
                return
            sim._resting = None
            t, v = release, _turn(system, release, q, u_fn(release))  # leaving the stop is a turning point
            if drive.mode == STUCK:
                continue
        if t >= t1:
            sim.q, sim.v = q, v
            return
    raise SimulationDiverged(f"more than {MAX_EVENTS_PER_STEP} events (mesh modes, current limit, stops, contact) in "
                             "one step", method=sim.method, t=t0, dt=sim.dt)


class DriveStepping(ModeStepping):
    """The drive's mesh modes (L = 0) as the Simulator steps them (`simulation.mode_stepping`): its start
    and advance here, its lean step, the method that can step the mesh, and its outputs recorded as the run
    goes (`actuators.record`). Stick–slip friction carries it (the two lock as one, `stick_slip`)."""

    name = "drive"

    def __init__(self, drive: Drive) -> None:
        self.drive = drive

    def method_for(self, scene: Scene, method: str, reason: str, stable: Callable[[str], bool]) -> tuple[str, str]:
        from finger_sim.scene import AUTO

        return drive_method(method, reason, scene.method == AUTO, stable, self.drive.inductive)

    # the module's functions themselves: no extra call on the step's path
    start = staticmethod(start)
    advance = staticmethod(advance)
    fast_stepper = staticmethod(fast_stepper)

    def record_run(self, sim: Simulator, n: int, again: Callable[[], Simulator] | None):  # type: ignore[no-untyped-def]
        from finger_sim.actuators import record

        return record.run(sim, n, again)

    def run_states(self, sim: Simulator, n: int) -> np.ndarray:
        from finger_sim.actuators import record

        return record.states(sim, n)


class InductiveDriveStepping(DriveStepping):
    """The drive with L > 0 (`actuators.inductive_stepping`): the winding current is its slot, its method
    carries it in substeps that resolve L/R, and its advance carries stick–slip friction's modes too."""

    name = "inductive drive"
    carries = ("stick_slip",)

    def integrator_for(self, scene: Scene, system: FingerSystem, method: type[Integrator],
                       integrator_cls: type[Integrator], kernel: str, gaps: bool) -> tuple[type[Integrator], str]:
        from finger_sim.actuators import inductive
        from finger_sim.scene import AUTO

        substeps = inductive.electrical_substeps(scene, system, method, scene.method == AUTO)  # type: ignore[arg-type]
        return inductive.integrator_class(integrator_cls, substeps), inductive.kernel_note(kernel, gaps)

    def start(self, sim: Simulator) -> None:
        from finger_sim.actuators import inductive_stepping

        DriveStepping.start(sim)  # the mesh mode, and the friction's with it (`inductive_stepping.start`)
        inductive_stepping.start_friction(sim)

    def advance(self, sim: Simulator, t0: float, t1: float, u: TorqueFn) -> None:
        from finger_sim.actuators import inductive_stepping

        inductive_stepping.advance(sim, t0, t1, u)

    def own_slots(self, sim: Simulator) -> tuple[float, ...]:
        return (self.drive.i,)


def stepping_of(drive: Drive) -> DriveStepping:
    """The drive's stepping: with its winding current as a state where L > 0."""
    return InductiveDriveStepping(drive) if drive.inductive else DriveStepping(drive)


# -- modes --------------------------------------------------------------------------------
def _turn(system: DrivenSystem, t: float, q: Vec3, u: float) -> Vec3:
    """At θ1' = 0: stick if the mesh holds τ_h, else roll towards sgn(N τ_a − τ_h). Returns q' (zero)."""
    drive = system.drive
    p = drive.params
    if p.ideal:
        return ZERO
    tau_h = system.holding_torque(t, q, ZERO)
    tau_a = p.torque_constant * drive.current(u, 0.0)
    if holding_margin(tau_h, tau_a, p.gear_ratio, p.efficiency, p.backward_efficiency) >= 0.0:
        drive.mode = STUCK
        return ZERO
    _roll(system, t, q, ZERO, u, _break_direction(system, t, q, u))
    return ZERO


def _break_direction(system: DrivenSystem, t: float, q: Vec3, u: float) -> float:
    """sgn(N τ_a − τ_h) at rest (§8): the way a mesh that does not hold starts to move."""
    p = system.drive.params
    excess = p.gear_ratio * p.torque_constant * system.drive.current(u, 0.0) - system.holding_torque(t, q, ZERO)
    return 1.0 if excess >= 0.0 else -1.0


def _roll(system: DrivenSystem, t: float, q: Vec3, v: Vec3, u: float, direction: float) -> None:
    """Enter the rolling flank whose solution meets its sign condition for motion along `direction`:
    drive when direction·τ_g ≥ 0, else back (§8: unique while N² J_m + η_b M_eff > 0)."""
    drive = system.drive
    drive.direction = direction
    if drive.params.ideal:
        drive.mode = DRIVE
        return
    tau_d = system.mesh(t, q, v, u, DRIVE)[0]
    drive.mode = DRIVE if direction * tau_d >= 0.0 else BACK


def _guards(system: DrivenSystem, t: float, q: Vec3, v: Vec3, u: float) -> tuple[float, float, float]:
    """(turn, flank, limit) of the rolling mesh at a state; ≥ 0 while the mode's conditions hold.
    On the compiled kernel they are compiled too (`kernel.numerics.drive_guards`, the same arithmetic).
    The last state asked is kept: a step's end is the next one's start."""
    drive = system.drive
    key = (t, u, drive.mode, drive.direction)
    cached = drive.guard_cache
    if cached is not None and cached[0] is q and cached[1] is v and cached[2] == key:
        return cached[3]
    model = drive.kernel_model
    if model is not None:
        out = _compiled_guards(model, t, q[0], q[1], q[2], v[0], v[1], v[2], u, drive.direction)
    else:
        p = drive.params
        limit = p.current_limit - abs(drive.unclamped_current(u, v[0]))
        if p.ideal:
            out = (math.inf, math.inf, limit)
        else:
            tau_g = system.mesh(t, q, v, u, drive.mode)[0]
            s = drive.direction
            out = (s * v[0], (s if drive.mode == DRIVE else -s) * tau_g, limit)
    drive.guard_cache = (q, v, key, out)
    return out


def _first_event(sim: Simulator, system: DrivenSystem, t: float, q: Vec3, v: Vec3, t1: float, q1: Vec3, v1: Vec3,
                u_fn: TorqueFn) -> GuardCrossing | None:
    """The earliest mesh guard crossing of the step (t, q, q') → (t1, q1, q1'), located (state (q, q')
    there); None if none."""
    def at(k: int, s: float) -> tuple[float, tuple[Vec3, Vec3]]:
        qs, vs = sim._step(t, q, v, s - t, u_fn)
        return _guards(system, s, qs, vs, u_fn(s))[k], (qs, vs)

    g0 = _guards(system, t, q, v, u_fn(t))
    g1 = _guards(system, t1, q1, v1, u_fn(t1))
    return first_guard_crossing(GUARDS_TWO_SIDED, g0, g1, at, t, t1, (q1, v1))


def _release_time(system: DrivenSystem, t: float, t1: float, q: Vec3, u_fn: TorqueFn) -> float | None:
    """When in [t, t1] a stuck mesh breaks free; None if it holds throughout. q is fixed and q' = 0,
    so the holding margin is a function of time alone: its root, by brentq."""
    drive = system.drive
    p = drive.params

    def margin(s: float) -> float:
        tau_a = p.torque_constant * drive.current(u_fn(s), 0.0)
        return holding_margin(system.holding_torque(s, q, ZERO), tau_a, p.gear_ratio, p.efficiency,
                              p.backward_efficiency)

    def end_margin(s: float) -> float:
        """margin(s), kept: a held step's end is the next one's start (the same s, u and q)."""
        key = (s, u_fn(s))
        cached = drive.margin_cache
        if cached is not None and cached[0] is q and cached[1] == key:
            return cached[2]
        value = margin(s)
        drive.margin_cache = (q, key, value)
        return value

    if end_margin(t) < 0.0:
        return t
    if end_margin(t1) >= 0.0:
        return None
    return brentq(margin, t, t1, xtol=LOCATE_TOLERANCE * (t1 - t), rtol=4 * np.finfo(float).eps)


def _integrate(ledger: EnergyLedger, system: DrivenSystem, a: float, b: float, state_at, u_fn: TorqueFn) -> None:
    """Add ∫_a^b of the drive's powers (3-point Gauss–Legendre; state_at(s) → (q, q') at s) to the ledger."""
    h = b - a
    if h <= 0.0:
        return
    for x, w in zip(GAUSS_NODES, GAUSS_WEIGHTS):
        s = a + x * h
        qs, vs = state_at(s)
        elec, copper, mesh, work = system.powers(s, qs, vs, u_fn(s))
        ledger.electrical_work += w * h * elec
        ledger.copper_loss += w * h * copper
        ledger.mesh_loss += w * h * mesh
        ledger.element_work += w * h * work
