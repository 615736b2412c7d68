"""The compiled numerics: the acceleration solve, the force elements, projection, RK stages, DOP853.

The laws are not written here: the acceleration solve (`dynamics.schur_solve`), the projection
(`projection.project_state`), the force laws the effects declare (`effects.base.kernel_law`, dispatched
by `element_force`, generated from the registry: `kernel.force_laws`) and the torque profiles
(`inputs.torque_at`, `inputs.switches_inside`) are the plain functions the Python path calls, compiled
here as they are, and so is the contact law (`effects.contact_law`: the candidates' geometry and the force).
So are a DOP853 attempt (`integrators.steps.dop853_attempt`, compiled with this module's `_rhs`) and the
contact's candidate loop (`effects.contact_candidates.walk_candidates`, compiled with the force sum as its
visitor). The explicit Runge–Kutta step is generated from one template of the stage loop (`kernel.rk_template`,
`rk_steps.py`) and compiled here with `accelerations`. What remains is the flat model's force sum and the
fixed-step steppers: the same arithmetic, in the same order, as their Python references
(`ExplicitRungeKutta.step`), so both paths agree to round-off (the tests ask 1e-13 rad).
Compiled by numba on first use and cached on disk (`cache=True`; see `finger_sim.kernel`).
Errors are status codes, raised as exceptions by the Python callers.
"""

from __future__ import annotations

import math

import numpy as np

from finger_sim.kernel.jit import JIT, LAW, compiled, njit  # first: it keys numba's cache

from finger_sim import dynamics, inputs, projection
from finger_sim.effects import contact_candidates, contact_law, friction_modes
from finger_sim.effects.friction_modes import KERNEL_BLOCK as SLIP_BLOCK
from finger_sim.effects.friction_modes import SLIDING
from finger_sim.integrators import steps
from finger_sim.inputs import BREAK_EPS, SQUARE, STEP
from finger_sim.kernel import rk_steps
from finger_sim.kernel.force_laws import element_forces
from finger_sim.kernel.layout import (BREAKPOINT, CONTACT, HEADER, NON_FINITE, NOT_CONVERGED, OK, STATE_NON_FINITE,
                                     STICK_SLIP_CONTACT)


# DOP853's step-size control: scipy's constants (scipy/integrate/_ivp/rk.py).
SAFETY = 0.9  # the factor on the optimal step after an accepted or rejected step
MIN_FACTOR = 0.2  # the step shrinks at most 5× after a rejection
MAX_FACTOR = 10.0  # and grows at most 10× after an acceptance
ERROR_EXPONENT = -1.0 / 8.0  # −1/(order of the error estimator + 1)
#: DOP853's step floor, in ulps of t (scipy's rule)
MIN_STEP_ULPS = 10.0

#: The laws compiled from their one definition (the plain functions the Python path calls).
schur_solve = njit(**LAW)(dynamics.schur_solve)
trig = njit(**LAW)(dynamics.trig)
project_state = njit(**LAW)(projection.project_state)
#: Q of an element whose law an effect declares (`effects.base.kernel_law`): the dispatch generated from the registry.
element_force = element_forces().element_force
linkage_slope = njit(**LAW)(friction_modes.linkage_slope)
tangent_gain = njit(**LAW)(friction_modes.tangent_gain)
sliding_friction = njit(**LAW)(friction_modes.sliding_friction)
_PROFILE_LAWS = {name: njit(**LAW)(getattr(inputs, name))
                 for name in ("ramp_torque", "sine_torque", "step_torque", "square_torque", "square_switch")}
torque_at = compiled(inputs.torque_at, **_PROFILE_LAWS)
switches_inside = compiled(inputs.switches_inside, **_PROFILE_LAWS)


