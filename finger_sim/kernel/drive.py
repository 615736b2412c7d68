"""The drive (spec §8) in the compiled kernel: its law and the integrator steps that apply it.

The law is compiled from its one definition (`finger_sim.actuators.drive`'s plain functions). The
step functions are numerics' own (`euler_step`, `rk_step`, `rk_step_tuple`) compiled a second time
with `accelerations` bound to `driven_accelerations`: the same code object under other globals,
so nothing is copied, and a scene without a drive compiles and runs exactly what it did before.
The drive's block ends the model (`Drive.kernel_block`; its first slot is the mesh mode, kept
current by `Drive.mirror`). With L > 0 the current is a seventh state, stepped by `inductive_rk_step`: the
template of `rk_step` (`kernel.rk_template`) with the width 7 and the stage `inductive_rates`.
"""

from __future__ import annotations

import math
import types
from collections.abc import Callable
from typing import Any

import numpy as np

from finger_sim.actuators import drive as law
from finger_sim.actuators.stepping import GUARD_TOLERANCE
from finger_sim.inputs import BREAK_EPS, HELD_ARRAY, SQUARE, STEP, Profile, profile_array
from finger_sim.kernel import numerics, rk_steps
from finger_sim.kernel.integrators import WARM_UP_STATE, CompiledRungeKutta, FastStepper, _entry_point
from finger_sim.kernel.jit import compiled
from finger_sim.kernel.layout import BREAKPOINT, OK
from finger_sim.kernel.numerics import (JIT, generalized_force, njit, plan_parts, project, solved_accelerations,
                                        switches_inside, torque_at, trig)
from finger_sim.stepper_slot import StageFunctions

motor_current = njit(**JIT)(law.motor_current)
unclamped_current = njit(**JIT)(law.unclamped_current)
mesh_torque = njit(**JIT)(law.mesh_torque)
linkage_inertia_at = njit(**JIT)(law.linkage_inertia_at)
unique = njit(**JIT)(law.unique)
current_rate = njit(**JIT)(law.current_rate)
BLOCK = law.KERNEL_BLOCK
DRIVE, STUCK = law.DRIVE, law.STUCK


@njit(**JIT)
def _trig(m, q0, q1, q2):
    """The sines and cosines of θ1, θ2, θ3 and θ1 − θ3 − α (`dynamics.trig`) that the acceleration
    solve and the linkage's inertia both use: computed once per state (the same values, so the same bits)."""
    return trig(q0, q1, q2, m[7])


@njit(**JIT)
def _mesh_torque(m, o, t, q0, q1, q2, v0, v1, v2, u, s1, c1, s2, c2, s3, c3, su, cu):
    """τ_g (N·m) of the rolling mesh in the mode m[o] (`DrivenSystem.mesh`); NaN where not unique.
    s1 … cu: `_trig` of the state."""
    i = motor_current(u, m[o + 3] * v0, m[o + 6], m[o + 5], m[o + 7], m[o + 8])
    return _mesh_torque_at(m, o, t, q0, q1, q2, v0, v1, v2, i, s1, c1, s2, c2, s3, c3, su, cu)


@njit(**JIT)
def _mesh_torque_at(m, o, t, q0, q1, q2, v0, v1, v2, i, s1, c1, s2, c2, s3, c3, su, cu):
    """τ_g (N·m) of the rolling mesh in the mode m[o] at the current i (A); NaN where not unique."""
    ratio, rotor, k_t = m[o + 3], m[o + 4], m[o + 5]
    f1, f2, f3 = generalized_force(m, t, q0, q1, q2, v0, v1, v2, 0.0)
    a0 = solved_accelerations(m, s1, c1, s2, c2, s3, c3, su, cu, v0, v1, v2, f1, f2, f3)[0]
    m_eff = linkage_inertia_at(m[4], m[5], m[6], m[0], m[1], m[2], m[3], s1, c1, s2, c2, s3, c3, cu)
    c = m[o + 1] if m[o] == DRIVE else m[o + 2]
    reflected = ratio * ratio * rotor / m_eff
    if not unique(c, reflected):
        return math.nan
    return mesh_torque(c, ratio, rotor, k_t, i, a0, 1.0 / m_eff)


