"""Shading: the material BRDF, shading frames and delta lights.

References are closed forms written out here (GGX by its formula, Lambert's rectangle form factor)
or the Monte Carlo reference estimator checked against quadrature in test_reference.py.
"""

from __future__ import annotations

import numpy as np

from prefilter.render.camera import GBuffer
from prefilter.render.driver import shading_frame, two_sided_frame
from prefilter.render.shading import (brdf_cos, local_view, point_incoming, shade_delta_lights,
                                      shading_frames)
from prefilter.render.lights import DirectionalLight, LightSet, PointLight


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
    a = np.array([0.3])
    out = shade_delta_lights(pos, t, b, n, local_view(view, t, b, n), a, a, base[None], f0[None],
                             lights)
    wi1, d2 = _unit(lp), lp @ lp
    wi2 = _unit(-d)
    want = ((base / np.pi * wi1[2] + _ggx_by_hand(view[0], wi1, 0.3, 0.3, f0)) * [2, 1, 0.5] / d2
            + (base / np.pi * wi2[2] + _ggx_by_hand(view[0], wi2, 0.3, 0.3, f0)) * [0.5, 0.5, 1])
    assert np.allclose(out[0], want, rtol=1e-10)


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
