"""The drive of spec §8: a DC motor behind a lossy, possibly self-locking gear train.

The scene's input is the terminal voltage command u (V). The motor current (L = 0) is
i = clamp((u − k_e N θ1')/R, ±i_max); the motor shaft passes τ_a = k_t i − J_m N θ1'' into the
mesh, and the mesh puts τ_g on link 1 in one of three modes (after Pelchen, Schweiger, Otter,
Modelica 2002; for η_b ≤ 0 as §8 states it, not as Modelica's `LossyGear`):

- `drive` (τ_g θ1' ≥ 0): τ_g = η_f N τ_a;
- `back` (τ_g θ1' ≤ 0): η_b τ_g = N τ_a, τ_g an unknown of the step's linear system;
- `stuck` (θ1' = 0): τ_g = τ_h, the torque that holds the linkage, while the holding test passes.

Both rolling modes are one linear law, c τ_g + N² J_m θ1'' = N k_t i with c = 1/η_f (drive) or
η_b (back). The linkage's θ1'' is affine in τ_g: θ1'' = a0 + τ_g / M_eff, a0 the acceleration
with no mesh torque and M_eff the linkage's inertia about θ1 (its one degree of freedom). So
τ_g = (N k_t i − N² J_m a0) / (c + N² J_m / M_eff): no negative inertia is ever added for
η_b ≤ 0, and the denominator's sign is §8's uniqueness condition N² J_m + η_b M_eff > 0.

The law is the plain float functions `motor_current`, `mesh_torque` and `holding_margin`;
`DrivenSystem` applies them, `Drive` owns the mode (discrete state) and its guards, and
`finger_sim.actuators.stepping` locates the mode changes inside the step.
"""

from __future__ import annotations

import math
import weakref
from collections.abc import Sequence
from dataclasses import asdict, dataclass
from typing import Any

from finger_sim.actuators.base import Actuator
from finger_sim.actuators.drive_outputs import (DRIVE_OUTPUTS, ENCODER, MESH_LOSS, MESH_MODE, MESH_TORQUE, MOTOR_ANGLE,
                                                MOTOR_CURRENT, MOTOR_VOLTAGE)
from finger_sim.dynamics import FingerSystem
from finger_sim.effects.base import ForceElement
from finger_sim.errors import SimulationDiverged
from finger_sim.kinematics import ZERO, Vec3
from finger_sim.model import FingerParams
from finger_sim.scene_yaml import mapping, number, whole
from finger_sim.state_layout import ModeSet, OwnModes, Slot

#: Mesh modes (the `mesh_mode` output's codes, index into MESH_MODES).
DRIVE, BACK, STUCK = 0, 1, 2
MESH_MODES = ("drive", "back", "stuck")
#: The mesh's declared mode and the guards that switch it (`actuators.stepping`): turn (θ1' reaches 0,
#: or the stuck mesh's holding margin), flank (τ_g against the flank), limit (the current limit acts).
MESH = ModeSet("mesh", MESH_MODES, ("turn", "flank", "limit"))
#: The drive's own continuous state with L > 0.
WINDING_CURRENT = Slot("i", "A", "winding current (L > 0)")
#: The drive's input.
VOLTAGE_INPUT = Slot("voltage", "V", "terminal voltage command")
#: Bounds of the drive's values: far beyond any prosthetic finger's motor and gear (spec §8's
#: defaults are 8 Ω, 4e-3 N·m/A, 5e-9 kg·m², 6 V, 0.5 A, N = 300); they keep products finite.
MAX_RESISTANCE = 1e4  # Ω
MAX_TORQUE_CONSTANT = 10.0  # N·m/A
MAX_ROTOR_INERTIA = 1.0  # kg·m²
MAX_SUPPLY_VOLTAGE = 1e3  # V
MAX_CURRENT_LIMIT = 1e3  # A
MAX_GEAR_RATIO = 1e5
#: Most negative backward efficiency: a worm at any lead and friction angle stays above −10.
MIN_BACKWARD_EFFICIENCY = -10.0
MAX_INDUCTANCE = 1.0  # H
MAX_ENCODER_COUNTS = 10**9  # per motor turn
#: A back flank whose denominator N² J_m / M_eff + η_b is at most this fraction of N² J_m / M_eff
#: is taken as non-unique (§8): the solution there is arbitrarily large.
UNIQUENESS_MARGIN = 1e-9