@njit(**JIT)
def driven_accelerations(m, t, q0, q1, q2, v0, v1, v2, u):
    """q'' (rad/s²) under the voltage u (V) in the mesh mode of the model's drive block:
    `DrivenSystem.accelerations`. Zero when stuck; NaN where the flank is not unique (the
    Simulator's non-finite check then stops the run)."""
    o = m.shape[0] - BLOCK
    if m[o] == STUCK:
        return 0.0, 0.0, 0.0
    s1, c1, s2, c2, s3, c3, su, cu = _trig(m, q0, q1, q2)
    tau_g = _mesh_torque(m, o, t, q0, q1, q2, v0, v1, v2, u, s1, c1, s2, c2, s3, c3, su, cu)
    f1, f2, f3 = generalized_force(m, t, q0, q1, q2, v0, v1, v2, tau_g)
    return solved_accelerations(m, s1, c1, s2, c2, s3, c3, su, cu, v0, v1, v2, f1, f2, f3)


@njit(**JIT)
def current_margin(m, o, u, v0):
    """i_max − |unclamped current| (A) under u (V) at θ1' = v0: the limit guard (< 0 while the limit acts)."""
    return m[o + 8] - abs(unclamped_current(u, m[o + 3] * v0, m[o + 6], m[o + 5], m[o + 7]))


@njit(**JIT)
def drive_guards(m, t, q0, q1, q2, v0, v1, v2, u, direction):
    """(turn, flank, limit) of the rolling mesh: `actuators.stepping._guards`, compiled."""
    o = m.shape[0] - BLOCK
    limit = current_margin(m, o, u, v0)
    if m[o + 1] == 1.0 and m[o + 2] == 1.0:  # an ideal gear: no modes
        return math.inf, math.inf, limit
    s1, c1, s2, c2, s3, c3, su, cu = _trig(m, q0, q1, q2)
    tau_g = _mesh_torque(m, o, t, q0, q1, q2, v0, v1, v2, u, s1, c1, s2, c2, s3, c3, su, cu)
    s = direction
    return s * v0, (s if m[o] == DRIVE else -s) * tau_g, limit


def _rebound(dispatcher: Any, **names: Callable) -> Any:
    """numerics' compiled function `dispatcher` compiled again with some of its globals rebound
    (`names`), under its own name (numba's disk cache keys on the name: no clash with the original)."""
    py = dispatcher.py_func
    name = "driven_" + py.__name__
    code = py.__code__.replace(co_name=name, co_qualname=name)
    function = types.FunctionType(code, {**vars(numerics), **names}, name, py.__defaults__, py.__closure__)
    function.__qualname__, function.__doc__ = name, f"{py.__doc__} With the drive (`driven_accelerations`)."
    return njit(**JIT)(function)


driven_euler_step = _rebound(numerics.euler_step, accelerations=driven_accelerations)
driven_rk_step = _rebound(numerics.rk_step, accelerations=driven_accelerations)
driven_rk_step_tuple = _rebound(numerics.rk_step_tuple, euler_step=driven_euler_step, rk_step=driven_rk_step)
driven_profile_step = _rebound(numerics._profile_step, euler_step=driven_euler_step, rk_step=driven_rk_step)


@njit(**JIT)
def driven_fast_step(plan, prof, held, k, q, v, direction):
    """`numerics.fast_step` of a drive scene while its mesh rolls (drive or back) through the whole
    step: (status, q, v, u at the step's end). A step that starts stuck, or in which a guard crosses
    (`actuators.stepping._first_event`'s tests on the same values), is not done: status BREAKPOINT,
    state unchanged, and `Simulator.step` takes it in Python, where the events are located.
    direction: the sign of θ1' the rolling mode was entered with (`Drive.direction`)."""
    dt, m, tab = plan_parts(plan)
    o = m.shape[0] - BLOCK
    if m[o] == STUCK:
        return BREAKPOINT, q, v, 0.0
    x = np.empty(6)
    x[0], x[1], x[2], x[3], x[4], x[5] = q[0], q[1], q[2], v[0], v[1], v[2]
    s = tab.shape[1]
    status, end = driven_profile_step(m, tab, prof, held, k, dt, x, np.empty((max(s, 1), 6)), np.empty(max(s, 1)))
    if status != OK:
        return status, (x[0], x[1], x[2]), (x[3], x[4], x[5]), end
    code = int(prof[0])
    # the input at the step's start as the Python path sees it: a switching profile's value on the segment
    start = end if code == STEP or code == SQUARE else torque_at(prof, held, k * dt)
    turn, flank, limit = drive_guards(m, (k + 1) * dt, x[0], x[1], x[2], x[3], x[4], x[5], end, direction)
    if turn < -GUARD_TOLERANCE or flank < -GUARD_TOLERANCE or (current_margin(m, o, start, v[0]) < 0.0) != (limit < 0.0):
        return BREAKPOINT, q, v, 0.0
    return OK, (x[0], x[1], x[2]), (x[3], x[4], x[5]), end


