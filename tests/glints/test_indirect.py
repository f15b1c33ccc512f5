"""Glints at path vertices: the batched footprint lobe keeps the lobe contract, the methods
path-trace with ``bounces > 1``, and on the kettle the compressed pyramid reproduces the direct
P-NDF's indirect glints (FLIP)."""

from __future__ import annotations

import numpy as np
import pytest

from prefilter import texture as tx
from prefilter.glints.indirect import FootprintGlintLobe, glint_surface, render_glints_paths
from prefilter.glints.render import baked_surface
from prefilter.render import load_scene, render
from prefilter.render.methods import RenderSettings
from prefilter.render.metrics import flip
from prefilter.render.pathtrace import PathOptions, PathStats
from prefilter.report.pathtrace import kettle_scene, write_assets
from prefilter.sphere.sampling import uniform_sphere


def _lobe(n, sigma, base=0.0):
    surf = baked_surface(tx.normal_map("brushed", 64, 1), direct=True)
    rng = np.random.default_rng(0)
    c = rng.random((n, 2)) * 64
    return FootprintGlintLobe(surf, c, np.full(n, sigma), [0.9, 0.8, 0.7], [base] * 3), rng


@pytest.mark.parametrize("base", [0.0, 0.3])
def test_weight_is_eval_over_pdf_and_albedos_agree(base):
    """Per draw ``weight = eval / pdf``; the mean weight (the albedo by the lobe's own sampling)
    equals the albedo by uniform sphere sampling of ``eval`` within 5 % (4000 draws of the same
    footprint each; the uniform estimate's standard error is about 2 %)."""
    n = 4000
    lobe, rng = _lobe(1, 3.0, base)
    lobe.center = np.repeat(lobe.center, n, 0)
    lobe.sigma_p = np.repeat(lobe.sigma_p, n)
    wo = np.tile([0.3, 0.1, np.sqrt(1 - 0.1)], (n, 1))
    wi, w = lobe.sample(wo, rng.random((n, lobe.n_uniforms)))
    ok = np.sum(w, -1) > 0
    assert np.allclose(w[ok], lobe.eval(wo[ok], wi[ok]) / lobe.pdf(wo[ok], wi[ok])[:, None])
    u = uniform_sphere(rng.random((40 * n, 2)))
    big = FootprintGlintLobe(lobe.surf, np.repeat(lobe.center[:1], 40 * n, 0),
                             np.full(40 * n, 3.0), lobe.f0, lobe.base)
    uni = np.mean(big.eval(np.tile(wo[:1], (40 * n, 1)), u), 0) * 4 * np.pi
    assert np.all(np.abs(w.mean(0) / uni - 1.0) < 0.05), (w.mean(0), uni)


@pytest.mark.slow
def test_glints_direct_with_bounces_renders_the_kettle(tmp_path):
    """``glints-direct`` with bounces=2 through the registry: finite, non-negative,
    deterministic; the indirect light (min_depth=1) is a part of the whole."""
    write_assets(tmp_path)
    scene = load_scene(kettle_scene(16, 12, 64), base_dir=tmp_path)
    a = render(scene, "glints-direct", spp=2, seed=1, params={"bounces": "2"})
    b = render(scene, "glints-direct", spp=2, seed=1, params={"bounces": "2"})
    assert np.array_equal(a, b) and np.all(np.isfinite(a)) and a.min() >= 0 and a.max() > 0
    stats = PathStats()
    ind = render_glints_paths(scene, RenderSettings(spp=2, seed=1), "direct", "x",
                              options=PathOptions(bounces=2), stats=stats, min_depth=1)
    assert np.all(ind <= a + 1e-6) and ind.sum() > 0
    assert stats.by_lobe[1].get("FootprintGlintLobe", 0.0) > 0.0
    assert len(glint_surface(scene, "direct")(_hits(scene), 1)[1]) == 3


def _hits(scene):
    from prefilter.render.camera import gbuffer_at

    cam = scene.camera
    xy = np.stack(np.meshgrid(np.arange(cam.width) + 0.5, np.arange(cam.height) + 0.5), -1)
    g = gbuffer_at(scene, xy).reshape(-1)
    return g.select(g.hit)


@pytest.mark.slow
def test_indirect_glints_compressed_match_direct(tmp_path):
    """The kettle's indirect glints (2 vertices, indirect light only, 48 x 32, 8 spp, 64^2 map:
    bakes it on first use, ~15 s): ``glints`` against ``glints-direct`` on the same paths, FLIP
    <= 0.05 (``benchmarks/bench_indirect_glints.py`` measures it at 96 x 64)."""
    write_assets(tmp_path)
    scene = load_scene(kettle_scene(48, 32, 64), base_dir=tmp_path)
    st = RenderSettings(spp=8, seed=0)
    a = render_glints_paths(scene, st, "compressed", "glints", options=PathOptions(bounces=2),
                            min_depth=1)
    b = render_glints_paths(scene, st, "direct", "glints-direct",
                            options=PathOptions(bounces=2), min_depth=1)
    assert flip(a, b).mean <= 0.05
