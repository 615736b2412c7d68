"""The force sum's dispatch over the compiled force laws the effects declare (`effects.base.kernel_law`).

Generated from the registry by `python -m finger_sim.kernel.force_laws`: do not edit.
"""

import math

from finger_sim.kernel.force_laws import compiled_laws
from finger_sim.kernel.jit import JIT, LAW, compiled_law, njit

_LAWS = {law.code: law for law in compiled_laws()}
law_1 = compiled_law(_LAWS[1])  # finger_sim.effects.spring.spring_force
law_2 = compiled_law(_LAWS[2])  # finger_sim.effects.damping.damping_force
law_3 = compiled_law(_LAWS[3])  # finger_sim.effects.gravity.gravity_force
law_4 = compiled_law(_LAWS[4])  # finger_sim.effects.tip_force.tip_force


@njit(**LAW)
def element_force(code, m, o, t, q0, q1, q2, v0, v1, v2):
    """Q (N·m) of an element whose law is `code`, its parameters at m[o:]; (0, 0, 0) for any other code."""
    if code == 1:
        return law_1(m[o], m[o + 1], q0, q2)
    if code == 2:
        return law_2(m[o], v0, v1, v2)
    if code == 3:
        return law_3(m[o], m[o + 1], m[o + 2], m[o + 3], m[o + 4], m[o + 5], q0, q1, q2)
    if code == 4:
        return law_4(m[o], m[o + 1], m[o + 2], m[o + 3], m[o + 4], q0, q2)
    return 0.0, 0.0, 0.0


#: The laws `tile_element_force` writes out for the rollout's lock-step tiles (`rollout_loop.run_lockstep`).
TILE_CODES = (1, 2, 3, 4)


@njit(**JIT)
def tile_element_force(code, m, o, y, force, n):
    """Adds Q (N·m) of an element whose law is `code` to force (3 × n) for each of n fingers, its
    parameters at m[o:] (a column a finger), the stage state y (q, q': 6 × n): the law's own statements
    over one finger at a time, written into the loop (`tile_statements`); (0, 0, 0) for any other code,
    added as `numerics.generalized_force` adds it."""
    if code == 1:
        for f in range(n):
            stiffness, alpha = m[o, f], m[o + 1, f]
            t1, t3 = y[0, f], y[2, f]
            kb = stiffness * (t3 + alpha - t1)
            force[0, f] += kb
            force[1, f] += 0.0
            force[2, f] += -kb
        return
    if code == 2:
        for f in range(n):
            c = m[o, f]
            w1, w2, w3 = y[3, f], y[4, f], y[5, f]
            beta_dot = w3 - w1
            force[0, f] += -c * w1 + c * beta_dot
            force[1, f] += -c * w2
            force[2, f] += -c * beta_dot
        return
    if code == 3:
        for f in range(n):
            gx, gy, w1, w2, w3, alpha = m[o, f], m[o + 1, f], m[o + 2, f], m[o + 3, f], m[o + 4, f], m[o + 5, f]
            t1, t2, t3 = y[0, f], y[1, f], y[2, f]
            psi = t3 + alpha
            force[0, f] += w1 * (-math.sin(t1) * gx + math.cos(t1) * gy)
            force[1, f] += w2 * (-math.sin(t2) * gx + math.cos(t2) * gy)
            force[2, f] += w3 * (-math.sin(psi) * gx + math.cos(psi) * gy)
        return
    if code == 4:
        for f in range(n):
            fx, fy, r1, l3, alpha = m[o, f], m[o + 1, f], m[o + 2, f], m[o + 3, f], m[o + 4, f]
            t1, t3 = y[0, f], y[2, f]
            psi = t3 + alpha
            force[0, f] += r1 * (-math.sin(t1) * fx + math.cos(t1) * fy)
            force[1, f] += 0.0
            force[2, f] += l3 * (-math.sin(psi) * fx + math.cos(psi) * fy)
        return
    for f in range(n):
        force[0, f] += 0.0
        force[1, f] += 0.0
        force[2, f] += 0.0
