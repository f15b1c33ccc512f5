"""Pre-convolved colour-map tables (Heitz et al. 2013, eq. 10) against independent quadrature."""

import numpy as np
import pytest
from scipy.integrate import quad
from scipy.stats import norm

from prefilter.colormap import gaussian_operator, lookup, prefilter_table
from prefilter.colormap.table import prefilter_rows
from prefilter.errors import PrefilterError


def _reference_map(c, lo, hi, edge):
    """The colour map as a function of value, built with np.interp (independent of the table)."""
    n = c.shape[0]
    centres = lo + (np.arange(n) + 0.5) * (hi - lo) / n
    span = hi - lo

    def f(v, ch=0):
        if edge == "periodic":
            return np.interp(v, centres, c[:, ch], period=span)
        if edge == "mirror":
            u = np.mod(v - lo, 2 * span)
            u = np.where(u < span, u, 2 * span - u)
            return np.interp(lo + u, centres, c[:, ch])
        return np.interp(v, centres, c[:, ch])

    return f, centres


@pytest.mark.parametrize("edge", ["clamp", "mirror", "periodic"])
def test_sigma_zero_row_is_the_colormap(edge):
    c = np.random.default_rng(3).random((32, 3))
    t = prefilter_table(c, (-2.0, 1.0), 0.4, size=32, edge=edge)
    np.testing.assert_array_equal(t.lookup(t.means, 0.0), c)
    # between texel centres, sigma = 0 is the linear interpolant of the map
    f, _ = _reference_map(c, -2.0, 1.0, edge)
    v = np.random.default_rng(4).uniform(-2.5, 1.5, 200)
    np.testing.assert_allclose(lookup(t, v, 0.0)[:, 1], f(v, 1), atol=1e-12)


def test_sigma_zero_of_a_smooth_callable():
    t = prefilter_table(lambda v: np.stack([np.sin(3 * v), v * v], -1), (0.0, 2.0), 0.5, size=256)
    v = np.linspace(0.05, 1.95, 101)
    want = np.stack([np.sin(3 * v), v * v], -1)
    # linear interpolation of a smooth map: error <= h^2 max|C''| / 8 with h = 2 / 256
    np.testing.assert_allclose(t.naive(v), want, atol=(2 / 256) ** 2 * 9 / 8)


@pytest.mark.parametrize("edge", ["clamp", "mirror", "periodic"])
def test_table_equals_numerical_convolution(edge):
    rng = np.random.default_rng(5)
    c = rng.random((12, 2))
    lo, hi = -1.0, 2.0
    t = prefilter_table(c, (lo, hi), 2.0, size=12, n_sigma=9, edge=edge)
    f, centres = _reference_map(c, lo, hi, edge)
    for j in (1, 4, 8):
        s = t.sigmas[j]
        for i in (0, 5, 11):
            m = t.means[i]
            kinks = np.concatenate([centres + k * (hi - lo) for k in range(-12, 13)]) - m
            kinks = np.sort(kinks[np.abs(kinks) < 9 * s])
            ref = quad(lambda x: f(m + x, 1) * norm.pdf(x, 0, s), -9 * s, 9 * s,
                       points=kinks, limit=1000, epsabs=1e-13)[0]
            assert abs(t.table[j, i, 1] - ref) < 1e-10, (j, i, t.table[j, i, 1], ref)


@pytest.mark.parametrize("edge", ["clamp", "mirror", "periodic"])
def test_fft_rows_equal_the_dense_operator(edge):
    # sigmas from a fraction of a texel to 2.5 ranges (kernel reach far beyond the map: folded
    # several times onto the period, clamp tails carrying most of the weight)
    rng = np.random.default_rng(8)
    for n in (2, 7, 40):
        c = rng.random((n, 3))
        sig = np.array([0.0, 0.2 / n, 1.0 / n, 0.13, 0.6, 2.5])
        rows = prefilter_rows(c, sig, edge)
        for r, s in zip(rows, sig):
            np.testing.assert_allclose(r, gaussian_operator(n, s, edge) @ c, rtol=0, atol=1e-14)


