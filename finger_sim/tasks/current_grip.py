"""`grip_current`: a grip controller for the device (spec §8) that closes its loop on the motor current.

A prosthetic hand's controller has no force sensor: it reads the motor current and the encoder.
While the mesh rolls forward (`drive`), the motor's torque reaches the link as η_f N k_t i (less the
rotor's inertia, nothing while it creeps), and that torque holds the linkage's own load (spring,
gravity) and the grip. So the current is the grip's proxy:

    F̂ = (torque_per_ampere · i − load_torque) / lever,

torque_per_ampere = η_f N k_t (N·m/A), load_torque the linkage's load at the grasp pose (N·m) and
lever the torque on θ1 per newton of grip (m), both calibrated for the object. The controller
turns the force setpoint F* into a current setpoint i* = (lever F* + load_torque) / torque_per_ampere
and runs in three phases:

1. approach: `closing_voltage` until contact. The current shows it: after its inrush (the
   motor starting from rest, ignored for `inrush_time`) it falls while the finger moves
   (back-EMF) and rises to u/R when the object stops the finger (`contact_current`);
2. current loop: u = closing_voltage + kp e + ki ∫e dt on e = i* − i, |u| ≤ max_voltage (the
   integral paused while u saturates). A self-locking mesh sticks at each turning point, where
   i = u/R says nothing about the grip; but it breaks free forward only once η_f N k_t i exceeds
   the load it holds, so raising i to i* presses the finger in until the grip's torque meets
   η_f N k_t i*: the grip follows the current from below;
3. hold: once |e| has stayed within lock_band · i* for lock_after s, 0 V for good (until the
   setpoint changes). The stuck mesh holds the grip without power (u = 0, ω = 0: i = 0, any load).

A setpoint of 0 opens: −opening_voltage for opening_time s, then 0 V. The current loop can only
raise the grip: it cannot take back an approach that hits harder than F* (choose closing_voltage
so that it does not), and F* is bounded by the current limit: i* ≤ i_max.
"""

from __future__ import annotations

import math
from collections.abc import Mapping

from finger_sim import drive_grip_law as drive_law
from finger_sim.actuators.drive_outputs import MOTOR_CURRENT
from finger_sim.errors import ConfigError
from finger_sim.tasks.controllers import Controller

#: grip_current defaults, for the default drive (spec §8) on the cup of config/drive_grasp.yaml:
GRIP_CURRENT = {
    "closing_voltage": 1.0,  # V: the approach (its impact on the cup leaves ≈ 0.9 N)
    "contact_current": 0.06,  # A: between the free finger's current (< 1 mA) and the stall's u/R (0.125 A at 1 V)
    "inrush_time": 0.03,  # s: the start-up current is ignored this long (it decays in ≈ 5 ms)
    "torque_per_ampere": 0.4 * 300.0 * 4.0e-3,  # N·m/A: η_f N k_t
    "lever": 0.1139,  # m: torque on θ1 per newton of grip on the cup (docs/drive_grip_current.md)
    "load_torque": 3.0e-4,  # N·m: the paper spring's load on θ1 at the grasp pose
    "kp": 4.0,  # V/A: half the stuck mesh's loop gain R
    "ki": 400.0,  # V/(A·s): ≈ 20 ms to the current setpoint with the mesh stuck (i = u/R)
    "max_voltage": 6.0,  # V
    "lock_band": 0.05,  # fraction of i*: the task metric's settling band
    "lock_after": 0.05,  # s in the band before the voltage goes off
    "opening_voltage": 2.0,  # V
    "opening_time": 0.2,  # s
}
#: grip_current's settings in the order `drive_grip_law.current_update` takes them (after the current).
CURRENT_LAW = ("closing_voltage", "contact_current", "inrush_time", "kp", "ki", "max_voltage", "lock_band",
               "lock_after", "opening_voltage", "opening_time")


def current_setpoint(force: float, p: Mapping[str, float]) -> float:
    """i* (A) that holds the grip `force` (N) through a forward-rolling mesh: (lever F + load) / (η_f N k_t)."""
    return (p["lever"] * force + p["load_torque"]) / p["torque_per_ampere"]


def grip_current(sample_period: float, feedback: str = MOTOR_CURRENT.name, **params: float) -> Controller:
    """The current-loop grip controller (module docstring), commanding the motor voltage (V).
    feedback: the current signal it reads: motor_current (A, the truth) or a scene sensor's
    motor_current_measured (finger_sim.sensors). params: GRIP_CURRENT overrides."""
    unknown = set(params) - set(GRIP_CURRENT)
    if unknown:
        raise ConfigError("controller parameter", f"one of {sorted(GRIP_CURRENT)}", sorted(unknown))
    p = {**GRIP_CURRENT, **params}
    for name in ("torque_per_ampere", "lever", "contact_current"):
        if not (p[name] > 0.0 and math.isfinite(p[name])):
            raise ConfigError(f"controller parameter {name}", "a finite number > 0", p[name])
    state = {"setpoint": 0.0, "target": 0.0, "law": (0.0, 0.0, False, False, 0.0)}  # law: (integral, in_band, locked, touched, since)
    gains = tuple(p[name] for name in CURRENT_LAW)

    def control(t: float, setpoint: float, measured: Mapping[str, float]) -> float:
        if setpoint != state["setpoint"]:
            state.update(setpoint=setpoint, target=current_setpoint(setpoint, p), law=drive_law.current_setpoint_state(t))
        if feedback not in measured:
            raise ConfigError("controller parameter feedback", f"one of the measured signals {sorted(measured)}", feedback)
        integral, in_band, locked, touched, since = state["law"]
        integral, in_band, locked, touched, u = drive_law.current_update(
            integral, in_band, locked, touched, since, t, setpoint, state["target"], measured[feedback], sample_period,
            *gains)
        state["law"] = (integral, in_band, locked, touched, since)
        return u

    return control


grip_current.input = "voltage"  # type: ignore[attr-defined]