class DrivenFastStepper:
    """The Simulator's lean path for a drive scene without gaps (no stops, no contact): one kernel
    call per step (`driven_fast_step`) while the mesh rolls; the steps with a mode change, a stuck
    mesh or an energy ledger to fill go through `actuators.stepping`. Same numbers, bit for bit.

    The interface `Simulator.step` calls: `call(plan, profile, held, k, q, v)`, `plan`, `profile`, `fail`."""

    fail = FastStepper.fail

    def __init__(self, integrator: CompiledRungeKutta, dt: float, profile: Profile, drive: law.Drive) -> None:
        self.method, self.dt, self._drive = integrator.name, dt, drive
        self.plan = integrator.step_plan(dt)
        #: the plan's model, a view: the drive keeps its mode slot current (`Drive.mirror`)
        self._model = self.plan[4: 4 + len(integrator.model)]
        drive.mirror(self._model)
        #: the scene profile's compiled form; None: it has none, steps under it go through Python
        self.profile = profile_array(profile)
        args = (self.plan, HELD_ARRAY, 0.0, 0, WARM_UP_STATE, WARM_UP_STATE, 1.0)
        driven_fast_step(*args)  # load (or compile) it now, not in the first paced step
        self._entry = _entry_point(driven_fast_step, args)

    def call(self, plan: np.ndarray, prof: np.ndarray, held: float, k: int, q, v):  # type: ignore[no-untyped-def]
        """`driven_fast_step` under the drive's current direction; BREAKPOINT while a ledger is kept."""
        drive = self._drive
        if drive.ledger is not None:
            return BREAKPOINT, q, v, 0.0
        return self._entry(plan, prof, held, k, q, v, drive.direction)


driven_rhs = _rebound(numerics._rhs, accelerations=driven_accelerations)
driven_dop853_attempt = _rebound(numerics.dop853_attempt, _rhs=driven_rhs)


def _no_internal_steps() -> None:
    """DOP853's internal steps with the drive go one by one: `kernel.internal_steps` is compiled with numerics'
    right-hand side."""
    return None


#: The stepping functions of a system with the drive (`kernel.ACTUATOR_STAGES`).
STAGES = StageFunctions(driven_rhs, driven_dop853_attempt, driven_rk_step_tuple, _no_internal_steps)


# -- L > 0: the current as a seventh state (`finger_sim.actuators.inductive`) ------------------
@njit(**JIT)
def inductive_rates(m, t, q0, q1, q2, v0, v1, v2, u, i):
    """(q'' rad/s², i' A/s) at the current i (A) under u (V) in the mesh mode of the model's drive
    block: `DrivenSystem.mesh(..., current=i)` and `Drive.current_rate`."""
    o = m.shape[0] - BLOCK
    di = current_rate(u, i, m[o + 3] * v0, m[o + 6], m[o + 5], m[o + 9], m[o + 7], m[o + 8])
    if m[o] == STUCK:
        return 0.0, 0.0, 0.0, di
    s1, c1, s2, c2, s3, c3, su, cu = _trig(m, q0, q1, q2)
    tau_g = _mesh_torque_at(m, o, t, q0, q1, q2, v0, v1, v2, i, s1, c1, s2, c2, s3, c3, su, cu)
    f1, f2, f3 = generalized_force(m, t, q0, q1, q2, v0, v1, v2, tau_g)
    a0, a1, a2 = solved_accelerations(m, s1, c1, s2, c2, s3, c3, su, cu, v0, v1, v2, f1, f2, f3)
    return a0, a1, a2, di


#: `numerics.rk_step` on x = (q, q', i) in place (`integrators.stateful.StatefulRungeKutta._substep`): the
#: same template of the stage loop (`kernel.rk_template`) with `inductive_rates`. Status.
inductive_rk_step = compiled(rk_steps.inductive_rk_step, options=JIT, inductive_rates=inductive_rates,
                             project=project)


@njit(**JIT)
def inductive_step_tuple(m, tab, t, q, v, i, h, n, taus):
    """n substeps of h/n of `inductive_rk_step` from (q, q', i) at t; taus[k]: the input (V) at the
    distinct nodes of substep k. Returns (status, q, q', i)."""
    x = np.empty(7)
    x[0], x[1], x[2], x[3], x[4], x[5], x[6] = q[0], q[1], q[2], v[0], v[1], v[2], i
    k = np.empty((tab.shape[1], 7))
    sub = h / n
    status = OK
    for j in range(n):
        status = inductive_rk_step(m, tab, t + j * sub, x, sub, taus[j], k)
        if status != OK:
            break
    return status, (x[0], x[1], x[2]), (x[3], x[4], x[5]), x[6]


# -- L > 0, the lean step: one kernel call per rolling step (`kernel.inductive.InductiveFastStepper`) ----
current_limit_guard = njit(**JIT)(law.current_limit_guard)


