"""Eq. 4 (mean resultant length) and eq. 5 (its inverse) of Tao et al. 2021.

References: Gauss-Legendre quadrature of eq. 4 as written (the LTC density over the hemisphere),
the 1-D integral of equations.md 4, and Monte Carlo with the LTC class's own sampler.
"""

from __future__ import annotations

import numpy as np
import pytest

from prefilter.errors import PrefilterError
from prefilter.ltc import LTC
from prefilter.multiscale import alpha_meso, alpha_meso_exact, mean_resultant_length

# crosses every branch: a = 0, the artanh form, the series (|1 - a^2| < 1/4), the arctan form
ALPHAS = np.array([0.0, 1e-6, 0.003, 0.03, 0.1, 0.3, 0.5, 0.86, 0.87, 0.95, 1.0, 1.05, 1.11,
                   1.12, 1.5, 3.0])


def _gauss_legendre(f, lo, hi, n):
    x, w = np.polynomial.legendre.leggauss(n)
    t = lo + (hi - lo) * (x + 1) / 2
    return np.sum(w * f(t)) * (hi - lo) / 2


def _equations_md_integral(a):
    # 2 int_0^1 u^2 / sqrt(a^2 (1 - u^2) + u^2) du; u = sin-like split keeps the a -> 0 peak
    f = lambda u: 2 * u * u / np.sqrt(a * a * (1 - u * u) + u * u)  # noqa: E731
    edges = np.concatenate([[0.0], np.geomspace(max(a, 1e-8) * 1e-3, 1.0, 40)])
    return sum(_gauss_legendre(f, lo, hi, 40) for lo, hi in zip(edges[:-1], edges[1:]))


def test_closed_form_matches_1d_quadrature():
    got = mean_resultant_length(ALPHAS)
    want = np.array([_equations_md_integral(a) for a in ALPHAS])
    np.testing.assert_allclose(got, want, rtol=0, atol=1e-12)
    assert got[0] == 1.0 and abs(got[ALPHAS == 1.0][0] - 2 / 3) < 1e-15


@pytest.mark.parametrize("a", [0.05, 0.3, 1.0])
def test_closed_form_is_eq4_over_the_hemisphere(a):
    # eq. 4 literally: int b_z gamma_me(b) d omega, gamma_me = LTC(diag(a, a, 1)).eval,
    # integrated in (cos theta, phi) with nodes packed near the pole where the lobe sits
    ltc = LTC(np.diag([a, a, 1.0]))
    x, w = np.polynomial.legendre.leggauss(200)
    # cos theta = 1 - s^2 (1 - 0) with s in [0, 1]: d cos = 2 s ds resolves narrow lobes
    s = (x + 1) / 2
    cos_t = 1 - s * s
    ws = w / 2 * 2 * s
    sin_t = np.sqrt(1 - cos_t**2)
    b = np.stack([sin_t, np.zeros_like(sin_t), cos_t], -1)
    # isotropic: the phi integral is 2 pi times the value at phi = 0
    got = 2 * np.pi * np.sum(ws * cos_t * ltc.eval(b))
    total = 2 * np.pi * np.sum(ws * ltc.eval(b))
    assert abs(total - 1.0) < 1e-6
    assert abs(float(mean_resultant_length(a)) - got) < 1e-6


def test_closed_form_matches_monte_carlo_of_the_ltc_sampler():
    rng = np.random.default_rng(5)
    for a in (0.02, 0.4, 0.9):
        z = LTC(np.diag([a, a, 1.0])).sample(rng.random((200_000, 2)))[:, 2]
        se = z.std() / np.sqrt(len(z))
        assert abs(z.mean() - float(mean_resultant_length(a))) < 4 * se + 1e-12


def test_decreasing():
    a = np.linspace(0, 2, 2001)
    assert np.all(np.diff(mean_resultant_length(a)) < 0)


def test_exact_inverse_round_trips():
    a = np.linspace(0.0, 1.0, 1001)
    np.testing.assert_allclose(alpha_meso_exact(mean_resultant_length(a)), a, atol=1e-12)
    r = np.linspace(2 / 3, 1.0, 5001)
    # the interpolated default against the closed form, both directions
    np.testing.assert_allclose(mean_resultant_length(alpha_meso(r)), r, rtol=0, atol=3e-8)
    np.testing.assert_allclose(alpha_meso(mean_resultant_length(a)), a, rtol=0, atol=1e-6)


def test_paper_eq5_within_one_percent_where_it_holds():
    r = np.linspace(2 / 3, 1.0 - 1e-9, 20001)
    exact = alpha_meso_exact(r)
    paper = alpha_meso(r, "paper")
    # Figure 2 plots r against alpha: there eq. 5 overlaps the exact curve everywhere
    np.testing.assert_array_less(np.abs(mean_resultant_length(paper) - r) / r, 0.01)
    # in alpha, within 1 % for alpha_me in [0.13, 1] (r <= 0.97) ...
    keep = exact >= 0.13
    assert np.max(np.abs(paper[keep] - exact[keep]) / exact[keep]) < 0.01
    # ... but not for smooth footprints: up to 0.012 absolute (about -45 %) near alpha 0.027
    worst = np.argmax(np.abs(paper - exact))
    assert 0.011 < abs(paper[worst] - exact[worst]) < 0.013
    assert 0.02 < exact[worst] < 0.035


def test_clamps():
    assert alpha_meso(1.0) == 0.0 and alpha_meso(1.0, "paper") == 0.0
    np.testing.assert_array_equal(alpha_meso([0.0, 0.5, 2 / 3]), 1.0)
    np.testing.assert_array_equal(alpha_meso([0.0, 0.5, 2 / 3], "paper"), 1.0)
    assert alpha_meso(1.0 + 5e-7) == 0.0


@pytest.mark.parametrize("bad", [-0.1, 1.01, np.nan, "x"])
def test_rejects_bad_lengths(bad):
    with pytest.raises(PrefilterError, match="r"):
        alpha_meso(bad)


def test_rejects_bad_variant_and_alpha():
    with pytest.raises(PrefilterError, match="variant"):
        alpha_meso(0.9, "fast")
    with pytest.raises(PrefilterError, match="alpha"):
        mean_resultant_length(-0.5)
