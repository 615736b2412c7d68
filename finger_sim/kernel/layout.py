"""The compiled kernel's data: a finger system flattened into one float64 array (no numba here).

The kernel reads the model as pure data, so one compiled function serves every scene:

    [0:10]  m11, m22, m33, c, r1, r2, r3, α, k1 = r4 cos θ4, k2 = r4 sin θ4   (SI, rad)
    [10]    number of force elements
    then per element, in the system's summation order: code, n, then its n parameters;
    with an actuator in the acceleration solve, its block last (the drive's, spec §8: `Drive.kernel_block`,
    the mode, ..., NaN as marker).

An element's compiled form is `kernel_code` (a law its effect declares, `effects.base.kernel_law`, or one
the kernel writes itself) and `kernel_params()` (floats) on the element itself (see
`finger_sim.effects.base.ForceElement`); an element without them, or whose law this process's kernel
does not compile (`force_laws.compiled_codes`), has no compiled form, and the Simulator then steps the
scene in Python.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

import numpy as np

from finger_sim.effects.base import CONTACT, DAMPING, GRAVITY, NO_FORCE, SPRING, STICK_SLIP_CONTACT, TIP_FORCE
from finger_sim.kernel.force_laws import compiled_codes
from finger_sim.projection import NON_FINITE, NOT_CONVERGED, OK
from finger_sim.stepper_slot import BREAKPOINT, STATE_NON_FINITE, STEP_TOO_SMALL

if TYPE_CHECKING:
    from finger_sim.dynamics import FingerSystem

#: Codes of the compiled force elements: the core's (`finger_sim.effects.base`), which the elements declare.
#: Length of the system header before the element count.
HEADER = 10

#: Status codes of the kernel's calls (`finger_sim.kernel.numerics`).
#: OK, NON_FINITE, NOT_CONVERGED (0, 1, 2): the projection's own (`finger_sim.projection.project_state`);
#: STEP_TOO_SMALL, BREAKPOINT, STATE_NON_FINITE (3, 4, 5): the core's (`finger_sim.stepper_slot`).


def model_array(system: "FingerSystem") -> np.ndarray | None:
    """The flat model of `system` for the kernel, or None when an element has no compiled form. The block of
    an actuator in the acceleration solve (`FingerSystem.actuator`: `kernel_block`) ends it, and its mode slot
    follows the actuator's mode (`mirror`, as `Drive.mirror`)."""
    p = system.params
    # the same expressions as FingerSystem.__init__, so the compiled solve sees the same bits
    data = [
        p.inertia_A + p.m3 * p.r1**2, p.inertia_D, p.inertia_G3 + p.m3 * p.L3**2 / 4.0,
        p.m3 * p.r1 * p.L3 / 2.0, p.r1, p.r2, p.r3, system.alpha,
        p.r4 * math.cos(p.theta4), p.r4 * math.sin(p.theta4), float(len(system.elements)),
    ]
    mirrored = []  # (element, offset of its parameters): elements whose discrete state the model follows
    for element in system.elements:
        code = getattr(element, "kernel_code", None)
        if code not in compiled_codes():
            return None
        params = [float(x) for x in element.kernel_params()]
        if hasattr(element, "mirror"):
            mirrored.append((element, len(data) + 2))
        data += [float(code), float(len(params)), *params]
    actuator = system.actuator  # one in the acceleration solve (the drive): its block last, its mode mirrored
    model = np.array(data if actuator is None else data + actuator.kernel_block(), dtype=np.float64)
    for element, offset in mirrored:  # a stick–slip contact's friction mode (`StickSlipContact.mirror`)
        element.mirror(model, offset)
    if actuator is not None:
        actuator.mirror(model)
    return model


def tableau_array(a: tuple[tuple[float, ...], ...], b: tuple[float, ...], c: tuple[float, ...]) -> np.ndarray:
    """An explicit Runge-Kutta tableau as one (s + 3) × s array: rows A, then B, then C, then
    for each stage the index of its node among the distinct nodes (`distinct_nodes`): stages
    that share a time share one torque evaluation."""
    s = len(b)
    tab = np.zeros((s + 3, s))
    for i, row in enumerate(a):
        tab[i, : len(row)] = row
    nodes = distinct_nodes(c)
    tab[s], tab[s + 1], tab[s + 2] = b, c, [nodes.index(x) for x in c]
    return tab


def distinct_nodes(c: tuple[float, ...]) -> tuple[float, ...]:
    """The distinct stage nodes of a tableau, in order of first use: where τ is evaluated."""
    return tuple(dict.fromkeys(float(x) for x in c))
