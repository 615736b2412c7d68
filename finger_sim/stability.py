"""Linear stability of a method on a scene: the fastest mode against dt.

The finger has one degree of freedom; along the null-space direction n of Φ_q
(n = g₁ × g₂) its linearization is I s² + C s + K = 0 with I = nᵀMn and (K, C) summed
over the force elements' `modal(q, n)` (the spring's stiffness, the dampers' damping). A method is stable at dt when
both roots s·dt lie in its stability region; this is checked over the reachable range.
"""

from __future__ import annotations

import cmath
import math
from typing import TYPE_CHECKING

from finger_sim import kinematics, stepper_slot
from finger_sim.dynamics import FingerSystem
from finger_sim.integrators.base import Integrator
from finger_sim.kinematics import Vec3

if TYPE_CHECKING:
    from finger_sim.scene import Scene

#: Poses sampled across the reachable MCP range when looking for the stiffest one.
SAMPLES = 33
#: Stay this far (rad) from the toggles, where the θ1-parametrized assembly is singular.
TOGGLE_MARGIN = 1e-3
#: On a scene with contact, a method with a bounded stability region must also resolve the
#: fastest mode: |s|·dt ≤ this (≥ 2π steps per period), not only hold it inside its region.
#: The contact mode lasts about half a period per impact and stiffens with the force
#: (ω ∝ F^((e−1)/(2e)), above the design force the check sees): dop8, stable up to |s|·dt ≈ 6,
#: passed the plain check on grasp_rigid at 1 ms (|s|·dt = 4.5) and ran 1.7e-2 rad off the
#: tight reference; at |s|·dt ≤ 1, rk4 follows grasp_impact to 8e-5 rad.
CONTACT_RESOLUTION = 1.0
#: A mode this far out in the left half-plane (|s|·dt) is stable only for a method with an
#: unbounded stability region (radau, or an adaptive method that sizes its own steps).
FAR_MODE = -1e6


def modal_roots(system: FingerSystem, q: Vec3) -> tuple[complex, complex]:
    """Roots s (1/s) of I s² + C s + K = 0 for the 1-DOF linearization at q."""
    g1, g2 = system.constraint_jacobian(q)
    n = (g1[1] * g2[2] - g1[2] * g2[1], g1[2] * g2[0] - g1[0] * g2[2], g1[0] * g2[1] - g1[1] * g2[0])
    m = system.mass_matrix(q)
    inertia = sum(n[i] * m[i][j] * n[j] for i in range(3) for j in range(3))
    stiffness, damping = 0.0, 0.0
    for element in system.elements:
        k, c = element.modal(q, n)
        stiffness += k
        damping += c
    disc = cmath.sqrt(damping * damping - 4.0 * inertia * stiffness)
    return ((-damping + disc) / (2.0 * inertia), (-damping - disc) / (2.0 * inertia))


def mcp_range(scene: Scene) -> tuple[float, float]:
    """The MCP interval the finger can reach, rad: its stops if it has them, else the assemblable
    range (the two toggles). The one range the stability check and `auto` sample."""
    return scene.mcp_limits or kinematics.assembly_range(scene.params)


#: Fastest modes kept by model (`_mode_key`): the method choice and the stability check of one
#: Simulator ask for the same one, and a sweep asks again for every run of the same finger.
MODE_CACHE_SIZE = 4096
_MODES: dict[tuple, complex] = {}


def _mode_key(system: FingerSystem, theta1_range: tuple[float, float]) -> tuple | None:
    """The system as numbers (parameters and the compiled kernel's flat model of its elements,
    which is all its dynamics), and the range; None when an element has no flat form."""
    model = stepper_slot.kernel().model_array(system)
    return None if model is None else (system.params, model.tobytes(), tuple(theta1_range))


def fastest_mode(system: FingerSystem, theta1_range: tuple[float, float]) -> complex:
    """The modal root of largest magnitude over poses θ1 in theta1_range (rad, e.g. `mcp_range`), 1/s.
    Kept per model (`_mode_key`): the same finger asked again costs a look-up."""
    key = _mode_key(system, theta1_range)
    if key is not None and key in _MODES:
        return _MODES[key]
    root = _fastest_mode(system, theta1_range)
    if key is not None:
        if len(_MODES) >= MODE_CACHE_SIZE:
            _MODES.pop(next(iter(_MODES)))  # the oldest
        _MODES[key] = root
    return root


def _fastest_mode(system: FingerSystem, theta1_range: tuple[float, float]) -> complex:
    lo, hi = kinematics.assembly_range(system.params)
    lo, hi = max(theta1_range[0], lo + TOGGLE_MARGIN), min(theta1_range[1], hi - TOGGLE_MARGIN)
    worst = 0j
    for i in range(SAMPLES):
        q = kinematics.assemble(system.params, lo + (hi - lo) * i / (SAMPLES - 1))
        if inside_object(system, q):
            continue
        for s in modal_roots(system, q):
            if abs(s) > abs(worst):
                worst = s
    return worst


def inside_object(system: FingerSystem, q: Vec3) -> bool:
    """Whether a phalanx overlaps an object at q (a kink gap, e.g. contact, is closed).

    `fastest_mode` skips such poses: the finger stops at an object's surface, so a pose deep
    inside it (the sampled range passes through every object) is never reached, and its contact
    mode (k_c e δ^(e−1) at δ of centimetres, or Hunt–Crossley damping at kilonewtons) is not the
    run's. The contact element shows its mode at the open poses through its design-force floor.
    """
    return any(g < 0.0 and e.impact(i) is None for e in system.elements if not e.smooth for i, g in enumerate(e.gaps(q)))


def has_contact(system: FingerSystem, q: Vec3) -> bool:
    """Whether the system has kink gaps (contact: a mode that exists only while a gap is closed)."""
    return any(e.impact(i) is None for e in system.elements if not e.smooth for i in range(len(e.gaps(q))))


def stable_at(method: type[Integrator], root: complex, dt: float, contact: bool = False) -> bool:
    """Whether `method` is stable on a mode with root s at step dt (checks s and its conjugate);
    with `contact`, a method with a bounded stability region must also resolve it
    (|s|·dt ≤ CONTACT_RESOLUTION)."""
    if contact and not method.is_stable(complex(FAR_MODE)) and abs(root) * dt > CONTACT_RESOLUTION:
        return False
    return method.is_stable(root * dt) and method.is_stable(root.conjugate() * dt)


def largest_stable_dt(method: type[Integrator], root: complex, dt: float, contact: bool = False) -> float:
    """The largest step ≤ dt at which `method` is stable on the mode (bisection), s; `contact` as in `stable_at`."""
    if stable_at(method, root, dt, contact):
        return dt
    lo, hi = 0.0, dt
    for _ in range(60):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if stable_at(method, root, mid, contact) else (lo, mid)
    return lo if lo > 0 else math.nan