@dataclass(frozen=True)
class DriveParams:
    """Spec §8's drive, SI: Ω, N·m/A (k_e = k_t), kg·m², H, V, A; gear_ratio N (motor turns per
    turn of θ1); efficiencies η_f, η_b (η_b ≤ 0: self-locking); encoder counts per motor turn."""

    resistance: float = 8.0
    torque_constant: float = 4.0e-3
    rotor_inertia: float = 5.0e-9
    inductance: float = 0.0
    supply_voltage: float = 6.0
    current_limit: float = 0.5
    gear_ratio: float = 300.0
    efficiency: float = 0.4
    backward_efficiency: float = 2.0 - 1.0 / 0.4
    encoder_counts: int = 0

    @property
    def ideal(self) -> bool:
        """η_f = η_b = 1: a rigid lossless gear, no modes."""
        return self.efficiency == 1.0 and self.backward_efficiency == 1.0

    def to_dict(self) -> dict[str, Any]:
        return asdict(self)


def drive_from_dict(value: Any, key: str = "model.drive") -> DriveParams:
    """`model.drive` ({} = spec §8's defaults); ConfigError names the key, the range and the value."""
    data = mapping(value, key, set(DriveParams.__dataclass_fields__))
    d = DriveParams()

    def get(name: str, default: float, **bounds: Any) -> float:
        return number(data.get(name, default), f"{key}.{name}", **bounds)

    efficiency = get("efficiency", d.efficiency, minimum=0.0, maximum=1.0, strict=True)
    inductance = get("inductance", d.inductance, minimum=0.0, maximum=MAX_INDUCTANCE)
    counts = whole(data.get("encoder_counts", d.encoder_counts), f"{key}.encoder_counts", 0, MAX_ENCODER_COUNTS,
                   f"an integer in [0, {MAX_ENCODER_COUNTS}] (0: no encoder)")
    return DriveParams(
        resistance=get("resistance", d.resistance, minimum=0.0, maximum=MAX_RESISTANCE, strict=True),
        torque_constant=get("torque_constant", d.torque_constant, minimum=0.0, maximum=MAX_TORQUE_CONSTANT, strict=True),
        rotor_inertia=get("rotor_inertia", d.rotor_inertia, minimum=0.0, maximum=MAX_ROTOR_INERTIA, strict=True),
        inductance=inductance,
        supply_voltage=get("supply_voltage", d.supply_voltage, minimum=0.0, maximum=MAX_SUPPLY_VOLTAGE, strict=True),
        current_limit=get("current_limit", d.current_limit, minimum=0.0, maximum=MAX_CURRENT_LIMIT, strict=True),
        gear_ratio=get("gear_ratio", d.gear_ratio, minimum=0.0, maximum=MAX_GEAR_RATIO, strict=True),
        efficiency=efficiency,
        backward_efficiency=get("backward_efficiency", 2.0 - 1.0 / efficiency, minimum=MIN_BACKWARD_EFFICIENCY,
                                maximum=1.0),
        encoder_counts=counts,
    )


# -- the law, plain float functions ---------------------------------------------------------
def motor_current(u: float, omega_m: float, resistance: float, k_t: float, supply: float, limit: float) -> float:
    """i = clamp((sat(u) − k_e ω_m)/R, ±i_max), A (L = 0): u V saturated at ±supply, ω_m rad/s."""
    u = min(supply, max(-supply, u))
    return min(limit, max(-limit, (u - k_t * omega_m) / resistance))


def unclamped_current(u: float, omega_m: float, resistance: float, k_t: float, supply: float) -> float:
    """(sat(u) − k_e ω_m)/R, A: the current limit acts where its magnitude exceeds i_max."""
    u = min(supply, max(-supply, u))
    return (u - k_t * omega_m) / resistance


def current_rate(u: float, current: float, omega_m: float, resistance: float, k_t: float, inductance: float,
                 supply: float, limit: float) -> float:
    """i' (A/s) of the winding with L > 0: (sat(u) − R i − k_e ω_m)/L, u V saturated at ±supply, i A,
    ω_m rad/s, L H; 0 while |i| ≥ i_max and that would push |i| further (the driver lowers the
    terminal voltage, §8)."""
    u = min(supply, max(-supply, u))
    push = u - resistance * current - k_t * omega_m
    if (current >= limit and push > 0.0) or (current <= -limit and push < 0.0):
        return 0.0
    return push / inductance


