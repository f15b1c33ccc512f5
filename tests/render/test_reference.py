"""The reference integrator: light sampling, MIS estimator, convergence, determinism.

Every check compares against an independent computation: Gauss-Legendre quadrature over the light's
area, the GGX albedo quadrature, Monte Carlo over the sphere, or a closed form.
"""

from __future__ import annotations

import numpy as np
import pytest

from prefilter.errors import PrefilterError
from prefilter.microfacet import GGX
from prefilter.render.lights import (
    LightSet,
    QuadLight,
    quad_light_pdf,
    quad_light_sample,
    sample_quad_area,
)
from prefilter.render.estimator import pdf_brdf, sample_brdf
from prefilter.render.driver import stratified_offsets
from prefilter.render.reference import estimate_quad, shade_reference
from prefilter.render.shading import brdf_cos, local_view
from prefilter.sphere.sampling import uniform_sphere

# A 1 x 0.6 rectangle at height 1.2, shifted sideways, emitting downwards (corners counter-clockwise
# seen from below).
RECT = np.array([[0.2, -0.3, 1.2], [0.2, 0.3, 1.2], [1.2, 0.3, 1.2], [1.2, -0.3, 1.2]])


def _frame(n):
    return np.tile([1.0, 0, 0], (n, 1)), np.tile([0, 1.0, 0], (n, 1)), np.tile([0, 0, 1.0], (n, 1))


def _quadrature(light, wo, ax, ay, base, f0, panels=48, order=8):
    """Composite Gauss-Legendre over the (parallelogram) light: integral of f cos L cos_l / d^2."""
    x, w = np.polynomial.legendre.leggauss(order)
    edges = np.linspace(0.0, 1.0, panels + 1)
    s = ((edges[:-1, None] + edges[1:, None]) / 2 + (edges[1:, None] - edges[:-1, None]) / 2 * x)
    ws = ((edges[1:, None] - edges[:-1, None]) / 2 * w)
    s, ws = s.ravel(), ws.ravel()
    S, T = np.meshgrid(s, s, indexing="ij")
    W = np.outer(ws, ws).ravel()
    v = light.vertices
    y = v[0] + S.ravel()[:, None] * (v[1] - v[0]) + T.ravel()[:, None] * (v[3] - v[0])
    area = np.linalg.norm(np.cross(v[1] - v[0], v[3] - v[0]))
    d2 = np.sum(y * y, axis=-1)
    wi = y / np.sqrt(d2)[:, None]
    cos_l = np.maximum(0.0, -(wi @ light.normal))
    n = len(y)
    f = brdf_cos(np.tile(wo, (n, 1)), wi, np.full(n, ax), np.full(n, ay), np.tile(base, (n, 1)),
                 np.tile(f0, (n, 1)))
    return np.sum(f * (cos_l / d2 * area * W)[:, None], axis=0) * light.radiance


def _mis(light, wo, ax, ay, base, f0, n, seed):
    t, b, nn = _frame(n)
    u = np.random.default_rng(seed).random((n, 4))
    est = estimate_quad(light, np.zeros((n, 3)), t, b, nn, np.tile(wo, (n, 1)), np.full(n, ax),
                        np.full(n, ay), np.tile(base, (n, 1)), np.tile(f0, (n, 1)), u)
    return est.mean(0), est.std(0) / np.sqrt(n)


def test_quad_light_rejects_bad_input():
    with pytest.raises(PrefilterError, match="vertices"):
        QuadLight(np.zeros((3, 3)), 1.0)
    with pytest.raises(PrefilterError, match="coplanar"):
        QuadLight(RECT + np.array([[0, 0, 0], [0, 0, 0.3], [0, 0, 0], [0, 0, 0]]), 1.0)
    with pytest.raises(PrefilterError, match="convex"):
        QuadLight(RECT[[0, 2, 1, 3]], 1.0)
    with pytest.raises(PrefilterError, match="radiance"):
        QuadLight(RECT, [-1.0, 0, 0])


