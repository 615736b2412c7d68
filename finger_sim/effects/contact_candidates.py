"""The contact's candidate loop, written once: which points of the phalanges meet which object
surfaces, in what order, and which are skipped.

The candidates sit in a flat parameter block (`Contact.kernel_params`): a header (r1, L3, α, k, e, d,
μ, v_s, then the count of each kind), then each candidate's floats, kind by kind in this order:

- a circle and the proximal phalanx: (cx, cy, ρ1 + R);
- a circle and the distal phalanx: (cx, cy, ρ3 + R, reach²), reach = L3 + ρ3 + R (m);
- a plane and the joint B: (ox, oy, nx, ny, ρ), one per phalanx radius;
- a plane and the fingertip: (ox, oy, nx, ny, ρ3, reach), reach = L3 + ρ3 (m).

`walk_candidates` evaluates them in that order (their geometry: `effects.contact_law`) and hands each to
`_visit(acc, ctx, i, geometry)`, which returns the new acc. `Contact` calls it as it is (its `_visit`
is `collect_hit`); the compiled kernel compiles it with its own visitors bound under that name (the
force sum, the gaps, the gaps with their rates and the grip force: `kernel.jit.compiled`), so the
loop is written once. A moving object is a candidate wherever it is: its reach is infinite.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

from finger_sim.effects.contact_law import Geometry, distal_circle, joint_plane, proximal_circle, tip_plane

#: The candidate kinds, in the loop's order, and the floats each takes in the block.
PROXIMAL_CIRCLE, DISTAL_CIRCLE, JOINT_PLANE, TIP_PLANE = range(4)
RECORD_SIZE = (3, 4, 5, 6)
#: Where the four counts start in the block's header, and where the candidates start.
COUNTS = 8
HEADER = COUNTS + 4


def collect_hit(acc: list, ctx: tuple, i: int, geometry: Geometry) -> list:  # type: ignore[type-arg]
    """Appends (*owners[i], *geometry) of candidate number i to acc where δ > 0, or always when `every`;
    ctx = (every, owners), owners[i] what names candidate i (`Contact`: its phalanx and object index)."""
    every, owners = ctx
    if geometry[0] > 0.0 or every:
        acc.append((*owners[i], *geometry))
    return acc


_visit = collect_hit


def walk_candidates(p: Sequence[float], o: int, q0: float, q2: float, every: bool, acc, ctx):  # type: ignore[no-untyped-def]
    """Every candidate of the block p[o:] at θ1 = q0, θ3 = q2 (rad), in order, through
    `_visit(acc, ctx, i, geometry)` (i: the candidate's number, from 0); returns the last acc.

    Unless `every`, a distal candidate that cannot touch is skipped (not visited) by a cheap bound, the
    distal segment lying within L3 of B, before the distal direction e(ψ) is evaluated.
    """
    r1, l3, alpha = p[o], p[o + 1], p[o + 2]
    c1, s1 = math.cos(q0), math.sin(q0)
    bx, by = r1 * c1, r1 * s1
    ux = uy = 0.0
    have_u = False
    size_p, size_d, size_j, size_t = RECORD_SIZE
    j = o + HEADER
    i = 0
    for _ in range(int(p[o + COUNTS + PROXIMAL_CIRCLE])):  # (cx, cy, ρ1 + R)
        acc = _visit(acc, ctx, i, proximal_circle(p[j], p[j + 1], p[j + 2], r1, bx, by, s1, c1))
        j += size_p
        i += 1
    for _ in range(int(p[o + COUNTS + DISTAL_CIRCLE])):  # (cx, cy, ρ3 + R, reach²)
        dx, dy = p[j] - bx, p[j + 1] - by
        if every or not dx * dx + dy * dy > p[j + 3]:
            if not have_u:
                psi = q2 + alpha
                ux, uy, have_u = math.cos(psi), math.sin(psi), True
            acc = _visit(acc, ctx, i, distal_circle(p[j], p[j + 1], p[j + 2], l3, bx, by, ux, uy))
        j += size_d
        i += 1
    for _ in range(int(p[o + COUNTS + JOINT_PLANE])):  # (ox, oy, nx, ny, ρ)
        acc = _visit(acc, ctx, i, joint_plane(p[j], p[j + 1], p[j + 2], p[j + 3], p[j + 4], bx, by))
        j += size_j
        i += 1
    for _ in range(int(p[o + COUNTS + TIP_PLANE])):  # (ox, oy, nx, ny, ρ3, reach)
        if every or not p[j + 2] * (bx - p[j]) + p[j + 3] * (by - p[j + 1]) - p[j + 5] >= 0.0:
            if not have_u:
                psi = q2 + alpha
                ux, uy, have_u = math.cos(psi), math.sin(psi), True
            acc = _visit(acc, ctx, i, tip_plane(p[j], p[j + 1], p[j + 2], p[j + 3], p[j + 4], l3, bx, by, ux, uy))
        j += size_t
        i += 1
    return acc
