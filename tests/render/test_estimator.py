"""The MIS estimator and its scrambled Sobol points: unbiased against closed forms and quadrature,
stratified, deterministic."""

from __future__ import annotations

import numpy as np
import pytest

from prefilter.microfacet import GGX
from prefilter.render.estimator import (
    Lambert,
    MaterialLobe,
    material_mis,
    mis_quad,
    owen_sobol,
)
from prefilter.render.lights import QuadLight
from prefilter.render.reference import control_table
from quadrature import parallelogram_rule  # tests/render/quadrature.py

# A 1 x 0.6 rectangle at height 1.2, shifted sideways, emitting downwards.
RECT = np.array([[0.2, -0.3, 1.2], [0.2, 0.3, 1.2], [1.2, 0.3, 1.2], [1.2, -0.3, 1.2]])


def lambert_form_factor(vertices) -> float:
    """Lambert's polygon formula: ``|1 / (2 pi) sum_i acos(v_i . v_j) (v_i x v_j)_z / |v_i x v_j||``
    with unit vertex directions ``v`` seen from the origin (a polygon above the horizon; the
    absolute value makes the winding irrelevant)."""
    v = vertices / np.linalg.norm(vertices, axis=-1, keepdims=True)
    total = 0.0
    for i in range(len(v)):
        a, b = v[i], v[(i + 1) % len(v)]
        c = np.cross(a, b)
        total += np.arccos(np.clip(a @ b, -1, 1)) * c[2] / np.linalg.norm(c)
    return abs(total) / (2 * np.pi)


def ggx_quadrature(light, wo, ax, ay, panels=48, order=8) -> float:
    """Composite Gauss-Legendre over the (parallelogram) light of ``GGX.eval cos_l / d^2``."""
    wi, weight = parallelogram_rule(light.vertices, normal=light.normal, panels=panels,
                                    order=order)
    f = GGX(ax, ay).eval(np.broadcast_to(wo, wi.shape), wi)
    return float(np.sum(f * weight))


def _replicates(lobe, light, wo, n, reps, heuristic="balance"):
    """Estimates of ``reps`` independently scrambled sets of ``n`` Sobol points (one "pixel"
    each; light and lobe samples from two 2-D blocks, as the renderer draws them), and the
    per-set estimates with independent uniform random numbers."""
    u = np.concatenate([owen_sobol(np.arange(reps), n, 2, seed=5, block=b) for b in (1, 2)],
                       axis=-1).reshape(-1, 4)
    m = len(u)
    frame = [np.tile(e, (m, 1)) for e in np.eye(3)]
    args = (np.zeros((m, 3)), *frame, np.tile(wo, (m, 1)))
    terms, _ = mis_quad(lobe, light, *args, u, heuristic=heuristic)
    qmc = terms.sum(axis=1).reshape(reps, n).mean(axis=1)
    terms, _ = mis_quad(lobe, light, *args, np.random.default_rng(6).random((m, 4)),
                        heuristic=heuristic)
    mc = terms.sum(axis=1).reshape(reps, n).mean(axis=1)
    return qmc, mc


@pytest.mark.parametrize("heuristic", ["balance", "power"])
def test_lambert_estimate_matches_closed_form(heuristic):
    light = QuadLight(RECT, 1.0)
    ref = lambert_form_factor(RECT)
    # Light samples uniform in the rectangle's solid angle make the light term almost constant;
    # what is left is the lobe samples' hit or miss, whose error under the nets falls as
    # n^-3/4 against MC's n^-1/2: their ratio reaches the bound below only at a few thousand
    qmc, mc = _replicates(Lambert(), light, np.array([0.0, 0.0, 1.0]), 4096, 64, heuristic)
    se = qmc.std() / np.sqrt(len(qmc))
    assert abs(qmc.mean() - ref) < 5 * se + 1e-12, (qmc.mean(), ref, se)
    assert qmc.std() < 0.25 * mc.std()  # the scrambled nets stratify: error well below MC's


@pytest.mark.parametrize("theta, ax, ay", [(30.0, 0.3, 0.3), (60.0, 0.15, 0.4)])
def test_ggx_estimate_matches_quadrature(theta, ax, ay):
    light = QuadLight(RECT, 1.0)
    t = np.radians(theta)
    wo = np.array([-np.sin(t), 0.0, np.cos(t)])  # specular peak towards the light (+x)
    ref = ggx_quadrature(light, wo, ax, ay)
    lobe = GGX(np.full(256 * 64, ax), np.full(256 * 64, ay))
    qmc, mc = _replicates(lobe, light, wo, 256, 64)
    se = qmc.std() / np.sqrt(len(qmc))
    assert abs(qmc.mean() - ref) < 5 * se + 1e-12, (qmc.mean(), ref, se)
    assert qmc.std() < 0.5 * mc.std()


def test_kernel_pairs_average_the_array_estimator():
    rng = np.random.default_rng(3)
    n, k = 500, 4
    wo = rng.normal(size=(n, 3))
    wo[:, 2] = np.abs(wo[:, 2]) + 0.05
    wo /= np.linalg.norm(wo, axis=-1, keepdims=True)
    frame = [np.tile(e, (n, 1)) for e in np.eye(3)]
    ax, ay = rng.uniform(0.05, 0.8, n), rng.uniform(0.05, 0.8, n)
    base, f0 = rng.random((n, 3)), rng.random((n, 3))
    u = rng.random((n, k, 4))
    light = QuadLight(RECT, 1.0)
    for heuristic in ("balance", "power"):
        total, terms, points = material_mis(light, np.zeros((n, 3)), *frame, wo, ax, ay, base,
                                            f0, u, heuristic=heuristic)
        lobe = MaterialLobe.for_view(wo, ax, ay, base, f0)
        for j in range(k):
            t, p = mis_quad(lobe, light, np.zeros((n, 3)), *frame, wo, u[:, j],
                            heuristic=heuristic)
            assert np.allclose(terms[:, j], t, rtol=1e-9, atol=1e-12)
            assert np.allclose(points[:, j], p, rtol=1e-9, atol=1e-12)
        assert np.allclose(total, terms.sum(axis=(1, 2)), rtol=1e-12)


