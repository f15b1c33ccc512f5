"""Section 6 combinations against a Monte Carlo of eq. 1 over independent (f, h, s)."""

import numpy as np
import pytest
from scipy.stats import norm

from prefilter.colormap.combine import combine_linear, combine_product
from prefilter.colormap.height import mean_visibility
from prefilter.errors import PrefilterError

LO, LI = 0.8, 2.1  # Lambda of the view and of the light
WO = np.array([0.5, 0.2, np.sqrt(1 - 0.29)])
COV = np.array([[0.06, 0.01], [0.01, 0.03]])


def _c0(f):
    return np.stack([np.sin(2 * f), f * f], -1)


def _ch(h):
    return np.stack([np.tanh(2 * h), np.cos(h)], -1)


def _cs(s):
    return np.stack([np.exp(s[:, 0]), 1.0 + s[:, 1] ** 2], -1)


def _samples(n, seed):
    rng = np.random.default_rng(seed)
    f = rng.normal(0.3, 0.7, n)
    h = rng.normal(0.0, 1.0, n)
    s = rng.multivariate_normal([0.05, -0.1], COV, n)
    p = norm.cdf(h)
    proj = np.maximum(0.0, WO[2] - s @ WO[:2])  # projected area towards the view
    return f, h, s, p**LO, p**LI, proj


def _ingredients():
    """Each filtered term from its own (independent) sample stream."""
    f, h, s, vo, vi, proj = _samples(400_000, 1)
    c0 = _c0(f).mean(0)
    ch = (_ch(h) * (vo * vi)[:, None]).mean(0) / vo.mean()  # eq. 14
    cs = (_cs(s) * proj[:, None]).mean(0) / proj.mean()  # eq. 20
    return c0, ch, cs


def test_linear_combination_matches_eq1():
    f, h, s, vo, vi, proj = _samples(400_000, 2)
    k = np.array([0.5, 1.5, -0.7])
    colour = k[0] * _c0(f) + k[1] * _ch(h) + k[2] * _cs(s)
    wt = vo * vi * proj
    truth = (colour * wt[:, None]).mean(0) / (vo * proj).mean()  # eq. 1 with L = rho = 1
    c0, ch, cs = _ingredients()
    got = combine_linear(k, c0, ch, cs, mean_visibility(LO, LI))
    np.testing.assert_allclose(got, truth, atol=0.015)
    # leaving V_bar out of the texture and slope terms (a plausible mistake) is far off
    wrong = k[0] * c0 + k[1] * ch + k[2] * cs
    assert np.abs(wrong - truth).max() > 0.05


def test_product_combination_matches_eq1():
    f, h, s, vo, vi, proj = _samples(400_000, 3)
    colour = _c0(f) * _ch(h) * _cs(s)
    truth = (colour * (vo * vi * proj)[:, None]).mean(0) / (vo * proj).mean()
    c0, ch, cs = _ingredients()
    np.testing.assert_allclose(combine_product(c0, ch, cs), truth, atol=0.015)


def test_bad_kappa_raises():
    with pytest.raises(PrefilterError, match="kappa"):
        combine_linear([1.0, 2.0], np.ones(3), np.ones(3), np.ones(3), 1.0)
