"""The drive tasks' closed loop in the kernel: many runs of one drive task (spec §8) in one call.

`run` steps every row i of a task from steps[i] on, as `finger_sim.tasks.runner.run_task` steps
it with a shipped voltage controller, nothing per step in Python:

- the script and the timing: as `closed_loop.run` (the setpoint schedule, a sample every
  `sample_steps` steps, the command acting `delay_steps` later and held);
- the controller: `grip_voltage` (LAW_VOLTAGE, on scale × the grip force or the motor current)
  or `grip_current` (LAW_CURRENT, on the motor current), compiled from their one definition
  (`finger_sim.drive_grip_law`, which the Python controllers call), on the outputs measured at
  the step's start (`tasks.runner._outputs`: the grip force, the motor current under the last
  step's voltage);
- the step: what `Simulator.step` (`actuators.stepping.advance`) does under the held voltage in
  a step that holds no event. A rolling mesh (drive, back): DOP853 on the driven right-hand
  side (`closed_loop._dop853_step` compiled again with `kernel.drive`'s attempt and rhs: the
  same code), then the mesh guards at the step's end (turn, flank, current limit) and the
  contact's gap tests (`closed_loop.may_cross`). A stuck mesh: q held, q' = 0, where its
  holding margin (`actuators.drive.holding_margin`) is ≥ 0 at both ends of the step;
- the outputs after the step: the grip force, and the drive's motor current and terminal
  voltage (`DrivenSystem.motor_outputs`' arithmetic), recorded at the next sample.

The mode of the mesh is changed only by the Simulator: a row hands a step over (EVENT, as
`closed_loop`) where a guard may cross in it or the stuck mesh may break free. The Simulator
takes a guard as crossed by `stepping._guards`' Python arithmetic; the kernel's flank torque
and holding margin may differ from it in the last bits, so a step whose flank or margin at
either end is within FLANK_BAND, HOLD_BAND of 0 is handed over too, and every mode decision is
the Simulator's own. Status codes as `closed_loop` (DONE, EVENT, WATCH, PAUSE).
"""

from __future__ import annotations

import types
from collections.abc import Callable
from typing import Any

import numpy as np

from finger_sim.kernel import use_writable_cache

use_writable_cache()  # before numba reads NUMBA_CACHE_DIR
from numba import njit, prange  # noqa: E402  (after the cache folder is set)

from finger_sim import drive_grip_law as law  # noqa: E402
from finger_sim.actuators import drive as drive_law  # noqa: E402
from finger_sim.actuators.stepping import GUARD_TOLERANCE  # noqa: E402
from finger_sim.kernel import closed_loop as kl  # noqa: E402
from finger_sim.kernel import drive as kd  # noqa: E402
from finger_sim.kernel.numerics import JIT, LAW, generalized_force, solved_accelerations  # noqa: E402

DONE, EVENT, WATCH, PAUSE = kl.DONE, kl.EVENT, kl.WATCH, kl.PAUSE
#: The columns of `run`'s record: `closed_loop`'s, then the drive's (`tasks.runner.DRIVE_COLUMNS`).
MOTOR_VOLTAGE, MOTOR_CURRENT = kl.N_RECORD, kl.N_RECORD + 1
N_COLUMNS = kl.N_RECORD + 2
#: The controller law of a row.
LAW_VOLTAGE, LAW_CURRENT = 0, 1
#: The signal a row's law reads: the grip force (N) or the motor current (A).
FEEDBACK_GRIP, FEEDBACK_CURRENT = 0, 1
#: A row's law state, in this order: the setpoint it was set to (N), the current setpoint (A,
#: grip_current), then `drive_grip_law`'s (integral, in_band, locked, touched, since).
SETPOINT, TARGET, INTEGRAL, IN_BAND, LOCKED, TOUCHED, SINCE = range(7)
#: A row's drive: the direction of the rolling mode (`Drive.direction`), η_f, η_b.
DIRECTION, ETA_F, ETA_B = range(3)
#: A step is the Simulator's when the kernel's flank torque at its end is below this (N·m): the
#: Python guard (crossed below −GUARD_TOLERANCE) may read it otherwise in the last bits.
FLANK_BAND = 1e-9
#: ... or a stuck mesh's holding margin at either end is below this fraction of |τ_h| + N |τ_a|.
HOLD_BAND = 1e-9
#: ... or the current limit's guard is within this of 0 (A) at either end.
LIMIT_BAND = 1e-12

