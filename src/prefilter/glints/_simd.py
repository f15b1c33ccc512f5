"""Scalar helpers that let LLVM vectorise the glint kernels' per-texel loops.

Two things kept those loops scalar: Numba's default (Python) error model puts a zero-division
check, a branch that raises, in front of every float division, and without Intel's SVML
``math.exp`` is a call into libm, which LLVM cannot vectorise either (``numba -s``: SVML state
False on the development machine). :func:`fdiv` is a plain IEEE division for denominators the
caller knows to be nonzero; :func:`exp_neg` is ``exp`` for non-positive arguments in straight-line
arithmetic (Cody-Waite reduction with fused multiply-adds, a degree-12 Taylor polynomial on
``|r| <= ln(2) / 2``, the power of two built in the exponent bits): within 1.5 ulp of
``math.exp`` and vectorisable; even where a branch keeps it scalar it costs a fraction of the
libm call.
"""

from __future__ import annotations

import numpy as np
from llvmlite import ir
from numba import types
from numba.core import cgutils
from numba.extending import intrinsic

from prefilter.jit import njit_inline


@intrinsic
def fdiv(typingctx, a, b):
    """``a / b`` for float64 ``a``, ``b`` without Numba's zero-division check (``b`` must not be
    zero: IEEE semantics apply otherwise)."""
    if not (isinstance(a, types.Float) and isinstance(b, types.Float)):
        return None
    sig = types.float64(types.float64, types.float64)

    def codegen(context, builder, signature, args):
        x, y = (context.cast(builder, v, t, types.float64) for v, t in zip(args, signature.args))
        return builder.fdiv(x, y)

    return sig, codegen


@intrinsic
def fma(typingctx, a, b, c):
    """``a * b + c`` rounded once (LLVM's ``llvm.fma.f64``; fast-math reassociation does not
    split it, unlike ``a * b + c`` written out)."""
    if not all(isinstance(x, types.Float) for x in (a, b, c)):
        return None
    sig = types.float64(types.float64, types.float64, types.float64)

    def codegen(context, builder, signature, args):
        d = ir.DoubleType()
        fn = cgutils.get_or_insert_function(builder.module, ir.FunctionType(d, [d, d, d]),
                                            "llvm.fma.f64")
        return builder.call(fn, [context.cast(builder, v, t, types.float64)
                                 for v, t in zip(args, signature.args)])

    return sig, codegen


@intrinsic
def _int64_as_float64(typingctx, x):
    """The float64 whose bits are the int64 ``x``."""
    if not isinstance(x, types.Integer):
        return None
    sig = types.float64(types.int64)

    def codegen(context, builder, signature, args):
        v = context.cast(builder, args[0], signature.args[0], types.int64)
        return builder.bitcast(v, ir.DoubleType())

    return sig, codegen


_LOG2E = 1.4426950408889634
# ln 2 split so that n * _LN2_HI is exact for |n| < 2^20 (the reduction's first product)
_LN2_HI = 0.6931471803691238
_LN2_LO = 1.9082149292705877e-10


@njit_inline
def exp_neg(t):  # pragma: no cover - compiled
    """``exp(t)`` for ``t <= 0`` (``t < -700`` gives ``exp(-700)``; tiny positive ``t`` from
    rounding are fine): ``2^n exp(r)`` with ``n`` the integer nearest ``t / ln 2`` and
    ``|r| <= ln(2) / 2``, whose Taylor series to degree 12 leaves ``< 2e-16`` relative."""
    t = max(t, -700.0)
    # truncation of x - 0.5 rounds x <= 0.5 to the nearest integer (no floor: it vectorises)
    n = np.int32(t * _LOG2E - 0.5)
    fn = np.float64(n)
    r = fma(-fn, _LN2_LO, fma(-fn, _LN2_HI, t))
    p = 1.0 / 479001600.0
    p = p * r + 1.0 / 39916800.0
    p = p * r + 1.0 / 3628800.0
    p = p * r + 1.0 / 362880.0
    p = p * r + 1.0 / 40320.0
    p = p * r + 1.0 / 5040.0
    p = p * r + 1.0 / 720.0
    p = p * r + 1.0 / 120.0
    p = p * r + 1.0 / 24.0
    p = p * r + 1.0 / 6.0
    p = p * r + 0.5
    p = p * r + 1.0
    p = p * r + 1.0
    return p * _int64_as_float64((np.int64(n) + 1023) << 52)
