"""Shading: the material BRDF, shading frames, delta lights and the LTC shader.

References are closed forms written out here (GGX by its formula, Lambert's rectangle form factor)
or the Monte Carlo reference estimator checked against quadrature in test_reference.py.
"""

from __future__ import annotations

import numpy as np
import pytest

from prefilter.render.lights import DirectionalLight, LightSet, PointLight, QuadLight
from prefilter.render.camera import GBuffer
from prefilter.render.shading import (brdf_cos, point_incoming, shade_ltc, shading_frame,
                                      shading_frames, two_sided_frame)


def _ggx_by_hand(wo, wi, ax, ay, f0):
    h = (wo + wi) / np.linalg.norm(wo + wi)
    d = 1 / (np.pi * ax * ay * ((h[0] / ax) ** 2 + (h[1] / ay) ** 2 + h[2] ** 2) ** 2)

    def lam(w):
        return (-1 + np.sqrt(1 + ((ax * w[0]) ** 2 + (ay * w[1]) ** 2) / w[2] ** 2)) / 2

    g2 = 1 / (1 + lam(wo) + lam(wi))
    f = f0 + (1 - f0) * (1 - wi @ h) ** 5
    return f * d * g2 / (4 * wo[2])


def _unit(v):
    v = np.asarray(v, float)
    return v / np.linalg.norm(v)


def test_brdf_matches_closed_form():
    rng = np.random.default_rng(0)
    f0 = np.array([0.9, 0.5, 0.04])
    base = np.array([0.2, 0.4, 0.6])
    for _ in range(20):
        wo = _unit(rng.normal(size=3) * [1, 1, 0.5] + [0, 0, 1.0])
        wi = _unit(rng.normal(size=3) * [1, 1, 0.5] + [0, 0, 1.0])
        if wo[2] <= 0.05 or wi[2] <= 0.05:
            continue
        got = brdf_cos(wo[None], wi[None], np.array([0.3]), np.array([0.1]), base[None], f0[None])
        want = base / np.pi * wi[2] + _ggx_by_hand(wo, wi, 0.3, 0.1, f0)
        assert np.allclose(got[0], want, rtol=1e-10)
    below = brdf_cos(np.array([[0, 0, 1.0]]), np.array([[0.6, 0, -0.8]]), np.array([0.3]),
                     np.array([0.3]), base[None], f0[None])
    assert np.all(below == 0)


def test_shading_frame_is_orthonormal_and_follows_the_normal_map():
    rng = np.random.default_rng(1)
    n = 500
    g = rng.normal(size=(n, 3, 3))
    q, _ = np.linalg.qr(g)
    t, b, nn = q[:, :, 0], q[:, :, 1], q[:, :, 2]
    nts = rng.normal(size=(n, 3)) * [0.4, 0.4, 0.1] + [0, 0, 1]  # unnormalised, like mip averages
    ts, bs, ns = shading_frame(t, b, nn, nts)
    want_n = nts[:, :1] * t + nts[:, 1:2] * b + nts[:, 2:] * nn
    want_n /= np.linalg.norm(want_n, axis=-1, keepdims=True)
    assert np.allclose(ns, want_n)
    for x, y in [(ts, ts), (bs, bs), (ns, ns)]:
        assert np.allclose(np.sum(x * y, -1), 1)
    for x, y in [(ts, bs), (ts, ns), (bs, ns)]:
        assert np.allclose(np.sum(x * y, -1), 0, atol=1e-12)
    # Tangent stays in the plane of the geometric tangent and the shading normal, on t's side.
    assert np.allclose(np.sum(np.cross(t, ns) * ts, -1), 0, atol=1e-12)
    assert np.all(np.sum(ts * t, -1) > 0)
    # Handedness kept (this geometric frame may be left- or right-handed).
    hand = np.sign(np.sum(np.cross(nn, t) * b, -1))
    assert np.all(np.sign(np.sum(np.cross(ns, ts) * bs, -1)) == hand)


