"""Light sampling: rectangles uniformly in solid angle (Urena et al. 2013), other quads and tiny or
near-hemispherical solid angles on the area; chi-square, density consistency and the closed-form
solid angle against quadrature."""

from __future__ import annotations

import numpy as np
import pytest

from prefilter.errors import PrefilterError
from prefilter.render.lights import (
    SOLID_ANGLE_MIN,
    QuadLight,
    light_pdf,
    light_sample,
    quad_light_pdf,
    quad_rectangle,
    solid_angle,
)
from prefilter.sphere import chi2_sphere, lobe_cap, uniform_sphere
from quadrature import parallelogram_rule  # tests/render/quadrature.py

# A 1 x 0.6 rectangle at height 1.2, shifted sideways, emitting downwards.
RECT = np.array([[0.2, -0.3, 1.2], [0.2, 0.3, 1.2], [1.2, 0.3, 1.2], [1.2, -0.3, 1.2]])
# A tilted rectangle (the demo's light): edges (1.2, 0, 0) and (0, 0.6, -0.3).
TILTED = np.array([[-0.6, 0.35, -2.0], [0.6, 0.35, -2.0], [0.6, 0.95, -2.3], [-0.6, 0.95, -2.3]])
TRAPEZOID = np.array([[0, -0.3, 1.2], [0, 0.3, 1.2], [1, 0.5, 1.2], [1, -0.5, 1.2]], float)

# Points in front of the lights: far, near, beside, almost in the plane (grazing), and a corner.
POINTS = {
    "RECT": [[0.0, 0.0, 0.0], [0.7, 0.0, 1.1], [2.5, 1.0, 0.2], [0.7, 0.1, 1.15],
             [0.2, -0.3, 0.5]],
    "TILTED": [[0.0, 0.0, 0.0], [0.3, 0.0, -1.5], [0.0, 0.48, 1.32], [2.0, 0.1, -1.8]],
}


def quadrature_solid_angle(vertices, o, panels=64, order=8) -> float:
    """Composite Gauss-Legendre over the (parallelogram) light of ``cos_l / d^2`` dA."""
    _, weight = parallelogram_rule(vertices, o, panels=panels, order=order)
    return float(np.sum(weight))


def test_rectangles_are_recognised():
    assert quad_rectangle(RECT) is not None and quad_rectangle(TILTED) is not None
    assert quad_rectangle(TRAPEZOID) is None
    sheared = RECT + np.array([[0, 0, 0], [0.3, 0, 0], [0.3, 0, 0], [0, 0, 0]])
    assert quad_rectangle(sheared) is None  # a parallelogram, edges not orthogonal
    r = quad_rectangle(TILTED)
    assert np.allclose(r[9:12], QuadLight(TILTED, 1.0).normal)  # z is the emission normal
    assert np.allclose(r[12:], [1.2, np.hypot(0.6, 0.3)])


@pytest.mark.parametrize("name", ["RECT", "TILTED"])
def test_solid_angle_matches_quadrature(name):
    v = {"RECT": RECT, "TILTED": TILTED}[name]
    light = QuadLight(v, 1.0)
    o = np.array(POINTS[name], float)
    omega = solid_angle(light, o)
    ref = np.array([quadrature_solid_angle(v, p) for p in o])
    assert np.allclose(omega, ref, rtol=1e-6, atol=1e-9), (omega, ref)
    # behind the light nothing is subtended
    assert np.all(solid_angle(light, 2 * v.mean(0) - o) == 0.0)


@pytest.mark.parametrize("name, k", [("RECT", 0), ("RECT", 1), ("RECT", 3), ("TILTED", 1),
                                     ("TILTED", 2)])
def test_solid_angle_samples_pass_chi2(name, k):
    v = {"RECT": RECT, "TILTED": TILTED}[name]
    light = QuadLight(v, 1.0)
    o = np.array(POINTS[name][k], float)
    n = 100_000
    pilot = light_sample(light, o, np.random.default_rng(1).random((20_000, 2)))[0]
    axis, th = lobe_cap(pilot)
    wi, pdf, _ = light_sample(light, o, np.random.default_rng(2).random((n, 2)))
    assert np.allclose(pdf, 1.0 / solid_angle(light, o[None])[0], rtol=1e-12)
    res = chi2_sphere(wi, lambda w: light_pdf(light, np.broadcast_to(o, w.reshape(-1, 3).shape),
                                              w.reshape(-1, 3))[0].reshape(w.shape[:-1]),
                      axis=axis, theta_max=th, res=(16, 32))
    assert res.passed(), res


@pytest.mark.parametrize("vertices", [RECT, TRAPEZOID])
def test_pdf_is_the_samplers_and_integrates_to_one(vertices):
    light = QuadLight(vertices, 1.0)
    n = 2000
    o = np.tile([0.4, 0.1, 0.2], (n, 1))
    wi, pdf, pts = light_sample(light, o, np.random.default_rng(3).random((n, 2)))
    p2, hit = light_pdf(light, o, wi)
    assert np.all(pdf > 0) and np.allclose(p2, pdf, rtol=1e-9)
    # the sampled points lie on the light, along the sampled directions
    assert np.allclose(hit, pts, atol=1e-9)
    d = pts - o
    assert np.allclose(d / np.linalg.norm(d, axis=-1, keepdims=True), wi, atol=1e-12)
    # pdf == 1 / solid angle for the rectangle, the area density for the trapezoid
    if quad_rectangle(vertices) is None:
        assert np.allclose(pdf, quad_light_pdf(light, o, wi), rtol=1e-9)
    else:
        assert np.allclose(pdf, 1.0 / solid_angle(light, o[:1])[0], rtol=1e-12)
    m = 400_000
    w = uniform_sphere(np.random.default_rng(4).random((m, 2)))
    est = light_pdf(light, np.tile(o[0], (m, 1)), w)[0] * 4 * np.pi
    assert abs(est.mean() - 1.0) < 5 * est.std() / np.sqrt(m)


def test_behind_and_tiny_solid_angles():
    light = QuadLight(RECT, 1.0)
    above = np.tile([0.5, 0.0, 3.0], (100, 1))
    wi, pdf, _ = light_sample(light, above, np.random.default_rng(5).random((100, 2)))
    assert np.all(pdf == 0)
    assert np.all(light_pdf(light, above, np.tile([0, 0, -1.0], (100, 1)))[0] == 0)
    # far away the solid angle is below SOLID_ANGLE_MIN: area sampling, the area density
    far = np.tile([0.7, 0.0, -60.0], (100, 1))
    assert solid_angle(light, far[:1])[0] < SOLID_ANGLE_MIN
    wi, pdf, _ = light_sample(light, far, np.random.default_rng(6).random((100, 2)))
    assert np.allclose(pdf, quad_light_pdf(light, far, wi), rtol=1e-9)
    assert np.allclose(light_pdf(light, far, wi)[0], pdf, rtol=1e-9)


def test_solid_angle_needs_a_rectangle():
    with pytest.raises(PrefilterError, match="rectangular"):
        solid_angle(QuadLight(TRAPEZOID, 1.0), np.zeros((1, 3)))
