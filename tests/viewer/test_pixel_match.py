"""The viewer against the Python renderer: the same scenes, methods and settings rendered by
WebGL2 (headless Chromium, SwiftShader) and by ``prefilter.render.render``; linear radiance,
relative RMSE over covered pixels <= 1 % per method, for float32 and float16 tables (and, for
``leadr-point``, float32 and float16 moment maps)."""

import numpy as np
import pytest

from prefilter.render.pipeline import render
from prefilter.viewer import METHODS, pixel_match
from prefilter.viewer.match import scene

TOL = 0.01
CASES = [(s, m) for s in ("delta", "textured") for m in METHODS
         if m != "leadr-point" and not m.startswith("colormap-")] + [
    ("leadr", "leadr-point"), ("colormap", "colormap-filtered"), ("colormap", "colormap-naive")]


@pytest.fixture(scope="module")
def rows(browser):
    return (pixel_match(scenes=("delta", "textured"), driver=browser, width=96, height=72)
            + pixel_match(scenes=("leadr",), methods=("leadr-point",), driver=browser, width=96,
                          height=72)
            + pixel_match(scenes=("colormap",), methods=("colormap-filtered", "colormap-naive"),
                          driver=browser, width=96, height=72))


@pytest.mark.parametrize("precision", ["f32", "f16"])
@pytest.mark.parametrize("scene_name, method", CASES)
def test_browser_matches_python(rows, scene_name, method, precision):
    key = (scene_name, method, precision)
    (r,) = [r for r in rows if (r["scene"], r["method"], r["precision"]) == key]
    assert r["covered"] > 0.3 * 96 * 72
    assert r["rel_rmse"] <= TOL, r


def _rel(a, b):
    return np.sqrt(np.mean((a - b) ** 2)) / np.sqrt(np.mean(b ** 2))


def test_methods_differ_by_more_than_the_tolerance(rows):
    """The 1 % bound can tell the methods apart: the Python images of ltc and ltc-multiscale on
    the bump map differ by far more (so a shader running the wrong method would fail)."""
    sc = scene("bumps-sphere", 96, 72)
    assert _rel(render(sc, "ltc"), render(sc, "ltc-multiscale")) > 10 * TOL


def test_leadr_differs_from_naive_by_more_than_the_tolerance():
    """On the ``leadr`` scene, LEADR and naive mip-mapped height-map normals (the same shading
    without the footprint's slope covariance) differ by far more than 1 %."""
    from prefilter.leadr.render import shade_leadr_delta
    from prefilter.render.methods import RenderSettings
    from prefilter.render.pipeline import render_samples
    from prefilter.render.scene import load_scene

    sc = load_scene(scene("leadr", 96, 72))
    lights = sc.light_set()
    naive = render_samples(sc, RenderSettings(),
                           lambda g, _u: shade_leadr_delta(sc, g, lights, meso=False))
    assert _rel(naive, render(sc, "leadr-point")) > 10 * TOL


@pytest.mark.slow
def test_other_scenes_all_methods(browser):
    for r in pixel_match(scenes=("flat", "brushed", "bumps-sphere", "horizon"), driver=browser):
        assert r["rel_rmse"] <= TOL, r


def test_colormap_filtered_differs_from_naive_by_more_than_the_tolerance():
    sc = scene("colormap", 96, 72)
    assert _rel(render(sc, "colormap-naive"), render(sc, "colormap-filtered")) > 10 * TOL
