"""The grip controller's law as plain functions: the PI with clamping anti-windup and the close /
hold / open sequence (`finger_sim.runtime.grip` describes both and wraps them in GripController).

Plain floats and ints in, tuples out, no state of their own: `runtime.grip` (finger_grip_controller,
the offline `grip_pi`) calls them, and the kernel compiles them as they are for the compiled gain
sweep (`finger_sim.kernel.closed_loop`). Units: force N, torque N·m, time s.
"""

from __future__ import annotations

#: A longer time between two samples (a stalled controller, a lost sample) counts as this, s:
#: the integral must not jump (at contact, 20 ms at once is 0.04 N·m on top of the impact).
MAX_SAMPLE_GAP = 0.005


def pi_update(integral: float, error: float, dt: float, kp: float, ki: float, limit: float) -> tuple[float, float]:
    """One PI sample: (the new integral I, the output u), N·m, for the error `error` (N) over `dt`
    s: u = clamp(kp e + I, ±limit), I' = ki e, with clamping anti-windup (module docstring). The
    one definition of the law: `runtime.grip.PiLaw` calls it, and the compiled gain sweep
    compiles it (`finger_sim.kernel.closed_loop`)."""
    trial = integral + ki * error * dt
    # The integral moves towards `trial`, but not past the value that puts the output on the
    # limit the error pushes towards, and never further out once it is there (frozen).
    if error > 0.0:
        trial = min(trial, max(integral, limit - kp * error))
    elif error < 0.0:
        trial = max(trial, min(integral, -limit - kp * error))
    integral = min(max(trial, -limit), limit)
    u = kp * error + integral
    return integral, min(max(u, -limit), limit)


#: `Phase` as the numbers `grip_update` works on (the compiled sweep keeps them in arrays).
IDLE, CLOSING, HOLDING, OPENING = 0, 1, 2, 3


def grip_setpoint(phase: int, opening_left: float, value: float, opening_time: float) -> tuple[int, float]:
    """The sequence's (phase, opening time left s) after a new setpoint `value` (N, ≥ 0)."""
    if value > 0.0 and (phase == IDLE or phase == OPENING):
        return CLOSING, opening_left
    if value == 0.0 and (phase == CLOSING or phase == HOLDING):
        return OPENING, opening_time
    return phase, opening_left


def grip_update(phase: int, integral: float, opening_left: float, setpoint: float, grip_force: float, dt: float,
                kp: float, ki: float, max_torque: float, closing_torque: float, contact_threshold: float,
                opening_torque: float) -> tuple[int, float, float, float]:
    """One sample of the close / hold / open sequence: (phase, PI integral N·m, opening time left
    s, motor torque N·m) answering `grip_force` (N), `dt` s after the last sample (at most
    MAX_SAMPLE_GAP counts). The one definition: `runtime.grip.GripController.update` calls it, and the compiled
    gain sweep compiles it (`finger_sim.kernel.closed_loop`)."""
    dt = min(dt, MAX_SAMPLE_GAP)
    if phase == CLOSING and grip_force > contact_threshold:
        phase = HOLDING
        integral = min(max(closing_torque - kp * (setpoint - grip_force), -max_torque), max_torque)  # bumpless
    if phase == CLOSING:
        return phase, integral, opening_left, closing_torque
    if phase == HOLDING:
        integral, u = pi_update(integral, setpoint - grip_force, dt, kp, ki, max_torque)
        return phase, integral, opening_left, u
    if phase == OPENING:
        opening_left -= dt
        if opening_left > -0.5 * dt:  # the sample that ends the opening time still opens
            return phase, integral, opening_left, -opening_torque
        phase = IDLE
    return phase, integral, opening_left, 0.0
