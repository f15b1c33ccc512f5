"""The leadr-point render method on small scenes; the compiled box filter of the moments."""

import numpy as np
import pytest

from prefilter.errors import PrefilterError
from prefilter.render import gbuffer, load_scene
from prefilter.render.methods import RenderSettings
from prefilter.leadr.render import FOOTPRINT_TAPS, footprint_moments, render_leadr_point
from prefilter.texture import MipChain
from prefilter.texture.mip import footprint_axes

LIGHT = np.array([0.3, -1.0, -0.2]) / np.linalg.norm([0.3, -1.0, -0.2])
SCENE = {
    "camera": {"origin": [0, 1.5, 3], "target": [0, 0, 0], "fov": 45, "width": 24, "height": 16},
    "objects": [{"type": "plane", "center": [0, 0, 0], "normal": [0, 1, 0], "size": [6, 6],
                 "material": {"alpha": 0.002, "base_color": [0.5, 0.25, 0.1], "f0": 0.0}}],
    "lights": [{"type": "directional", "direction": LIGHT.tolist(), "irradiance": [2, 2, 2]}],
}


def test_smooth_diffuse_plane_is_lambertian():
    scene = load_scene(SCENE)
    img = render_leadr_point(scene, RenderSettings())
    g = gbuffer(scene)
    cos = np.maximum(np.sum(-LIGHT * g.normal, -1), 0.0)
    expect = np.asarray([0.5, 0.25, 0.1]) / np.pi * 2.0 * cos[..., None]
    expect = np.where(g.hit[..., None], expect, 0.0)
    np.testing.assert_allclose(img, expect, rtol=1e-3, atol=1e-6)


def test_height_mapped_render_is_finite_and_deterministic():
    d = {**SCENE, "objects": [dict(SCENE["objects"][0], material={
        "alpha": 0.1, "base_color": [0.3, 0.3, 0.3], "f0": 0.04,
        "height_map": {"procedural": "gaussian", "size": 64, "rms_slope": 0.4, "scale": 1.0}})],
         "lights": SCENE["lights"] + [{"type": "point", "position": [0, 2, 0],
                                       "intensity": [3, 3, 3]}]}
    a = render_leadr_point(load_scene(d), RenderSettings())
    b = render_leadr_point(load_scene(d), RenderSettings())
    assert np.all(np.isfinite(a)) and np.all(a >= 0) and a.max() > 0
    assert np.array_equal(a, b)


def test_quad_lights_are_rejected():
    d = {**SCENE, "lights": [{"type": "quad", "radiance": [1, 1, 1], "vertices":
                              [[-1, 1, -1], [1, 1, -1], [1, 2, -1], [-1, 2, -1]]}]}
    with pytest.raises(PrefilterError, match="leadr-point"):
        render_leadr_point(load_scene(d), RenderSettings())


def box_filter_numpy(chain, uv, dudv, max_taps: int = FOOTPRINT_TAPS) -> np.ndarray:
    """:func:`footprint_moments` in NumPy: ``T x T`` trilinear taps of ``MipChain.lookup``."""
    major = footprint_axes(dudv, chain.shape[:2])[0]
    taps = np.clip(np.ceil(major / 2.0), 1, max_taps).astype(np.int64)
    out = np.empty((len(uv), chain.shape[2]))
    for t in np.unique(taps):
        m = taps == t
        lod = np.log2(np.maximum(major[m] / t, 1.0))
        o = (np.arange(t) + 0.5) / t - 0.5
        ox, oy = np.meshgrid(o, o)
        off = np.einsum("nab,kb->nka", dudv[m], np.stack([ox.ravel(), oy.ravel()], -1))
        out[m] = chain.lookup(uv[m][:, None, :] + off,
                              np.broadcast_to(lod[:, None], off.shape[:2])).mean(axis=1)
    return out


def test_compiled_box_filter_equals_the_numpy_one():
    rng = np.random.default_rng(5)
    chain = MipChain(rng.random((128, 64, 5)))  # non-square, wrapped uv, tiny to wide footprints
    uv = rng.uniform(-2.0, 3.0, (3000, 2))
    dudv = rng.normal(scale=0.1, size=(3000, 2, 2))
    dudv[:100] *= 1e-4
    np.testing.assert_allclose(footprint_moments(chain, uv, dudv),
                               box_filter_numpy(chain, uv, dudv), rtol=0, atol=1e-12)
