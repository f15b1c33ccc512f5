"""The viewer against the Python renderer: the same scenes, methods and settings rendered by
WebGL2 (headless Chromium, SwiftShader) and by ``prefilter.render.render``; linear radiance,
relative RMSE over covered pixels <= 1 % per method, for float32 and float16 tables."""

import pytest

from prefilter.viewer import METHODS, pixel_match

TOL = 0.01


@pytest.fixture(scope="module")
def rows(browser):
    return pixel_match(scenes=("delta", "textured"), driver=browser, width=96,
                       height=72)


@pytest.mark.parametrize("precision", ["f32", "f16"])
@pytest.mark.parametrize("method", METHODS)
@pytest.mark.parametrize("scene", ["delta", "textured"])
def test_browser_matches_python(rows, scene, method, precision):
    key = (scene, method, precision)
    (r,) = [r for r in rows if (r["scene"], r["method"], r["precision"]) == key]
    assert r["covered"] > 0.3 * 96 * 72
    assert r["rel_rmse"] <= TOL, r


def test_methods_differ_by_more_than_the_tolerance(rows):
    """The 1 % bound can tell the methods apart: the Python images of ltc and ltc-multiscale on
    the bump map differ by far more (so a shader running the wrong method would fail)."""
    import numpy as np

    from prefilter.render.pipeline import render
    from prefilter.viewer.match import scene

    sc = scene("bumps-sphere", 96, 72)
    a, b = render(sc, "ltc"), render(sc, "ltc-multiscale")
    assert np.sqrt(np.mean((a - b) ** 2)) / np.sqrt(np.mean(b ** 2)) > 10 * TOL


@pytest.mark.slow
def test_other_scenes_all_methods(browser):
    for r in pixel_match(scenes=("flat", "brushed", "bumps-sphere", "horizon"), driver=browser):
        assert r["rel_rmse"] <= TOL, r
