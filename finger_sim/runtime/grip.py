"""Grip-force control, ROS-free: a PI law with anti-windup and the close / hold / open sequence.

`finger_sim.ros.grip_controller` runs it on every `grip_force` sample; here it is plain Python,
so that it is tested without DDS. Units: force N, torque N·m, time s.

The sequence (`GripController`):

- IDLE (setpoint 0): torque 0;
- CLOSING (a setpoint > 0 given): the constant `closing_torque` until grip_force exceeds
  `contact_threshold`;
- HOLDING: the PI law on e = setpoint − grip_force, started bumplessly (its integral set so that
  the first output continues the closing torque);
- OPENING (setpoint back to 0): −`opening_torque` for `opening_time` s, then IDLE.

Anti-windup by clamping (conditional integration, Åström & Hägglund, "Advanced PID Control",
§3.5): the integral grows only until the output reaches ±max_torque; while it is saturated and
the error would drive it further out, the integral is frozen; it is also kept within ±max_torque. The output leaves saturation as
soon as the error changes sign, with no wound-up integral to unwind.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from enum import Enum
from typing import Any

from finger_sim.grip_law import (CLOSING, HOLDING, IDLE, MAX_SAMPLE_GAP, OPENING, grip_setpoint,  # noqa: F401
                                 grip_update, pi_update)
from finger_sim.runtime.parameters import Param, ParameterError, check_all

#: Gains tuned on grasp_cylinder (the cup, k_c = 1e5 N/m^1.5, joint damping 0.005 N·m·s/rad).
#: Below its contact mode the plant from torque to grip force is a static gain: holding 0.5 N
#: takes τ = 0.0571 N·m (the contact force's lever along the linkage, λ ≈ 0.11 m, plus the PIP
#: spring), G = 1/λ ≈ 8.8 N per N·m. The contact mode itself is fast and lightly damped:
#: ≈ 400 rad/s (spec §7), Hunt–Crossley damping ζ ≈ 0.05 at 0.5 N. So the loop is integral-
#: dominated: G·KI ≈ 35 rad/s (a first-order response, time constant ≈ 30 ms) lies a decade
#: below the contact mode, and G·KP ≈ 0.04 keeps the proportional path's gain at the resonance
#: (× 1/2ζ ≈ 10) below 1. Simulated with a loop delay of 1-15 ms (Simulator, no DDS): 98 % of
#: 0.5 N 0.1 s after contact, overshoot 0 (≤ 5 % at 15 ms), error < 1e-9 N after 1 s.
KP = 0.005  # N·m per N
KI = 4.0  # N·m per N·s
#: Output saturation, N·m: holding 0.5 N on the cup takes ≈ 0.06 N·m, above finger_node's
#: default max_torque (0.05), so run the node with max_torque ≥ this.
MAX_TORQUE = 0.1
#: Closing: brings the finger from extension onto the cup in ≈ 0.29 s, slowly enough that the
#: impact stays below a 0.5 N setpoint (0.02 N·m hits it at 1 rad/s: a 0.58 N peak).
CLOSING_TORQUE = 0.015  # N·m
#: Contact is declared above this grip force, N (well above round-off, far below any setpoint).
CONTACT_THRESHOLD = 0.01
#: Opening: this torque backwards (N·m) for this long (s), then 0.
OPENING_TORQUE = 0.01
OPENING_TIME = 0.2
#: The time between two grip_force samples when no /clock tells it, s: finger_node's default 1 kHz.
SAMPLE_PERIOD = 0.001


#: finger_grip_controller's parameters (read once at start).
GRIP_PARAMETERS = (
    Param("kp", KP, "proportional gain, N·m per N of grip-force error", (0.0, 100.0)),
    Param("ki", KI, "integral gain, N·m per N·s", (0.0, 1000.0)),
    Param("max_torque", MAX_TORQUE, "output saturation (and integral bound), N·m", (0.0, 100.0)),
    Param("closing_torque", CLOSING_TORQUE, "torque that closes the finger until contact, N·m", (0.0, 100.0)),
    Param("contact_threshold", CONTACT_THRESHOLD, "grip force above which contact is declared, N", (0.0, 1000.0)),
    Param("opening_torque", OPENING_TORQUE, "backward torque that opens the finger on a setpoint of 0, N·m", (0.0, 100.0)),
    Param("opening_time", OPENING_TIME, "how long the opening torque is applied, s", (0.0, 60.0)),
    Param("sample_period", SAMPLE_PERIOD, "time between grip_force samples while no /clock is received "
          "(1/the node's publish rate), s", (1e-6, 1.0)),
    Param("setpoint", 0.0, "initial grip-force setpoint, N (then the grip_setpoint topic); 0 = open", (0.0, 1000.0)),
)


class Phase(Enum):
    IDLE = "idle"
    CLOSING = "closing"
    HOLDING = "holding"
    OPENING = "opening"


@dataclass(frozen=True)
class GripSettings:
    """The parameters of GRIP_PARAMETERS, validated (SI)."""

    kp: float
    ki: float
    max_torque: float
    closing_torque: float
    contact_threshold: float
    opening_torque: float
    opening_time: float
    sample_period: float
    setpoint: float

    @classmethod
    def from_values(cls, values: Mapping[str, Any]) -> GripSettings:
        """Check `values` against GRIP_PARAMETERS (missing ones: defaults); ParameterError names the one that fails."""
        v = check_all(GRIP_PARAMETERS, values)
        for name in ("closing_torque", "opening_torque"):
            if v[name] > v["max_torque"]:
                raise ParameterError.expected(name, f"a torque ≤ max_torque ({v['max_torque']:g} N·m)", v[name])
        return cls(**v)  # type: ignore[arg-type]


class PiLaw:
    """u = clamp(kp e + I, ±limit), I' = ki e, with clamping anti-windup (`pi_update`)."""

    def __init__(self, kp: float, ki: float, limit: float) -> None:
        self.kp, self.ki, self.limit = kp, ki, limit
        self.integral = 0.0  # I, N·m

    def reset(self, integral: float = 0.0) -> None:
        """Restart from the integral `integral` (N·m, kept within ±limit)."""
        self.integral = min(max(integral, -self.limit), self.limit)

    def update(self, error: float, dt: float) -> float:
        """The output (N·m) for the error `error` (N) over the last `dt` s."""
        self.integral, u = pi_update(self.integral, error, dt, self.kp, self.ki, self.limit)
        return u