def test_quad_normal_points_to_counter_clockwise_side():
    # Seen from below (looking up +z with y up on screen, x points left) RECT runs
    # counter-clockwise, so it emits downwards.
    assert np.allclose(QuadLight(RECT, 1.0).normal, [0, 0, -1])
    assert np.isclose(QuadLight(RECT, 1.0).area, 0.6)


def test_area_samples_are_uniform_on_a_trapezoid():
    # Trapezoid: exact centroid and second moment by closed form (x in [0, 1], y in [0, 1 + x]).
    v = np.array([[0, 0, 0], [1, 0, 0], [1, 2, 0], [0, 1, 0]], dtype=float)
    p = sample_quad_area(v, np.random.default_rng(1).random((400_000, 2)))
    area = 1.5
    mean_x = (1 / 2 + 1 / 3) / area  # integral of x (1 + x) dx
    mean_y = (1 / 2) * (1 + 1 + 1 / 3) / area  # integral of (1 + x)^2 / 2 dx
    se = 1.0 / np.sqrt(len(p))
    assert abs(p[:, 0].mean() - mean_x) < 5 * se
    assert abs(p[:, 1].mean() - mean_y) < 5 * se
    assert np.all((p[:, 1] <= 1 + p[:, 0] + 1e-12) & (p[:, 1] >= 0) & (p[:, 2] == 0))


def test_light_pdf_integrates_to_one_and_matches_sampler():
    light = QuadLight(RECT, 1.0)
    n = 400_000
    w = uniform_sphere(np.random.default_rng(2).random((n, 2)))
    pdf = quad_light_pdf(light, np.zeros((n, 3)), w)
    est = pdf * 4 * np.pi
    assert abs(est.mean() - 1.0) < 5 * est.std() / np.sqrt(n)
    wi, p_s = quad_light_sample(light, np.zeros((1000, 3)),
                                np.random.default_rng(3).random((1000, 2)))
    assert np.allclose(quad_light_pdf(light, np.zeros((1000, 3)), wi), p_s, rtol=1e-9)
    # Behind the light (above it) nothing is emitted towards the point.
    above = np.tile([0.5, 0.0, 3.0], (1000, 1))
    assert np.all(
        quad_light_sample(light, above, np.random.default_rng(4).random((1000, 2)))[1] == 0)
    assert np.all(quad_light_pdf(light, above, -wi) == 0)


@pytest.mark.parametrize("theta", [0.0, 50.0, 80.0])
def test_brdf_pdf_integrates_to_one(theta):
    t = np.radians(theta)
    wo = np.array([np.sin(t), 0.0, np.cos(t)])
    n = 200_000
    w = uniform_sphere(np.random.default_rng(5).random((n, 2)))
    wot = np.tile(wo, (n, 1))
    for ax, ay in [(0.4, 0.4), (0.5, 0.25)]:
        est = pdf_brdf(wot, w, np.full(n, ax), np.full(n, ay), np.full(n, 0.7)) * 4 * np.pi
        assert abs(est.mean() - 1.0) < 5 * est.std() / np.sqrt(n)
    # And the sampler lands where its density says: mean of 1/pdf over its samples = 4 pi.
    wi = sample_brdf(wot, np.random.default_rng(6).random((n, 2)), np.full(n, 0.4),
                     np.full(n, 0.4), np.full(n, 0.7))
    p = pdf_brdf(wot, wi, np.full(n, 0.4), np.full(n, 0.4), np.full(n, 0.7))
    assert np.all(p > 0)


