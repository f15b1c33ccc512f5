"""Headless Chromium (Debian's ``/usr/bin/chromium`` + ``chromedriver``) driven by Selenium:
float read-back of the viewer's frames, screenshots and frame times.

No browser is ever downloaded: the driver is given explicitly (Selenium Manager is not used).
"""

from __future__ import annotations

import base64
import os
import tempfile
from pathlib import Path

import numpy as np

from prefilter.errors import PrefilterError

__all__ = ["CHROMEDRIVER", "CHROMIUM", "chromium", "open_viewer", "render_linear"]

CHROMIUM = "/usr/bin/chromium"
CHROMEDRIVER = "/usr/bin/chromedriver"
FLAGS = ("--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
         "--disable-background-networking", "--disable-component-update", "--disable-sync",
         "--use-angle=swiftshader", "--enable-unsafe-swiftshader", "--window-size=1024,800")


def chromium(user_data_dir=None):
    """A headless Chromium WebDriver with WebGL2 on SwiftShader (fresh profile by default)."""
    try:
        from selenium import webdriver
        from selenium.webdriver.chrome.service import Service
    except ImportError as exc:
        raise PrefilterError(f"selenium is needed to drive the browser ({exc})") from None
    for exe in (CHROMIUM, CHROMEDRIVER):
        if not os.access(exe, os.X_OK):
            raise PrefilterError(f"{exe}: not found (install Debian's chromium and "
                                 "chromium-driver)")
    opts = webdriver.ChromeOptions()
    opts.binary_location = CHROMIUM
    for f in FLAGS:
        opts.add_argument(f)
    udd = user_data_dir or tempfile.mkdtemp(prefix="prefilter-chromium-")
    opts.add_argument(f"--user-data-dir={udd}")
    return webdriver.Chrome(service=Service(CHROMEDRIVER), options=opts)


def open_viewer(driver, url: str, timeout: float = 60.0) -> None:
    """Load the page at ``url`` and wait until the viewer has loaded (raises on page errors)."""
    driver.set_script_timeout(timeout)
    driver.get(url)
    try:
        # the module script may still be running when `get` returns: wait for it, then for it
        # to finish loading
        driver.execute_async_script(
            "const done = arguments[arguments.length - 1];"
            "const poll = () => window.prefilterViewer ? window.prefilterViewer.ready.then("
            "() => done('ok'), e => done('error: ' + (e && e.message || e)))"
            " : setTimeout(poll, 20);"
            "poll();")
    except Exception as exc:
        raise PrefilterError(f"viewer at {url} failed to load: {exc}") from None
    msg = driver.execute_script("return window.prefilterViewer.error();")
    if msg:
        raise PrefilterError(f"viewer at {url} failed to load: {msg}")


def render_linear(driver, method: str = "ltc", precision: str = "f32", *, split=None,
                  method_right: str = "ltc"):
    """Linear radiance ``(H, W, 3)`` float32 of the open viewer's scene (row 0 at the top) and
    the coverage mask ``(H, W)`` (alpha = 1 where a ray hit an object).

    ``split``: fraction of the width (from the left) drawn by ``method``, the rest by
    ``method_right`` (the page's split view); ``None`` draws ``method`` everywhere."""
    size = driver.execute_script("const c = window.prefilterViewer.viewer.camera;"
                                 "return [c.width, c.height];")
    opts = {"method": method, "precision": precision}
    if split is not None:
        opts.update(split=float(split), methodRight=method_right)
    b64 = driver.execute_script("return window.prefilterViewer.renderLinear(arguments[0]);",
                                opts)
    a = np.frombuffer(base64.b64decode(b64), "<f4").reshape(size[1], size[0], 4)
    return a[..., :3].copy(), a[..., 3] > 0.5


def screenshot(driver, path) -> Path:
    """The page's canvas as a PNG (display encoding: sRGB)."""
    p = Path(path)
    p.parent.mkdir(parents=True, exist_ok=True)
    driver.execute_script("window.prefilterViewer.redraw();")
    el = driver.find_element("id", "canvas")
    p.write_bytes(el.screenshot_as_png)
    return p