voltage_update = njit(**LAW)(law.voltage_update)
voltage_setpoint = njit(**LAW)(law.voltage_setpoint)
current_update = njit(**LAW)(law.current_update)
current_setpoint_state = njit(**LAW)(law.current_setpoint_state)
holding_margin = njit(**LAW)(drive_law.holding_margin)


def _rebound(dispatcher: Any, **names: Callable) -> Any:
    """closed_loop's compiled function `dispatcher` compiled again with some of its globals rebound
    (`names`) under its own name, as `kernel.drive._rebound` does for numerics."""
    py = dispatcher.py_func
    name = "driven_" + py.__name__.lstrip("_")
    code = py.__code__.replace(co_name=name, co_qualname=name)
    function = types.FunctionType(code, {**vars(kl), **names}, name, py.__defaults__, py.__closure__)
    function.__qualname__, function.__doc__ = name, f"{py.__doc__} With the drive (`kernel.drive`)."
    return njit(**JIT)(function)


driven_advance = _rebound(kl._advance, dop853_attempt=kd.driven_dop853_attempt)
driven_dop853_step = _rebound(kl._dop853_step, _advance=driven_advance, _rhs=kd.driven_rhs)


@njit(**JIT)
def _holds(m, ob, t, x, u, eta_f, eta_b):
    """Whether a stuck mesh surely holds at t under u (V), q = x[:3], q' = 0: its holding margin
    (`stepping._release_time`'s) is above HOLD_BAND of its scale."""
    q0, q1, q2 = x[0], x[1], x[2]
    s1, c1, s2, c2, s3, c3, su, cu = kd._trig(m, q0, q1, q2)
    f1, f2, f3 = generalized_force(m, t, q0, q1, q2, 0.0, 0.0, 0.0, 0.0)
    a0 = solved_accelerations(m, s1, c1, s2, c2, s3, c3, su, cu, 0.0, 0.0, 0.0, f1, f2, f3)[0]
    m_eff = kd.linkage_inertia_at(m[4], m[5], m[6], m[0], m[1], m[2], m[3], s1, c1, s2, c2, s3, c3, cu)
    tau_h = -a0 * m_eff
    ratio = m[ob + 3]
    tau_a = m[ob + 5] * kd.motor_current(u, 0.0, m[ob + 6], m[ob + 5], m[ob + 7], m[ob + 8])
    margin = holding_margin(tau_h, tau_a, ratio, eta_f, eta_b)
    return margin > HOLD_BAND * (abs(tau_h) + ratio * abs(tau_a))


