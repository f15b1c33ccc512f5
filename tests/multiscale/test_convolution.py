"""Eqs. 6-7 of Tao et al. 2021: Monte Carlo convolution, the LTC fit and ``alpha_total``.

References: the GGX NDF written out (chi-square), the closed-form product of mean resultant
lengths (zonal convolution), GGX sampling from ``prefilter.microfacet`` (independent sampler),
and maximum-likelihood alphas of fresh Monte Carlo grids.
"""

from __future__ import annotations

import numpy as np
import pytest

from prefilter.errors import PrefilterError
from prefilter.microfacet import GGX
from prefilter.multiscale import (
    alpha_total,
    convolution_grid,
    convolve_samples,
    fit_alpha_ml,
    fit_polynomial,
    mean_resultant_length,
    sample_ltc_iso,
)
from prefilter.multiscale.convolution import grid_errors
from prefilter.sphere.chi2 import chi2_sphere, lobe_cap


@pytest.mark.parametrize("a", [0.03, 0.5])
def test_isotropic_ltc_samples_are_ggx_normals(a):
    # LTC(diag(a, a, 1)) = D_GGX(m) m_z with D by its formula
    def pdf(m):
        c2 = np.clip(m[..., 2], 0, 1) ** 2
        s2 = 1 - c2
        d = 1 / (np.pi * a * a * (s2 / (a * a) + c2) ** 2)
        return np.where(m[..., 2] > 0, d * m[..., 2], 0.0)

    rng = np.random.default_rng(1)
    axis, th = lobe_cap(sample_ltc_iso(a, rng.random((20_000, 2))))
    res = chi2_sphere(sample_ltc_iso(a, rng.random((100_000, 2))), pdf, axis=axis, theta_max=th)
    assert res.passed(), res


@pytest.mark.parametrize("a_mi, a_me", [(0.03, 0.03), (0.1, 0.6), (0.5, 0.2), (0.9, 0.9)])
def test_convolution_multiplies_mean_resultant_lengths(a_mi, a_me):
    # zonal lobes: E[m_z] = E[b_z] E[m'_z] exactly (the cross terms average out)
    m = convolve_samples(a_mi, a_me, 200_000, 3)
    se = m[:, 2].std() / np.sqrt(len(m))
    want = float(mean_resultant_length(a_mi) * mean_resultant_length(a_me))
    assert abs(m[:, 2].mean() - want) < 4 * se
    np.testing.assert_allclose(np.linalg.norm(m, axis=-1), 1.0, atol=1e-12)


@pytest.mark.parametrize("a", [0.01, 0.05, 0.3, 0.8])
def test_ml_fit_recovers_ggx_roughness(a):
    # an independent sampler: visible normals of GGX for the normal view are D(m) m_z
    rng = np.random.default_rng(7)
    n = 100_000
    m = GGX(a).sample_vndf(np.broadcast_to([0.0, 0.0, 1.0], (n, 3)), rng.random((n, 2)))
    # the ML estimate's relative standard error is about 1/sqrt(n) times a small constant
    assert abs(float(fit_alpha_ml(m)) / a - 1) < 0.01


def test_flat_meso_convolution_is_the_micro_lobe():
    m = convolve_samples(0.2, 0.0, 100_000, 11)
    assert abs(float(fit_alpha_ml(m)) / 0.2 - 1) < 0.01


def test_grid_is_reproducible_with_a_seed():
    ax = [0.05, 0.4]
    g1 = convolution_grid(ax, ax, 4096, seed=9)
    g2 = convolution_grid(ax, ax, 4096, seed=9)
    g3 = convolution_grid(ax, ax, 4096, seed=10)
    for k in ("alpha_ml", "mrl", "below"):
        assert g1[k].tobytes() == g2[k].tobytes()
    assert not np.array_equal(g1["alpha_ml"], g3["alpha_ml"])
    # convolution commutes for zonal lobes: the grid is symmetric up to Monte Carlo noise
    assert abs(g1["alpha_ml"][0, 1] / g1["alpha_ml"][1, 0] - 1) < 0.03


def test_flat_footprint_keeps_the_micro_roughness():
    a = np.geomspace(0.01, 1.0, 50)
    np.testing.assert_allclose(alpha_total(a, 0.0), a, rtol=0.02)  # ours: exact by construction
    np.testing.assert_allclose(alpha_total(a, 0.0, "mrl"), a, atol=1e-6)
    # the paper's eq. 7 at alpha_me = 0: 0.07 a^2 + 0.94 a, i.e. -5.8 % at a = 0.03
    dev = alpha_total(a, 0.0, "paper") / a - 1
    assert -0.06 < dev.min() < -0.058 and 0.0 < dev.max() < 0.011


@pytest.mark.parametrize("variant", ["fit", "paper", "mrl"])
def test_monotone_in_both_arguments(variant):
    a = np.linspace(0.0, 1.0, 201)
    A, B = np.meshgrid(a, a, indexing="ij")
    t = alpha_total(A, B, variant)
    assert np.all(np.diff(t, axis=0) >= 0) and np.all(np.diff(t, axis=1) >= 0)
    inner = t[1:, 1:] < 1.0  # strictly increasing below the clamp
    assert np.all(np.diff(t, axis=0)[:, 1:][inner[:, :]] > 0)
    assert np.all(np.diff(t, axis=1)[1:, :][inner[:, :]] > 0)


def test_shipped_fit_matches_fresh_monte_carlo():
    # a grid the coefficients were not fitted on (other nodes, other seed)
    ax = np.array([0.02, 0.07, 0.15, 0.35, 0.6])
    g = convolution_grid(ax, ax, 1 << 15, seed=123)
    ours = grid_errors(g, "fit")
    paper = grid_errors(g, "paper")
    assert ours["max_rel"] < 0.035
    assert ours["sse"] < 0.2 * paper["sse"]


@pytest.mark.slow
def test_refit_reproduces_the_shipped_coefficients():
    ax = np.linspace(0.1, 1.0, 16) ** 2
    g = convolution_grid(ax, ax, 1 << 16, seed=1)
    ours, paper_form = fit_polynomial(g, "ours"), fit_polynomial(g, "paper")
    shipped = grid_errors(g, "fit")
    assert shipped["sse"] < 1.5 * ours["sse"]
    assert ours["sse"] < 0.2 * paper_form["sse"] < 0.2 * grid_errors(g, "paper")["sse"]


def test_rejects_bad_input():
    with pytest.raises(PrefilterError, match="alpha_meso"):
        alpha_total(0.1, 1.5)
    with pytest.raises(PrefilterError, match="alpha_micro"):
        alpha_total(np.nan, 0.1)
    with pytest.raises(PrefilterError, match="variant"):
        alpha_total(0.1, 0.1, "poly")
    with pytest.raises(PrefilterError, match="rng"):
        convolve_samples(0.1, 0.1, 10, None)
    with pytest.raises(PrefilterError, match="form"):
        fit_polynomial(convolution_grid([0.1, 0.2], [0.1, 0.2], 16), "cubic")
