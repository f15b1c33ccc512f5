"""Symmetries (anisotropic-LTC paper, section 6, eqs. 13-16), on GGX itself and on the table."""

import numpy as np
import pytest

from prefilter.ltc import LTC
from prefilter.ltc.aniso import symmetry
from prefilter.microfacet import GGX
from prefilter.sphere import uniform_sphere


def view(theta_deg, phi_deg):
    t, p = np.radians(theta_deg), np.radians(phi_deg)
    return np.array([np.sin(t) * np.cos(p), np.sin(t) * np.sin(p), np.cos(t)])


SX, SY = np.diag([-1.0, 1, 1]), np.diag([1.0, -1, 1])
P = symmetry.SWAP_XY


def test_ggx_lobe_symmetries():
    """The facts eqs. 13-15 rely on, checked on GGX.eval (independent of the table)."""
    rng = np.random.default_rng(0)
    wi = uniform_sphere(rng.random((2000, 2)))
    wo = view(60, 25)
    g, gs = GGX(0.4, 0.1), GGX(0.1, 0.4)
    for S in (SX, SY, SX @ SY):
        np.testing.assert_allclose(g.eval(S @ wo, wi @ S), g.eval(wo, wi), rtol=1e-12)
    np.testing.assert_allclose(gs.eval(P @ wo, wi @ P), g.eval(wo, wi), rtol=1e-12)


def test_conjugation_maps_ltc_densities():
    rng = np.random.default_rng(1)
    M = np.array([[0.3, 0.1, -0.5], [0.05, 0.2, 0.3], [0.1, 0.0, 0.8]])
    w = uniform_sphere(rng.random((1000, 2)))
    for Q, M2 in ((SX, symmetry.mirror(M, -1, 1)), (SY, symmetry.mirror(M, 1, -1)),
                  (P, symmetry.swap_xy(M))):
        np.testing.assert_allclose(LTC(M2).eval(w @ Q), LTC(M).eval(w), rtol=1e-10)


def _configs(n, seed):
    rng = np.random.default_rng(seed)
    t = np.radians(rng.uniform(0, 85, n))
    p = rng.uniform(-np.pi, np.pi, n)
    wo = np.stack([np.sin(t) * np.cos(p), np.sin(t) * np.sin(p), np.cos(t)], -1)
    return wo, rng.uniform(0.02, 1, n), rng.uniform(0.02, 1, n)


def test_lookup_mirror_and_swap_exact(table):
    wo, ax, ay = _configs(500, 2)
    M, mag, fr = table.lookup(wo, ax, ay)
    for S, s in ((SX, (-1, 1)), (SY, (1, -1)), (SX @ SY, (-1, -1))):
        M2, mag2, fr2 = table.lookup(wo @ S, ax, ay)
        np.testing.assert_allclose(M2, symmetry.mirror(M, *s), rtol=0, atol=1e-14)
        np.testing.assert_array_equal(mag2, mag)
        np.testing.assert_array_equal(fr2, fr)
    M3, mag3, _ = table.lookup(wo @ P, ay, ax)
    np.testing.assert_allclose(M3, symmetry.swap_xy(M), rtol=0, atol=1e-14)
    np.testing.assert_array_equal(mag3, mag)


def test_lookup_continuous_across_fold_boundaries(table):
    """Folding (eqs. 13, 15) must not create seams: M changes by O(eps) across each boundary."""
    eps = 1e-7
    rng = np.random.default_rng(3)
    for _ in range(50):
        t = np.radians(rng.uniform(1, 85))
        a = rng.uniform(0.05, 1)
        b = rng.uniform(0.05, 1)
        for p0 in (0.0, np.pi / 2, np.pi, -np.pi / 2):
            wo = np.stack([view(np.degrees(t), np.degrees(p0 + d)) for d in (-eps, eps)])
            M, mag, _ = table.lookup(wo, a, b)
            assert np.abs(M[0] - M[1]).max() < 1e-4
        wo = view(np.degrees(t), rng.uniform(-180, 180))
        M, _, _ = table.lookup(np.stack([wo, wo]), a, np.array([a * (1 - eps), a * (1 + eps)]))
        assert np.abs(M[0] - M[1]).max() < 1e-4


def test_enforced_entries(table):
    """Eq. 16 on the stored matrices: zero patterns and phi-independence at theta = 0."""
    M = table.M
    assert np.all(M[:, 0][..., [0, 1, 1, 2], [1, 0, 2, 1]] == 0)
    assert np.all(M[:, -1][..., [0, 1, 0, 2], [1, 0, 2, 0]] == 0)
    off = ~np.eye(3, dtype=bool)
    assert np.all(M[0][..., off] == 0)
    assert np.all(M[0] == M[0, :1])
    iso = M[:, :, :, -1]
    np.testing.assert_allclose(iso, symmetry.swap_xy(iso[:, ::-1]), atol=1e-15)
    np.testing.assert_allclose(np.linalg.norm(M[..., :, 2], axis=-1), 1.0, rtol=1e-12)


def test_canonical_view_domain():
    wo, ax, ay = _configs(200, 4)
    v, alpha, ratio, swap, sx, sy = symmetry.canonical_view(wo, ax, ay)
    assert np.all(v[..., :2] >= 0) and np.all(ratio <= 1) and np.all(alpha == np.maximum(ax, ay))
    with pytest.raises(ValueError):
        symmetry.enforce(np.zeros((2, 3, 2, 2, 3, 3)), [0, 1], [0, 0.2, 1.0], [0.5, 1])
