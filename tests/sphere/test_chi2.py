"""The chi-square test itself: accepts right samplers, rejects wrong ones, integrates bins well."""

import numpy as np
import pytest

from prefilter.errors import PrefilterError
from prefilter.sphere import (
    chi2_sphere,
    chi2_warped,
    cosine_hemisphere,
    cosine_hemisphere_pdf,
    lobe_cap,
    slope_warp,
    uniform_sphere,
    uniform_sphere_pdf,
    warp_integral,
)


def test_rejects_wrong_density():
    w = cosine_hemisphere(np.random.default_rng(0).random((100_000, 2)))
    res = chi2_sphere(w, lambda d: np.where(d[..., 2] > 0, 1 / (2 * np.pi), 0.0))
    assert res.p_value < 1e-6


def test_rejects_samples_where_density_is_zero():
    w = uniform_sphere(np.random.default_rng(1).random((50_000, 2)))
    res = chi2_sphere(w, cosine_hemisphere_pdf)
    assert res.p_value == 0.0 and "zero density" in res.message


def test_rejects_slightly_too_narrow_power_cosine():
    # Samples of z^n / norm with n = 22 tested against n = 20: a 10% narrower lobe.
    rng = np.random.default_rng(2)
    u = rng.random((200_000, 2))

    def power(nexp, u):
        z = u[:, 0] ** (1 / (nexp + 1))
        r = np.sqrt(1 - z * z)
        return np.stack([r * np.cos(2 * np.pi * u[:, 1]), r * np.sin(2 * np.pi * u[:, 1]), z], -1)

    pdf = lambda d: np.maximum(d[..., 2], 0) ** 20 * 21 / (2 * np.pi)  # noqa: E731
    axis, th = lobe_cap(power(20, rng.random((20_000, 2))))
    assert chi2_sphere(power(20, u), pdf, axis=axis, theta_max=th).passed()
    assert chi2_sphere(power(22, u), pdf, axis=axis, theta_max=th).p_value < 1e-3


def test_p_values_under_the_null_are_not_too_small():
    # Under H0 the p-value is uniform: 20 independent runs at 1% should fail at most twice
    # (binomial tail probability < 2e-3).
    fails = 0
    for seed in range(20):
        w = uniform_sphere(np.random.default_rng(100 + seed).random((20_000, 2)))
        fails += not chi2_sphere(w, uniform_sphere_pdf, res=(8, 16)).passed()
    assert fails <= 2


def test_bin_masses_across_a_discontinuity():
    # Uniform density on the upper hemisphere, cap = hemisphere x > 0: the jump at z = 0 cuts
    # through the bins. The exact mass in the cap is a quarter sphere / (2 pi) = 1/2.
    w = uniform_sphere(np.random.default_rng(3).random((100_000, 2)))
    w[:, 2] = np.abs(w[:, 2])
    pdf = lambda d: np.where(d[..., 2] > 0, 1 / (2 * np.pi), 0.0)  # noqa: E731
    res = chi2_sphere(w, pdf, axis=(1.0, 0.0, 0.0), theta_max=np.pi / 2)
    assert res.mass_in_cap == pytest.approx(0.5, abs=2e-4)
    assert res.passed(), res


def test_lobe_cap_contains_the_quantile():
    w = cosine_hemisphere(np.random.default_rng(4).random((50_000, 2)))
    axis, th = lobe_cap(w, quantile=0.9)
    np.testing.assert_allclose(axis, [0, 0, 1], atol=0.02)
    # P(theta < t) = sin^2 t for the cosine lobe: the 0.9 quantile is asin(sqrt(0.9)), x 1.05.
    assert th == pytest.approx(1.05 * np.arcsin(np.sqrt(0.9)), rel=0.02)


def _direction(theta_deg, phi_deg):
    th, ph = np.radians(theta_deg), np.radians(phi_deg)
    return np.array([np.sin(th) * np.cos(ph), np.sin(th) * np.sin(ph), np.cos(th)])


