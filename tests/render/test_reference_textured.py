"""The reference integrator with textured quad lights, against Gauss-Legendre quadrature of the
equivalent untextured lights (a constant texture scales the light; a texture split in two colours
is the sum of the two half quads) and end to end through ``render``."""

from __future__ import annotations

import copy

import numpy as np
import pytest

from prefilter.render import load_scene, render
from prefilter.render.lights import LightSet, QuadLight
from prefilter.render.lighttex import LightTexture, TexturedQuad
from prefilter.render.reference import estimate_quad, estimate_quad_fast, shade_reference
from prefilter.render.shading import brdf_cos
from quadrature import parallelogram_rule  # tests/render/quadrature.py

# 1 x 0.6 rectangle at height 1.2, shifted sideways, emitting downwards; v1 - v0 runs along y
# (texture u, columns), v3 - v0 along x (texture v, rows).
RECT = np.array([[0.2, -0.3, 1.2], [0.2, 0.3, 1.2], [1.2, 0.3, 1.2], [1.2, -0.3, 1.2]])
RADIANCE = np.array([1.0, 2.0, 0.5])


def _quadrature(vertices, radiance, wo, ax, ay, base, f0, panels=48, order=8):
    """Composite Gauss-Legendre over a parallelogram light seen from the origin (frame = world):
    the integral of ``f cos L cos_l / d^2`` over its area."""
    wi, weight = parallelogram_rule(vertices, panels=panels, order=order)
    n = len(wi)
    f = brdf_cos(np.tile(wo, (n, 1)), wi, np.full(n, ax), np.full(n, ay), np.tile(base, (n, 1)),
                 np.tile(f0, (n, 1)))
    return np.sum(f * weight[:, None], axis=0) * radiance


def _args(n, wo, ax, ay, base, f0):
    frame = [np.tile(e, (n, 1)) for e in np.eye(3)]
    return (np.zeros((n, 3)), *frame, np.tile(wo, (n, 1)), np.full(n, ax), np.full(n, ay),
            np.tile(base, (n, 1)), np.tile(f0, (n, 1)))


