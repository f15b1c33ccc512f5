"""Property-based tests of prefilter.multiscale: eqs. 4-7 of Tao et al. 2021 at the edges."""

import numpy as np
import pytest
from hypothesis import example, given, settings
from hypothesis import strategies as st
from scipy import integrate

from prefilter.errors import PrefilterError
from prefilter.multiscale import (
    alpha_meso,
    alpha_meso_exact,
    alpha_total,
    convolution_grid,
    convolve_samples,
    fit_alpha_ml,
    fit_polynomial,
    mean_resultant_length,
    sample_ltc_iso,
)

N = settings.default.max_examples
alpha01 = st.one_of(st.sampled_from([0.0, 1e-3, 1.0]), st.floats(0.0, 1.0))


def expect_error(fn, name):
    with pytest.raises(PrefilterError) as err:
        fn()
    assert name in str(err.value), str(err.value)


def mrl_quadrature(alpha):
    # E[b_z] for b ~ LTC(diag(alpha, alpha, 1)): b_z = y / sqrt(y^2 + alpha^2 (1 - y^2)) with
    # y = cos t and y^2 uniform on [0, 1] (cosine-weighted t), i.e. E[b_z] = int 2 y b_z dy.
    # Adaptive quadrature, told where the integrand bends: y ~ alpha, and 1 - y ~ 1 / alpha^2.
    def f(y):
        return 2.0 * y * y / max(np.hypot(y, alpha * np.sqrt(1.0 - y * y)), 1e-300)

    pts = [p for p in (alpha, 1.0 - 1.0 / max(alpha, 1.0) ** 2) if 1e-12 < p < 1.0]
    return integrate.quad(f, 0.0, 1.0, points=pts or None, epsabs=1e-13, epsrel=1e-12,
                          limit=200)[0]


@settings(max_examples=N)
@given(st.one_of(st.sampled_from([0.0, 1e-3, 1.0, 1.1180339887, 1e154, 1e200, 1e308]),
                 st.floats(0.0, 1e3)))
@example(1e200)  # overflowed to NaN (a * a = inf)
@example(0.00390625)
def test_mean_resultant_length(a):
    r = mean_resultant_length(a)
    assert np.isfinite(r) and 0.0 < r <= 1.0
    if a <= 1e3:
        assert r == pytest.approx(mrl_quadrature(a), rel=1e-6, abs=1e-9)
    else:
        assert r == pytest.approx(np.pi / (2 * a), rel=1e-9)  # large-alpha limit


@settings(max_examples=N)
@given(st.floats(0.0, 1.0 + 1e-6), st.sampled_from(["exact", "paper"]))
def test_alpha_meso_inverts_eq4(r, variant):
    a = alpha_meso(r, variant)
    assert np.isfinite(a) and 0.0 <= a <= 1.0
    if variant == "exact" and 2 / 3 + 1e-6 < r < 1.0 - 1e-9:
        assert mean_resultant_length(a) == pytest.approx(r, abs=1e-6)
        assert alpha_meso_exact(r) == pytest.approx(a, abs=1e-6)


@settings(max_examples=N)
@given(alpha01, alpha01, st.sampled_from(["fit", "paper", "mrl"]))
def test_alpha_total_in_range(a, b, variant):
    t = alpha_total(a, b, variant)
    assert np.isfinite(t) and 0.0 <= t <= 1.0
    if variant == "mrl":  # convolution only roughens (resultant lengths multiply)
        assert t >= max(a, b) - 1e-6


