"""The grip PI's closed loop in the kernel: many runs of one task (gains, settings) in one call.

`run` steps every row i of a task from steps[i] on, as `finger_sim.tasks.runner.run_task` steps
it with the shipped grip PI (`grip_pi`), nothing per step in Python:

- the script: the setpoint schedule (set_k, set_v: step, N) in force at each step;
- the controller: at every `sample_steps`-th step the law's state is advanced by the law itself,
  compiled (`grip_law.grip_setpoint`, `grip_update`, `pi_update`: the plain functions that
  `runtime.grip.GripController` calls) on the grip force measured at the step's start; its command acts from
  `delay_steps` steps later and is held (a ring buffer of pending commands);
- the step: what `Simulator.step` does under the held command with the method `auto` picks on
  these scenes, DOP853 (`integrators.dop853.DormandPrince853.step`: its internal solution
  continued while the command is unchanged, else restarted; `_advance`'s step-size control;
  the projected dense output at the step's end), on the compiled attempt it calls
  (`numerics.dop853_attempt`); or, on a scene without contact (a row whose only object was
  crushed, free space), the lean step `Simulator.step` takes there with auto's fixed-step method
  (`numerics._profile_step` under the held command, tableau `tab`);
- the grip force after the step (`Contact.outputs`' Σ F_n), measured at the next sample.

The contact law here (`contact_states`) is the force's own (`effects.contact_law` and the candidate loop
`effects.contact_candidates`, compiled in `numerics`): `Contact.gaps`, `gap_gradient` and `_forces` in their
order and arithmetic (sqrt, not hypot), so every decision the Simulator takes on the gaps (whether a step may hold a crossing) is
taken here on the same numbers. The internal
solution's state is kept per row (`INTEGRATOR`, and y, f, y_old, dense), handed to the row's
Simulator and read back from it around every step that Python takes (`finger_sim.tasks.batch_rows`).

A row stops and hands over to Python (its status) where the Simulator or the scene must act:
EVENT, before a step that may hold a contact onset or release or a depth crossing, that fails,
or that needs DOP853's first internal step (the Simulator locates, raises or starts; the row's
pre-step part, sample and record, is done; its state and internal solution are those before the step); WATCH,
after a step whose grip force exceeds the row's smallest break force (the crush rule decides);
PAUSE, at until[i] (a tip-force switch: the scene changes); DONE, at the last step.
"""

from __future__ import annotations

import math

import numpy as np

from finger_sim.kernel import use_writable_cache

use_writable_cache()  # before numba reads NUMBA_CACHE_DIR
from numba import njit, prange  # noqa: E402  (after the cache folder is set)

from finger_sim.kernel.event_checks import EVENT_TOLERANCE, predicted_crossing  # noqa: E402
from finger_sim.integrators import dop853  # noqa: E402
from finger_sim.inputs import HELD, HELD_ARRAY  # noqa: E402
from finger_sim.kernel.numerics import (ERROR_EXPONENT, JIT, LAW, MAX_FACTOR, MIN_FACTOR, OK, SAFETY,  # noqa: E402
                                        _profile_step, _rhs, candidate_walk, compiled, crossing_retry, dop853_attempt,
                                        dop853_output, gap_gradient, normal_force, point_velocity, torque_at)
from finger_sim import grip_law as grip  # noqa: E402

#: A row's status after `run` (module docstring).
DONE, EVENT, WATCH, PAUSE = 0, 1, 2, 3
#: The columns of `run`'s record, as `finger_sim.tasks.runner.COLUMNS`.
T, GRIP, SETPOINT, THETA1, THETA1_DOT, COMMAND, TIP_X, TIP_Y, CRUSHED = range(9)
N_RECORD = 9
#: The controller settings per row, in this order (GripSettings' names).
GAINS = ("kp", "ki", "max_torque", "closing_torque", "contact_threshold", "opening_torque", "opening_time")
#: The controller state per row, in this order: phase (grip.IDLE …), integral N·m, opening time
#: left s, the law's setpoint N.
PHASE, INTEGRAL, OPENING_LEFT, LAW_SETPOINT = range(4)