def _split_texture(a, b, axis, size=64):
    """Colour ``a`` in the first half of the texture along ``axis`` (1: columns, texture u;
    0: rows, texture v), ``b`` in the second half."""
    shape = [2, 2, 3]
    shape[axis] = size
    tex = np.empty(shape)
    idx = [slice(None)] * 3
    idx[axis] = slice(0, size // 2)
    tex[tuple(idx)] = a
    idx[axis] = slice(size // 2, size)
    tex[tuple(idx)] = b
    return tex


WO = np.array([-np.sin(np.radians(30.0)), 0.0, np.cos(np.radians(30.0))])
BASE, F0 = np.array([0.5, 0.2, 0.1]), np.array([0.04, 0.04, 0.04])


def test_constant_texture_equals_scaled_untextured_light():
    c = np.array([0.3, 0.7, 1.5])
    light = TexturedQuad(RECT, RADIANCE, LightTexture(np.broadcast_to(c, (3, 5, 3))))
    n = 200_000
    u = np.random.default_rng(1).random((n, 4))
    est = estimate_quad_fast(light, *_args(n, WO, 0.3, 0.3, BASE, F0), u)
    ref = _quadrature(RECT, RADIANCE * c, WO, 0.3, 0.3, BASE, F0)
    m, se = est.mean(0), est.std(0) / np.sqrt(n)
    assert np.all(np.abs(m - ref) < 5 * se), (m, ref, se)
    assert np.all(se < 0.02 * ref)
    # per sample (NumPy estimator): the numbers of the untextured light of radiance c L
    k = 20_000
    tex = estimate_quad(light, *_args(k, WO, 0.3, 0.3, BASE, F0), u[:k])
    plain = estimate_quad(QuadLight(RECT, RADIANCE * c), *_args(k, WO, 0.3, 0.3, BASE, F0), u[:k])
    assert np.count_nonzero(plain) > k
    np.testing.assert_allclose(tex, plain, rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(est[:k], plain, rtol=1e-9, atol=1e-12)


@pytest.mark.parametrize("axis, theta, ax, ay", [(1, 30.0, 0.3, 0.3), (0, 60.0, 0.15, 0.5)])
def test_two_colour_texture_is_the_sum_of_two_half_quads(axis, theta, ax, ay):
    a, b = np.array([1.0, 0.0, 0.2]), np.array([0.0, 1.0, 0.2])
    light = TexturedQuad(RECT, RADIANCE, LightTexture(_split_texture(a, b, axis)))
    t, phi = np.radians(theta), np.radians(30.0)  # off both symmetry planes of the light
    wo = np.array([-np.sin(t) * np.cos(phi), -np.sin(t) * np.sin(phi), np.cos(t)])
    n = 200_000
    u = np.random.default_rng(2).random((n, 4))
    est = estimate_quad_fast(light, *_args(n, wo, ax, ay, BASE, F0), u)
    # texture u runs along v1 - v0, v along v3 - v0
    v0, v1, v2, v3 = RECT
    if axis == 1:
        m0, m3 = (v0 + v1) / 2, (v3 + v2) / 2
        first, second = np.array([v0, m0, m3, v3]), np.array([m0, v1, v2, m3])
    else:
        m0, m1 = (v0 + v3) / 2, (v1 + v2) / 2
        first, second = np.array([v0, v1, m1, m0]), np.array([m0, m1, v2, v3])
    ref = (_quadrature(first, RADIANCE * a, wo, ax, ay, BASE, F0)
           + _quadrature(second, RADIANCE * b, wo, ax, ay, BASE, F0))
    m, se = est.mean(0), est.std(0) / np.sqrt(n)
    assert np.all(np.abs(m - ref) < 5 * se), (m, ref, se)
    # the halves differ enough for a swapped or transposed texture to fail
    swapped = (_quadrature(first, RADIANCE * b, wo, ax, ay, BASE, F0)
               + _quadrature(second, RADIANCE * a, wo, ax, ay, BASE, F0))
    assert np.all(np.abs(swapped - ref)[:2] > 10 * se[:2]), (swapped, ref, se)


def test_kernel_matches_numpy_estimator_with_texture():
    rng = np.random.default_rng(3)
    n = 20_000
    q, _ = np.linalg.qr(rng.normal(size=(n, 3, 3)) * 0.3 + np.eye(3))
    wo = rng.normal(size=(n, 3))
    wo[:, 2] = np.abs(wo[:, 2]) + 0.02
    wo /= np.linalg.norm(wo, axis=-1, keepdims=True)
    args = (rng.normal(size=(n, 3)) * 0.4, q[:, :, 0], q[:, :, 1], q[:, :, 2], wo,
            rng.uniform(0.01, 1, n), rng.uniform(0.01, 1, n), rng.random((n, 3)),
            rng.random((n, 3)), rng.random((n, 4)))
    light = TexturedQuad(RECT, RADIANCE, LightTexture(rng.random((7, 9, 3))))
    a = estimate_quad(light, *args)
    k = estimate_quad_fast(light, *args)
    assert np.count_nonzero(a) > n
    np.testing.assert_allclose(k, a, rtol=1e-9, atol=1e-12)


def test_shade_reference_takes_textured_quads_after_the_plain_ones():
    n = 1000
    c = 0.25
    light = QuadLight(RECT, RADIANCE)
    tq = TexturedQuad(RECT, RADIANCE, LightTexture(np.full((2, 2), c)))  # one channel
    u = np.random.default_rng(4).random((n, 2, 4))
    args = _args(n, WO, 0.3, 0.3, BASE, F0)
    both = shade_reference(*args, LightSet(quads=(light,)), u, textured=(tq,))
    one = shade_reference(*args, LightSet(quads=(light,)), u[:, :1])
    two = shade_reference(*args, LightSet(quads=(light,)), u[:, 1:])
    np.testing.assert_allclose(both, one + c * two, rtol=1e-12, atol=1e-14)


SCENE = {
    "camera": {"origin": [0, 1.2, 3], "target": [0, 0.3, 0], "fov": 40, "width": 12,
               "height": 8},
    "objects": [{"type": "plane", "size": [4, 4],
                 "material": {"alpha": 0.3, "base_color": [0.5, 0.4, 0.3], "f0": 0.04}}],
    "lights": [{"type": "quad", "radiance": [2, 2, 2],
                "vertices": [[-1, 2, -1], [1, 2, -1], [1, 2, 1], [-1, 2, 1]]}],
}


def test_render_reference_with_textured_quad(tmp_path):
    from prefilter.texture.io import write_image

    write_image(tmp_path / "half.exr", np.full((4, 4, 3), 0.5))
    # plain MIS for both: the control variate (the default) applies to untextured quads only
    plain = render(load_scene(SCENE, base_dir=tmp_path), "reference", spp=4, seed=3,
                   params={"control": "none"})
    scene = copy.deepcopy(SCENE)
    scene["lights"][0]["texture"] = "half.exr"
    img = render(load_scene(scene, base_dir=tmp_path), "reference", spp=4, seed=3,
                 params={"control": "none"})
    assert plain.max() > 0.05
    # same random numbers, radiance halved
    np.testing.assert_allclose(img, 0.5 * plain, rtol=1e-5, atol=1e-7)