# -- the contact law (`effects.contact_law`, the plain functions `Contact` calls), compiled as it is: the
# candidates' geometry, shared by the force, the closed loop and the event checks, and the force
circle_depth = njit(**LAW)(contact_law.circle_depth)
proximal_circle = compiled(contact_law.proximal_circle, circle_depth=circle_depth)
distal_circle = compiled(contact_law.distal_circle, circle_depth=circle_depth)
joint_plane = njit(**LAW)(contact_law.joint_plane)
tip_plane = njit(**LAW)(contact_law.tip_plane)
point_velocity = njit(**LAW)(contact_law.point_velocity)
along_tangent = njit(**LAW)(contact_law.along_tangent)
normal_force = njit(**LAW)(contact_law.normal_force)
contact_force = compiled(contact_law.contact_force, along_tangent=along_tangent, normal_force=normal_force)
gap_gradient = njit(**LAW)(contact_law.gap_gradient)
generalized = njit(**LAW)(contact_law.generalized)


@njit(**JIT)
def _contact(m, o, q0, q2, v0, v2, slide, direction, mu_k, mu_s, v_st, n3):
    """Contact's (Q1, Q3): `finger_sim.effects.contact.Contact.force`, same order of terms. `slide`: the
    stick–slip law's sliding friction too (`StickSlipContact._forces`; direction ±1, μ_k, μ_s, v_st m/s,
    n3 = dθ3/dθ1)."""
    k, e, d, mu, vs = m[o + 3], m[o + 4], m[o + 5], m[o + 6], m[o + 7]
    return contact_forces(m, o, q0, q2, False, (0.0, 0.0),
                          (v0, v2, k, e, d, mu, vs, slide, direction, mu_k, mu_s, v_st, n3))


@njit(**JIT)
def _contact_force(delta, nx, ny, j1x, j1y, j3x, j3y, v0, v2, k, e, d, mu, vs, slide, direction, mu_k, mu_s, v_st,
                   n3):
    """J_pᵀ F of one candidate in contact: `Contact._forces` (with `slide`, `StickSlipContact._forces`) then
    the sum in `Contact.force`."""
    vx, vy = point_velocity(j1x, j1y, j3x, j3y, v0, v2)
    fn, fx, fy = contact_force(delta, nx, ny, vx, vy, k, e, d, mu, vs)
    if slide and fn > 0.0:
        ft = sliding_friction(fn, tangent_gain(nx, ny, j1x, j1y, j3x, j3y, n3), direction, v0, mu_k, mu_s, v_st)
        fx, fy = along_tangent(fx, fy, ft, nx, ny)
    return generalized(j1x, j1y, j3x, j3y, fx, fy)


@njit(**LAW)
def _add_force(acc, ctx, i, geometry):
    """acc = (Q1, Q3) plus J_pᵀ F of candidate i where in contact: `Contact.force`'s sum, one candidate."""
    delta, _, _, nx, ny, j1x, j1y, j3x, j3y = geometry
    if not delta > 0.0:
        return acc
    v0, v2, k, e, d, mu, vs, slide, direction, mu_k, mu_s, v_st, n3 = ctx
    f1, f3 = _contact_force(delta, nx, ny, j1x, j1y, j3x, j3y, v0, v2, k, e, d, mu, vs, slide, direction, mu_k, mu_s,
                            v_st, n3)
    return acc[0] + f1, acc[1] + f3


def candidate_walk(visit):  # type: ignore[no-untyped-def]
    """The candidate loop (`effects.contact_candidates.walk_candidates`) compiled with `visit` as its `_visit`
    and the compiled geometry (inlined into its caller)."""
    return compiled(contact_candidates.walk_candidates, _visit=visit, proximal_circle=proximal_circle,
                    distal_circle=distal_circle, joint_plane=joint_plane, tip_plane=tip_plane)


#: The candidate loop summing the force: (Q1, Q3), N·m.
contact_forces = candidate_walk(_add_force)


@njit(**LAW)
def _store_gap(acc, gaps, i, geometry):
    """gaps[i] = −δ (m), the gap of candidate i (`Contact.gaps`); acc: the count so far."""
    gaps[i] = -geometry[0]
    return acc + 1