#: DOP853's internal solution per row, these scalars in this order: its time, next step, the last
#: accepted step's start and length (s), the held command it was computed under (N·m; NaN: none,
#: restart), whether the last output is the row's state (1/0) and its time (s), and whether the
#: solution's origin is the row's state (1/0: `DormandPrince853.step`'s first branch).
INTEGRATOR = ("t", "h", "t_old", "h_old", "value", "continues", "last_t", "origin")
I_T, I_H, I_T_OLD, I_H_OLD, I_VALUE, I_CONTINUES, I_LAST_T, I_ORIGIN = range(len(INTEGRATOR))
#: A row's DOP853 continues its last output within this fraction of a step (`DormandPrince853.step`).
LAST_OUTPUT_SLACK = 1e-9
#: scipy's DOP853 coefficients, as `DormandPrince853` passes them.
A, B, C, E3, E5, D = dop853._A, dop853._B, dop853._C, dop853._E3, dop853._E5, dop853._D
N_NODES, N_STAGES = len(dop853._NODES), dop853._N_STAGES
#: The stage nodes c of an attempt, as `DormandPrince853._advance` evaluates τ(t + c h).
NODES = np.array(dop853._NODES)
MAX_ATTEMPTS, MAX_STEP = dop853.MAX_ATTEMPTS, dop853.MAX_STEP
#: An internal step below this many ulps of t fails (`DormandPrince853._advance`).
MIN_STEP_ULPS = 10.0

PARALLEL = {**JIT, "parallel": True}

#: The laws compiled from their one definition (`finger_sim.grip_law`).
pi_update = njit(**LAW)(grip.pi_update)
grip_setpoint = njit(**LAW)(grip.grip_setpoint)
grip_update = compiled(grip.grip_update, pi_update=pi_update)


@njit(**LAW)
def gap_and_rate(geometry, v0, v1, v2):
    """A candidate's gap −δ (m) and its rate ∂gap/∂q · q' (m/s) at q' = (v0, v1, v2) from its `geometry`
    (`Contact.gaps`, `Contact.gap_gradient`)."""
    d, _, _, nx, ny, j1x, j1y, j3x, j3y = geometry
    (g0, g2), g1 = gap_gradient(nx, ny, j1x, j1y, j3x, j3y), 0.0
    return -d, g0 * v0 + g1 * v1 + g2 * v2


@njit(**LAW)
def _store_state(acc, ctx, i, geometry):
    """gaps[i] = −δ (m) and rates[i] = ∂gap/∂q · q' (m/s) of candidate i; acc = (count, Σ F_n N) plus it."""
    gaps, rates, v0, v1, v2, k, e, dd = ctx
    d, _, _, nx, ny, j1x, j1y, j3x, j3y = geometry
    gaps[i], rates[i] = gap_and_rate(geometry, v0, v1, v2)
    grip_force = acc[1]
    if d > 0.0:
        vx, vy = point_velocity(j1x, j1y, j3x, j3y, v0, v2)
        fn = normal_force(d, nx, ny, vx, vy, k, e, dd)
        grip_force += fn if fn > 0.0 else 0.0
    return acc[0] + 1, grip_force


#: The candidate loop (`effects.contact_candidates`) storing every candidate's gap and rate.
_walk_states = candidate_walk(_store_state)


@njit(**JIT)
def contact_states(m, o, x, gaps, rates):
    """Every contact candidate's gap −δ (m) and rate (m/s) at the state x (q, q') into gaps and
    rates, as the Simulator reads them (`Contact.gaps`; ∂gap/∂q · q' from `Contact.gap_gradient`);
    returns (count, grip force Σ F_n over the candidates in contact, N: `Contact.outputs`).
    o: where the contact element's parameters start in the model m (`Contact.kernel_params`)."""
    ctx = (gaps, rates, x[3], x[4], x[5], m[o + 3], m[o + 4], m[o + 5])
    return _walk_states(m, o, x[0], x[2], True, (0, 0.0), ctx)


