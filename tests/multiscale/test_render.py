"""The ``ltc-multiscale`` render method.

References: closed-form mean normals of synthetic normal maps (a two-normal checkerboard averages
to ``(0, 0, cos theta)``), the ``ltc`` method on maps where multi-scale and naive must agree, and
(slow) the Monte Carlo ``reference`` renderer.
"""

from __future__ import annotations

import numpy as np
import pytest

import prefilter.multiscale  # noqa: F401  (registers the methods)
from prefilter.ltc.table import GGXTable
from prefilter.multiscale import alpha_meso_exact, alpha_total
from prefilter.multiscale.render import multiscale_attributes
from prefilter.render import gbuffer, load_scene
from prefilter.render.methods import available
from prefilter.render.driver import render, surface_attributes


def _toy_table() -> GGXTable:
    # an LTC table whose lobes are M = diag(alpha, alpha, 1): enough to exercise the pipeline
    t = np.linspace(0.0, 0.99, 8)
    r = np.linspace(0.1, 1.0, 8)
    M = np.zeros((8, 8, 3, 3))
    M[..., 0, 0] = M[..., 1, 1] = (r**2)[None, :]
    M[..., 2, 2] = 1.0
    return GGXTable(t, r, M, np.ones((8, 8)), np.zeros((8, 8)))


def _scene(normals: np.ndarray, tmp_path, *, uv_scale: float, alpha: float = 0.1) -> dict:
    np.save(tmp_path / "n.npy", (normals + 1) / 2)
    return {
        "camera": {"origin": [0, 2, 0.01], "target": [0, 0, 0], "fov": 40, "width": 24,
                   "height": 16},
        "objects": [{"type": "plane", "size": [4, 4], "uv_scale": [uv_scale, uv_scale],
                     "material": {"alpha": alpha, "f0": 1.0, "base_color": 0.1,
                                  "normal_map": {"path": "n.npy", "convention": "directx"}}}],
        "lights": [{"type": "quad", "radiance": 5.0,
                    # counter-clockwise seen from below: lights the plane
                    "vertices": [[-0.5, 1.5, -0.5], [0.5, 1.5, -0.5], [0.5, 1.5, 0.5],
                                 [-0.5, 1.5, 0.5]]}],
    }


def _checker(theta: float, size: int = 64) -> np.ndarray:
    s, c = np.sin(theta), np.cos(theta)
    n = np.empty((size, size, 3))
    odd = (np.add.outer(np.arange(size), np.arange(size)) % 2).astype(bool)
    n[~odd] = [s, 0, c]
    n[odd] = [-s, 0, c]
    return n


def test_method_is_registered_with_its_variants():
    from prefilter.render.methods import method_params

    assert "ltc-multiscale" in available()
    assert method_params("ltc-multiscale") == {"footprint": ("fit", "paper", "mrl")}
    assert not {"ltc-multiscale-paper", "ltc-multiscale-mrl"} & set(available())


def test_far_checkerboard_gives_the_closed_form_length(tmp_path):
    theta = 0.4
    sc = load_scene(_scene(_checker(theta), tmp_path, uv_scale=200.0), base_dir=tmp_path)
    g = gbuffer(sc).reshape(-1)
    g = g.select(g.hit)
    a = multiscale_attributes(sc, g)
    # every footprint spans many texels: the average of +-theta tilts is (0, 0, cos theta)
    np.testing.assert_allclose(a["r"], np.cos(theta), atol=1e-9)
    np.testing.assert_allclose(a["n"], np.broadcast_to([0, 1, 0], a["n"].shape), atol=1e-9)
    want = alpha_total(0.1, alpha_meso_exact(np.cos(theta)))
    np.testing.assert_allclose(a["alpha"], want, atol=1e-6)
    paper = multiscale_attributes(sc, g, meso="paper", total="paper")["alpha"]
    assert np.all(np.abs(paper - a["alpha"]) > 1e-4)  # the variants are really switched


def test_constant_map_renders_like_ltc(tmp_path):
    # one tilted normal everywhere: r = 1, alpha_total = alpha_micro, same image as `ltc`
    n = np.broadcast_to(np.array([np.sin(0.2), 0.0, np.cos(0.2)]), (16, 16, 3)).copy()
    sc = load_scene(_scene(n, tmp_path, uv_scale=50.0), base_dir=tmp_path)
    table = _toy_table()
    ms = render(sc, "ltc-multiscale", table=table)
    naive = render(sc, "ltc", table=table)
    assert naive.max() > 0.01
    np.testing.assert_allclose(ms, naive, rtol=1e-6, atol=1e-7)


def test_rough_footprints_render_wider_highlights_than_ltc(tmp_path):
    # the far checkerboard averages to the flat normal: `ltc` sees a mirror-like flat plane,
    # multi-scale a rougher one whose highlight spreads over more pixels with the same energy
    sc = load_scene(_scene(_checker(0.5), tmp_path, uv_scale=200.0, alpha=0.05),
                    base_dir=tmp_path)
    table = _toy_table()
    ms = render(sc, "ltc-multiscale", table=table).mean(-1)
    naive = render(sc, "ltc", table=table).mean(-1)
    assert ms.max() < naive.max()
    assert (ms > 0.1 * ms.max()).sum() > (naive > 0.1 * naive.max()).sum()