#: The candidate loop storing every candidate's gap (`crossing_retry`).
_walk_gaps = candidate_walk(_store_gap)


@njit(**JIT)
def generalized_force(m, t, q0, q1, q2, v0, v1, v2, tau):
    """Q = (τ, 0, 0) + Σ elements, N·m: `FingerSystem.generalized_force`."""
    f1, f2, f3 = tau, 0.0, 0.0
    o = HEADER + 1
    for _ in range(int(m[HEADER])):
        code, n = int(m[o]), int(m[o + 1])
        o += 2
        e2 = 0.0
        if code == CONTACT:
            e1, e3 = _contact(m, o, q0, q2, v0, v2, False, 0.0, 0.0, 0.0, 0.0, 0.0)
        elif code == STICK_SLIP_CONTACT:  # the mode block first (`StickSlipContact.kernel_params`)
            slide = m[o] == SLIDING and m[o + 3] != 0.0
            n3 = linkage_slope(m[4], m[5], m[6], q0, q1, q2) if slide else 0.0
            e1, e3 = _contact(m, o + SLIP_BLOCK, q0, q2, v0, v2, slide, m[o + 1], m[o + 2], m[o + 3], m[o + 4], n3)
        else:  # a declared law (NO_FORCE: zero)
            e1, e2, e3 = element_force(code, m, o, t, q0, q1, q2, v0, v1, v2)
        f1 += e1
        f2 += e2
        f3 += e3
        o += n
    return f1, f2, f3


@njit(**JIT)
def crossing_retry(m, y, y_new, h, shrunk):
    """The step (s) of the attempt after a rejected DOP853 trial of h s from y to y_new (q, q'), whose error control
    proposes `shrunk`: where the trial lands inside a contact that was open at its start (a candidate's gap −δ > 0
    at y, < 0 at y_new), the step to the earliest such linearly interpolated crossing, h·g0/(g0 − g1), if longer
    (the trial's error is the contact force's, switched on inside it: a shrink by the error's rule lands inside
    again); else `shrunk`, also for a model without a contact element (Python's stages: `DormandPrince853.compiled`
    False). Called by `DormandPrince853._advance` and its compiled twin (`closed_loop._advance`) alike."""
    o = HEADER + 1
    fraction = math.inf
    for _ in range(int(m[HEADER])):
        code, n = int(m[o]), int(m[o + 1])
        o += 2
        if code == CONTACT:
            count = 0
            for kind in range(len(contact_candidates.RECORD_SIZE)):  # the candidates of each kind
                count += int(m[o + contact_candidates.COUNTS + kind])
            before, after = np.empty(count), np.empty(count)
            _walk_gaps(m, o, y[0], y[2], True, 0, before)
            _walk_gaps(m, o, y_new[0], y_new[2], True, 0, after)
            for i in range(count):
                if before[i] > 0.0 > after[i]:
                    fraction = min(fraction, before[i] / (before[i] - after[i]))
        o += n
    return shrunk if fraction == math.inf else max(shrunk, h * fraction)


@njit(**JIT)
def accelerations(m, t, q0, q1, q2, v0, v1, v2, tau):
    """q'' (rad/s²) of the index-1 system: `FingerSystem.accelerations`, the same `schur_solve`."""
    s1, c1, s2, c2, s3, c3, su, cu = trig(q0, q1, q2, m[7])
    f1, f2, f3 = generalized_force(m, t, q0, q1, q2, v0, v1, v2, tau)
    return solved_accelerations(m, s1, c1, s2, c2, s3, c3, su, cu, v0, v1, v2, f1, f2, f3)