@njit(**JIT)
def may_cross(g0, r0, g1, r1, h):
    """Whether the Simulator looks for a crossing of a gap (g0, r0) → (g1, r1) over a step of h s
    and may find one (`Simulator._first_crossing` and `_bracket`'s first tests): then the step is
    the Simulator's to take."""
    if min(g0, g1) > h * (abs(r0) + abs(r1)):
        return False
    closed = g0 < -EVENT_TOLERANCE
    if (g1 < -EVENT_TOLERANCE) != closed:
        return True
    return predicted_crossing(g0, r0, g1, r1, h, closed) is not None


@njit(**JIT)
def _advance(m, rtol, atol, st, y, f, y_old, dense, kk, y_new, taus, prof):
    """One accepted internal step from st[I_T]: `DormandPrince853._advance`. False if it fails.
    prof: a compiled profile (`inputs.profile_array`), τ at each attempt's stage times; or
    HELD_ARRAY: taus already hold the held torque."""
    t, h = st[I_T], st[I_H]
    rejected = False
    smooth = int(prof[0]) != HELD
    for _ in range(MAX_ATTEMPTS):
        if h < MIN_STEP_ULPS * abs(np.nextafter(t, np.inf) - t):
            return False
        if smooth:  # `DormandPrince853._advance`: τ(t + c h) at every node
            for c in range(N_NODES):
                taus[c] = torque_at(prof, 0.0, t + NODES[c] * h)
        norm = dop853_attempt(m, A, B, C, E3, E5, D, t, y, f, h, taus, rtol, atol, kk, y_new, dense)
        if norm < 1.0:
            factor = MAX_FACTOR if norm == 0.0 else min(MAX_FACTOR, SAFETY * norm**ERROR_EXPONENT)
            st[I_T_OLD], st[I_H_OLD] = t, h
            y_old[:] = y
            y[:] = y_new
            f[:] = kk[N_STAGES]
            st[I_T] = t + h
            st[I_H] = min(MAX_STEP, h * (min(1.0, factor) if rejected else factor))
            return True
        shrunk = h * (max(MIN_FACTOR, SAFETY * norm**ERROR_EXPONENT) if math.isfinite(norm) else MIN_FACTOR)
        h = crossing_retry(m, y, y_new, h, shrunk)
        rejected = True
    return False


@njit(**JIT)
def _dop853_step(m, rtol, atol, t, dt, command, x, st, y, f, y_old, dense, kk, y_new, taus, out):
    """`DormandPrince853.step(t, q, q', dt, held command)` on x = (q, q') in place. False where
    Python must take it (its first internal step, a failure); st, y, f, y_old, dense may then
    have moved: the caller restores them."""
    target = t + dt
    same = st[I_VALUE] == command  # the Simulator's HeldTorque is the same object iff the value is
    if same and st[I_ORIGIN] == 1.0 and target >= t:
        pass
    elif same and st[I_CONTINUES] == 1.0 and abs(st[I_LAST_T] - t) <= LAST_OUTPUT_SLACK * dt and target >= st[I_T_OLD]:
        pass
    else:  # `_restart`
        st[I_VALUE] = command
        st[I_T] = st[I_T_OLD] = t
        y[:] = x
        _rhs(m, t, y, command, f)
        if st[I_H] <= 0.0:
            return False
    for c in range(N_NODES):
        taus[c] = command
    while st[I_T] < target:
        if not _advance(m, rtol, atol, st, y, f, y_old, dense, kk, y_new, taus, HELD_ARRAY):
            return False
    status, _, _ = dop853_output(m, st[I_T_OLD], st[I_H_OLD], y_old, dense, target, out)
    if status != OK:
        return False
    x[:] = out
    st[I_CONTINUES], st[I_LAST_T], st[I_ORIGIN] = 1.0, target, 0.0
    return True


@njit(**JIT)
def save_solution(save, x, st, y, f, y_old, dense):
    """A row's state x and DOP853 internal solution (st, y, f, y_old, dense) into save (12 × 8)."""
    save[0, :6] = x
    save[1, :8] = st
    save[2, :6], save[3, :6], save[4, :6] = y, f, y_old
    save[5:12, :6] = dense


