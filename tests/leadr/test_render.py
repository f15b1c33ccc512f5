"""The leadr-point render method on small scenes."""

import numpy as np
import pytest

from prefilter.errors import PrefilterError
from prefilter.render import gbuffer, load_scene
from prefilter.render.methods import RenderSettings
from prefilter.leadr.render import render_leadr_point

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
