"""The drive (spec §8) in the compiled kernel: its law and the integrator steps that apply it.

The law is compiled from its one definition (`finger_sim.actuators.drive`'s plain functions). The
step functions are numerics' own (`euler_step`, `rk_step`, `rk_step_tuple`) compiled a second time
with `accelerations` bound to `driven_accelerations`: the same code object under other globals,
so nothing is copied, and a scene without a drive compiles and runs exactly what it did before.
The drive's block ends the model (`Drive.kernel_block`; its first slot is the mesh mode, kept
current by `Drive.mirror`).
"""

from __future__ import annotations

import math
import types
from collections.abc import Callable
from typing import Any

from finger_sim.actuators import drive as law
from finger_sim.kernel import numerics
from finger_sim.kernel.numerics import JIT, accelerations, njit

motor_current = njit(**JIT)(law.motor_current)
unclamped_current = njit(**JIT)(law.unclamped_current)
mesh_torque = njit(**JIT)(law.mesh_torque)
linkage_inertia = njit(**JIT)(law.linkage_inertia)
unique = njit(**JIT)(law.unique)
BLOCK = law.KERNEL_BLOCK
DRIVE, STUCK = law.DRIVE, law.STUCK


@njit(**JIT)
def _mesh_torque(m, o, t, q0, q1, q2, v0, v1, v2, u):
    """τ_g (N·m) of the rolling mesh in the mode m[o] (`DrivenSystem.mesh`); NaN where not unique."""
    ratio, rotor, k_t = m[o + 3], m[o + 4], m[o + 5]
    i = motor_current(u, ratio * v0, m[o + 6], k_t, m[o + 7], m[o + 8])
    a0 = accelerations(m, t, q0, q1, q2, v0, v1, v2, 0.0)[0]
    m_eff = linkage_inertia(m[4], m[5], m[6], m[0], m[1], m[2], m[3], m[7], q0, q1, q2)
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
    return accelerations(m, t, q0, q1, q2, v0, v1, v2, _mesh_torque(m, o, t, q0, q1, q2, v0, v1, v2, u))


@njit(**JIT)
def drive_guards(m, t, q0, q1, q2, v0, v1, v2, u, direction):
    """(turn, flank, limit) of the rolling mesh: `actuators.stepping._guards`, compiled."""
    o = m.shape[0] - BLOCK
    limit = m[o + 8] - abs(unclamped_current(u, m[o + 3] * v0, m[o + 6], m[o + 5], m[o + 7]))
    if m[o + 1] == 1.0 and m[o + 2] == 1.0:  # an ideal gear: no modes
        return math.inf, math.inf, limit
    tau_g = _mesh_torque(m, o, t, q0, q1, q2, v0, v1, v2, u)
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