@njit(**JIT)
def restore_solution(save, x, st, y, f, y_old, dense):
    """`save_solution` undone: a step not taken leaves the row as at its start, for the Simulator."""
    x[:] = save[0, :6]
    st[:] = save[1, :8]
    y[:], f[:], y_old[:] = save[2, :6], save[3, :6], save[4, :6]
    dense[:] = save[5:12, :6]


@njit(**JIT)
def setpoint_at(set_k, set_v, k):
    """The setpoint schedule's value in force at step k (N; 0 before its first step)."""
    setpoint = 0.0
    for n in range(set_k.shape[0]):
        if set_k[n] <= k:
            setpoint = set_v[n]
    return setpoint


@njit(**JIT)
def hold_command(pend_k, pend_u, pend_n, command, i, k, acts_from, u, sampled):
    """Row i at step k: when `sampled`, the law's command u queued to act from step acts_from; then
    every pending command due by k taken in turn, the last held in command[i] (zero-order hold)."""
    if sampled:
        pend_k[pend_n[i]], pend_u[pend_n[i]] = acts_from, u
        pend_n[i] += 1
    due = 0
    while due < pend_n[i] and pend_k[due] <= k:
        command[i] = pend_u[due]
        due += 1
    if due:
        for n in range(due, pend_n[i]):
            pend_k[n - due], pend_u[n - due] = pend_k[n], pend_u[n]
        pend_n[i] -= due


@njit(**JIT)
def record_sample(r, k, dt, force, setpoint, x, command, scene_rec):
    """The sample of step k (the record's first N_RECORD columns, T …) into r."""
    r[T], r[GRIP], r[SETPOINT], r[THETA1], r[THETA1_DOT] = k * dt, force, setpoint, x[0], x[3]
    r[COMMAND], r[TIP_X], r[TIP_Y], r[CRUSHED] = command, scene_rec[0], scene_rec[1], scene_rec[2]


@njit(**JIT)
def _grip_law(law, setpoint, force, period, gains):
    """The grip PI at a sample: its command (N·m) on the measured grip force (N); law (PHASE …) in place."""
    if setpoint != law[LAW_SETPOINT]:
        phase, left = grip_setpoint(int(law[PHASE]), law[OPENING_LEFT], setpoint, gains[6])
        law[PHASE], law[OPENING_LEFT], law[LAW_SETPOINT] = phase, left, setpoint
    phase, integral, left, u = grip_update(int(law[PHASE]), law[INTEGRAL], law[OPENING_LEFT], law[LAW_SETPOINT], force,
                                           period, gains[0], gains[1], gains[2], gains[3], gains[4], gains[5])
    law[PHASE], law[INTEGRAL], law[OPENING_LEFT] = phase, integral, left
    return u


@njit(**JIT)
def _physics(m, o, lean, tab, depth, depths, rtol, atol, dt, k, command, x, st, y, f, y_old, dense, save, kk, y_new,
             taus, out, ga, ra, gb, rb):
    """Step k of one row under the held `command` (N·m) on x in place, as `Simulator.step` takes a
    step that holds no event; returns (taken, grip force after it, N). Not taken: x and the
    internal solution are left as at the step's start, for the Simulator. lean: the row steps
    with the fixed-step method of tableau `tab` (no contact, no internal solution)."""
    if lean:
        save[0, :6] = x
        status, _ = _profile_step(m, tab, HELD_ARRAY, command, k, dt, x, kk, taus)
        if status != OK:
            x[:] = save[0, :6]
            return False, 0.0
        return True, 0.0
    t0, t1 = k * dt, (k + 1) * dt
    h = t1 - t0
    n = 0
    if o >= 0:
        n, _ = contact_states(m, o, x, ga, ra)
    save_solution(save, x, st, y, f, y_old, dense)
    taken = _dop853_step(m, rtol, atol, t0, h, command, x, st, y, f, y_old, dense, kk, y_new, taus, out)
    grip_force = 0.0
    if taken and o >= 0:
        _, grip_force = contact_states(m, o, x, gb, rb)
        for c in range(n):
            if may_cross(ga[c], ra[c], gb[c], rb[c], h) or \
                    (depth and may_cross(ga[c] + depths[c], ra[c], gb[c] + depths[c], rb[c], h)):
                taken = False
                break
    if not taken:
        restore_solution(save, x, st, y, f, y_old, dense)
    return taken, grip_force