@pytest.mark.parametrize(
    "theta, ax, ay, base, f0",
    [
        (30.0, 0.3, 0.3, [0.5, 0.2, 0.1], [0.04, 0.04, 0.04]),
        (70.0, 0.2, 0.5, [0.0, 0.0, 0.0], [1.0, 0.8, 0.3]),
        (0.0, 0.6, 0.6, [0.8, 0.8, 0.8], [0.5, 0.5, 0.5]),
    ],
)
def test_mis_estimator_matches_quadrature(theta, ax, ay, base, f0):
    light = QuadLight(RECT, [1.0, 2.0, 0.5])
    t = np.radians(theta)
    wo = np.array([-np.sin(t), 0.0, np.cos(t)])  # specular peak towards the light (+x)
    base, f0 = np.array(base), np.array(f0)
    ref = _quadrature(light, wo, ax, ay, base, f0)
    est, se = _mis(light, wo, ax, ay, base, f0, 200_000, seed=7)
    assert np.all(np.abs(est - ref) < 5 * se + 1e-9), (est, ref, se)
    assert np.all(se < 0.02 * ref)  # the estimator is useful, not just unbiased


def test_mis_estimator_for_light_straddling_the_horizon():
    v = np.array([[1.0, -0.5, -0.4], [1.0, 0.5, -0.4], [1.0, 0.5, 0.6], [1.0, -0.5, 0.6]])
    light = QuadLight(v[::-1].copy(), 1.0)  # faces -x, towards the point
    assert light.normal[0] < -0.99
    wo = np.array([-np.sin(0.6), 0.0, np.cos(0.6)])
    base, f0 = np.array([0.3, 0.3, 0.3]), np.array([0.9, 0.9, 0.9])
    ref = _quadrature(light, wo, 0.25, 0.25, base, f0, panels=96)
    est, se = _mis(light, wo, 0.25, 0.25, base, f0, 200_000, seed=8)
    assert np.all(np.abs(est - ref) < 5 * se + 1e-9), (est, ref, se)


def _box_lights(radiance=1.0):
    """Ceiling and 4 walls of the box [-1, 1]^2 x [0, 2], emitting inwards: they cover exactly the
    upper hemisphere of the origin."""
    c = np.array([[x, y, z] for x in (-1, 1) for y in (-1, 1) for z in (0, 2)], dtype=float)

    def quad(idx, inward):
        v = c[list(idx)]
        ctr = v.mean(0)
        order = np.argsort(np.arctan2(*(np.linalg.svd(v - ctr)[2][:2] @ (v - ctr).T)[::-1]))
        v = v[order]
        n = np.cross(v[1] - v[0], v[2] - v[0])
        return QuadLight(v if n @ inward > 0 else v[::-1].copy(), radiance)

    faces = [((1, 3, 5, 7), [0, 0, -1]), ((0, 1, 2, 3), [1, 0, 0]), ((4, 5, 6, 7), [-1, 0, 0]),
             ((0, 1, 4, 5), [0, 1, 0]), ((2, 3, 6, 7), [0, -1, 0])]
    return LightSet(quads=tuple(quad(i, np.array(d, float)) for i, d in faces))


@pytest.mark.parametrize("theta, ax, ay", [(20.0, 0.3, 0.3), (75.0, 0.15, 0.6)])
def test_white_furnace_box(theta, ax, ay):
    lights = _box_lights()
    t = np.radians(theta)
    wo = np.array([np.sin(t) * 0.6, np.sin(t) * 0.8, np.cos(t)])
    n = 100_000
    tt, bb, nn = _frame(n)
    u = np.random.default_rng(9).random((n, len(lights.quads), 4))
    base = np.tile([0.5, 0.0, 0.0], (n, 1))
    f0 = np.tile([1.0, 1.0, 0.0], (n, 1))
    est = shade_reference(np.zeros((n, 3)), tt, bb, nn, np.tile(wo, (n, 1)), np.full(n, ax),
                          np.full(n, ay), base, f0, lights, u)
    # Red: diffuse 0.5 plus specular albedo with F = 1; green: albedo; blue: Schlick with f0 = 0.
    albedo = float(GGX(ax, ay).albedo(wo))
    m, se = est.mean(0), est.std(0) / np.sqrt(n)
    assert abs(m[0] - (0.5 + albedo)) < 5 * se[0]
    assert abs(m[1] - albedo) < 5 * se[1]
    assert 0 < m[2] < albedo


