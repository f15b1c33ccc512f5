"""The LTC shader over flat arrays: closed forms (Lambert's rectangle form factor, the polygon
integral of the rotated table matrix) and the NumPy shader the fused kernel is checked against.
"""

from __future__ import annotations

import numpy as np
import pytest

from ltc_numpy import shade_ltc_numpy

from prefilter.ltc.shading import scaled_inverse, shade_ltc
from prefilter.render.lights import LightSet, QuadLight


def _unit(v):
    v = np.asarray(v, float)
    return v / np.linalg.norm(v)


class _NoSpecular:
    """A table stand-in with zero specular magnitude: isolates the diffuse polygon integral."""

    alpha_min = 1e-4

    def lookup(self, wo, alpha):
        n = len(wo)
        return np.broadcast_to(np.eye(3), (n, 3, 3)), np.zeros(n), np.zeros(n)


def _rect_form_factor(a, b, c):
    """Form factor from a point to a parallel a x b rectangle at distance c, the point below one
    corner (standard closed form)."""
    x, y = a / c, b / c
    return (x / np.sqrt(1 + x * x) * np.arctan(y / np.sqrt(1 + x * x))
            + y / np.sqrt(1 + y * y) * np.arctan(x / np.sqrt(1 + y * y))) / (2 * np.pi)


def test_ltc_diffuse_is_the_rectangle_form_factor_in_a_rotated_frame():
    # A tilted surface frame, a rectangle parallel to it, the point under one corner.
    q, _ = np.linalg.qr(np.random.default_rng(2).normal(size=(3, 3)))
    t, b, n = q[:, 0], q[:, 1], q[:, 2]
    p0 = np.array([0.3, -1.0, 2.0])
    a_, b_, c_ = 0.8, 1.5, 0.7
    corners = [p0 + c_ * n, p0 + c_ * n + b_ * b, p0 + c_ * n + a_ * t + b_ * b,
               p0 + c_ * n + a_ * t]
    light = QuadLight(np.array(corners), [1.0, 2.0, 3.0])
    if light.normal @ n > 0:  # make it face the point
        light = QuadLight(np.array(corners[::-1]), [1.0, 2.0, 3.0])
    base = np.array([[0.5, 0.25, 1.0]])
    out = shade_ltc_numpy(p0[None], t[None], b[None], n[None], n[None], np.array([0.5]), base,
                          np.zeros((1, 3)), LightSet(quads=(light,)), _NoSpecular())
    want = base[0] * [1, 2, 3] * _rect_form_factor(a_, b_, c_)
    assert np.allclose(out[0], want, rtol=1e-9)
    # Seen from behind the light nothing arrives (one-sided).
    back = shade_ltc_numpy((p0 + 2 * c_ * n)[None], t[None], b[None], (-n)[None], (-n)[None],
                           np.array([0.5]), base, np.zeros((1, 3)), LightSet(quads=(light,)),
                           _NoSpecular())
    assert np.all(back == 0)


def test_scaled_inverse_is_a_positive_multiple_of_the_inverse():
    M = np.random.default_rng(3).normal(size=(200, 3, 3))
    S = scaled_inverse(M)
    prod = S @ M  # = |det M| I
    det = np.abs(np.linalg.det(M))
    assert np.allclose(prod, det[:, None, None] * np.eye(3), atol=1e-12)


def _const_table(M, magnitude, fresnel):
    """A 2 x 2 GGXTable whose entries are all ``M``, ``magnitude``, ``fresnel``."""
    from prefilter.ltc.table import GGXTable

    return GGXTable([0.0, 0.9], [0.1, 1.0], np.broadcast_to(M, (2, 2, 3, 3)),
                    np.full((2, 2), magnitude), np.full((2, 2), fresnel))


def _corner_rectangle(seed):
    q, _ = np.linalg.qr(np.random.default_rng(seed).normal(size=(3, 3)))
    t, b, n = q[:, 0], q[:, 1], q[:, 2]
    p0 = np.array([0.3, -1.0, 2.0])
    a_, b_, c_ = 0.8, 1.5, 0.7
    corners = [p0 + c_ * n, p0 + c_ * n + b_ * b, p0 + c_ * n + a_ * t + b_ * b,
               p0 + c_ * n + a_ * t]
    light = QuadLight(np.array(corners), [1.0, 2.0, 3.0])
    if light.normal @ n > 0:
        light = QuadLight(np.array(corners[::-1]), [1.0, 2.0, 3.0])
    return t, b, n, p0, light, _rect_form_factor(a_, b_, c_)