def test_fft_rows_do_not_depend_on_the_batch():
    c = np.random.default_rng(9).random((64, 3))
    sig = np.linspace(0.0, 0.4, 40)
    full = prefilter_rows(c, sig, "mirror")
    np.testing.assert_array_equal(prefilter_rows(c, sig[7:19], "mirror"), full[7:19])


def _gauss_legendre_convolution(f, m, s, kinks):
    """``int f(m + x) N(x; 0, s^2) dx`` over ``|x| < 9 s``: 12-node Gauss-Legendre on pieces that
    split at the kinks of ``f`` and are at most ``s / 4`` long (f linear on each piece)."""
    edges = np.unique(np.concatenate([np.linspace(-9 * s, 9 * s, 73),
                                      kinks[np.abs(kinks) < 9 * s]]))
    x, w = np.polynomial.legendre.leggauss(12)
    a, b = edges[:-1, None], edges[1:, None]
    xs = 0.5 * (a + b) + 0.5 * (b - a) * x
    return float(np.sum(0.5 * (b - a) * w * f(m + xs) * norm.pdf(xs, 0, s)))


def test_large_table_against_numerical_convolution():
    # a 1024-texel clamp map (the size that took minutes with the dense operators)
    rng = np.random.default_rng(10)
    c = np.cumsum(rng.normal(size=(1024, 1)), 0) / 30
    lo, hi = 0.0, 4.0
    t = prefilter_table(c, (lo, hi), 0.5, size=1024, n_sigma=64)
    f, centres = _reference_map(c, lo, hi, "clamp")
    for j, i in ((1, 0), (1, 700), (20, 511), (63, 1023), (63, 3)):
        ref = _gauss_legendre_convolution(f, t.means[i], t.sigmas[j], centres - t.means[i])
        assert abs(t.table[j, i, 0] - ref) < 1e-12, (j, i, t.table[j, i, 0], ref)


def test_lookup_between_texels_matches_convolution():
    # bilinear interpolation error of a smooth map's table is small at 256 x 256
    t = prefilter_table(lambda v: np.cos(4 * v), (0.0, 1.0), 0.3, size=256)
    m, s = 0.37, 0.123
    ref = quad(lambda x: np.cos(4 * (m + x)) * norm.pdf(x, 0, s), -9 * s, 9 * s)[0]
    assert abs(t.lookup(m, s)[0] - ref) < 2e-4


def test_operator_rows_sum_to_one_and_large_sigma_tends_to_mean():
    for edge in ("clamp", "mirror", "periodic"):
        op = gaussian_operator(20, 0.37, edge)
        np.testing.assert_allclose(op.sum(1), 1.0, atol=1e-13)
    c = np.random.default_rng(0).random(16)
    op = gaussian_operator(16, 3.0, "periodic")
    # a wide blur of a periodic map is its mean (the integral of the linear interpolant)
    np.testing.assert_allclose(op @ c, c.mean(), atol=1e-12)


def test_lookup_clamps_sigma_and_wraps_periodic_means():
    c = np.random.default_rng(1).random((16, 1))
    t = prefilter_table(c, (0.0, 1.0), 0.2, size=16, edge="periodic")
    np.testing.assert_allclose(t.lookup(0.3 + 3.0, 0.1), t.lookup(0.3, 0.1), atol=1e-12)
    np.testing.assert_allclose(t.lookup(0.3, 5.0), t.lookup(0.3, 0.2))


@pytest.mark.parametrize("bad", [
    dict(value_range=(1.0, 0.0)), dict(sigma_max=0.0), dict(edge="wrap"), dict(size=1),
])
def test_bad_input_raises(bad):
    kw = dict(colormap=np.zeros((4, 3)), value_range=(0.0, 1.0), sigma_max=0.1, size=8)
    kw.update(bad)
    with pytest.raises(PrefilterError):
        prefilter_table(**kw)


def test_negative_sigma_and_nan_mean_raise():
    t = prefilter_table(np.zeros((4, 3)), (0.0, 1.0), 0.1, size=8)
    with pytest.raises(PrefilterError, match="sigma"):
        t.lookup(0.5, -0.1)
    with pytest.raises(PrefilterError, match="mean"):
        t.lookup(np.nan, 0.1)