def test_point_and_directional_lights_closed_form():
    pos = np.array([[0.0, 0.0, 0.0]])
    t, b, n = np.eye(3)[None, 0], np.eye(3)[None, 1], np.eye(3)[None, 2]
    view = _unit([0.3, 0.0, 1.0])[None]
    lp = np.array([1.0, 0.5, 2.0])
    d = np.array([-0.2, 0.1, -1.0])
    lights = LightSet(points=(PointLight(lp, [2.0, 1.0, 0.5]),),
                      directionals=(DirectionalLight(d, [0.5, 0.5, 1.0]),))
    base, f0 = np.array([0.5, 0.3, 0.2]), np.array([0.04, 0.5, 1.0])
    out = shade_ltc(pos, t, b, n, view, np.array([0.3]), base[None], f0[None], lights, table=None)
    wi1, d2 = _unit(lp), lp @ lp
    wi2 = _unit(-d)
    want = ((base / np.pi * wi1[2] + _ggx_by_hand(view[0], wi1, 0.3, 0.3, f0)) * [2, 1, 0.5] / d2
            + (base / np.pi * wi2[2] + _ggx_by_hand(view[0], wi2, 0.3, 0.3, f0)) * [0.5, 0.5, 1])
    assert np.allclose(out[0], want, rtol=1e-10)


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
    out = shade_ltc(p0[None], t[None], b[None], n[None], n[None], np.array([0.5]), base,
                    np.zeros((1, 3)), LightSet(quads=(light,)), _NoSpecular())
    want = base[0] * [1, 2, 3] * _rect_form_factor(a_, b_, c_)
    assert np.allclose(out[0], want, rtol=1e-9)
    # Seen from behind the light nothing arrives (one-sided).
    back = shade_ltc((p0 + 2 * c_ * n)[None], t[None], b[None], (-n)[None], (-n)[None],
                     np.array([0.5]), base, np.zeros((1, 3)), LightSet(quads=(light,)),
                     _NoSpecular())
    assert np.all(back == 0)


def test_scaled_inverse_is_a_positive_multiple_of_the_inverse():
    from prefilter.render.shading import scaled_inverse

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
    from prefilter.ltc.polygon import clip_to_horizon, polygon_integral

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
    from prefilter.render.shading import _shade_ltc_numpy

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
    want = _shade_ltc_numpy(pos, t, b, nn, view, alpha, base, f0, lights, table)
    assert np.count_nonzero(want.sum(-1)) > n // 4
    assert np.allclose(got, want, rtol=1e-9, atol=1e-12)


def _hits(view, normal):
    n = len(view)
    z3, z2 = np.zeros((n, 3)), np.zeros((n, 2))
    return GBuffer(hit=np.ones(n, bool), object_id=np.zeros(n, np.int32), position=z3,
                   normal=normal, tangent=np.tile([1.0, 0.0, 0.0], (n, 1)),
                   bitangent=np.cross(normal, [1.0, 0.0, 0.0]), uv=z2,
                   dudv=np.zeros((n, 2, 2)), dpdx=z3, dpdy=z3, distance=np.ones(n), view=view,
                   direction=-view)


def test_two_sided_frame_flips_b_and_n_towards_the_viewer_and_stays_right_handed():
    view = np.array([[0.0, 0.6, 0.8], [0.0, 0.6, -0.8]])
    g = _hits(view, np.tile([0.0, 0.0, 1.0], (2, 1)))
    t, b, n = two_sided_frame(g)
    np.testing.assert_array_equal(n, [[0, 0, 1], [0, 0, -1]])
    np.testing.assert_array_equal(b, [[0, 1, 0], [0, -1, 0]])
    np.testing.assert_allclose(np.cross(t, b), n)
    _, _, _, wo = shading_frames(g)
    # the local view is above the flipped frame's horizon on both sides, and unit
    np.testing.assert_allclose(wo, [[0.0, 0.6, 0.8], [0.0, -0.6, 0.8]], atol=1e-15)


def test_point_incoming_is_the_inverse_square_irradiance_and_the_directionals_constant():
    pos = np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0]])
    lights = LightSet(points=(PointLight(np.array([0.0, 0.0, 2.0]), np.array([4.0, 8.0, 12.0])),),
                      directionals=(DirectionalLight(np.array([0.0, 0.0, -1.0]),
                                                     np.array([1.0, 2.0, 3.0])),))
    (wp, ep), (wd, ed) = point_incoming(lights, pos)
    np.testing.assert_allclose(wp, [[0, 0, 1], [-1 / 5 ** 0.5, 0, 2 / 5 ** 0.5]])
    np.testing.assert_allclose(ep, [[1, 2, 3], [0.8, 1.6, 2.4]])
    np.testing.assert_array_equal(wd, [[0, 0, 1], [0, 0, 1]])
    assert ed.shape == (2, 3)
    np.testing.assert_array_equal(ed, [[1, 2, 3], [1, 2, 3]])
    assert point_incoming(LightSet(), pos) == []