@njit(**PARALLEL)
def run(models, contact_at, lean, tab, depth, depths, break_min, rtol, atol, dt, sample_steps, delay_steps, set_k, set_v,
        gains, law, pend_k, pend_u, pend_n, command, states, grip_force, integ, ys, fs, y_olds, denses, steps, until,
        last, scene_rec, record):
    """Every row from steps[i] until its status (module docstring), in place.

    models: (nbatch, L) each row's flat model (zero-padded); contact_at[i]: where its contact
    parameters start (−1: no contact); lean[i]: the row steps with the fixed-step method of
    tableau tab (`layout.tableau_array`), else with DOP853; depth[i], depths[i]: whether it checks depth gaps ρ − δ,
    and each candidate's ρ (m); break_min[i]: the smallest break force of its objects (N; inf:
    none watched); rtol, atol: DOP853's. dt s; sample_steps, delay_steps: the task's; set_k,
    set_v: the setpoint schedule (step, N). gains: (nbatch, len(GAINS)); law: (nbatch, 4) the
    law's state (PHASE …); pend_k, pend_u, pend_n: each row's pending commands (step they act
    from, N·m), oldest first, and their count; command[i]: the held command; states: (nbatch, 6)
    (q, q'); grip_force[i]: at the state; integ, ys, fs, y_olds, denses: each row's DOP853
    internal solution (INTEGRATOR; 6, 6, 6, 7 × 6); steps[i]: the step to take next; until[i],
    last: where to pause and end. scene_rec: (nbatch, 3) tip force x, y (N) and crushes so far,
    recorded as they are; record: (nbatch, last + 1, 9) the run's samples. Returns each row's status.
    """
    nbatch = states.shape[0]
    status = np.empty(nbatch, dtype=np.int64)
    period = sample_steps * dt
    for i in prange(nbatch):
        status[i] = _row(models[i], contact_at[i], lean[i], tab, depth[i], depths[i], break_min[i], rtol, atol, dt, sample_steps,
                         delay_steps, period, set_k, set_v, gains[i], law[i], pend_k[i], pend_u[i], pend_n, command,
                         states[i], grip_force, integ[i], ys[i], fs[i], y_olds[i], denses[i], steps, until[i], last,
                         scene_rec[i], record[i], i)
    return status


@njit(**JIT)
def _row(m, o, lean, tab, depth, depths, break_min, rtol, atol, dt, sample_steps, delay_steps, period, set_k, set_v, gains,
         law, pend_k, pend_u, pend_n, command, x, grip_force, st, y, f, y_old, dense, steps, until, last, scene_rec,
         rec, i):
    """One row of `run`: its status."""
    kk, y_new, taus, out = np.empty((16, 6)), np.empty(6), np.empty(N_NODES), np.empty(6)
    save = np.empty((12, 8))
    cand = max(depths.shape[0], 1)
    ga, ra, gb, rb = np.empty(cand), np.empty(cand), np.empty(cand), np.empty(cand)
    k = steps[i]
    while k < last:
        if k == until:
            steps[i] = k
            return PAUSE
        setpoint = setpoint_at(set_k, set_v, k)
        sampled = k % sample_steps == 0
        u = _grip_law(law, setpoint, grip_force[i], period, gains) if sampled else 0.0
        hold_command(pend_k, pend_u, pend_n, command, i, k, k + delay_steps, u, sampled)
        record_sample(rec[k], k, dt, grip_force[i], setpoint, x, command[i], scene_rec)
        taken, force = _physics(m, o, lean, tab, depth, depths, rtol, atol, dt, k, command[i], x, st, y, f, y_old, dense, save,
                                kk, y_new, taus, out, ga, ra, gb, rb)
        if not taken:
            steps[i] = k
            return EVENT
        grip_force[i] = force
        k += 1
        if force > break_min:
            steps[i] = k
            return WATCH
    steps[i] = k
    return DONE