#: Phase of each number of `grip_update`.
_PHASES = {IDLE: Phase.IDLE, CLOSING: Phase.CLOSING, HOLDING: Phase.HOLDING, OPENING: Phase.OPENING}
#: The number of each Phase (`grip_update`).
PHASE_NUMBERS = {phase: number for number, phase in _PHASES.items()}


class GripController:
    """Close until contact, hold the grip force at the setpoint with the PI law, open on 0
    (module docstring; the sequence is `grip_setpoint` and `grip_update`)."""

    def __init__(self, settings: GripSettings) -> None:
        self.settings = s = settings
        self.pi = PiLaw(s.kp, s.ki, s.max_torque)
        self.phase = Phase.IDLE
        self.setpoint = 0.0
        self._opening_left = 0.0  # s
        self.set_setpoint(s.setpoint)

    def set_setpoint(self, value: float) -> None:
        """A new grip-force setpoint, N: > 0 closes (or keeps holding), 0 opens. ValueError if
        negative or not finite."""
        if not (math.isfinite(value) and value >= 0.0):
            raise ValueError(f"grip setpoint: expected a finite force ≥ 0 N, got {value!r}")
        self.setpoint = value
        phase, self._opening_left = grip_setpoint(PHASE_NUMBERS[self.phase], self._opening_left, value,
                                                  self.settings.opening_time)
        self.phase = _PHASES[phase]

    def update(self, grip_force: float, dt: float) -> float:
        """The motor torque (N·m) answering the grip force `grip_force` (N), `dt` s after the last
        sample (at most MAX_SAMPLE_GAP counts)."""
        s = self.settings
        phase, self.pi.integral, self._opening_left, u = grip_update(
            PHASE_NUMBERS[self.phase], self.pi.integral, self._opening_left, self.setpoint, grip_force, dt,
            s.kp, s.ki, s.max_torque, s.closing_torque, s.contact_threshold, s.opening_torque)
        self.phase = _PHASES[phase]
        return u
