"""The drive grip controllers' laws as plain functions: `grip_voltage` (PI on the grip force) and
`grip_current` (PI on the motor current), both commanding the motor voltage (spec §8) and switching
it off once settled, so that a self-locking gear holds the grip without power.

Plain floats and bools in, tuples out, no state of their own: the Python controllers
(`finger_sim.tasks.controllers.grip_voltage`, `finger_sim.tasks.current_grip.grip_current`) keep
their state and call these, and the kernel compiles them as they are for the compiled gain sweep
(`finger_sim.kernel.closed_loop_drive`). Units: force N, current A, voltage V, time s.

The state of both: the PI's integral (of the error, N·s or A·s), the time in the lock band (s),
whether the voltage is off for good (locked), whether contact was seen (touched), and the time of
the last setpoint change (since, s). A new setpoint resets them (`voltage_setpoint`, `current_setpoint_state`).
"""

from __future__ import annotations


def voltage_setpoint(t: float, touched: bool) -> tuple[float, float, bool, bool, float]:
    """grip_voltage's state after a new setpoint at t (s): (integral, in_band, locked, touched, since);
    `touched` is kept (the finger may already hold the object)."""
    return 0.0, 0.0, False, touched, t


def current_setpoint_state(t: float) -> tuple[float, float, bool, bool, float]:
    """grip_current's state after a new setpoint at t (s): (integral, in_band, locked, touched, since)."""
    return 0.0, 0.0, False, False, t


def voltage_update(integral: float, in_band: float, locked: bool, touched: bool, since: float, t: float,
                   setpoint: float, force: float, period: float, closing_voltage: float, kp: float, ki: float,
                   max_voltage: float, lock_band: float, lock_after: float, contact_threshold: float,
                   opening_voltage: float, opening_time: float) -> tuple[float, float, bool, bool, float]:
    """One sample of grip_voltage at t (s) on the grip force `force` (N): (integral, in_band, locked,
    touched, u V). `controllers.grip_voltage` describes the law; period: the sample period (s)."""
    if setpoint == 0.0:
        return integral, in_band, locked, touched, -opening_voltage if t - since < opening_time and t > 0.0 else 0.0
    if locked:
        return integral, in_band, locked, touched, 0.0
    if not touched:
        touched = force > contact_threshold
        if not touched:
            return integral, in_band, locked, touched, closing_voltage
    error = setpoint - force
    integral += error * period
    in_band = in_band + period if abs(error) <= lock_band * setpoint else 0.0
    if in_band >= lock_after:
        return integral, in_band, True, touched, 0.0
    u = closing_voltage + kp * error + ki * integral
    return integral, in_band, locked, touched, min(max(u, -max_voltage), max_voltage)


def current_update(integral: float, in_band: float, locked: bool, touched: bool, since: float, t: float,
                   setpoint: float, target: float, current: float, period: float, closing_voltage: float,
                   contact_current: float, inrush_time: float, kp: float, ki: float, max_voltage: float,
                   lock_band: float, lock_after: float, opening_voltage: float,
                   opening_time: float) -> tuple[float, float, bool, bool, float]:
    """One sample of grip_current at t (s) on the motor current `current` (A) towards the current
    setpoint `target` (A) of the force setpoint `setpoint` (N): (integral, in_band, locked, touched,
    u V). `tasks.current_grip` describes the law; period: the sample period (s)."""
    if setpoint == 0.0:
        return integral, in_band, locked, touched, -opening_voltage if t - since < opening_time and t > 0.0 else 0.0
    if locked:
        return integral, in_band, locked, touched, 0.0
    if not touched:
        touched = t - since >= inrush_time and current >= contact_current
        if not touched:
            return integral, in_band, locked, touched, closing_voltage
    error = target - current
    in_band = in_band + period if abs(error) <= lock_band * target else 0.0
    if in_band >= lock_after:
        return integral, in_band, True, touched, 0.0
    u = closing_voltage + kp * error + ki * (integral + error * period)
    if abs(u) < max_voltage:  # conditional integration: no wind-up while the voltage saturates
        integral += error * period
    return integral, in_band, locked, touched, min(max(u, -max_voltage), max_voltage)