@njit(**JIT)
def solved_accelerations(m, s1, c1, s2, c2, s3, c3, su, cu, v0, v1, v2, f1, f2, f3):
    """q'' (rad/s²) under the generalized force (f1, f2, f3) (N·m), from the sines and cosines of
    θ1, θ2, θ3 and θ1 − θ3 − α (`dynamics.trig`): `accelerations` after its force sum (a drive reuses
    them, kernel.drive)."""
    a0, a1, a2, _, _ = schur_solve(m[0], m[1], m[2], m[3], m[4], m[5], m[6], s1, c1, s2, c2, s3, c3, su, cu,
                                   v0, v1, v2, f1, f2, f3)
    return a0, a1, a2


@njit(**JIT)
def project(m, x):
    """Project x = (q, q') (6 floats, in place) onto Φ = 0, Φ_q q' = 0: `projection.project_state`. Status."""
    status, _, t1, t2, t3, w1, w2, w3 = project_state(m[4], m[5], m[6], m[8], m[9], x[0], x[1], x[2], x[3], x[4], x[5])
    if status == OK:
        x[0], x[1], x[2], x[3], x[4], x[5] = t1, t2, t3, w1, w2, w3
    return status


@njit(**JIT)
def euler_step(m, t, x, h, tau):
    """The paper's Euler step (equations 6-7) on x = (q, q') in place: `PaperEuler.step`."""
    a0, a1, a2 = accelerations(m, t, x[0], x[1], x[2], x[3], x[4], x[5], tau)
    h2 = 0.5 * h * h
    x[0], x[1], x[2] = x[0] + x[3] * h + a0 * h2, x[1] + x[4] * h + a1 * h2, x[2] + x[5] * h + a2 * h2
    x[3], x[4], x[5] = x[3] + a0 * h, x[4] + a1 * h, x[5] + a2 * h
    return OK


#: One projected explicit RK step on x = (q, q') in place (`ExplicitRungeKutta.step`), generated from the
#: template of the stage loop (`kernel.rk_template`) with this module's `accelerations` and `project`.
rk_step = compiled(rk_steps.rk_step, options=JIT, accelerations=accelerations, project=project)


# -- DOP853: Hairer's embedded 8(5,3) pair with its 7th-order dense output ------------------
@njit(**JIT)
def _rhs(m, t, y, tau, out):
    out[0], out[1], out[2] = y[3], y[4], y[5]
    out[3], out[4], out[5] = accelerations(m, t, y[0], y[1], y[2], y[3], y[4], y[5], tau)


#: One DOP853 attempt compiled from its one definition (`integrators.steps.dop853_attempt`, the function
#: the Python path calls) with this module's `_rhs`; not inlined: a call, as it was when written here.
#: (`kernel.drive` compiles it again with the drive's `_rhs`: every global it reads is a name here.)
_stage_state = njit(**LAW)(steps._stage_state)
DOP853_STAGES, E3_WEIGHT = steps.DOP853_STAGES, steps.E3_WEIGHT
dop853_attempt = compiled(steps.dop853_attempt, options=JIT, _rhs=_rhs, _stage_state=_stage_state)


@njit(**JIT)
def dop853_theta_error(e53, kk, h, weight):
    """The local error estimate of an accepted step on θ (rad): scipy's DOP853 combination of its
    5th- and 3rd-order estimates, |h|·e5²/√(e5² + weight·e3²), for each angle, the largest of the three.
    e53: the E5 and E3 rows (2 × 13); kk: the step's stages (as `dop853_attempt` leaves them); h: s."""
    worst = 0.0
    for i in range(3):
        e5 = 0.0
        e3 = 0.0
        for j in range(e53.shape[1]):
            e5 += e53[0, j] * kk[j, i]
            e3 += e53[1, j] * kk[j, i]
        denominator = e5 * e5 + weight * e3 * e3
        if denominator > 0.0:
            worst = max(worst, e5 * e5 / math.sqrt(denominator))
    return abs(h) * worst


