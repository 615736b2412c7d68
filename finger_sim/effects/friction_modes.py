"""Exact stick–slip friction at the contacts (spec §7, `model.contact.friction_model: stick_slip`).

The linkage has one degree of freedom, so stick is a state of the linkage, not of each contact:

- `locked` (θ1' = 0): the contacts' friction supplies one holding torque τ_h on θ1, the torque that
  keeps θ1'' = 0 (spec §4 with the friction left out). It holds while |τ_h| ≤ Σ μ_s F_n,k |j_k|,
  j_k = t_k·∂p_k/∂θ1 along the linkage (m/rad), t_k = n_c turned by +90°;
- `sliding` (θ1' ≠ 0, its sign `direction`): F_t,k = −μ F_n,k sgn(j_k θ1'), μ = μ_k, or with a
  Stribeck velocity v_st, μ = μ_k + (μ_s − μ_k) exp(−(v_t/v_st)²), v_t = j_k θ1'.

This module holds the law (`FrictionLaw`, the scene keys) and the force element
(`StickSlipContact`, the §7 contact with this friction); `finger_sim.stick_slip` steps the modes
(breakaway and lock located inside the step). The regularized law (`Contact`) is the default and
is untouched by this one.
"""

from __future__ import annotations

import math
import weakref
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any, ClassVar

import numpy as np

from finger_sim.effects.base import STICK_SLIP_CONTACT
from finger_sim.effects.contact import Contact, _Hit
from finger_sim.effects.contact_law import along_tangent
from finger_sim.effects.contact_outputs import FRICTION_MODE, FRICTION_POWER, FRICTION_TORQUE
from finger_sim.errors import ConfigError, SimulationDiverged
from finger_sim.kinematics import Vec3
from finger_sim.state_layout import ModeSet, OwnModes

REGULARIZED, STICK_SLIP = "regularized", "stick_slip"
FRICTION_MODELS = (REGULARIZED, STICK_SLIP)
#: The keys of `model.contact` that belong to the friction law (besides `friction`, μ_k).
FRICTION_KEYS = ("friction_model", "static_friction", "stribeck_velocity")
#: Largest friction coefficient a scene may set (as `scene.MAX_FRICTION` for μ_k).
MAX_STATIC_FRICTION = 10.0
#: Bounds of the Stribeck velocity v_st, m/s.
MIN_STRIBECK_VELOCITY, MAX_STRIBECK_VELOCITY = 1e-9, 10.0
#: The friction modes as the `friction_mode` output reports them.
SLIDING, LOCKED = 0, 1
#: The linkage's friction mode and its guards: the turn (θ1' reaches 0 sliding, then the holding test)
#: and the breakaway (the locked holding margin turns negative).
FRICTION = ModeSet("friction", ("sliding", "locked"), ("turn", "breakaway"), initial=LOCKED)
#: Locked step ends whose holding torque an element remembers for `outputs` (the oldest go first):
#: more than a streamed block's rows (`streaming.BLOCK_STEPS`), whose outputs are taken after the block.
HOLD_MEMORY = 4096
#: Length of the law's block before the contact's own parameters in `kernel_params`: mode, direction,
#: μ_k, μ_s, v_st (0: no Stribeck term).
KERNEL_BLOCK = 5
#: A tangential gain |j_k| below this (m/rad) is round-off of j_k = 0 (the proximal capsule on a circle):
#: such a contact cannot carry the linkage along a moving object (`StickSlipContact.stick_speed`).
MIN_TANGENT_GAIN = 1e-9
#: Two contacts in touch with one moving object whose stick speeds w_k/j_k differ by more than this
#: (relative, rad/s) cannot stick at once: the one-DOF linkage cannot follow both.
STICK_SPEED_TOLERANCE = 1e-9


# -- the law, plain float functions (the kernel compiles these same functions) -------------------
def linkage_slope(r1: float, r2: float, r3: float, q0: float, q1: float, q2: float) -> float:
    """dθ3/dθ1 on Φ = 0 at q = (q0, q1, q2) rad (r1..r3 m): `kinematics.dependent_rates` at θ1' = 1,
    the same Cramer solve. Singular at the toggle (the scene keeps away from it)."""
    b1 = r1 * math.sin(q0) * 1.0
    b2 = -r1 * math.cos(q0) * 1.0
    s2, c2, s3, c3 = math.sin(q1), math.cos(q1), math.sin(q2), math.cos(q2)
    d = r2 * s2 * (-r3 * c3) - r3 * s3 * (-r2 * c2)
    return (r2 * s2 * b2 - b1 * (-r2 * c2)) / d


