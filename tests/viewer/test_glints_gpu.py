"""The viewer's ``glints`` mode against ``prefilter.render.render(scene, "glints")``: the glints
measurement plane (``prefilter.viewer.glints.glints_scene``, 64^2 built-in maps baked at the
render's settings, cached under ``$PREFILTER_GLINTS_CACHE``, see tests/conftest.py) at near /
mid / far under a point light and far under a quad light, relative RMSE over hit pixels <= 1 %
with float32 codes; float16 and 8-bit codes are reported (their quantisation is not the Python
method's). The default run checks flakes at mid distance and under the quad light; the four
maps at three distances are slow (a bake per map on first use)."""

import numpy as np
import pytest

from prefilter.viewer.glints import DISTANCES, GLINT_MAPS

TOL = 0.01


def _check(rows, kind, distance):
    (r,) = [r for r in rows if (r["map"], r["distance"], r["codes"]) == (kind, distance, "f32")]
    assert r["covered"] > 0.3 * 96 * 72
    assert r["rel_rmse"] <= TOL, r


@pytest.fixture(scope="module")
def fast_rows(browser):
    from prefilter.viewer.glints import glints_pixel_match

    return glints_pixel_match(kinds=("flakes",), distances=("mid",), codes=("f32",),
                              driver=browser)


def test_flakes_mid_matches_python(fast_rows):
    _check(fast_rows, "flakes", "mid")


@pytest.fixture(scope="module")
def all_rows(browser):
    from prefilter.viewer.glints import glints_pixel_match

    rows = glints_pixel_match(codes=("f32", "f16", "u8"), driver=browser)
    for r in rows:  # the table of docs/viewer.md
        print(f"| {r['map']} | {r['distance']} | {r['codes']} | {r['rel_rmse']:.2e} | "
              f"{r['max_rel']:.2e} |")
    return rows


@pytest.mark.slow
@pytest.mark.parametrize("distance", list(DISTANCES))
@pytest.mark.parametrize("kind", list(GLINT_MAPS))
def test_glints_match_python(all_rows, kind, distance):
    _check(all_rows, kind, distance)


@pytest.mark.slow
def test_reduced_codes_are_reported(all_rows):
    for codes in ("f16", "u8"):
        sub = [r for r in all_rows if r["codes"] == codes]
        assert len(sub) == len(GLINT_MAPS) * len(DISTANCES)
        assert all(np.isfinite(r["rel_rmse"]) for r in sub)


def test_glints_differ_from_the_smooth_lobe(browser):
    """The 1 % bound tells the glint NDF from the smooth lobe of the same moments (the split
    view's right half): their images differ by far more."""
    from prefilter.viewer.browser import render_linear
    from prefilter.viewer.glints import glint_pages, glints_scene, open_viewer_glints

    sc = {"p": glints_scene("flakes", "mid")}
    with glint_pages(sc, ("flakes",), driver=browser) as (drv, url_of):
        open_viewer_glints(drv, url_of("p"), "flakes")
        a, cov = render_linear(drv, "glints")
        b, _ = render_linear(drv, "glints-smooth")
    e = (a - b)[cov]
    assert np.sqrt(np.mean(e * e)) / np.sqrt(np.mean(a[cov] ** 2)) > 10 * TOL


@pytest.mark.slow
def test_sphere_under_a_directional_light_matches_python(browser):
    from prefilter.viewer.glints import glints_pixel_match

    (r,) = glints_pixel_match(kinds=("flakes",), distances=("mid",), lights="directional",
                              shape="sphere", driver=browser)
    assert r["covered"] > 0.3 * 96 * 72
    assert r["rel_rmse"] <= TOL, r


def test_quad_light_matches_python(browser):
    """A quad light (``measurement_scene``'s square) at the far distance on a 48 x 36 frame:
    every hit pixel takes Python's range path (2 x 2 patches, 4 x 4 where those are too
    large), which the page draws with one ``glRangeMulti`` per pixel."""
    from prefilter.viewer.glints import glints_pixel_match

    (r,) = glints_pixel_match(kinds=("flakes",), distances=("far",), lights="quad", width=48,
                              height=36, driver=browser)
    assert r["covered"] > 0.3 * 48 * 36
    assert r["rel_rmse"] <= TOL, r


def test_glints_scene_takes_named_and_numeric_distances():
    from prefilter.errors import PrefilterError
    from prefilter.viewer.glints import glints_scene

    far, d8 = glints_scene("flakes", "far"), glints_scene("flakes", 8)
    assert far["camera"] == d8["camera"]
    for bad in ("farther", -1.0, 0, [8]):
        with pytest.raises(PrefilterError, match="distance"):
            glints_scene("flakes", bad)
