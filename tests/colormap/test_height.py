"""Height-correlated colour (Heitz et al. 2013, section 5.1) against quadrature and Monte Carlo."""

import numpy as np
import pytest
from scipy.integrate import quad
from scipy.stats import chi2, norm

from prefilter.colormap import prefilter_table
from prefilter.colormap.height import (
    OWN_PARAMS,
    PAPER_PARAMS,
    filter_height,
    fit_height_params,
    height_density,
    height_moments_approx,
    height_moments_exact,
    mean_visibility,
    smith_lambda,
    smith_lambda_direction,
)
from prefilter.errors import PrefilterError


def _dir(theta_deg, phi=0.3):
    t = np.radians(theta_deg)
    return np.array([np.sin(t) * np.cos(phi), np.sin(t) * np.sin(phi), np.cos(t)])


@pytest.mark.parametrize("cot,sigma_s", [(0.05, 0.3), (0.5, 0.3), (2.0, 0.7), (1.0, 0.2)])
def test_lambda_against_its_integral_definition(cot, sigma_s):
    # Smith: Lambda(mu) = (1 / mu) int_mu^inf (q - mu) p(q) dq for slopes q ~ N(0, sigma_s^2)
    ref = quad(lambda q: (q - cot) * norm.pdf(q, 0, sigma_s), cot, np.inf, epsabs=1e-14)[0] / cot
    assert smith_lambda(cot, sigma_s) == pytest.approx(ref, rel=1e-9, abs=1e-14)


def test_lambda_direction_uses_the_slope_std_along_the_azimuth():
    cov = np.array([[0.09, 0.0], [0.0, 0.01]])
    w = _dir(70.0, phi=0.0)
    assert smith_lambda_direction(w, cov) == pytest.approx(smith_lambda(w[2] / w[0], 0.3))
    w = _dir(70.0, phi=np.pi / 2)
    assert smith_lambda_direction(w, cov) == pytest.approx(smith_lambda(w[2] / w[1], 0.1))
    assert smith_lambda_direction(np.array([0.0, 0.0, 1.0]), cov) == 0.0


@pytest.mark.parametrize("lo,li", [(0.0, 0.0), (0.3, 1.2), (2.0, 0.1), (5.0, 7.0)])
def test_mean_visibility_eq13_against_quadrature(lo, li):
    p = norm.cdf
    num = quad(lambda h: p(h) ** (lo + li) * norm.pdf(h), -12, 12, epsabs=1e-13)[0]
    den = quad(lambda h: p(h) ** lo * norm.pdf(h), -12, 12, epsabs=1e-13)[0]
    assert mean_visibility(lo, li) == pytest.approx(num / den, rel=1e-9)


@pytest.mark.parametrize("lam", [0.0, 0.4, 3.0, 40.0])
def test_exact_moments_against_scipy_quad(lam):
    sh = 0.7
    f = lambda h, k: h**k * norm.cdf(h / sh) ** lam * norm.pdf(h, 0, sh)  # noqa: E731
    z = quad(f, -10 * sh, 10 * sh, args=(0,), epsabs=1e-14)[0]
    m1 = quad(f, -10 * sh, 10 * sh, args=(1,), epsabs=1e-14)[0] / z
    m2 = quad(f, -10 * sh, 10 * sh, args=(2,), epsabs=1e-14)[0] / z
    mu, sd = height_moments_exact(lam, sh)
    assert z == pytest.approx(1.0 / (1.0 + lam), rel=1e-9)  # the normaliser used by eq. 16
    assert mu == pytest.approx(m1, abs=1e-9)
    assert sd == pytest.approx(np.sqrt(m2 - m1 * m1), abs=1e-9)
    assert quad(lambda h: height_density(h, lam, sh), -10, 10)[0] == pytest.approx(1.0, abs=1e-9)


@pytest.mark.parametrize("lam", [0.5, 2.5, 12.0])
def test_height_filtering_distribution_against_monte_carlo(lam):
    # visible-and-lit heights: h ~ p_h, kept with probability V_o V_i = P_h(h)^L (eq. 15)
    rng = np.random.default_rng(11)
    sh = 1.3
    h = rng.normal(0.0, sh, 1_500_000)
    h = h[rng.random(h.size) < norm.cdf(h / sh) ** lam]
    mu, sd = height_moments_exact(lam, sh)
    se = sd / np.sqrt(h.size)
    assert abs(h.mean() - mu) < 5 * se
    assert abs(h.std() - sd) < 5 * se * 1.5
    # chi-square of the histogram against the density of eq. 16
    edges = np.quantile(h, np.linspace(0, 1, 41))
    edges[0], edges[-1] = -np.inf, np.inf
    hist = np.histogram(h, edges)[0]
    cdf = [quad(lambda x: height_density(x, lam, sh), -12 * sh, e)[0] if np.isfinite(e)
           else (0.0 if e < 0 else 1.0) for e in edges]
    expected = np.diff(cdf) * h.size
    stat = np.sum((hist - expected) ** 2 / expected)
    assert stat < chi2.ppf(1 - 1e-4, df=39)


