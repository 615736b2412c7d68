"""An explicit method's step as a plain function: one DOP853 attempt, written once, run by both paths.

The Python path calls it as it is, on lists (the state y = (q, q'), the stages, the coefficients), with m
a `StageModel` and the `rhs` below; the compiled kernel compiles this same function (`kernel.numerics`,
numba `njit`) with m its flat model array and its own `_rhs` bound under that name, so both paths take
the same floating-point operations in the same order. Indexing is `a[i][j]`, so the same code reads
nested lists and 2-D arrays; a scratch state is `y.copy()`, a list or an array as y is.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from collections.abc import MutableSequence, Sequence

    from finger_sim.dynamics import FingerSystem

#: Weight of the 3rd-order estimate in DOP853's error combination |e5|²/√(|e5|² + w|e3|²) (scipy's).
E3_WEIGHT = 0.01
#: DOP853's stages of a step (its 13th evaluation, at t + h, is the next step's first; 3 more for dense output).
DOP853_STAGES = 12


@dataclass(frozen=True)
class StageModel:
    """The Python path's model m of a step: the system whose state y = (q, q') it advances."""

    system: FingerSystem


def rhs(m: StageModel, t: float, y: Sequence[float], u: float, out: MutableSequence[float]) -> None:
    """y' = (q', q'') at (t, y) under the torque u (N·m) into out: `FingerSystem.accelerations`. The steps
    call it as `_rhs`, the name under which the kernel binds its own (`numerics._rhs`)."""
    q, v = (y[0], y[1], y[2]), (y[3], y[4], y[5])
    out[0], out[1], out[2] = v
    out[3], out[4], out[5] = m.system.accelerations(t, q, v, u)[0]


_rhs = rhs


def dop853_attempt(m, a, b, c, e3, e5, d, t, y, f, h, taus, rtol, atol, kk, y_new, dense):  # type: ignore[no-untyped-def]
    """One DOP853 step attempt from (t, y) with y' = f at t, step h (s): scipy's `rk_step` and
    `_estimate_error_norm`, then on acceptance the three extra stages and the dense coefficients
    (`_dense_output_impl`). `DormandPrince853._advance` (in Python) and the kernel's loops call it.

    a (16 × 16), b (12), c (16), e3, e5 (13), d (4 × 16): scipy's dop853_coefficients.
    taus: the input at t + c_i h for the 12 stages, then at t + h, then at the 3 extra stages.
    kk: 16 rows of len(y), the stages (kk[0] = f on return); y_new: the result; dense: 7 rows.
    Returns the error norm (accepted when < 1)."""
    n = len(y)
    kk0 = kk[0]
    for i in range(n):
        kk0[i] = f[i]
    ys = y.copy()  # a stage's state
    for s in range(1, DOP853_STAGES):
        _stage_state(a[s], s, y, h, kk, ys)
        _rhs(m, t + c[s] * h, ys, taus[s], kk[s])
    for i in range(n):
        acc = 0.0
        for j in range(DOP853_STAGES):
            acc += kk[j][i] * b[j]
        y_new[i] = y[i] + h * acc
    _rhs(m, t + h, y_new, taus[DOP853_STAGES], kk[DOP853_STAGES])
    err5 = 0.0
    err3 = 0.0
    for i in range(n):
        scale = atol + max(abs(y[i]), abs(y_new[i])) * rtol
        s5 = 0.0
        s3 = 0.0
        for j in range(DOP853_STAGES + 1):
            s5 += kk[j][i] * e5[j]
            s3 += kk[j][i] * e3[j]
        err5 += (s5 / scale) ** 2
        err3 += (s3 / scale) ** 2
    if err5 == 0.0 and err3 == 0.0:
        norm = 0.0
    else:
        norm = abs(h) * err5 / math.sqrt((err5 + E3_WEIGHT * err3) * n)
    if norm < 1.0:
        for s in range(DOP853_STAGES + 1, 16):
            _stage_state(a[s], s, y, h, kk, ys)
            _rhs(m, t + c[s] * h, ys, taus[s], kk[s])
        last = kk[DOP853_STAGES]
        for i in range(n):
            dy = y_new[i] - y[i]
            dense[0][i] = dy
            dense[1][i] = h * kk0[i] - dy
            dense[2][i] = 2.0 * dy - h * (last[i] + kk0[i])
            for r in range(4):
                acc = 0.0
                dr = d[r]
                for j in range(16):
                    acc += dr[j] * kk[j][i]
                dense[3 + r][i] = h * acc
    return norm


def _stage_state(row, s, y, h, kk, out):  # type: ignore[no-untyped-def]
    """out = y + h Σ_{j<s} row[j] kk[j] (row: the stage's row of A), each sum in order of j."""
    for i in range(len(y)):
        acc = 0.0
        for j in range(s):
            acc += kk[j][i] * row[j]
        out[i] = y[i] + acc * h