def current_limit_guard(u: float, current: float, omega_m: float, resistance: float, k_t: float, supply: float,
                        limit: float) -> float:
    """The current limit's guard with L > 0 (its sign changes where the limit starts or stops acting):
    i_max − |i| (A) below the limit; at it, −sgn(i)·(sat(u) − R i − k_e ω_m) (V), negative while the
    winding would push |i| further."""
    if abs(current) < limit:
        return limit - abs(current)
    u = min(supply, max(-supply, u))
    push = u - resistance * current - k_t * omega_m
    return -push if current > 0.0 else push


def mesh_torque(c: float, ratio: float, rotor_inertia: float, k_t: float, current: float, a0: float,
                inv_inertia: float) -> float:
    """τ_g (N·m on θ1) of a rolling mesh: c τ_g + N² J_m θ1'' = N k_t i with θ1'' = a0 + τ_g/M_eff.

    c: 1/η_f (drive), η_b (back), 1 (ideal); a0: θ1'' without mesh torque (rad/s²);
    inv_inertia: 1/M_eff (1/(kg·m²)). The caller checks the denominator (uniqueness)."""
    nj = ratio * ratio * rotor_inertia
    return (ratio * k_t * current - nj * a0) / (c + nj * inv_inertia)


def unique(c: float, reflected: float) -> bool:
    """Whether a rolling flank's τ_g is unique: c + N² J_m / M_eff > 0 (§8), with a margin."""
    return c + reflected > UNIQUENESS_MARGIN * reflected


def holding_margin(tau_h: float, tau_a: float, ratio: float, eta_f: float, eta_b: float) -> float:
    """≥ 0 while a stuck mesh holds the load τ_h (N·m on θ1) under the motor's τ_a (N·m), §8.

    η_b > 0: holds while η_f N τ_a ≤ τ_h ≤ N τ_a/η_b. η_b ≤ 0: holds unless τ_h lies strictly
    between N τ_a/η_b and η_f N τ_a (motor off: any load)."""
    forward = eta_f * ratio * tau_a
    if eta_b > 0.0:
        backward = ratio * tau_a / eta_b
        return min(tau_h - min(forward, backward), max(forward, backward) - tau_h)
    if tau_a == 0.0:
        return abs(tau_h)
    backward = ratio * tau_a / eta_b if eta_b < 0.0 else -math.copysign(math.inf, tau_a)
    return max(min(forward, backward) - tau_h, tau_h - max(forward, backward))


def linkage_inertia(r1: float, r2: float, r3: float, m11: float, m22: float, m33: float, cc: float, alpha: float,
                    q0: float, q1: float, q2: float) -> float:
    """M_eff = nᵀ M n, kg·m²: the linkage's inertia about θ1, n = ∂q/∂θ1 on Φ = 0 (spec §2, §4).

    r1..r3 m; m11, m22, m33 and cc = m3 r1 L3/2 the mass matrix's constants (kg·m²), α rad."""
    s1, c1, s2, c2, s3, c3 = math.sin(q0), math.cos(q0), math.sin(q1), math.cos(q1), math.sin(q2), math.cos(q2)
    return linkage_inertia_at(r1, r2, r3, m11, m22, m33, cc, s1, c1, s2, c2, s3, c3, math.cos(q0 - q2 - alpha))


def linkage_inertia_at(r1: float, r2: float, r3: float, m11: float, m22: float, m33: float, cc: float, s1: float,
                       c1: float, s2: float, c2: float, s3: float, c3: float, cu: float) -> float:
    """`linkage_inertia` from the sines and cosines of θ1, θ2, θ3 and cu = cos(θ1 − θ3 − α)."""
    # [[r2 s2, r3 s3], [−r2 c2, −r3 c3]] (n2, n3) = (r1 s1, −r1 c1), as kinematics.dependent_rates
    det = r2 * s2 * (-r3 * c3) - r3 * s3 * (-r2 * c2)
    b1, b2 = r1 * s1, -r1 * c1
    n2 = (b1 * (-r3 * c3) - r3 * s3 * b2) / det
    n3 = (r2 * s2 * b2 - b1 * (-r2 * c2)) / det
    m13 = cc * cu
    return m11 + m22 * n2 * n2 + m33 * n3 * n3 + 2.0 * m13 * n3


#: Length of the drive's block at the end of the compiled model (`Drive.kernel_block`): mode, c in
#: drive, c in back, N, J_m, k_t, R, u_max, i_max, L, then NaN, which marks the block (every other
#: value of the model is finite).
KERNEL_BLOCK = 11


