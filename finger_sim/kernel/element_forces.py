"""The force sum's dispatch over the compiled force laws the effects declare (`effects.base.kernel_law`).

Generated from the registry by `python -m finger_sim.kernel.force_laws`: do not edit.
"""

from finger_sim.kernel.force_laws import compiled_laws
from finger_sim.kernel.jit import LAW, compiled_law, njit

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
