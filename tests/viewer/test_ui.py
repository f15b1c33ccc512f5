"""The page's controls in a real browser: a slider moved by an input event changes the image as
the Python renderer says it should; screenshots per mode; the frame time is measurable."""

import copy

import numpy as np
import pytest
from PIL import Image

from prefilter.render.driver import render
from prefilter.viewer import METHODS, default_scene, export_scene, frame_time, screenshots, serve
from prefilter.viewer.browser import open_viewer, render_linear


@pytest.fixture(scope="module")
def page(browser, tmp_path_factory):
    sc = default_scene(96, 72)
    out = export_scene(sc, tmp_path_factory.mktemp("ui") / "site", builtin_maps=False)
    server, url = serve(out)
    open_viewer(browser, url + "index.html")
    yield browser, sc
    server.shutdown()
    server.server_close()


def _slide(driver, id_, value):
    driver.execute_script("const e = document.getElementById(arguments[0]); e.value = arguments[1];"
                          "e.dispatchEvent(new Event('input'));", id_, str(value))


def test_roughness_slider_changes_the_image_as_python_does(page):
    driver, sc = page
    before, covered = render_linear(driver, "ltc")
    _slide(driver, "roughness", 0.8)
    after, _ = render_linear(driver, "ltc")
    rough = copy.deepcopy(sc)
    for o in rough["objects"]:
        m = o["material"]
        m.pop("alpha_x", None), m.pop("alpha_y", None)
        m["alpha"] = 0.8
    ref = render(rough, "ltc")
    err = np.sqrt(np.mean((after - ref)[covered] ** 2)) / np.sqrt(np.mean(ref[covered] ** 2))
    assert err < 0.01
    # a rougher surface spreads the highlight: the peak drops
    assert after.max() < 0.5 * before.max()


def test_light_slider_moves_the_highlight(page):
    driver, _ = page
    _slide(driver, "light-x", 0.0)
    a, _ = render_linear(driver, "ltc")
    _slide(driver, "light-x", 1.5)
    b, _ = render_linear(driver, "ltc")
    _slide(driver, "light-x", 0.0)
    col = lambda img: np.argmax(img.sum(-1).sum(0))  # brightest column  # noqa: E731
    assert col(b) > col(a)


def test_screenshots_per_mode(browser, tmp_path):
    paths = screenshots(tmp_path / "demo", default_scene(128, 96), driver=browser)
    assert [p.name for p in paths] == [f"viewer_{m}.png" for m in METHODS] + ["viewer_split.png"]
    imgs = [np.asarray(Image.open(p).convert("RGB"), float) for p in paths]
    assert all(i.shape == (96, 128, 3) and i.std() > 5 for i in imgs)
    # ltc and ltc-multiscale shade the bump map differently
    assert np.abs(imgs[0] - imgs[1]).mean() > 1.0


def test_frame_time_is_measured(browser):
    ms = frame_time(128, 128, frames=2, driver=browser)
    assert 0.0 < ms < 60_000.0