class Drive(OwnModes, Actuator):
    """The actuator: the drive's parameters and its discrete state (mesh mode, direction of motion).

    `mode` is DRIVE, BACK or STUCK (an ideal gear stays in DRIVE with c = 1), kept in the run's
    `ModeValues` once a Simulator binds it; `direction` is the
    sign of θ1' the rolling mode was entered with (its guards are signed by it). The compiled
    models made from it (`kernel_block`) follow every change of the mode. Declared (`actuators.base`):
    the input is the voltage, the mode is MESH, and with L > 0 the winding current is its own slot."""

    name = "drive"
    input = VOLTAGE_INPUT
    modes = (MESH,)

    def __init__(self, params: DriveParams) -> None:
        self.params = params
        self._mirrors: list[weakref.ref] = []  # compiled models whose block's first slot is the mode
        self.own_modes()  # DRIVE, MESH's initial value, until a run binds it
        self.direction = 1.0
        #: how often the mode was set (`mode_key`)
        self.changes = 0
        #: L > 0: the current is a state (`i`), integrated with the linkage (`actuators.inductive`)
        self.inductive = params.inductance > 0.0
        self.slots = (WINDING_CURRENT,) if self.inductive else ()
        #: the winding current at the Simulator's state, A: a state of its own when L > 0 (0 at t = 0)
        self.i = 0.0
        #: (q, q', (t, u, mode, direction), guards) of the last guard evaluation (`stepping._guards`)
        self.guard_cache: tuple | None = None
        #: (q, (t, u), holding margin) of the last stuck state tested (`stepping._release_time`)
        self.margin_cache: tuple | None = None
        #: the compiled model the Simulator steps with (None: the Python kernel)
        self.kernel_model = None
        #: an `actuators.stepping.EnergyLedger` the steps add their energy integrals to, or None
        self.ledger = None

    def mode_changed(self, value: int) -> None:
        """Count the switch and mirror the mesh mode into every compiled model of this drive."""
        self.changes += 1
        for ref in self._mirrors:
            model = ref()
            if model is not None:
                model[len(model) - KERNEL_BLOCK] = float(value)

    def mode_key(self) -> int:
        """`changes`: every setting of the mode, even to its value, starts the mesh law afresh."""
        return self.changes

    def kernel_block(self) -> list[float]:
        """The drive as the compiled model's last KERNEL_BLOCK floats (`finger_sim.kernel.layout`)."""
        p = self.params
        return [float(self.mode), self.c(DRIVE), self.c(BACK), p.gear_ratio, p.rotor_inertia, p.torque_constant,
                p.resistance, p.supply_voltage, p.current_limit, p.inductance, math.nan]

    def mirror(self, model) -> None:  # type: ignore[no-untyped-def]
        """Keep the mode slot of compiled model `model` (a numpy array ending in `kernel_block`) current."""
        self._mirrors = [ref for ref in self._mirrors if ref() is not None]
        self._mirrors.append(weakref.ref(model))

    # -- the actuator slot (`actuators.base.Actuator`): own = (i,) with L > 0, () with L = 0
    def initial(self) -> tuple[float, ...]:
        """The current is 0 A at t = 0."""
        return (0.0,) if self.inductive else ()

    def torque(self, system: FingerSystem, t: float, q: Vec3, v: Vec3, u: float, own: tuple[float, ...]) -> float:
        """τ_g (N·m) in the current mode (`DrivenSystem.mesh`)."""
        return system.mesh(t, q, v, u, self.mode, own[0] if own else None)[0]  # type: ignore[attr-defined]

    def accelerations(self, system: FingerSystem, t: float, q: Vec3, v: Vec3, u: float,
                      own: tuple[float, ...]) -> Vec3:
        """q'' in the current mode: the mesh is solved with the linkage (reflected inertia), not a torque."""
        return system.mesh(t, q, v, u, self.mode, own[0] if own else None)[2]  # type: ignore[attr-defined]

    def rates(self, t: float, q: Vec3, v: Vec3, u: float, own: tuple[float, ...]) -> tuple[float, ...]:
        """(i',) in A/s with L > 0 (`current_rate`), () with L = 0."""
        return (self.current_rate(u, own[0], v[0]),) if own else ()

    def current_rate(self, u: float, current: float, theta1_dot: float) -> float:
        """i' (A/s) with L > 0 (`current_rate`)."""
        p = self.params
        return current_rate(u, current, p.gear_ratio * theta1_dot, p.resistance, p.torque_constant, p.inductance,
                            p.supply_voltage, p.current_limit)

    def limit_guard(self, u: float, current: float, theta1_dot: float) -> float:
        """The current limit's guard with L > 0 (`current_limit_guard`)."""
        p = self.params
        return current_limit_guard(u, current, p.gear_ratio * theta1_dot, p.resistance, p.torque_constant,
                                   p.supply_voltage, p.current_limit)

    def c(self, mode: int) -> float:
        """The mesh law's coefficient on τ_g in a rolling mode."""
        p = self.params
        if p.ideal:
            return 1.0
        return 1.0 / p.efficiency if mode == DRIVE else p.backward_efficiency

    def current(self, u: float, theta1_dot: float) -> float:
        p = self.params
        return motor_current(u, p.gear_ratio * theta1_dot, p.resistance, p.torque_constant, p.supply_voltage,
                             p.current_limit)

    def unclamped_current(self, u: float, theta1_dot: float) -> float:
        """(sat(u) − k_e ω_m)/R, A (`unclamped_current`)."""
        p = self.params
        return unclamped_current(u, p.gear_ratio * theta1_dot, p.resistance, p.torque_constant, p.supply_voltage)


