"""Colour-map render methods: plumbing against the NumPy path, and far-away images against a
supersampled reference."""

import numpy as np
import pytest

from prefilter.studies.colormap import scene_dict
from prefilter.colormap.height import filter_height_footprint, smith_lambda_direction
from prefilter.colormap.driver import colormap_driver
from prefilter.colormap.render import render_colormap_filtered, render_colormap_naive
from prefilter.colormap.texture import footprint_stats, moments_mip
from prefilter.errors import PrefilterError
from prefilter.render import gbuffer, load_scene
from prefilter.render.methods import RenderSettings
from prefilter.texture.procedural import height_map, noise

COLORS = [[0.05, 0.1, 0.4], [0.9, 0.9, 0.85], [0.1, 0.45, 0.15], [0.95, 0.55, 0.1],
          [0.5, 0.05, 0.05]] * 3  # bands: strongly non-linear in the driving value
TEX = {"procedural": "noise", "size": 64, "seed": 3, "corr_length": 1.5}


def _scene(density, view=60.0, size=24):
    return load_scene(scene_dict("plane", view, density * 256 / 64, size, size))


def test_texture_render_equals_numpy_footprint_stats():
    scene = _scene(40.0)
    spec = {"driver": "texture", "texture": TEX, "colors": COLORS, "range": [-4, 4],
            "sigma_max": 1.5}
    img = render_colormap_filtered(scene, RenderSettings(), spec)
    naive = render_colormap_naive(scene, RenderSettings(), spec)
    g = gbuffer(scene)
    hit = g.hit
    f = noise(64, 3, corr_length=1.5)
    table = colormap_driver(spec).table
    mean, var = footprint_stats(moments_mip(f), g.uv[hit], g.dudv[hit], anisotropic=True)
    np.testing.assert_allclose(img[hit], table.lookup(mean, np.sqrt(var)), atol=1e-9)
    np.testing.assert_allclose(naive[hit], table.naive(mean), atol=1e-9)
    assert np.all(img[~hit] == 0)


def test_height_render_equals_numpy_path_with_scene_light():
    scene = load_scene({**scene_dict("plane", 70.0, 400.0, 16, 16),
                        "lights": [{"type": "directional", "direction": [-0.95, -0.15, -0.2],
                                    "irradiance": 1.0}]})
    tex = {"procedural": "gaussian", "size": 64, "seed": 1, "rms_slope": 0.5, "corr_length": 3.0}
    spec = {"driver": "height", "texture": tex, "colors": COLORS, "range": [-4.5, 4.5]}
    img = render_colormap_filtered(scene, RenderSettings(), spec)
    g = gbuffer(scene).reshape(-1)
    g = g.select(g.hit)
    hm = height_map("gaussian", 64, 1, rms_slope=0.5, corr_length=3.0)
    x = (hm.height - hm.height.mean()) / hm.height.std()
    cov = np.cov(hm.slopes.reshape(-1, 2).T, bias=True)
    light = np.array([0.95, 0.15, 0.2]) / np.linalg.norm([0.95, 0.15, 0.2])  # grazing

    def local(w):
        w = np.stack([np.sum(w * g.tangent, -1), np.sum(w * g.bitangent, -1),
                      np.maximum(np.sum(w * g.normal, -1), 1e-3)], -1)
        return w / np.linalg.norm(w, axis=-1, keepdims=True)

    lo = smith_lambda_direction(local(g.view), cov)
    li = smith_lambda_direction(local(np.broadcast_to(light, g.view.shape)), cov)
    mu, var = footprint_stats(moments_mip(x), g.uv, g.dudv, anisotropic=True)
    want = filter_height_footprint(colormap_driver(spec).table, mu, np.sqrt(var), lo, li)
    got = img.reshape(-1, 3)[gbuffer(scene).reshape(-1).hit]
    np.testing.assert_allclose(got, want, atol=1e-6)
    unlit = filter_height_footprint(colormap_driver(spec).table, mu, np.sqrt(var), lo, 0.0 * li)
    assert np.abs(got - unlit).max() > 0.05  # the light matters here


