"""`kernel.vector_trig.sincos_row` against sine and cosine summed in 60-digit decimal arithmetic."""

from __future__ import annotations

import ctypes.util
import decimal
from pathlib import Path

import numpy as np
import pytest

numba = pytest.importorskip("numba")
from finger_sim.kernel.vector_trig import LANES, sincos_row  # noqa: E402

#: glibc's manual bounds libmvec's sin and cos by 4 ulp (libm's scalar ones by 1).
MAX_ULP = 4
DIGITS = 60  # enough for Taylor sums of |x| ≤ 40 (largest term ~1e16) to stay exact to 1e-40


def _exact_sin_cos(x: float) -> tuple[float, float]:
    """sin x and cos x of the double x, Taylor series in DIGITS-digit decimal, rounded once."""
    with decimal.localcontext() as ctx:
        ctx.prec = DIGITS
        d = decimal.Decimal(x)  # the double's exact value
        sums, term, k = [decimal.Decimal(0), decimal.Decimal(0)], decimal.Decimal(1), 0
        while abs(term) > decimal.Decimal(10) ** (-DIGITS + 5) or k < 4:
            sums[k % 2 == 1] += term if k % 4 < 2 else -term  # cos: k = 0, 2, …; sin: k = 1, 3, …
            k += 1
            term = term * d / k
        return float(sums[1]), float(sums[0])


def test_the_vector_form_runs_where_the_host_has_libmvec_and_the_registers():
    flags = Path("/proc/cpuinfo").read_text().split() if Path("/proc/cpuinfo").exists() else []
    if not ctypes.util.find_library("mvec") or numba.config.CPU_NAME not in (None, "host"):
        expected = 0  # no libmvec, or code for a named CPU: libm
    else:
        expected = 8 if "avx512f" in flags else 4 if "avx2" in flags else 0
    assert LANES == expected


@pytest.mark.parametrize("n", [0, 1, 7, 8, 9, 64, 67])
def test_every_angle_of_a_row_is_within_4_ulp(n):
    # rows shorter than, equal to and longer than the lanes (the tail runs libm); angles over
    # several turns, both signs, and near the zeros of sin and cos
    rng = np.random.default_rng(n)
    x = rng.uniform(-40.0, 40.0, n)
    x[: min(n, 4)] = [np.pi, np.pi / 2, 1e-9, -3 * np.pi / 2][: min(n, 4)]
    x = np.concatenate([x, np.zeros(max(LANES - n, 0))])  # a row shorter than LANES is padded
    sines, cosines = np.full(len(x), np.nan), np.full(len(x), np.nan)
    sincos_row(x, sines, cosines, n)
    x = x[:n]
    for i, xi in enumerate(x):
        s, c = _exact_sin_cos(float(xi))
        assert abs(sines[i] - s) <= MAX_ULP * np.spacing(abs(s)), (xi, sines[i], s)
        assert abs(cosines[i] - c) <= MAX_ULP * np.spacing(abs(c)), (xi, cosines[i], c)


def test_an_angles_result_does_not_depend_on_its_place_or_the_rows_length():
    # a sweep's chunks must equal the whole sweep: the same angle gives the same bits at every
    # position of a row of any length (rows padded to LANES, as the lock-step tiles are)
    rng = np.random.default_rng(7)
    x = rng.uniform(-4.0, 4.0, 40)
    s_all, c_all = np.empty(40), np.empty(40)
    sincos_row(x, s_all, c_all, 40)
    for n in range(1, 20):
        for offset in (0, 3, 20):
            row = np.zeros(max(n, LANES))
            row[:n] = x[offset: offset + n]
            s, c = np.empty_like(row), np.empty_like(row)
            sincos_row(row, s, c, n)
            np.testing.assert_array_equal(s[:n], s_all[offset: offset + n])
            np.testing.assert_array_equal(c[:n], c_all[offset: offset + n])