class DrivenSystem(FingerSystem):
    """The finger's equations with the drive's mesh torque on θ1: `accelerations(t, q, q', u)` takes
    the voltage command u (V) where FingerSystem takes τ, and applies the drive's current mode."""

    def __init__(self, params: FingerParams, elements: Sequence[ForceElement], drive: Drive) -> None:
        super().__init__(params, elements, drive)
        self.drive = drive
        self._inductive = drive.inductive
        #: whether τ_h at a held state may be kept (`holding_torque`): set where no element carries a state
        #: of its own (stick–slip friction, an actuator's slots), which would change it at the same (t, q)
        self.keeps_holding_torque = False
        #: whether τ_h at a fixed q is the same at every t (no element depends on time): kept across steps then
        self.holding_torque_is_steady = False
        self._held: tuple | None = None  # (t, q, τ_h) of the last held state asked

    def effective_inertia(self, q: Vec3) -> float:
        """M_eff = nᵀ M n, kg·m²: the linkage's inertia about θ1 (`linkage_inertia`)."""
        r1, r2, r3 = self._r
        return linkage_inertia(r1, r2, r3, self._m11, self._m22, self._m33, self._c, self.alpha, q[0], q[1], q[2])

    def holding_torque(self, t: float, q: Vec3, v: Vec3) -> float:
        """τ_h, N·m: the torque on θ1 that keeps θ1'' = 0 (§8), from the §4 system without mesh torque.
        At a held state (q' is ZERO) it is kept for the same t and q (the same tuple) when
        `keeps_holding_torque`: a stuck step's release test and its outputs ask for it at its end; for any t
        at that q when `holding_torque_is_steady` as well: a held stretch evaluates it once."""
        held = v is ZERO and self.keeps_holding_torque
        if held and self._held is not None and self._held[1] is q and (self._held[0] == t or self.holding_torque_is_steady):
            return self._held[2]
        a0 = FingerSystem.accelerations(self, t, q, v, 0.0)[0][0]
        tau_h = -a0 * self.effective_inertia(q)
        if held:
            self._held = (t, q, tau_h)
        return tau_h

    def mesh(self, t: float, q: Vec3, v: Vec3, u: float, mode: int,
             current: float | None = None) -> tuple[float, float, Vec3, tuple[float, float]]:
        """(τ_g N·m, i A, q'' rad/s², λ) at (t, q, q') under u (V) in `mode`; `current` (A): the winding's
        state when L > 0 (None: i follows u at once, L = 0).

        Stuck: q'' = 0 exactly and τ_g = τ_h. Rolling: τ_g from `mesh_torque`; SimulationDiverged where
        the back flank is not unique (N² J_m + η_b M_eff ≤ 0, near the toggle)."""
        drive = self.drive
        p = drive.params
        i = drive.current(u, v[0]) if current is None else current
        a0, lam0 = FingerSystem.accelerations(self, t, q, v, 0.0)
        m_eff = self.effective_inertia(q)
        if mode == STUCK:
            return -a0[0] * m_eff, i, ZERO, lam0
        c = drive.c(mode)
        reflected = p.gear_ratio * p.gear_ratio * p.rotor_inertia / m_eff
        if not unique(c, reflected):
            raise SimulationDiverged(
                f"the drive's back flank is not unique at θ1 = {q[0]:.6f} rad: N²·J_m + η_b·M_eff = "
                f"{(c + reflected) * m_eff:.3e} kg·m² ≤ 0 (spec §8; M_eff = {m_eff:.3e} grows without bound near the toggle)",
                t=t)
        tau_g = mesh_torque(c, p.gear_ratio, p.rotor_inertia, p.torque_constant, i, a0[0], 1.0 / m_eff)
        a, lam = FingerSystem.accelerations(self, t, q, v, tau_g)
        return tau_g, i, a, lam

    def accelerations(self, t: float, q: Vec3, v: Vec3, tau: float) -> tuple[Vec3, tuple[float, float]]:
        """(q'', λ) under the voltage command `tau` (V, the input slot) in the drive's current mode."""
        _, _, a, lam = self.mesh(t, q, v, tau, self.drive.mode, self.drive.i if self._inductive else None)
        return a, lam

    def output_names(self) -> tuple[str, ...]:
        """The names of `motor_outputs`, in order (the drive's CSV columns)."""
        counts = self.drive.params.encoder_counts
        return tuple(o.name for o in DRIVE_OUTPUTS if counts or o is not ENCODER)

    def motor_outputs(self, t: float, q: Vec3, v: Vec3, u: float, current: float | None = None) -> dict[str, float]:
        """The drive's outputs at a state (§8): motor_voltage (terminal, V), motor_current (A),
        motor_angle (rad, N θ1), encoder (counts, when set), mesh_mode (code, MESH_MODES), mesh_loss (W),
        mesh_torque (N·m on θ1). With L > 0 the current is the state `current` (A; None: the drive's `i`)."""
        drive = self.drive
        p = drive.params
        mode = drive.mode
        if self._inductive and current is None:
            current = drive.i
        if mode == STUCK and v is ZERO:  # τ_g = τ_h, as `mesh` gives it (the same arithmetic), kept
            tau_g, i, a = self.holding_torque(t, q, v), drive.current(u, v[0]) if current is None else current, ZERO
        else:
            tau_g, i, a, _ = self.mesh(t, q, v, u, mode, current)
        omega = p.gear_ratio * v[0]
        tau_a = p.torque_constant * i - p.rotor_inertia * p.gear_ratio * a[0]
        voltage = p.resistance * i + p.torque_constant * omega
        if self._inductive:  # v = R i + L i' + k_e ω_m (L i' = 0 while the limit acts: the driver lowers v)
            voltage = p.resistance * i + p.inductance * drive.current_rate(u, i, v[0]) + p.torque_constant * omega
        out = {
            MOTOR_VOLTAGE.name: voltage,
            MOTOR_CURRENT.name: i,
            MOTOR_ANGLE.name: p.gear_ratio * q[0],
        }
        if p.encoder_counts:
            out[ENCODER.name] = float(math.floor(p.gear_ratio * q[0] / (2.0 * math.pi) * p.encoder_counts))
        out[MESH_MODE.name] = float(mode)
        out[MESH_LOSS.name] = tau_a * omega - tau_g * v[0]
        out[MESH_TORQUE.name] = tau_g
        return out

    def powers(self, t: float, q: Vec3, v: Vec3, u: float, current: float | None = None) -> tuple[float, float, float, float]:
        """(electrical v·i, copper R i², mesh loss, Σ elements' Q·q') in W at a state, current mode
        (`current`: the winding's state with L > 0, A)."""
        out = self.motor_outputs(t, q, v, u, current)
        i = out[MOTOR_CURRENT.name]
        q_el = FingerSystem.generalized_force(self, t, q, v, 0.0)
        return (out[MOTOR_VOLTAGE.name] * i, self.drive.params.resistance * i * i, out[MESH_LOSS.name],
                q_el[0] * v[0] + q_el[1] * v[1] + q_el[2] * v[2])

    def rotor_energy(self, v: Vec3) -> float:
        """½ J_m ω_m², J."""
        p = self.drive.params
        return 0.5 * p.rotor_inertia * (p.gear_ratio * v[0]) ** 2

    def magnetic_energy(self, current: float) -> float:
        """½ L i², J."""
        return 0.5 * self.drive.params.inductance * current * current