@njit(**JIT)
def _physics(m, o, depth, depths, rtol, atol, dt, k, u, x, drv, st, y, f, y_old, dense, save, kk, y_new, taus, out,
             ga, ra, gb, rb):
    """Step k of one drive row under the held voltage u (V) on x in place, as `Simulator.step`
    takes a step that holds no event; returns (taken, grip force after it, N). Not taken: x and
    the internal solution are left as at the step's start, for the Simulator."""
    ob = m.shape[0] - kd.BLOCK
    t0, t1 = k * dt, (k + 1) * dt
    h = t1 - t0
    if m[ob] == kd.STUCK:  # `stepping.advance`: held throughout unless the mesh breaks free
        if not (_holds(m, ob, t0, x, u, drv[ETA_F], drv[ETA_B]) and _holds(m, ob, t1, x, u, drv[ETA_F], drv[ETA_B])):
            return False, 0.0
        x[3], x[4], x[5] = 0.0, 0.0, 0.0
        grip_force = 0.0
        if o >= 0:
            _, grip_force = kl.contact_states(m, o, x, ga, ra)
        return True, grip_force
    n = 0
    if o >= 0:
        n, _ = kl.contact_states(m, o, x, ga, ra)
    limit0 = kd.current_margin(m, ob, u, x[3])
    kl.save_solution(save, x, st, y, f, y_old, dense)
    taken = driven_dop853_step(m, rtol, atol, t0, h, u, x, st, y, f, y_old, dense, kk, y_new, taus, out)
    grip_force = 0.0
    if taken:  # the mesh guards at the step's end (`stepping._first_event`)
        turn, flank, limit1 = kd.drive_guards(m, t1, x[0], x[1], x[2], x[3], x[4], x[5], u, drv[DIRECTION])
        if not (turn >= -GUARD_TOLERANCE and flank >= FLANK_BAND) or (limit0 < 0.0) != (limit1 < 0.0) \
                or min(abs(limit0), abs(limit1)) < LIMIT_BAND:
            taken = False
    if taken and o >= 0:
        _, grip_force = kl.contact_states(m, o, x, gb, rb)
        for c in range(n):
            if kl.may_cross(ga[c], ra[c], gb[c], rb[c], h) or \
                    (depth and kl.may_cross(ga[c] + depths[c], ra[c], gb[c] + depths[c], rb[c], h)):
                taken = False
                break
    if not taken:
        kl.restore_solution(save, x, st, y, f, y_old, dense)
    return taken, grip_force


@njit(**JIT)
def motor_outputs(m, u, v0):
    """(motor current A, terminal voltage V) under u (V) at θ1' = v0 (`DrivenSystem.motor_outputs`, L = 0)."""
    ob = m.shape[0] - kd.BLOCK
    i = kd.motor_current(u, m[ob + 3] * v0, m[ob + 6], m[ob + 5], m[ob + 7], m[ob + 8])
    omega = m[ob + 3] * v0
    return i, m[ob + 6] * i + m[ob + 5] * omega


@njit(**kl.PARALLEL)
def run(models, widths, contact_at, depth, depths, break_min, rtol, atol, dt, sample_steps, delay_steps, set_k, set_v,
        kind, feedback, scale, gains, state, pend_k, pend_u, pend_n, command, states, signals, drives, integ, ys, fs,
        y_olds, denses, steps, until, last, scene_rec, record):
    """Every row from steps[i] until its status (module docstring), in place.

    models: (nbatch, L) each row's flat model, its first widths[i] values (it ends in the drive's
    block); contact_at, depth, depths, break_min, rtol, atol, dt, sample_steps, delay_steps, set_k,
    set_v, pend_*, command, states, integ … denses, steps, until, last, scene_rec: as `closed_loop.run`.
    kind[i]: LAW_VOLTAGE or LAW_CURRENT; feedback[i], scale[i]: what the law reads (FEEDBACK_*, times
    scale); gains: (nbatch, 10) the law's settings in `drive_grip_law`'s order (`controllers.VOLTAGE_LAW`,
    `current_grip.CURRENT_LAW`), its current setpoint's (lever, load torque, torque per ampere) after
    them for grip_current; state: (nbatch, 7) the law's state (SETPOINT …); signals: (nbatch, 3) the
    grip force (N), motor current (A) and voltage (V) at the state; drives: (nbatch, 3) (DIRECTION …);
    record: (nbatch, last + 1, N_COLUMNS). Returns each row's status.
    """
    nbatch = states.shape[0]
    status = np.empty(nbatch, dtype=np.int64)
    period = sample_steps * dt
    for i in prange(nbatch):
        status[i] = _row(models[i, : widths[i]], contact_at[i], depth[i], depths[i], break_min[i], rtol, atol, dt,
                         sample_steps, delay_steps, period, set_k, set_v, kind[i], feedback[i], scale[i], gains[i],
                         state[i], pend_k[i], pend_u[i], pend_n, command, states[i], signals[i], drives[i], integ[i],
                         ys[i], fs[i], y_olds[i], denses[i], steps, until[i], last, scene_rec[i], record[i], i)
    return status


