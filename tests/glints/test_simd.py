"""The vectorisable scalar helpers of the glint kernels (prefilter.glints._simd)."""

from fractions import Fraction

import numpy as np

from prefilter.jit import njit_serial
from prefilter.glints._simd import exp_neg, fdiv, fma


@njit_serial
def _exp_all(t, out):
    for i in range(t.size):
        out[i] = exp_neg(t[i])


@njit_serial
def _fdiv_all(a, b, out):
    for i in range(a.size):
        out[i] = fdiv(a[i], b[i])


@njit_serial
def _fma_all(a, b, c, out):
    for i in range(a.size):
        out[i] = fma(a[i], b[i], c[i])


def test_exp_neg_matches_exp():
    """Within 2 ulp of the correctly rounded exp (NumPy's) on [-700, 0], including the reduction's
    rounding points (multiples of ln(2) / 2) and zero; clamped below -700."""
    rng = np.random.default_rng(0)
    t = np.concatenate([-rng.uniform(0.0, 80.0, 200_000), -rng.uniform(0.0, 700.0, 50_000),
                        -np.arange(2019) * (np.log(2.0) / 2.0),
                        [0.0, -0.0, -1e-300, -700.0]])
    t = t[t >= -700.0]
    out = np.empty_like(t)
    _exp_all(t, out)
    ref = np.exp(t)
    ulp = np.spacing(ref)
    assert np.max(np.abs(out - ref) / ulp) <= 2.0
    assert out[t == 0.0].tolist() == [1.0] * int(np.sum(t == 0.0))
    o = np.empty(2)
    _exp_all(np.array([-800.0, 1e-17]), o)
    assert o[0] == np.exp(-700.0) and o[1] == 1.0


def test_fdiv_and_fma():
    """fdiv is IEEE division; fma rounds once (the exact product-sum, checked with fractions,
    where a * b + c written out would round twice)."""
    rng = np.random.default_rng(1)
    a, b, c = rng.normal(size=(3, 1000))
    o = np.empty(1000)
    _fdiv_all(a, b, o)
    assert np.array_equal(o, a / b)
    _fma_all(a, b, c, o)
    exact = [float(Fraction(x) * Fraction(y) + Fraction(z)) for x, y, z in zip(a, b, c)]
    assert np.array_equal(o, exact)
    # 1 + 2^-30 squared minus 1 - 2^-29: the 2^-60 survives only if rounded once
    x = 1.0 + 2.0 ** -30
    _fma_all(np.array([x]), np.array([x]), np.array([-(1.0 + 2.0 ** -29)]), o[:1])
    assert o[0] == 2.0 ** -60