def test_owen_sobol_is_deterministic_and_per_pixel():
    a = owen_sobol(np.arange(50), 64, 4, seed=1, block=2)
    assert a.tobytes() == owen_sobol(np.arange(50), 64, 4, seed=1, block=2).tobytes()
    # a pixel's points do not depend on which other pixels are asked for
    assert np.array_equal(owen_sobol(np.array([7, 3]), 64, 4, 1, 2)[1], a[3])
    assert not np.array_equal(a, owen_sobol(np.arange(50), 64, 4, seed=2, block=2))
    assert not np.array_equal(a, owen_sobol(np.arange(50), 64, 4, seed=1, block=3))
    assert not np.array_equal(a[0], a[1])
    assert np.all((a >= 0) & (a < 1))


def test_owen_sobol_sets_are_nets():
    n = 64
    a = owen_sobol(np.arange(20), n, 4, seed=4, block=0)
    # every 1-D projection: one point per interval of width 1/n
    cells = np.floor(a * n)
    assert np.all(np.sort(cells, axis=1) == np.arange(n)[None, :, None])
    # dimensions 0 and 1: a (0, 6, 2)-net, one point in each 8 x 8 cell
    cells2 = np.floor(a[..., 0] * 8) * 8 + np.floor(a[..., 1] * 8)
    assert np.all(np.sort(cells2, axis=1) == np.arange(n))
    # aligned runs of 4 (the pairs of one sub-pixel position): one point per quarter
    runs = np.sort(np.floor(a[..., 0] * 4).reshape(20, n // 4, 4), axis=-1)
    assert np.all(runs == np.arange(4))


def test_owen_sobol_points_are_uniform():
    a = owen_sobol(np.arange(4000), 16, 3, seed=9, block=1)
    # across pixels each point (index j) is uniform: mean 1/2, variance 1/12
    m = a.mean(axis=0)
    se = np.sqrt(1 / 12 / 4000)
    assert np.all(np.abs(m - 0.5) < 5 * se)
    assert np.all(np.abs(a.var(axis=0) - 1 / 12) < 0.01)


def _material_replicates(light, wo, ax, ay, n, reps, control):
    """``reps`` estimates of ``n`` scrambled Sobol pairs each by the material kernel (base 0,
    f0 1: the GGX lobe alone), with the control variate's table ``control`` or none."""
    u = np.concatenate([owen_sobol(np.arange(reps), n, 2, seed=8, block=b) for b in (1, 2)],
                       axis=-1).reshape(-1, 1, 4)
    m = len(u)
    frame = [np.tile(e, (m, 1)) for e in np.eye(3)]
    total, _, _ = material_mis(light, np.zeros((m, 3)), *frame, np.tile(wo, (m, 1)),
                               np.full(m, ax), np.full(m, ay), np.zeros((m, 3)),
                               np.ones((m, 3)), u, keep=False, control=control)
    return total[:, 0].reshape(reps, n).mean(axis=1)


# a quad in front of the shading point, its lower part below the shading horizon
STANDING = np.array([[1.0, -0.6, -0.4], [1.0, 0.6, -0.4], [1.0, 0.6, 0.9], [1.0, -0.6, 0.9]])


@pytest.mark.parametrize("vertices, theta, ax, ay", [
    (RECT, 30.0, 0.1, 0.1),      # sharp lobe, light edges crossing it
    (RECT, 60.0, 0.2, 0.35),     # anisotropic within 2:1: the isotropic fit of sqrt(ax ay)
    (STANDING, 50.0, 0.3, 0.3),  # light crossing the horizon
    (RECT, 30.0, 0.005, 0.005),  # below the table's alpha range: no control variate
])
def test_ltc_control_variate_is_unbiased_and_lowers_the_noise(vertices, theta, ax, ay):
    light = QuadLight(vertices if np.cross(vertices[1] - vertices[0], vertices[2] - vertices[0])
                      @ vertices[0] < 0 else vertices[::-1].copy(), 1.0)
    t = np.radians(theta)
    wo = np.array([-np.sin(t), 0.0, np.cos(t)])
    ref = ggx_quadrature(light, wo, ax, ay, panels=96)
    table = control_table()
    cv = _material_replicates(light, wo, ax, ay, 256, 64, table)
    plain = _material_replicates(light, wo, ax, ay, 256, 64, None)
    se = cv.std() / np.sqrt(len(cv))
    assert ref > 0.01
    assert abs(cv.mean() - ref) < 5 * se + 1e-9 * ref, (cv.mean(), ref, se)
    if ax >= 0.1:
        assert cv.std() < 0.5 * plain.std(), (cv.std(), plain.std())
    else:
        assert np.array_equal(cv, plain)
    # any table keeps it unbiased: a wrong fit (the lobe tilted and widened) only adds noise
    wrong = list(table)
    wrong[2] = table[2] @ np.array([[1.6, 0.0, 0.4], [0.0, 1.3, 0.0], [0.0, 0.0, 1.0]])
    bad = _material_replicates(light, wo, ax, ay, 256, 64, tuple(
        np.ascontiguousarray(a) for a in wrong))
    se = bad.std() / np.sqrt(len(bad))
    assert abs(bad.mean() - ref) < 5 * se + 1e-9 * ref, (bad.mean(), ref, se)