def test_fused_ltc_shader_diffuse_and_cosine_lobe_are_the_form_factor():
    # A table of identity matrices with n = 1, f5 = 0 and f0 = 1 makes the specular term the
    # clamped cosine too: radiance = (base + 1) * form factor, through the fused kernel.
    t, b, n, p0, light, ff = _corner_rectangle(2)
    base = np.array([[0.5, 0.25, 1.0]])
    view = (0.3 * t + n) / np.linalg.norm(0.3 * t + n)
    out = shade_ltc(p0[None], t[None], b[None], n[None], view[None], np.array([0.5]), base,
                    np.ones((1, 3)), LightSet(quads=(light,)), _const_table(np.eye(3), 1.0, 0.0))
    assert np.allclose(out[0], (base[0] + 1.0) * [1, 2, 3] * ff, rtol=1e-9)
    # n = f5 = 0: diffuse only; and nothing from behind the (one-sided) light
    out = shade_ltc(p0[None], t[None], b[None], n[None], view[None], np.array([0.5]), base,
                    np.ones((1, 3)), LightSet(quads=(light,)), _const_table(np.eye(3), 0.0, 0.0))
    assert np.allclose(out[0], base[0] * [1, 2, 3] * ff, rtol=1e-9)
    back = shade_ltc((p0 + 1.4 * n)[None], t[None], b[None], (-n)[None], (-n)[None],
                     np.array([0.5]), base, np.ones((1, 3)), LightSet(quads=(light,)),
                     _const_table(np.eye(3), 1.0, 0.0))
    assert np.all(back == 0)


def test_fused_ltc_shader_rotates_the_table_matrix_to_the_view_azimuth():
    # A constant anisotropic M: the specular part must be the LTC integral (polygon_integral,
    # an independent kernel) with Rz(phi) M Rz(phi)^T over the light clipped at the horizon.
    from prefilter.sphere.polygon import clip_to_horizon, polygon_integral

    M = np.array([[0.4, 0.0, 0.15], [0.0, 0.7, 0.0], [-0.1, 0.0, 1.0]])
    light = QuadLight(np.array([[-1.0, -1.0, 1.5], [1.0, -1.0, 1.5], [1.0, 1.0, -0.3],
                                [-1.0, 1.0, -0.3]])[::-1], [1.0, 1.0, 1.0])
    rng = np.random.default_rng(4)
    e = np.eye(3)
    for _ in range(10):
        phi, th = rng.uniform(0, 2 * np.pi), rng.uniform(0.1, 1.2)
        view = np.array([np.sin(th) * np.cos(phi), np.sin(th) * np.sin(phi), np.cos(th)])
        pos = np.array([rng.uniform(-0.5, 0.5), rng.uniform(-0.5, 0.5), 0.0])
        out = shade_ltc(pos[None], e[None, 0], e[None, 1], e[None, 2], view[None],
                        np.array([0.3]), np.zeros((1, 3)), np.ones((1, 3)),
                        LightSet(quads=(light,)), _const_table(M, 1.0, 0.0))
        c, s = np.cos(phi), np.sin(phi)
        rz = np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]])
        P = clip_to_horizon(light.vertices - pos)
        want = polygon_integral(rz @ M @ rz.T, P) if (pos - light.vertices[0]) @ light.normal > 0 \
            else 0.0
        assert np.allclose(out[0], want, rtol=1e-9, atol=1e-14)


def test_fused_ltc_shader_matches_the_numpy_path_on_random_inputs():
    from prefilter.ltc.table import GGXTable

    try:
        table = GGXTable.load()
    except Exception as exc:  # noqa: BLE001 - the table is another part's output
        pytest.skip(f"no LTC table: {exc}")
    rng = np.random.default_rng(5)
    n = 3000
    q, _ = np.linalg.qr(rng.normal(size=(n, 3, 3)))
    t, b, nn = q[:, :, 0], q[:, :, 1], q[:, :, 2]
    pos = rng.uniform(-2, 2, (n, 3))
    view = rng.normal(size=(n, 3))  # many below the shading horizon: the clamp
    view /= np.linalg.norm(view, axis=-1, keepdims=True)
    alpha = rng.uniform(0.0005, 1.0, n)  # also below the table's range
    base, f0 = rng.uniform(0, 1, (n, 3)), rng.uniform(0, 1, (n, 3))
    lights = LightSet(quads=(
        QuadLight(np.array([[-1.0, 2.5, -1], [1, 2.5, -1], [1, 2.5, 1], [-1, 2.5, 1]]), [3, 2, 1]),
        QuadLight(np.array([[2.5, -1, -1], [2.5, 1, -1], [2.5, 1, 1], [2.5, -1, 1]]), 1.5)))
    got = shade_ltc(pos, t, b, nn, view, alpha, base, f0, lights, table)
    want = shade_ltc_numpy(pos, t, b, nn, view, alpha, base, f0, lights, table)
    assert np.count_nonzero(want.sum(-1)) > n // 4
    assert np.allclose(got, want, rtol=1e-9, atol=1e-12)
