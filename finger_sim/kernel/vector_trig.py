"""Sines and cosines of a row of angles, several at once: glibc's vector math library (libmvec).

numba vectorises `math.sin` only with Intel's SVML, which the llvmlite wheels here lack
(`numba -s`: "llvmlite Using SVML Patched LLVM: False"), and LLVM's own `-vector-library`
switch is not in llvmlite's build, so a loop of `math.sin` calls libm once per angle. glibc
ships the vector forms as libmvec (`_ZGVeN8v_sin`: 8 doubles in a zmm register with AVX-512,
`_ZGVdN4v_sin`: 4 in a ymm with AVX2; x86_64 vector function ABI). `sincos_row` calls them
through a numba intrinsic, LANES angles per call, every angle of the row in the vector form.

libmvec's sin and cos are within 4 ulp (glibc's manual), not correctly rounded as libm's are:
a result differs from the scalar one in the last bits (under 1e-15). Where
libmvec or the instruction set is missing, or numba compiles for a named CPU rather than this
host (NUMBA_CPU_NAME, whose register use the ABI cannot rely on), LANES is 0 and `sincos_row`
is the scalar loop.
"""

from __future__ import annotations

import ctypes.util
import math

from finger_sim.kernel import use_writable_cache

use_writable_cache()  # before numba reads NUMBA_CACHE_DIR
import llvmlite.binding as llvm  # noqa: E402  (after the cache folder is set)
from llvmlite import ir  # noqa: E402
from numba import config, njit, types  # noqa: E402
from numba.core import cgutils  # noqa: E402
from numba.extending import intrinsic  # noqa: E402

#: glibc's vector sin/cos by register width: (lanes, CPU feature, symbol prefix) (x86_64 vector ABI).
VARIANTS = ((8, "avx512f", "_ZGVeN8v_"), (4, "avx2", "_ZGVdN4v_"))


def _choose() -> tuple[int, str]:
    """(lanes, symbol prefix) of the widest libmvec variant this host runs, or (0, "")."""
    if config.CPU_NAME not in (None, "host") or not ctypes.util.find_library("mvec"):
        return 0, ""
    try:
        llvm.load_library_permanently(ctypes.util.find_library("mvec"))
        features = llvm.get_host_cpu_features()
    except (OSError, RuntimeError):
        return 0, ""
    for lanes, feature, prefix in VARIANTS:
        if features.get(feature, False):
            return lanes, prefix
    return 0, ""


LANES, _PREFIX = _choose()


@intrinsic
def _sincos_lanes(typingctx, src, sines, cosines, start):  # type: ignore[no-untyped-def]
    """sines[start:start + LANES], cosines[...] = sin, cos of src[start:start + LANES] (contiguous float64)."""
    vector = ir.VectorType(ir.DoubleType(), max(LANES, 1))

    def codegen(context, builder, signature, args):  # type: ignore[no-untyped-def]
        def lanes_at(array_type, array):  # type: ignore[no-untyped-def]
            data = context.make_array(array_type)(context, builder, array).data
            return builder.bitcast(builder.gep(data, [args[3]]), vector.as_pointer())

        x = builder.load(lanes_at(signature.args[0], args[0]), align=8)
        for k, name in ((1, "sin"), (2, "cos")):
            fn = cgutils.get_or_insert_function(builder.module, ir.FunctionType(vector, [vector]), _PREFIX + name)
            builder.store(builder.call(fn, [x]), lanes_at(signature.args[k], args[k]), align=8)
        return context.get_dummy_value()

    return types.void(src, sines, cosines, start), codegen


@njit(cache=True, nogil=True, inline="always")
def _vector_sincos_row(src, sines, cosines, n):  # type: ignore[no-untyped-def]
    # every angle goes through the vector form, the last group overlapping the one before (or
    # reading the padding of a row shorter than LANES): an angle's sine is the same bits
    # whatever its position in the row and the row's length (a sweep's chunks equal the whole)
    i = 0
    while i < n:
        _sincos_lanes(src, sines, cosines, min(i, n - LANES) if n >= LANES else 0)
        i += LANES


@njit(cache=True, nogil=True, inline="always")
def _scalar_sincos_row(src, sines, cosines, n):  # type: ignore[no-untyped-def]
    for i in range(n):
        sines[i], cosines[i] = math.sin(src[i]), math.cos(src[i])


#: sines[:n], cosines[:n] = sin, cos of src[:n] (contiguous float64 rows, rad), LANES at a time
#: where the host allows (module docstring), else libm's. The rows must be at least max(n, LANES)
#: long: a row shorter than LANES is read and written up to LANES (its padding).
sincos_row = _vector_sincos_row if LANES > 0 else _scalar_sincos_row