@pytest.mark.parametrize("theta", [0.0, 60.0, 89.0])
def test_slope_warp_domains_have_closed_form_masses(theta):
    # The power-cosine density 5 z^4 / (2 pi) has mass 1 on the upper hemisphere: over all
    # normals, and over reflected directions (the half-vector Jacobian 4 (wo.h) h_z^3, the
    # horizon-disk packing and the chord clipping are all exercised). Visible normals from
    # wo = z: the same hemisphere.
    wo = _direction(theta, 35)
    scale = [[1.0, 0.2], [0.0, 0.5]]
    pdf = lambda d: 5 * np.maximum(d[..., 2], 0) ** 4 / (2 * np.pi)  # noqa: E731
    u = np.random.default_rng(5).random((20_000, 2))
    z = u[:, 0] ** (1 / 5)  # inverse CDF of 5 z^4 dz
    r = np.sqrt(1 - z * z)
    w = np.stack([r * np.cos(2 * np.pi * u[:, 1]), r * np.sin(2 * np.pi * u[:, 1]), z], -1)
    warps = [slope_warp((0.1, -0.2), scale), slope_warp((0.1, -0.2), scale, wo=wo, reflect=True),
             slope_warp((0.1, -0.2), scale, wo=_direction(0, 0))]
    for warp in warps:
        res = chi2_warped(w, pdf, warp, res=(8, 8))
        # the bins are integrated to 0.05 sd of their counts: |error| < 0.05 sqrt(64 / n)
        assert res.mass_in_cap == pytest.approx(1.0, abs=1e-3)
        assert res.passed(), res


def test_chi2_warped_accepts_cosine_and_rejects_uniform():
    wo = _direction(60, 10)
    warp = slope_warp((0.0, 0.0), [[1.0, 0.0], [0.0, 1.0]], wo=wo, reflect=True)
    w = cosine_hemisphere(np.random.default_rng(7).random((20_000, 2)))
    assert chi2_warped(w, cosine_hemisphere_pdf, warp, res=(16, 16)).passed()
    uni = lambda d: np.where(d[..., 2] > 0, 1 / (2 * np.pi), 0.0)  # noqa: E731
    assert chi2_warped(w, uni, warp, res=(16, 16)).p_value < 1e-6


def test_chi2_warped_bad_input():
    w = cosine_hemisphere(np.random.default_rng(8).random((100, 2)))
    with pytest.raises(PrefilterError, match="warp"):
        chi2_warped(w, cosine_hemisphere_pdf, "slopes")
    with pytest.raises(PrefilterError, match="scale"):
        slope_warp((0, 0), [[1.0, 2.0], [2.0, 4.0]])
    with pytest.raises(PrefilterError, match="wo"):
        slope_warp((0, 0), reflect=True)
    with pytest.raises(PrefilterError, match="spread"):
        slope_warp((0, 0), spread=0.0)


@pytest.mark.parametrize("above", [(0.0, 0.0, 1.0), (0.6, -0.3, 0.5), (0.0, 0.0, -1.0)])
def test_above_bins_only_the_half_space_exactly(above):
    # Uniform directions: the half space w.v > 0 holds mass 1/2 whatever the cap, and its arcs
    # are integrated exactly (a density jump there would otherwise need refinement).
    w = uniform_sphere(np.random.default_rng(4).random((100_000, 2)))
    axis, th = (0.3, 0.4, 0.8), 2.0
    res = chi2_sphere(w, uniform_sphere_pdf, axis=axis, theta_max=th, above=above, max_refine=0)
    cap = (1 - np.cos(th)) / 2
    assert res.passed(), res
    assert 0.0 < res.mass_in_cap < cap
    full = chi2_sphere(w, uniform_sphere_pdf, theta_max=np.pi, above=above, max_refine=0)
    assert full.mass_in_cap == pytest.approx(0.5, abs=1e-12)


def test_above_counts_lower_draws_outside():
    # Cosine draws half of them flipped below the horizon: tested on the upper hemisphere with
    # half the cosine density the flipped ones fall in the outside bin, with its expected mass 1/2.
    rng = np.random.default_rng(5)
    w = cosine_hemisphere(rng.random((100_000, 2)))
    w[::2, 2] *= -1.0
    res = chi2_sphere(w, lambda d: 0.5 * cosine_hemisphere_pdf(d), above=(0, 0, 1.0))
    assert res.passed(), res
    assert res.mass_in_cap == pytest.approx(0.5, abs=1e-6)
    wrong = chi2_sphere(w, cosine_hemisphere_pdf, above=(0, 0, 1.0))
    assert wrong.p_value < 1e-6


def test_warp_integral_of_densities_is_one():
    # the NDF's projected area and the visible normals of a grazing view over their domains
    from prefilter.microfacet import Beckmann

    model = Beckmann([0.2, -0.1], [[0.05, 0.02], [0.02, 0.01]])
    wo = np.array([np.sin(1.3), 0.0, np.cos(1.3)])
    scale = np.linalg.cholesky(model.slope_cov)
    proj = warp_integral(lambda m: model.D(m) * m[..., 2], slope_warp(model.mean_slope, scale))
    vis = warp_integral(lambda m: model.pdf_vndf(wo, m),
                        slope_warp(model.mean_slope, scale, wo=wo))
    assert proj == pytest.approx(1.0, abs=1e-9) and vis == pytest.approx(1.0, abs=1e-8)
    with pytest.raises(PrefilterError, match="warp"):
        warp_integral(lambda m: m[..., 2], "square")
