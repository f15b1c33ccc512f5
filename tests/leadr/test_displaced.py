"""The displaced-geometry reference: exact bilinear moments, flat-surface closed forms, and
Smith's masking against the geometry's own visibility (ray marching)."""

import numpy as np

from prefilter.leadr import point_light
from prefilter.leadr.displaced import (gradient, march, cell_moments, displaced_radiance,
                                       naive_radiance, normal_mapped_radiance)
from prefilter.microfacet import Beckmann
from prefilter.texture import height_map


def _unit(v):
    v = np.asarray(v, float)
    return v / np.linalg.norm(v)


def test_cell_moments_match_monte_carlo_over_the_bilinear_surface():
    rng = np.random.default_rng(0)
    h = rng.normal(size=(8, 8))
    x, y = rng.random(400_000) * 8, rng.random(400_000) * 8
    s = gradient(h, x, y)
    mc = np.stack([s[:, 0], s[:, 1], s[:, 0] ** 2, s[:, 1] ** 2, s[:, 0] * s[:, 1]], -1).mean(0)
    exact = cell_moments(h).reshape(-1, 5).mean(0)
    np.testing.assert_allclose(exact, mc, atol=0.02 * np.abs(mc).max())
    np.testing.assert_allclose(exact[:2], 0.0, atol=1e-12)  # periodic surface


def test_flat_surface_reproduces_the_closed_forms():
    h = np.zeros((16, 16))
    wo, wi = _unit([0.5, 0.1, 0.8]), _unit([-0.4, 0.2, 0.85])
    spec = point_light(wo, wi, [0.0, 0.0], np.eye(2) * 0.01)
    for f in (displaced_radiance, normal_mapped_radiance, naive_radiance):
        np.testing.assert_allclose(f(h, 16, 0, 0, wo, wi, k=8, sigma_b=0.1), spec, rtol=1e-9)
        np.testing.assert_allclose(f(h, 16, 0, 0, wo, wi, k=8, specular=False, albedo=0.5),
                                   0.5 / np.pi * wi[2], rtol=1e-9)


def test_smith_masking_equals_the_visible_fraction_of_a_gaussian_height_field():
    # Supplemental eq. 8: G1(wo) = E[V <wo, m> / m_z] / E[<wo, m> / m_z] over the surface.
    h = np.ascontiguousarray(height_map("gaussian", size=128, seed=0, rms_slope=0.5,
                                        corr_length=4.0).height)
    m = cell_moments(h).reshape(-1, 5).mean(0)
    model = Beckmann([0.0, 0.0], [[m[2], m[4]], [m[4], m[3]]])
    rng = np.random.default_rng(1)
    n = 60_000
    x, y = rng.random(n) * 128, rng.random(n) * 128
    fx, fy = np.floor(x).astype(int), np.floor(y).astype(int)
    tx, ty = x - fx, y - fy
    j1, i1 = (fx + 1) % 128, (fy + 1) % 128
    z = ((h[fy, fx] * (1 - tx) + h[fy, j1] * tx) * (1 - ty)
         + (h[i1, fx] * (1 - tx) + h[i1, j1] * tx) * ty)
    s = gradient(h, x, y)
    for wz in (0.5, 0.25):
        wo = np.array([np.sqrt(1 - wz * wz), 0.0, wz])
        w = np.maximum(wo[2] - s @ wo[:2], 0.0)
        t = march(h, x + 1e-5 * wo[0], y + 1e-5 * wo[1], z + 1e-5 * wo[2], np.full(n, wo[0]),
                   np.full(n, wo[1]), np.full(n, wo[2]), h.min() - 1, h.max(),
                   0.05 / np.hypot(wo[0], wo[2]), 100_000)
        visible = np.sum(w * ~np.isfinite(t)) / np.sum(w)
        assert abs(visible - float(model.G1(wo))) < 0.015, (wz, visible, float(model.G1(wo)))