@njit(**JIT)
def inductive_guards(m, t, q0, q1, q2, v0, v1, v2, i, u, direction):
    """(turn, flank, limit) of the rolling mesh at the winding current i (A) under u (V):
    `inductive_stepping._guards` without stick–slip friction, compiled. NaN where the flank is not unique."""
    o = m.shape[0] - BLOCK
    limit = current_limit_guard(u, i, m[o + 3] * v0, m[o + 6], m[o + 5], m[o + 7], m[o + 8])
    if m[o + 1] == 1.0 and m[o + 2] == 1.0:  # an ideal gear: no flanks, and no turn without friction
        return math.inf, math.inf, limit
    s1, c1, s2, c2, s3, c3, su, cu = _trig(m, q0, q1, q2)
    tau_g = _mesh_torque_at(m, o, t, q0, q1, q2, v0, v1, v2, i, s1, c1, s2, c2, s3, c3, su, cu)
    s = direction
    return s * v0, (s if m[o] == DRIVE else -s) * tau_g, limit


@njit(**JIT)
def substep_inputs(prof, held, tab, t, h, n):
    """The input (V) at each distinct node of each of n substeps of h/n from t (s), n × nodes: what
    `CompiledInductiveRungeKutta.advance_state` evaluates in Python, here from the profile's flat encoding."""
    s = tab.shape[1]
    nodes = 0
    for r in range(s):
        nodes = max(nodes, int(tab[s + 2, r]) + 1)
    taus = np.empty((n, nodes))
    sub = h / n
    for j in range(n):
        tk = t + j * sub
        for r in range(s):
            taus[j, int(tab[s + 2, r])] = torque_at(prof, held, tk + tab[s + 1, r] * sub)
    return taus


@njit(**JIT)
def inductive_profile_step(m, tab, t, q, v, i, h, n, prof, held):
    """`inductive_step_tuple` with the input from a profile's flat encoding (`substep_inputs`)."""
    return inductive_step_tuple(m, tab, t, q, v, i, h, n, substep_inputs(prof, held, tab, t, h, n))


@njit(**JIT)
def inductive_fast_step(plan, prof, held, k, q, v, i, direction, n):
    """`Simulator.step` k of an inductive drive scene without gaps while its mesh rolls through the whole
    step, in one call: the input at every substep node, n substeps of `inductive_rk_step` (the integrator's
    `advance_state`) and the guards of `inductive_stepping._first_event` at both ends, on the same values.
    Returns (status, q, q', i at the end (A), u at the end (V)). A step that starts stuck, holds a switch
    of the input, crosses a guard (turn, flank, the current limit starting or ending) or leaves a
    non-finite value is not done: status BREAKPOINT, state unchanged, and the Python event loop takes it
    (locating the event there, and setting i = ±i_max exactly where the limit starts to act)."""
    dt, m, tab = plan_parts(plan)
    o = m.shape[0] - BLOCK
    if m[o] == STUCK:
        return BREAKPOINT, q, v, i, 0.0
    t0, t1 = k * dt, (k + 1) * dt
    code = int(prof[0])
    if code == STEP or code == SQUARE:  # `on_segment`: the level of a segment without a switch
        if switches_inside(prof, t0, t1, BREAK_EPS * dt):
            return BREAKPOINT, q, v, i, 0.0
        start = end = torque_at(prof, held, 0.5 * (t0 + t1))
        taus = substep_inputs(HELD_ARRAY, start, tab, t0, t1 - t0, n)
    else:
        start, end = torque_at(prof, held, t0), torque_at(prof, held, t1)
        taus = substep_inputs(prof, held, tab, t0, t1 - t0, n)
    status, q1, v1, i1 = inductive_step_tuple(m, tab, t0, q, v, i, t1 - t0, n, taus)
    if status != OK or not math.isfinite(q1[0] + q1[1] + q1[2] + v1[0] + v1[1] + v1[2] + i1):
        return BREAKPOINT, q, v, i, 0.0
    g0 = inductive_guards(m, t0, q[0], q[1], q[2], v[0], v[1], v[2], i, start, direction)
    g1 = inductive_guards(m, t1, q1[0], q1[1], q1[2], v1[0], v1[1], v1[2], i1, end, direction)
    if math.isnan(g0[2] + g1[0] + g1[1] + g1[2]):  # a flank that is not unique: the Python path says so
        return BREAKPOINT, q, v, i, 0.0
    if g1[0] < -GUARD_TOLERANCE or g1[1] < -GUARD_TOLERANCE or (g0[2] < 0.0) != (g1[2] < 0.0):
        return BREAKPOINT, q, v, i, 0.0
    return OK, q1, v1, i1, end
