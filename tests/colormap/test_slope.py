"""Slope-correlated colour (Heitz et al. 2013, section 5.2) against Monte Carlo and quadrature."""

import numpy as np
import pytest
from scipy.interpolate import RegularGridInterpolator

from prefilter.colormap.slope import (
    filter_slope,
    slope_density,
    slope_distribution,
    slope_prefilter_table,
)
from prefilter.errors import PrefilterError

MU = np.array([0.1, -0.2])
COV = np.array([[0.09, 0.03], [0.03, 0.04]])


def _dir(theta_deg, phi):
    t = np.radians(theta_deg)
    return np.array([np.sin(t) * np.cos(phi), np.sin(t) * np.sin(phi), np.cos(t)])


def _weighted_mc(w, mu, cov, n=1_000_000, seed=0):
    """Slopes of the footprint weighted by their projected area towards w (eq. 20)."""
    s = np.random.default_rng(seed).multivariate_normal(mu, cov, n)
    wt = np.maximum(0.0, w[2] - s @ w[:2])
    return s, wt / wt.sum()


@pytest.mark.parametrize("theta,phi", [(0, 0.0), (35, 0.7), (70, 2.0), (85, -1.2), (89.5, 0.3)])
def test_moments_against_monte_carlo(theta, phi):
    w = _dir(theta, phi)
    s, wt = _weighted_mc(w, MU, COV, seed=int(theta))
    mean_mc = wt @ s
    d = s - mean_mc
    cov_mc = (d * wt[:, None]).T @ d
    mean, cov = slope_distribution(w, MU, COV)
    n_eff = 1.0 / np.sum(wt**2)
    se = np.sqrt(np.diag(cov_mc) / n_eff)
    assert np.all(np.abs(mean - mean_mc) < 5 * se)
    # the variance of a sample variance of a near-Gaussian is ~ 2 var^2 / n
    assert np.abs(cov - cov_mc).max() < 5 * np.sqrt(2.0 / n_eff) * COV.max()


def test_moments_shift_away_from_the_view_and_shrink_along_it():
    w = _dir(80, 0.0)  # looking from +x: facets facing +x (negative s_x) are seen more
    mean, cov = slope_distribution(w, np.zeros(2), np.diag([0.09, 0.04]))
    assert mean[0] < -0.05 and abs(mean[1]) < 1e-12
    assert cov[0, 0] < 0.09 and cov[1, 1] == pytest.approx(0.04)


def test_density_integrates_to_one_and_matches_moments():
    w = _dir(75, 0.9)
    x = np.linspace(-2.0, 2.0, 801)
    sx, sy = np.meshgrid(x, x)
    s = np.stack([sx, sy], -1)
    d = slope_density(s, w, MU, COV)
    da = (x[1] - x[0]) ** 2
    assert d.sum() * da == pytest.approx(1.0, abs=1e-6)
    mean, _ = slope_distribution(w, MU, COV)
    np.testing.assert_allclose((d[..., None] * s).sum((0, 1)) * da, mean, atol=1e-6)


def test_batches_broadcast():
    w = np.stack([_dir(t, 0.3) for t in (0, 40, 80)])
    mean, cov = slope_distribution(w, MU, COV)
    assert mean.shape == (3, 2) and cov.shape == (3, 2, 2)
    m1, c1 = slope_distribution(w[2], MU, COV)
    np.testing.assert_allclose(mean[2], m1)
    np.testing.assert_allclose(cov[2], c1)


def _slope_map(n=64, extent=1.0):
    x = -extent + (np.arange(n) + 0.5) * 2 * extent / n
    c = np.stack([np.sin(5 * x)[None, :] * np.cos(3 * x)[:, None] + 0.3 * np.outer(x, x),
                  0.5 + 0.5 * np.tanh(4 * x)[None, :] * np.ones((n, 1))], -1)
    interp = RegularGridInterpolator((x, x), c)

    def f(s):  # bilinear, clamped: independent of the table code
        return interp(np.clip(s, x[0], x[-1])[..., ::-1])

    return c, f


@pytest.mark.parametrize("cov", [np.array([[0.02, 0.01], [0.01, 0.03]]),
                                 np.array([[0.09, 0.0], [0.0, 0.001]]),
                                 np.array([[0.05, 0.04], [0.04, 0.05]]),
                                 np.zeros((2, 2))])
def test_table_lookup_equals_gaussian_convolution(cov):
    c, f = _slope_map()
    table = slope_prefilter_table(c, 1.0, 0.5, 32)
    mean = np.array([0.2, -0.1])
    # reference: 48 x 48 Gauss-Hermite quadrature of the bilinear map under N(mean, cov)
    x, w = np.polynomial.hermite_e.hermegauss(48)
    w = w / w.sum()
    chol = np.linalg.cholesky(cov + 1e-14 * np.eye(2))
    z = np.stack(np.meshgrid(x, x), -1).reshape(-1, 2)
    ref = (np.outer(w, w).reshape(-1)[:, None] * f(mean + z @ chol.T)).sum(0)
    assert np.abs(table.lookup(mean, cov) - ref).max() < 3e-3


def test_filtered_slope_colour_against_monte_carlo():
    c, f = _slope_map()
    table = slope_prefilter_table(c, 1.0, 0.5, 32)
    for theta, phi in [(0, 0.0), (60, 0.4), (80, 2.5), (88, -0.8)]:
        w = _dir(theta, phi)
        s, wt = _weighted_mc(w, MU, COV, n=400_000, seed=theta)
        ref = wt @ f(s)
        got = filter_slope(table, w, MU, COV)
        naive = table.naive(MU)
        # Gaussian approximation of D_s: a few percent; the naive C(mean) is far off
        assert np.abs(got - ref).max() < 0.03, theta
        assert np.abs(got - ref).max() < 0.25 * np.abs(naive - ref).max(), theta


def test_bad_input_raises():
    with pytest.raises(PrefilterError, match="cov"):
        slope_distribution(_dir(10, 0), MU, -COV)
    with pytest.raises(PrefilterError, match="wo"):
        slope_distribution(np.array([1.0, 0.0, 0.0]), MU, COV)
    with pytest.raises(PrefilterError, match="colormap"):
        slope_prefilter_table(np.zeros((4, 5, 3)))