@njit(**LAW)
def dense_component(x, rows, first, i):
    """Component i of the dense output's polynomial at x (the fraction of the step, (t − t_old)/h), its 7
    coefficients in rows[first:first + 7, i] (`Dop853DenseOutput`'s Horner form), without y_old."""
    acc = 0.0
    for r in range(6, -1, -1):
        acc += rows[first + r, i]
        if (6 - r) % 2 == 0:
            acc *= x
        else:
            acc *= 1.0 - x
    return acc


@njit(**JIT)
def dop853_dense(t_old, h, y_old, dense, t, out):
    """The dense output of the last accepted step at t, into out (6): scipy's `Dop853DenseOutput`."""
    x = (t - t_old) / h
    for i in range(6):
        out[i] = dense_component(x, dense, 0, i) + y_old[i]


@njit(**JIT)
def rk_step_tuple(m, tab, t, q, v, h, taus):
    """`rk_step` (or Euler when tab is empty) on tuples: the single step the Simulator calls.

    q, v: 3-tuples (rad, rad/s); taus: τ at the distinct nodes, a tuple. Returns (status, q, v).
    """
    s = tab.shape[1]
    x = np.empty(6)
    x[0], x[1], x[2], x[3], x[4], x[5] = q[0], q[1], q[2], v[0], v[1], v[2]
    if s == 0:
        status = euler_step(m, t, x, h, taus[0])
    else:
        k = np.empty((s, 6))
        tau = np.empty(len(taus))
        for i in range(len(taus)):
            tau[i] = taus[i]
        status = rk_step(m, tab, t, x, h, tau, k)
    return status, (x[0], x[1], x[2]), (x[3], x[4], x[5])


@njit(**LAW)
def projected_output(m, y0, y1, y2, y3, y4, y5):
    """A dense output's state (q, q') checked finite and projected (`project_state`): (status, q, q') as
    tuples, the unprojected state where the status is not OK (NON_FINITE or the projection's)."""
    if not (math.isfinite(y0) and math.isfinite(y1) and math.isfinite(y2) and math.isfinite(y3) and math.isfinite(y4)
            and math.isfinite(y5)):
        return NON_FINITE, (y0, y1, y2), (y3, y4, y5)
    status, _, t1, t2, t3, w1, w2, w3 = project_state(m[4], m[5], m[6], m[8], m[9], y0, y1, y2, y3, y4, y5)
    if status != OK:
        return status, (y0, y1, y2), (y3, y4, y5)
    return OK, (t1, t2, t3), (w1, w2, w3)


@njit(**JIT)
def dop853_output(m, t_old, h, y_old, dense, t, out):
    """The dense output at t projected (`dop853_dense`, then `projected_output`): (status, q, q') as tuples;
    out (6) holds the state, projected where the status is OK."""
    dop853_dense(t_old, h, y_old, dense, t, out)
    status, q, v = projected_output(m, out[0], out[1], out[2], out[3], out[4], out[5])
    if status == OK:
        out[0], out[1], out[2], out[3], out[4], out[5] = q[0], q[1], q[2], v[0], v[1], v[2]
    return status, q, v


@njit(**JIT)
def dop853_output_rows(m, t_old, h, rows, y_old, dense, t):
    """`dop853_output` from the rows of one 2-D array (rows[y_old]: y_old; rows[dense:dense + 7]: the dense
    output's coefficients), on scalars: no view of rows, no output array. (status, q, q') as tuples, the
    unprojected state where the status is not OK."""
    x = (t - t_old) / h
    return projected_output(m, dense_component(x, rows, dense, 0) + rows[y_old, 0],
                            dense_component(x, rows, dense, 1) + rows[y_old, 1],
                            dense_component(x, rows, dense, 2) + rows[y_old, 2],
                            dense_component(x, rows, dense, 3) + rows[y_old, 3],
                            dense_component(x, rows, dense, 4) + rows[y_old, 4],
                            dense_component(x, rows, dense, 5) + rows[y_old, 5])