def tangent_gain(nx: float, ny: float, j1x: float, j1y: float, j3x: float, j3y: float, n3: float) -> float:
    """j_k = t_c·∂p/∂θ1 along the linkage, m/rad: t_c = (−ny, nx), ∂p/∂θ1 = j1 + n3 j3 (n3 = dθ3/dθ1)."""
    return -ny * (j1x + n3 * j3x) + nx * (j1y + n3 * j3y)


def sliding_friction(fn: float, j: float, direction: float, theta1_dot: float, mu_k: float, mu_s: float,
                     v_st: float) -> float:
    """F_t along t_c (N) of a contact sliding with the linkage towards `direction` (±1): −μ F_n sgn(j direction),
    μ = μ_k, or with v_st > 0 (m/s) μ_k + (μ_s − μ_k) exp(−(j θ1'/v_st)²); 0 where j = 0 (no tangential motion)."""
    if j == 0.0:
        return 0.0
    mu = mu_k
    if v_st > 0.0:
        mu += (mu_s - mu_k) * math.exp(-((j * theta1_dot) / v_st) ** 2)
    return -mu * fn * math.copysign(1.0, j * direction)


@dataclass(frozen=True)
class FrictionLaw:
    """Which friction law the contacts use (spec §7): `model` is "regularized" (the tanh law, the
    default) or "stick_slip"; `static_friction` μ_s (None: μ_k); `stribeck_velocity` v_st, m/s (None: no
    Stribeck term, the kinetic coefficient at every sliding speed)."""

    model: str = REGULARIZED
    static_friction: float | None = None
    stribeck_velocity: float | None = None

    def to_dict(self) -> dict[str, Any]:
        """The law's keys of `model.contact`; none for the default law, so old scenes dump as before."""
        if self.model == REGULARIZED:
            return {}
        out: dict[str, Any] = {"friction_model": self.model}
        if self.static_friction is not None:
            out["static_friction"] = self.static_friction
        if self.stribeck_velocity is not None:
            out["stribeck_velocity"] = self.stribeck_velocity
        return out


def split_friction_keys(value: Any) -> tuple[Any, dict[str, Any]]:
    """(`model.contact` without the friction law's keys, those keys): the contact law and the friction
    law are validated apart. A value that is not a mapping is passed on for the contact law to refuse."""
    if not isinstance(value, dict):
        return value, {}
    return ({k: v for k, v in value.items() if k not in FRICTION_KEYS},
            {k: v for k, v in value.items() if k in FRICTION_KEYS})


def friction_law_from_dict(keys: Mapping[str, Any], kinetic: float) -> FrictionLaw:
    """Validate the friction law's keys of `model.contact` (`split_friction_keys`) given μ_k = `kinetic`.
    ConfigError names the key and the range: μ_s in [μ_k, MAX_STATIC_FRICTION], v_st in
    [MIN_STRIBECK_VELOCITY, MAX_STRIBECK_VELOCITY] m/s, both only with `friction_model: stick_slip`."""
    key = "model.contact."
    model = keys.get("friction_model", REGULARIZED)
    if model not in FRICTION_MODELS:
        raise ConfigError(key + "friction_model", f"one of {list(FRICTION_MODELS)}", model)
    if model == REGULARIZED:
        extra = [k for k in ("static_friction", "stribeck_velocity") if k in keys]
        if extra:
            raise ConfigError(key + extra[0], f"no value with friction_model: {REGULARIZED} (it belongs to {STICK_SLIP})",
                              keys[extra[0]])
        return FrictionLaw()
    static = keys.get("static_friction")
    if static is not None and not (_is_number(static) and kinetic <= static <= MAX_STATIC_FRICTION):
        raise ConfigError(key + "static_friction", f"a number in [friction = {kinetic:g}, {MAX_STATIC_FRICTION:g}] (μ_s ≥ μ_k)",
                          static)
    stribeck = keys.get("stribeck_velocity")
    if stribeck is not None and not (_is_number(stribeck) and MIN_STRIBECK_VELOCITY <= stribeck <= MAX_STRIBECK_VELOCITY):
        raise ConfigError(key + "stribeck_velocity", f"a speed in [{MIN_STRIBECK_VELOCITY:g}, {MAX_STRIBECK_VELOCITY:g}] m/s",
                          stribeck)
    return FrictionLaw(STICK_SLIP, None if static is None else float(static), None if stribeck is None else float(stribeck))


