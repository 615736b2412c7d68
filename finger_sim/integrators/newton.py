"""Newton plumbing shared by the implicit methods (radau, rattle): a forward-difference
Jacobian and the simplified Newton iteration on its LU factors.

Hairer & Wanner, *Solving ODEs II*, §IV.8: the Jacobian is evaluated once per step (or
kept from an earlier one) and factored once; the iteration reuses the factors.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from typing import TypeVar

import numpy as np
from scipy.linalg import lu_factor, lu_solve

#: Relative finite-difference step for the Jacobian: ~ sqrt(machine epsilon).
FD_STEP = 1.5e-8

#: A residual or function of a vector of unknowns (lists in, anything array-like out).
VectorFn = Callable[[list[float]], Sequence[float] | np.ndarray]
#: Newton's unknowns: a list of floats or a float array.
Unknowns = TypeVar("Unknowns", list[float], np.ndarray)
#: LU factors as scipy's lu_factor returns them.
LU = tuple[np.ndarray, np.ndarray]


def forward_jacobian(fun: VectorFn, x: list[float], scale: Sequence[float], f0: np.ndarray | None = None) -> np.ndarray:
    """∂fun/∂x by forward differences, column j stepped by FD_STEP·max(|x_j|, scale_j).

    scale: the size of each unknown below which its step stops shrinking (its typical
    magnitude); f0: fun(x) if the caller has it already.
    """
    r0 = np.array(fun(x)) if f0 is None else f0
    jac = np.empty((len(r0), len(x)))
    for j in range(len(x)):
        dxj = FD_STEP * max(abs(x[j]), scale[j])
        xp = list(x)
        xp[j] += dxj
        jac[:, j] = (np.array(fun(xp)) - r0) / dxj
    return jac


def factor(jac: np.ndarray) -> LU:
    """LU factors of a Newton matrix."""
    return lu_factor(jac, check_finite=False)


def simplified_newton(residual: Callable[[Unknowns], Sequence[float] | np.ndarray], x: Unknowns, lu: LU,
                      scale: np.ndarray, tolerance: float, max_iterations: int, *,
                      stop_when_growing: bool = False) -> Unknowns | None:
    """Solve residual(x) = 0 by x ← x − J⁻¹ residual(x) with fixed factors `lu`.

    x: a list (small systems of scalar code: stays a list of floats) or an array (stays one).

    Converged when every update scaled by `scale` is below `tolerance`; None when it is not
    after max_iterations, when an update is non-finite, or (stop_when_growing) when the
    scaled update grows (the iteration diverges: the caller shortens its step).
    """
    previous = math.inf
    for _ in range(max_iterations):
        dx = lu_solve(lu, -np.array(residual(x)), check_finite=False)
        x = x + dx if isinstance(x, np.ndarray) else [a + b for a, b in zip(x, dx.tolist())]
        size = float(np.max(np.abs(dx) / scale))
        if not math.isfinite(size) or (stop_when_growing and size > previous):
            return None
        if size < tolerance:
            return x
        previous = size
    return None