@njit(**JIT)
def dop853_outputs(m, t_old, h, y_old, dense, targets, out):
    """`dop853_output` at every time of `targets` into the rows of out (len(targets) × 6). Status."""
    for n in range(targets.shape[0]):
        status, _, _ = dop853_output(m, t_old, h, y_old, dense, targets[n], out[n])
        if status != OK:
            return status
    return OK


# -- compiled torque profiles and the Simulator's step (`finger_sim.inputs`, `Simulator.step`) --------
@njit(**JIT)
def plan_parts(plan):
    """(dt, model, tableau) of a step plan: [dt, len(model), tableau rows, tableau columns,
    model..., tableau row by row] (`finger_sim.kernel.integrators.step_plan`)."""
    nm, rows, cols = int(plan[1]), int(plan[2]), int(plan[3])
    m = plan[4: 4 + nm]
    tab = plan[4 + nm: 4 + nm + rows * cols].reshape((rows, cols))
    return plan[0], m, tab


@njit(**JIT)
def _profile_step(m, tab, prof, held, k, dt, x, work, taus):
    """Step k of a scene (t0 = k·dt to (k + 1)·dt) on x in place under a compiled profile, as
    `Simulator.step` does it on a step with no switch inside. Returns (status, τ at the step's end)."""
    t0, t1 = k * dt, (k + 1) * dt
    code = int(prof[0])
    piecewise = code == STEP or code == SQUARE
    value = 0.0
    if piecewise:
        if switches_inside(prof, t0, t1, BREAK_EPS * dt):
            return BREAKPOINT, 0.0
        value = torque_at(prof, held, 0.5 * (t0 + t1))  # `on_segment`: the value on the segment
        end = value
    else:
        end = torque_at(prof, held, t1)
    h = t1 - t0
    s = tab.shape[1]
    if s == 0:
        tau = value if piecewise else torque_at(prof, held, t0)
        status = euler_step(m, t0, x, h, tau)
    else:
        for i in range(s):
            taus[int(tab[s + 2, i])] = value if piecewise else torque_at(prof, held, t0 + tab[s + 1, i] * h)
        status = rk_step(m, tab, t0, x, h, taus, work)
    if status == OK and not (math.isfinite(x[0] + x[1] + x[2] + x[3] + x[4] + x[5])):
        status = STATE_NON_FINITE
    return status, end


@njit(**JIT)
def fast_step(plan, prof, held, k, q, v):
    """`Simulator.step` k of a smooth scene under a compiled profile (or a held value), in one
    call: (status, q, v, τ at the step's end). Status BREAKPOINT: a switch lies inside the
    step and nothing was done (the Simulator splits the step in Python)."""
    dt, m, tab = plan_parts(plan)
    x = np.empty(6)
    x[0], x[1], x[2], x[3], x[4], x[5] = q[0], q[1], q[2], v[0], v[1], v[2]
    s = tab.shape[1]
    status, end = _profile_step(m, tab, prof, held, k, dt, x, np.empty((max(s, 1), 6)), np.empty(max(s, 1)))
    return status, (x[0], x[1], x[2]), (x[3], x[4], x[5]), end


@njit(**JIT)
def fast_run(plan, prof, k0, xs):
    """Steps k0, k0 + 1, … of `fast_step` under the scene's profile from xs[0], filling xs[1:],
    until done or a step with a switch inside. Returns (status, steps done, τ at the last end)."""
    dt, m, tab = plan_parts(plan)
    s = tab.shape[1]
    work, taus = np.empty((max(s, 1), 6)), np.empty(max(s, 1))
    x = xs[0].copy()
    end = 0.0
    for n in range(xs.shape[0] - 1):
        status, tau = _profile_step(m, tab, prof, 0.0, k0 + n, dt, x, work, taus)
        if status != OK:
            return status, n, end
        end = tau
        xs[n + 1] = x
    return OK, xs.shape[0] - 1, end