def _is_number(value: Any) -> bool:
    return isinstance(value, (int, float)) and not isinstance(value, bool) and math.isfinite(value)


class StickSlipContact(OwnModes, Contact):
    """The §7 contact (Hunt–Crossley normal force, the same candidates and gaps) with stick–slip
    friction in place of the regularized law. It owns the linkage's friction mode (`mode`, LOCKED or
    SLIDING, kept in the run's `ModeValues`) and the sliding `direction` ±1, which `finger_sim.stick_slip`
    switches; each Simulator of such a scene builds its own element. Its compiled form (`kernel_code`: KERNEL_BLOCK floats, then the
    contact's) reads the mode and direction from the flat model, whose slots follow them (`mirror`)."""

    #: the declared friction mode (`state_layout`), switched by `finger_sim.stick_slip`
    modes: ClassVar[tuple[ModeSet, ...]] = (FRICTION,)
    kernel_code: ClassVar[int] = STICK_SLIP_CONTACT

    def __init__(self, *args: Any, law: FrictionLaw, **kwargs: Any) -> None:
        self._mirrors: list[tuple[weakref.ref, int]] = []  # (compiled model, offset of the mode slot)
        self.own_modes()  # LOCKED, FRICTION's initial value, until a run binds it
        self._direction = 0.0
        super().__init__(*args, **kwargs)
        self.kinetic = self._mu
        self.static = self._mu if law.static_friction is None else law.static_friction
        self.stribeck = law.stribeck_velocity
        self._v_st = 0.0 if law.stribeck_velocity is None else law.stribeck_velocity  # 0: no Stribeck term
        self._r = (self.params.r1, self.params.r2, self.params.r3)
        # the regularized law's viscous slope μ F_n / v_s is not in this law: `modal` sees none
        self._mu, self._friction_design = 0.0, 0.0
        #: the holding torque τ_h of the locked state, N·m (set by the stepper)
        self.hold = 0.0
        #: t → (q, mode, direction, friction torque) of the recent states at rest (`remember`), for `outputs`
        self.holds: dict[float, tuple[Vec3, int, float, float]] = {}
        #: how many of them it keeps (`simulate` raises it to a run's rows, which it reads after the run)
        self.memory = HOLD_MEMORY
        self._at: Vec3 = (0.0, 0.0, 0.0)  # the pose of the last `_hits`: its hits' j_k are taken there
        self._slope: tuple[Vec3 | None, float] = (None, 0.0)  # (q, dθ3/dθ1 at q), see `_tangent_gain`

    # -- the mode, mirrored into compiled models -------------------------------------------
    def mode_changed(self, value: int) -> None:
        """Mirror the mode into compiled models."""
        self._mirror_modes()

    @property
    def direction(self) -> float:
        return self._direction

    @direction.setter
    def direction(self, value: float) -> None:
        self._direction = value
        self._mirror_modes()

    def mode_key(self) -> tuple[int, float]:
        """(mode, direction): what the force law depends on besides the state (`OwnModes.mode_key`)."""
        return self.mode, self._direction

    def kernel_params(self) -> tuple[float, ...]:
        """(mode, direction, μ_k, μ_s, v_st or 0, then the contact's `kernel_params`), read by the compiled law."""
        return (float(self.mode), self._direction, self.kinetic, self.static, self._v_st, *super().kernel_params())

    def mirror(self, model: np.ndarray, offset: int) -> None:
        """Keep the mode and direction slots of compiled model `model` (at `offset`, `offset` + 1) current."""
        self._mirrors = [(ref, o) for ref, o in self._mirrors if ref() is not None]
        self._mirrors.append((weakref.ref(model), offset))

    def _mirror_modes(self) -> None:
        for ref, offset in self._mirrors:
            model = ref()
            if model is not None:
                model[offset], model[offset + 1] = float(self.mode), self._direction

    # -- the law -------------------------------------------------------------------------
    def _hits(self, q: Vec3, all_candidates: bool, t: float = 0.0) -> list[_Hit]:
        """The base class's candidates; also keeps their pose q, where `_tangent_gain` (called on these
        hits right after) takes dθ3/dθ1 for each contact's j_k."""
        self._at = q
        return super()._hits(q, all_candidates, t)

    def _tangent_gain(self, hit: _Hit) -> float:
        """j_k = t_c·∂p/∂θ1 along the linkage, m/rad (the tangential speed per unit θ1')."""
        _, _, _, _, _, nx, ny, j1x, j1y, j3x, j3y = hit
        q = self._at
        if self._slope[0] != q:
            self._slope = (q, linkage_slope(*self._r, *q))
        return tangent_gain(nx, ny, j1x, j1y, j3x, j3y, self._slope[1])

    def _forces(self, hit: _Hit, v: Vec3, t: float = 0.0) -> tuple[float, float, float]:
        """(F_n, Fx, Fy), N: the Hunt–Crossley normal force, and while sliding the kinetic friction
        −μ F_n sgn(j_k θ1') (sign from the mode's `direction`, so a step's stages past θ1' = 0 keep the
        mode's law until the event). Locked: the normal force alone (the holding friction is τ_h)."""
        fn, fx, fy = super()._forces(hit, v, t)  # the normal force alone: this element's regularized μ is 0
        if fn > 0.0 and self.mode == SLIDING and self.static:  # μ_s ≥ μ_k: zero only without friction
            j = self._tangent_gain(hit)
            nx, ny = hit[5], hit[6]
            # the Stribeck term's speed: j θ1' at a fixed object, the relative t_c·(ṗ − ċ) at a moving one
            moving = self.time_varying and self._motions[hit[1]] is not None
            if moving and j != 0.0:
                vx, vy = self._velocity(hit, v, t)
                speed = (nx * vy - ny * vx) / j
            else:
                speed = v[0]
            ft = sliding_friction(fn, j, self._direction, speed, self.kinetic, self.static, self._v_st)
            fx, fy = along_tangent(fx, fy, ft, nx, ny)
        return (fn, fx, fy)

    def capacity(self, q: Vec3, t: float = 0.0, v: Vec3 = (0.0, 0.0, 0.0)) -> float:
        """Σ μ_s F_n,k |j_k| at q (at rest, or at (t, q') riding with a moving object), N·m: the largest
        holding torque the friction cones supply."""
        total = 0.0
        for hit in self._hits(q, False, t):
            total += self.static * self._forces(hit, v, t)[0] * abs(self._tangent_gain(hit))
        return total

    def stick_speed(self, t: float, q: Vec3) -> float:
        """ω, rad/s: the θ1' at which the contacts in touch at (t s, q) do not slide on their objects,
        ω = w_k / j_k with w_k = t_k·ċ_k the object's tangential velocity; 0 with fixed objects or
        without a contact that has j_k (`MIN_TANGENT_GAIN`). SimulationDiverged if two contacts would
        need different speeds (the one-DOF linkage cannot stick to both)."""
        if not self.time_varying:
            return 0.0
        omega = None
        for hit in self._hits(q, False, t):
            j = self._tangent_gain(hit)
            if abs(j) < MIN_TANGENT_GAIN:
                continue
            motion = self._motions[hit[1]]
            w = 0.0
            if motion is not None:
                cvx, cvy = motion.velocity(t)
                w = hit[5] * cvy - hit[6] * cvx  # t_c·ċ, t_c = (−ny, nx)
            if omega is None:
                omega = w / j
            elif abs(w / j - omega) > STICK_SPEED_TOLERANCE * max(1.0, abs(omega)):
                raise SimulationDiverged(f"{STICK_SLIP}: two contacts would stick at different speeds ({omega:.6g} and "
                                         f"{w / j:.6g} rad/s) on a moving object, which the one-DOF linkage cannot follow",
                                         t=t)
        return 0.0 if omega is None else omega

    def friction_torque(self, t: float, q: Vec3, v: Vec3) -> tuple[float, float]:
        """(Σ j_k F_t,k N·m, Σ F_t,k v_t,k W) of the sliding law at a state: the friction's torque on θ1
        along the linkage and its power (≤ 0)."""
        torque = power = 0.0
        for hit in self._hits(q, False, t):
            _, fx, fy = self._forces(hit, v, t)
            nx, ny = hit[5], hit[6]
            ft = -ny * fx + nx * fy  # t_c·F
            torque += self._tangent_gain(hit) * ft
            vx, vy = self._velocity(hit, v, t)  # the slip is relative to the object
            power += ft * (-ny * vx + nx * vy)
        return torque, power

    def remember(self, t: float, q: Vec3, v: Vec3 = (0.0, 0.0, 0.0)) -> None:
        """Keep the mode, direction and friction torque of the state (t s, q, q') at rest relative to the
        objects (θ1' = 0, or θ1' = `stick_speed` riding with a moving object: not a function of the state)
        for `outputs`: the holding torque τ_h (N·m, `hold`) while locked, the sliding law's torque at a
        turn. The last `memory` such states are kept."""
        holds = self.holds
        torque = self.hold if self.mode == LOCKED else self.friction_torque(t, q, v)[0]
        holds[t] = (q, self.mode, self.direction, torque)
        if len(holds) > self.memory:
            del holds[next(iter(holds))]

    def outputs(self, t: float, q: Vec3, v: Vec3) -> Mapping[str, float]:
        """The contact's outputs, then friction_mode (1 locked, 0 sliding), friction_torque (N·m on θ1:
        the holding torque τ_h while locked, Σ j_k F_t,k while sliding) and friction_power (W, ≤ 0:
        the friction's loss).

        A function of the state, so that rows can be computed after the run, except at rest
        (θ1' = 0.0 exactly: the locked mode holds q' = 0, a sliding state lands on it only at a
        turn): there the stepper's record of that state (`remember`) tells; mode and torque are NaN
        for a state at rest it did not see or no longer remembers. Sliding is towards sgn θ1'. Locked,
        the contact forces are the normal forces (which split of τ_h among the contacts is not
        observable, spec §7)."""
        mode, direction = self.mode, self.direction
        if self.time_varying:
            return self._moving_outputs(t, q, v)
        known = self.holds.get(t) if v[0] == 0.0 else None
        if v[0] != 0.0:
            self.mode, self.direction = SLIDING, math.copysign(1.0, v[0])
        elif known is not None and known[0] == q:
            self.mode, self.direction = known[1], known[2]
        else:
            self.mode, self.direction, known = LOCKED, 0.0, None  # unknown: normal forces only, NaN below
        try:
            out = dict(super().outputs(t, q, v))
            if v[0] == 0.0:
                out[FRICTION_MODE.name] = math.nan if known is None else float(known[1])
                out[FRICTION_TORQUE.name] = math.nan if known is None else known[3]
                out[FRICTION_POWER.name] = 0.0
            else:
                out[FRICTION_MODE.name] = float(SLIDING)
                out[FRICTION_TORQUE.name], out[FRICTION_POWER.name] = self.friction_torque(t, q, v)
        finally:
            self.mode, self.direction = mode, direction
        return out

    def _moving_outputs(self, t: float, q: Vec3, v: Vec3) -> Mapping[str, float]:
        """`outputs` with a moving object: the stepper's record of (t, q) where it has one (every locked
        step end, every turn), else sliding towards sgn(θ1' − ω) (`stick_speed`); NaN mode and torque for
        a state at rest relative to the object that it did not record."""
        mode, direction = self.mode, self.direction
        known = self.holds.get(t)
        if known is not None and known[0] == q:
            self.mode, self.direction = known[1], known[2]
        else:
            known = None
            slip = v[0] - self.stick_speed(t, q)
            self.mode, self.direction = (SLIDING, math.copysign(1.0, slip)) if slip != 0.0 else (LOCKED, 0.0)
        try:
            out = dict(super().outputs(t, q, v))
            if known is not None:
                out[FRICTION_MODE.name], out[FRICTION_TORQUE.name] = float(known[1]), known[3]
                out[FRICTION_POWER.name] = 0.0 if known[1] == LOCKED else self.friction_torque(t, q, v)[1]
            elif self.mode == SLIDING:
                out[FRICTION_MODE.name] = float(SLIDING)
                out[FRICTION_TORQUE.name], out[FRICTION_POWER.name] = self.friction_torque(t, q, v)
            else:
                out[FRICTION_MODE.name] = out[FRICTION_TORQUE.name] = math.nan
                out[FRICTION_POWER.name] = 0.0
        finally:
            self.mode, self.direction = mode, direction
        return out