def test_approximation_matches_at_normal_incidence():
    mu, sd = height_moments_approx(0.0, 2.0, PAPER_PARAMS)
    assert mu == 0.0 and sd == 2.0


def test_own_fit_is_reproducible_and_beats_the_papers_constants():
    params, report = fit_height_params(n=200)
    np.testing.assert_allclose(params, OWN_PARAMS, atol=2e-3)
    assert report["fit"]["mu_max_abs"] < 0.05
    assert report["fit"]["sigma_max_abs"] < 0.005
    assert report["fit"]["mu_max_abs"] < report["paper"]["mu_max_abs"]
    assert report["fit"]["sigma_max_abs"] < report["paper"]["sigma_max_abs"]


@pytest.mark.parametrize("theta_o,theta_i", [(0, 0), (60, 30), (80, 75), (88, 85)])
def test_filtered_height_colour_against_monte_carlo(theta_o, theta_i):
    # eq. 14 by Monte Carlo: E[C(h) P^(Lo+Li)] / E[P^Lo] over h ~ N(0, sigma_h^2)
    sh, var_s = 0.5, 0.08
    wo, wi = _dir(theta_o, 0.2), _dir(theta_i, 2.5)
    lo = smith_lambda_direction(wo, var_s)
    li = smith_lambda_direction(wi, var_s)
    cmap = lambda v: np.stack([0.5 + 0.5 * np.tanh(3 * v), 0.5 + 0.4 * np.sin(5 * v)], -1)  # noqa
    table = prefilter_table(cmap, (-3.0, 3.0), 1.0, size=256)
    h = np.random.default_rng(2).normal(0.0, sh, 2_000_000)
    p = norm.cdf(h / sh)
    ref = (cmap(h) * (p ** (lo + li))[:, None]).mean(0) / (p**lo).mean()
    got = filter_height(table, wo, wi, var_s, sh)
    naive = cmap(np.zeros(1))[0]
    # the Gaussian approximation of D_h is what limits accuracy; normal incidence is exact
    assert np.abs(got - ref).max() < (2e-3 if theta_o == theta_i == 0 else 0.03)
    if theta_o >= 60:
        assert np.abs(got - ref).max() < 0.5 * np.abs(naive - ref).max()


def test_bad_input_raises():
    with pytest.raises(PrefilterError, match="lambda_o"):
        mean_visibility(-1.0, 0.0)
    with pytest.raises(PrefilterError, match="w"):
        smith_lambda_direction(np.array([0.0, 0.0, -1.0]), 0.1)
    with pytest.raises(PrefilterError, match="sigma_s"):
        smith_lambda(1.0, 0.0)


def test_footprint_extension_reduces_to_the_whole_surface():
    from prefilter.colormap.height import height_footprint

    lam = np.array([0.01, 0.3, 1.0, 5.0, 40.0])
    mu, sd = height_moments_exact(lam, 2.0)
    m, s, vb = height_footprint(0.0, 2.0, 0.25 * lam, 0.75 * lam, 2.0)
    np.testing.assert_allclose(m, mu, atol=5e-4)  # 1D table interpolation
    np.testing.assert_allclose(s, sd, atol=0.04)
    np.testing.assert_allclose(vb, mean_visibility(0.25 * lam, 0.75 * lam), atol=2e-4)


@pytest.mark.parametrize("mf,sf,lo,li", [(0.5, 0.5, 1, 2), (1.5, 0.8, 3, 10), (0.0, 0.2, 0.1, 0.2),
                                         (0.7, 0.0, 2.0, 3.0)])
def test_footprint_extension_against_quadrature(mf, sf, lo, li):
    from prefilter.colormap.height import height_footprint

    m, s, vb = height_footprint(mf, sf, lo, li, 1.0)
    if sf == 0.0:  # a point: its own height, lit with probability P_h(h)^Lambda_i
        assert m == mf and s == 0.0
        assert vb == pytest.approx(norm.cdf(mf) ** li, rel=0.05)
        return
    f = lambda h, k, lam: h**k * norm.cdf(h) ** lam * norm.pdf(h, mf, sf)  # noqa: E731
    z = quad(f, -12, 12, args=(0, lo + li))[0]
    m1 = quad(f, -12, 12, args=(1, lo + li))[0] / z
    m2 = quad(f, -12, 12, args=(2, lo + li))[0] / z
    assert m == pytest.approx(m1, abs=0.02)
    assert s == pytest.approx(np.sqrt(m2 - m1 * m1), abs=0.01)
    assert vb == pytest.approx(z / quad(f, -12, 12, args=(0, lo))[0], abs=0.01)