def test_attributes_agree_with_surface_attributes_on_the_frame(tmp_path):
    rng = np.random.default_rng(0)
    n = rng.normal(size=(32, 32, 3)) * [0.3, 0.3, 0] + [0, 0, 1]
    n /= np.linalg.norm(n, axis=-1, keepdims=True)
    sc = load_scene(_scene(n, tmp_path, uv_scale=3.0), base_dir=tmp_path)
    g = gbuffer(sc).reshape(-1)
    g = g.select(g.hit)
    a = multiscale_attributes(sc, g)
    b = surface_attributes(sc, g, filtered=True)
    for k in ("t", "b", "n", "base_color", "f0"):
        np.testing.assert_allclose(a[k], b[k], atol=1e-12)
    assert np.all(a["r"] <= 1.0) and np.all(a["alpha"] >= 0.1 - 1e-12)


@pytest.mark.slow
def test_far_distance_error_at_most_half_of_ltc():
    try:
        table = GGXTable.load()
    except Exception:  # noqa: BLE001
        pytest.skip("no shipped LTC table")
    import sys
    from pathlib import Path

    sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "benchmarks"))
    from bench_multiscale import scene

    from prefilter.render.metrics import rmse

    sc = scene(4.0, 64, 40, 0.03, "gaussian")  # about 16 texels per pixel
    r1 = render(sc, "reference", spp=256, seed=0)
    r2 = render(sc, "reference", spp=256, seed=1)
    ref = 0.5 * (r1 + r2)
    noise = rmse(r1, r2) / 2

    def err(m):
        e = rmse(render(sc, m, table=table), ref)
        return np.sqrt(max(e * e - noise * noise, 0.0))

    assert err("ltc-multiscale") <= 0.5 * err("ltc")


def test_study_supersampled_ltc_is_the_full_resolution_shader(tmp_path):
    # benchmarks/study_multiscale_decomp.py's "ss" image (the fused kernel with the normal-map
    # footprint scaled to nothing) must be the NumPy stages with level-0 normals
    import sys
    from pathlib import Path

    sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "benchmarks"))
    from study_multiscale_decomp import render_ss

    from prefilter.render.methods import RenderSettings
    from prefilter.ltc.shading import shade_ltc
    from prefilter.render.driver import render_samples

    rng = np.random.default_rng(3)
    n = rng.normal(size=(32, 32, 3)) * [0.3, 0.3, 0.0] + [0.0, 0.0, 1.0]
    n /= np.linalg.norm(n, axis=-1, keepdims=True)
    sc = load_scene(_scene(n, tmp_path, uv_scale=8.0, alpha=0.2), base_dir=tmp_path)
    table = GGXTable.load()
    lights = sc.light_set()

    def shade(g, _u):
        a = surface_attributes(sc, g, filtered=False)
        return shade_ltc(g.position, a["t"], a["b"], a["n"], g.view, np.sqrt(a["alpha_x"]
                         * a["alpha_y"]), a["base_color"], a["f0"], lights, table)

    want = render_samples(sc, RenderSettings(spp=4, table=table), shade, stratified=True)
    got = render_ss(sc, table, 4)
    assert np.abs(want).max() > 0.1
    np.testing.assert_allclose(got, want, rtol=1e-5, atol=1e-6)
    # and it differs from the mip-filtered ltc method (the footprint spans 8 texels)
    assert np.abs(render(sc, "ltc", table=table, spp=4) - got).max() > 1e-3


def test_box_footprint_has_no_interpolation_shortening(tmp_path):
    # magnified checkerboard (a pixel covers < 0.1 texel): the bilinear mip lookup blends +-theta
    # texels into normals as short as cos(theta) near texel corners, although the surface the
    # reference shades (normalised bilinear normals) barely turns within such a footprint;
    # the box footprint of normalised taps sees that
    theta = 0.4
    sc = load_scene(_scene(_checker(theta), tmp_path, uv_scale=0.05), base_dir=tmp_path)
    g = gbuffer(sc).reshape(-1)
    g = g.select(g.hit)
    texels = np.abs(g.dudv).max() * 64
    assert texels < 0.1
    mip = multiscale_attributes(sc, g)["r"]
    box = multiscale_attributes(sc, g, box_taps=4)
    assert mip.min() < 1.0 - 0.5 * (1.0 - np.cos(theta))
    assert box["r"].min() > 1.0 - 0.1 * (1.0 - np.cos(theta))
    np.testing.assert_allclose(box["alpha"], alpha_total(0.1, alpha_meso_exact(box["r"])),
                               atol=1e-6)


def test_box_footprint_of_a_constant_map_renders_like_ltc(tmp_path):
    n = np.broadcast_to(np.array([np.sin(0.2), 0.0, np.cos(0.2)]), (16, 16, 3)).copy()
    sc = load_scene(_scene(n, tmp_path, uv_scale=50.0), base_dir=tmp_path)
    table = _toy_table()
    from prefilter.multiscale.render import render_multiscale
    from prefilter.render.methods import RenderSettings

    ms = render_multiscale(sc, RenderSettings(table=table), box_taps=3)
    naive = render(sc, "ltc", table=table)
    assert naive.max() > 0.01
    np.testing.assert_allclose(ms, naive, rtol=1e-6, atol=1e-6)
    with pytest.raises(ValueError, match="box_taps"):
        render_multiscale(sc, RenderSettings(table=table), box_taps=-1)