def test_mis_error_falls_as_inverse_square_root():
    light = QuadLight(RECT, 1.0)
    wo = np.array([-np.sin(0.5), 0.0, np.cos(0.5)])
    base, f0 = np.array([0.5, 0.5, 0.5]), np.array([0.04, 0.04, 0.04])
    ref = _quadrature(light, wo, 0.3, 0.3, base, f0)[0]
    rng = np.random.default_rng(10)
    errs = []
    for n in (16, 256):
        trials = 400
        t, b, nn = _frame(n * trials)
        u = rng.random((n * trials, 4))
        est = estimate_quad(light, np.zeros((n * trials, 3)), t, b, nn,
                            np.tile(wo, (n * trials, 1)),
                            np.full(n * trials, 0.3), np.full(n * trials, 0.3),
                            np.tile(base, (n * trials, 1)), np.tile(f0, (n * trials, 1)), u)[:, 0]
        errs.append(np.sqrt(np.mean((est.reshape(trials, n).mean(1) - ref) ** 2)))
    slope = np.log(errs[1] / errs[0]) / np.log(16)
    assert -0.6 < slope < -0.4, (errs, slope)


def test_view_below_shading_horizon_is_clamped():
    t, b, n = _frame(2)
    wo = local_view(np.array([[0.6, 0, -0.8], [0, 0.6, 0.8]]), t, b, n)
    assert np.all(wo[:, 2] > 0) and np.allclose(np.linalg.norm(wo, axis=-1), 1)


def test_stratified_offsets_one_per_stratum():
    rng = np.random.default_rng(11)
    for spp in (16, 7):
        o = stratified_offsets(spp, 50, rng)
        assert o.shape == (50, spp, 2) and np.all((o >= 0) & (o < 1))
        k = int(round(np.sqrt(spp)))
        if k * k == spp:
            cells = np.floor(o[..., 0] * k) + k * np.floor(o[..., 1] * k)
        else:
            cells = np.floor(o[..., 0] * spp)
            assert np.all(np.sort(np.floor(o[..., 1] * spp), axis=1) == np.arange(spp))
        assert np.all(np.sort(cells, axis=1) == np.arange(spp))


def test_shade_reference_deterministic():
    lights = LightSet(quads=(QuadLight(RECT, 1.0),))
    n = 1000
    t, b, nn = _frame(n)
    args = (np.zeros((n, 3)), t, b, nn, np.tile([0, 0, 1.0], (n, 1)), np.full(n, 0.3),
            np.full(n, 0.3), np.full((n, 3), 0.5), np.full((n, 3), 0.04), lights)
    a = shade_reference(*args, np.random.default_rng(12).random((n, 1, 4)))
    b2 = shade_reference(*args, np.random.default_rng(12).random((n, 1, 4)))
    assert a.tobytes() == b2.tobytes()


def test_numba_kernel_matches_numpy_estimator():
    from prefilter.render.reference import estimate_quad_fast

    rng = np.random.default_rng(13)
    n = 20_000
    q, _ = np.linalg.qr(rng.normal(size=(n, 3, 3)) * 0.3 + np.eye(3))
    t, b, nn = q[:, :, 0], q[:, :, 1], q[:, :, 2]
    pos = rng.normal(size=(n, 3)) * 0.4
    wo = rng.normal(size=(n, 3))
    wo[:, 2] = np.abs(wo[:, 2]) + 0.02
    wo /= np.linalg.norm(wo, axis=-1, keepdims=True)
    args = (pos, t, b, nn, wo, rng.uniform(0.01, 1, n), rng.uniform(0.01, 1, n),
            rng.random((n, 3)), rng.random((n, 3)), rng.random((n, 4)))
    light = QuadLight(RECT, [1.0, 2.0, 3.0])
    a = estimate_quad(light, *args)
    k = estimate_quad_fast(light, *args)
    assert np.count_nonzero(a) > n  # the comparison covers real contributions
    assert np.allclose(k, a, rtol=1e-9, atol=1e-12)