@njit(**JIT)
def _law(kind, feedback, scale, g, s, t, setpoint, signals, period):
    """The row's controller at a sample at t (s): its voltage (V); s (its state) updated in place."""
    if setpoint != s[SETPOINT]:
        s[SETPOINT] = setpoint
        if kind == LAW_CURRENT:
            s[TARGET] = (g[10] * setpoint + g[11]) / g[12]  # `current_grip.current_setpoint`
            s[INTEGRAL], s[IN_BAND], locked, touched, s[SINCE] = current_setpoint_state(t)
        else:
            s[INTEGRAL], s[IN_BAND], locked, touched, s[SINCE] = voltage_setpoint(t, s[TOUCHED] != 0.0)
        s[LOCKED], s[TOUCHED] = 1.0 if locked else 0.0, 1.0 if touched else 0.0
    value = signals[0] if feedback == FEEDBACK_GRIP else signals[1]
    if kind == LAW_CURRENT:
        integral, in_band, locked, touched, u = current_update(
            s[INTEGRAL], s[IN_BAND], s[LOCKED] != 0.0, s[TOUCHED] != 0.0, s[SINCE], t, setpoint, s[TARGET], value, period,
            g[0], g[1], g[2], g[3], g[4], g[5], g[6], g[7], g[8], g[9])
    else:
        integral, in_band, locked, touched, u = voltage_update(
            s[INTEGRAL], s[IN_BAND], s[LOCKED] != 0.0, s[TOUCHED] != 0.0, s[SINCE], t, setpoint, scale * value, period,
            g[0], g[1], g[2], g[3], g[4], g[5], g[6], g[7], g[8])
    s[INTEGRAL], s[IN_BAND] = integral, in_band
    s[LOCKED], s[TOUCHED] = 1.0 if locked else 0.0, 1.0 if touched else 0.0
    return u


@njit(**JIT)
def _row(m, o, depth, depths, break_min, rtol, atol, dt, sample_steps, delay_steps, period, set_k, set_v, kind, feedback,
         scale, gains, s, pend_k, pend_u, pend_n, command, x, signals, drv, st, y, f, y_old, dense, steps, until, last,
         scene_rec, rec, i):
    """One row of `run`: its status."""
    kk, y_new, taus, out = np.empty((16, 6)), np.empty(6), np.empty(kl.N_NODES), np.empty(6)
    save = np.empty((12, 8))
    cand = max(depths.shape[0], 1)
    ga, ra, gb, rb = np.empty(cand), np.empty(cand), np.empty(cand), np.empty(cand)
    k = steps[i]
    while k < last:
        if k == until:
            steps[i] = k
            return PAUSE
        setpoint = kl.setpoint_at(set_k, set_v, k)
        sampled = k % sample_steps == 0
        u = _law(kind, feedback, scale, gains, s, k * dt, setpoint, signals, period) if sampled else 0.0
        kl.hold_command(pend_k, pend_u, pend_n, command, i, k, k + delay_steps, u, sampled)
        r = rec[k]
        kl.record_sample(r, k, dt, signals[0], setpoint, x, command[i], scene_rec)
        r[MOTOR_VOLTAGE], r[MOTOR_CURRENT] = signals[2], signals[1]
        taken, force = _physics(m, o, depth, depths, rtol, atol, dt, k, command[i], x, drv, st, y, f, y_old, dense, save,
                                kk, y_new, taus, out, ga, ra, gb, rb)
        if not taken:
            steps[i] = k
            return EVENT
        signals[0] = force
        signals[1], signals[2] = motor_outputs(m, command[i], x[3])
        k += 1
        if force > break_min:
            steps[i] = k
            return WATCH
    steps[i] = k
    return DONE
