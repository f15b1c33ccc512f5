"""The page's mode controls against the Python renderer: the split view (method | naive ltc) and
the normal-map choice (a procedural built-in applied to every object)."""

import copy

import numpy as np
import pytest

from prefilter.render.driver import render
from prefilter.viewer import BUILTIN_MAPS, default_scene, export_scene, serve
from prefilter.viewer.browser import open_viewer, render_linear


@pytest.fixture(scope="module")
def page(browser, tmp_path_factory):
    sc = default_scene(96, 72)
    out = export_scene(sc, tmp_path_factory.mktemp("modes") / "site", builtin_maps=True)
    server, url = serve(out)
    open_viewer(browser, url + "index.html")
    yield browser, sc
    server.shutdown()
    server.server_close()


def _rel(a, b, m):
    return np.sqrt(np.mean((a - b)[m] ** 2)) / np.sqrt(np.mean(b[m] ** 2))


def test_split_view_is_method_left_and_naive_right(page):
    driver, sc = page
    img, covered = render_linear(driver, "ltc-multiscale", split=0.5, method_right="ltc")
    left, right = render(sc, "ltc-multiscale"), render(sc, "ltc")
    w = img.shape[1]
    lm, rm = covered.copy(), covered.copy()
    lm[:, w // 2:] = False
    rm[:, :w // 2] = False
    assert _rel(img, left, lm) < 0.01 and _rel(img, right, rm) < 0.01
    # and not the other way round
    assert _rel(img, right, lm) > 0.05


def test_normal_map_choice(page):
    driver, sc = page
    driver.execute_script("const e = document.getElementById('map'); e.value = 'flakes';"
                          "e.dispatchEvent(new Event('input'));")
    try:
        img, covered = render_linear(driver, "ltc-multiscale")
    finally:
        driver.execute_script("const e = document.getElementById('map'); e.value = 'scene';"
                              "e.dispatchEvent(new Event('input'));")
    flakes = copy.deepcopy(sc)
    for o in flakes["objects"]:
        o["material"]["normal_map"] = dict(BUILTIN_MAPS["flakes"])
    ref = render(flakes, "ltc-multiscale")
    assert _rel(img, ref, covered) < 0.01
    # the scene's own (Gaussian) map gives another image: 3.4 %, > 2x the bound
    assert _rel(img, render(sc, "ltc-multiscale"), covered) > 0.02


def test_map_list_offers_the_builtins(page):
    driver, _ = page
    names = driver.execute_script(
        "return Array.from(document.getElementById('map').options).map(o => o.value);")
    assert names == ["scene", "none", *BUILTIN_MAPS]


def test_leadr_map_choice_none_drops_the_height_maps(browser, tmp_path):
    """``leadr-point`` reads the height maps' moments; the map choice ``none`` gives the Python
    image of the scene without height maps (and differs from the scene's own)."""
    from prefilter.viewer.match import scene

    sc = scene("leadr", 64, 48)
    out = export_scene(sc, tmp_path / "site", builtin_maps=False)
    server, url = serve(out)
    try:
        open_viewer(browser, url + "index.html")
        own, covered = render_linear(browser, "leadr-point")
        browser.execute_script("const e = document.getElementById('map'); e.value = 'none';"
                               "e.dispatchEvent(new Event('input'));")
        flat, _ = render_linear(browser, "leadr-point")
    finally:
        server.shutdown()
        server.server_close()
    bare = copy.deepcopy(sc)
    for o in bare["objects"]:
        del o["material"]["height_map"]
    ref = render(bare, "leadr-point")
    assert _rel(own, render(sc, "leadr-point"), covered) < 0.01
    assert _rel(flat, ref, covered) < 0.01 and _rel(own, ref, covered) > 0.05