def test_far_filtered_is_closer_to_supersampling_than_naive():
    # ~20 texels per pixel: the naive C(mean) is far from the pixel average of C(f)
    scene = _scene(1200.0, view=0.0, size=12)
    spec = {"driver": "noise", "texture": TEX, "colors": COLORS, "range": [-4, 4],
            "sigma_max": 1.5}
    filt = render_colormap_filtered(scene, RenderSettings(), spec)
    naive = render_colormap_naive(scene, RenderSettings(), spec)
    # reference: 24 x 24 supersampling of the unfiltered map (level 0, bilinear)
    d = colormap_driver(spec)
    f = noise(64, 3, corr_length=1.5)
    k = 24
    off = (np.stack(np.meshgrid(np.arange(k), np.arange(k)), -1).reshape(-1, 2) + 0.5) / k
    g = gbuffer(scene, offsets=off)
    u = g.uv[..., 0] * 64 - 0.5
    v = g.uv[..., 1] * 64 - 0.5
    i0, j0 = np.floor(v).astype(int), np.floor(u).astype(int)
    fx, fy = u - j0, v - i0
    val = ((f[i0 % 64, j0 % 64] * (1 - fx) + f[i0 % 64, (j0 + 1) % 64] * fx) * (1 - fy)
           + (f[(i0 + 1) % 64, j0 % 64] * (1 - fx) + f[(i0 + 1) % 64, (j0 + 1) % 64] * fx) * fy)
    ref = d.table.naive(val).mean(axis=2)
    e_f = np.sqrt(np.mean((filt - ref) ** 2))
    e_n = np.sqrt(np.mean((naive - ref) ** 2))
    assert e_f < 0.35 * e_n, (e_f, e_n)


@pytest.mark.parametrize("bad, match", [
    ({"driver": "combine"}, "driver"),
    ({"driver": "slope", "colors": [[[0.0] * 3] * 2] * 2}, "texture"),
    ({"driver": "noise", "texture": "x.png", "colors": COLORS}, "texture"),
    ({"driver": "texture", "texture": TEX, "colors": COLORS, "edge": "wrap"}, "edge"),
    ({"driver": "texture", "texture": TEX, "colors": COLORS, "colour": 1}, "colour"),
])
def test_bad_driver_raises(bad, match):
    with pytest.raises(PrefilterError, match=match):
        render_colormap_filtered(_scene(40.0, size=4), RenderSettings(), bad)


def test_missing_driver_raises():
    with pytest.raises(PrefilterError, match="extras.colormap"):
        render_colormap_naive(_scene(40.0, size=4), RenderSettings())


def test_driver_from_scene_extras():
    # the scene format's extras.colormap
    spec = {"driver": "texture", "texture": TEX, "colors": COLORS, "range": [-4, 4],
            "sigma_max": 1.5}
    scene = _scene(40.0, size=6)
    with_extras = load_scene({**scene_dict("plane", 60.0, 40.0 * 256 / 64, 6, 6),
                              "extras": {"colormap": spec}})
    np.testing.assert_array_equal(render_colormap_filtered(with_extras, RenderSettings()),
                                  render_colormap_filtered(scene, RenderSettings(), spec))


def test_slope_render_is_the_lit_slope_term_without_the_light():
    """The slope driver's unlit image is ``V_bar Cs_bar(wo)``: ``colormap-lit`` of the same scene
    (one directional light, a plane: one cosine) divided by ``E cos / pi``; the naive image
    differs from the filtered one."""
    from prefilter.colormap.lit import render_colormap_lit

    g = np.linspace(0.0, 1.0, 6)
    colors = np.stack([np.broadcast_to(g, (6, 6)), np.broadcast_to(g[:, None], (6, 6)),
                       0.5 + 0.45 * np.cos(6.0 * np.add.outer(g, g))], -1).tolist()
    spec = {"driver": "slope", "colors": colors, "extent": 1.5, "sigma_max": 1.0, "size": 8,
            "texture": {"procedural": "gaussian", "size": 64, "seed": 1, "rms_slope": 0.5,
                        "corr_length": 3.0}}
    d = np.array([-0.6, -0.5, -0.2])
    scene = load_scene({**scene_dict("plane", 50.0, 100.0, 12, 12),
                        "lights": [{"type": "directional", "direction": d.tolist(),
                                    "irradiance": 2.0}]})
    img = render_colormap_filtered(scene, RenderSettings(), spec)
    naive = render_colormap_naive(scene, RenderSettings(), spec)
    lit = render_colormap_lit(scene, RenderSettings(), spec)
    cos = -d[1] / np.linalg.norm(d)
    hit = gbuffer(scene).hit
    np.testing.assert_allclose(img[hit] * 2.0 * cos / np.pi, lit[hit], rtol=1e-12, atol=1e-15)
    assert np.abs(naive[hit] - img[hit]).max() > 0.02