@settings(max_examples=N // 3)
@given(alpha01, alpha01, st.integers(0, 2**31))
def test_convolution_samples_and_ml_fit(a, b, seed):
    m = convolve_samples(a, b, 256, seed)
    assert m.shape == (256, 3) and np.allclose(np.linalg.norm(m, axis=-1), 1.0)
    if np.any(m[:, 2] > 0):
        fit = fit_alpha_ml(m[None])
        assert np.all(np.isfinite(fit)) and np.all((fit >= 0.0) & (fit <= 2.0))


@settings(max_examples=N)
@given(st.floats(0.0, 10.0), st.floats(0.0, 1.0), st.floats(0.0, 1.0))
@example(0.0, 0.0, 0.0)  # flat meso-scale, cosine sample on the horizon: was 0 / 0 = NaN
@example(2.457856245784976e-162, 0.0, 0.0)  # |w|^2 underflowed: a non-unit result
def test_sample_ltc_iso_unit_upper(a, u1, u2):
    w = sample_ltc_iso(a, np.array([u1, u2]))
    assert np.isclose(np.linalg.norm(w), 1.0) and w[2] >= 0.0


def test_ml_fit_recovers_known_roughness():
    # samples of the LTC itself: the ML roughness converges to the true one (Monte Carlo, 4e4)
    rng = np.random.default_rng(5)
    m = sample_ltc_iso(0.4, rng.random((40000, 2)))
    assert fit_alpha_ml(m[None])[0] == pytest.approx(0.4, abs=0.01)


def test_multiscale_rejects_bad_input():
    expect_error(lambda: mean_resultant_length(-0.1), "alpha")
    expect_error(lambda: mean_resultant_length(np.nan), "alpha")
    expect_error(lambda: alpha_meso(1.1), "r")
    expect_error(lambda: alpha_meso(0.9, "bogus"), "variant")
    expect_error(lambda: alpha_meso_exact(0.9, iterations=-1), "iterations")
    expect_error(lambda: alpha_total(1.5, 0.1), "alpha_micro")
    expect_error(lambda: alpha_total(0.1, np.nan), "alpha_meso")
    expect_error(lambda: alpha_total(0.1, 0.1, "x"), "variant")
    expect_error(lambda: convolve_samples(0.1, 0.1, 0, 0), "n")
    expect_error(lambda: convolve_samples(0.1, 0.1, 10, None), "rng")
    expect_error(lambda: sample_ltc_iso(np.nan, [0.5, 0.5]), "alpha")
    expect_error(lambda: sample_ltc_iso(0.5, [0.5, 2.0]), "u")
    # no direction above the horizon: used to return alpha = 2 silently
    expect_error(lambda: fit_alpha_ml(np.array([[[0.0, 0.0, -1.0]] * 3])), "m")
    expect_error(lambda: fit_alpha_ml(np.array([[[0.0, 0.0, 3.0]] * 3])), "m")
    expect_error(lambda: fit_alpha_ml(np.zeros((3, 2))), "m")


@settings(max_examples=N // 6)
@given(st.lists(alpha01, min_size=2, max_size=3, unique=True),
       st.lists(alpha01, min_size=2, max_size=3, unique=True), st.integers(0, 2**31))
def test_convolution_grid_and_fits(ami, ame, seed):
    grid = convolution_grid(ami, ame, 512, seed)
    for k in ("alpha_ml", "mrl", "below"):
        assert grid[k].shape == (len(ami), len(ame)) and np.all(np.isfinite(grid[k]))
    assert np.all((grid["below"] >= 0) & (grid["below"] <= 1)) and np.all(grid["mrl"] <= 1)
    if len(ami) * len(ame) >= 4:
        for form in ("ours", "paper"):
            fit = fit_polynomial(grid, form)
            assert np.all(np.isfinite(fit["coeffs"]))


def test_fit_polynomial_rejects_bad_grids():
    grid = convolution_grid([0.1, 0.5], [0.1, 0.5], 256, 0)
    # a non-dict or a grid with fewer nodes than coefficients: was KeyError / scipy's TypeError
    expect_error(lambda: fit_polynomial({"alpha_micro": [0.1]}), "grid")
    expect_error(lambda: fit_polynomial(dict(grid, alpha_ml=grid["alpha_ml"][:1])),
                 "grid['alpha_ml']")
    small = convolution_grid([0.1], [0.1, 0.5], 64, 0)
    expect_error(lambda: fit_polynomial(small), "grid['alpha_ml']")
    expect_error(lambda: fit_polynomial(grid, "cubic"), "form")
    expect_error(lambda: convolution_grid([0.1, 1.5], [0.1], 64), "alpha_micro")


@pytest.mark.parametrize("args,name", [
    ((np.array([0.1, 0.2]), 0.1, 10, 0), "alpha_micro"),   # was TypeError
    ((0.1, np.array([0.1, 0.2]), 10, 0), "alpha_meso"),
    (("0.1", 0.1, 10, 0), "alpha_micro"),
    ((0.1, 0.1, 10, -3), "rng"),                           # was NumPy's ValueError
])
def test_convolve_samples_rejects_arrays_strings_and_negative_seeds(args, name):
    with pytest.raises(PrefilterError) as err:
        convolve_samples(*args)
    assert str(err.value).startswith(name + ":"), str(err.value)
