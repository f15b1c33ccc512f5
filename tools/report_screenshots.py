"""Screenshot each section of the demo report in headless Chromium: docs/img/report-<section>.png.

    python tools/report_screenshots.py [out/demo/index.html] [--out docs/img] [--width 1280]

One PNG per ``<h2>`` section (from its heading to the next one), named after the section's anchor
without its number (``report-showcase-area-light-methods-vs-reference.png``). Uses the Chromium
and chromedriver of the viewer tests (``prefilter.viewer.browser``); run ``prefilter demo`` first.
"""
import argparse
import base64
import sys
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO / "src"))

# [anchor, top, bottom] of every section, in page pixels
SECTIONS_JS = """
const hs = Array.from(document.querySelectorAll('h2'));
const end = document.documentElement.scrollHeight;
return hs.map((h, i) => [h.id, h.getBoundingClientRect().top + window.scrollY - 8,
                         i + 1 < hs.length ? hs[i + 1].getBoundingClientRect().top
                                             + window.scrollY - 8 : end]);
"""
LOADED_JS = ("return document.readyState === 'complete' && "
             "Array.from(document.images).every(i => i.complete);")


def screenshot_sections(index: Path, out_dir: Path, width: int = 1280) -> list[Path]:
    """Write one PNG per section of the report ``index``; returns their paths."""
    from prefilter.viewer.browser import chromium

    out_dir.mkdir(parents=True, exist_ok=True)
    written = []
    with tempfile.TemporaryDirectory(prefix="prefilter-report-shots-") as tmp:
        driver = chromium(Path(tmp) / "profile")
        try:
            driver.set_window_size(width, 1000)
            driver.get(index.resolve().as_uri())
            t0 = time.monotonic()
            while not driver.execute_script(LOADED_JS):
                if time.monotonic() - t0 > 60:
                    raise RuntimeError(f"{index}: images still loading after 60 s")
                time.sleep(0.1)
            for anchor, top, bottom in driver.execute_script(SECTIONS_JS):
                name = anchor.split("-", 1)[1] if "-" in anchor else anchor
                clip = {"x": 0, "y": max(0.0, top), "width": width,
                        "height": max(1.0, bottom - max(0.0, top)), "scale": 1}
                shot = driver.execute_cdp_cmd("Page.captureScreenshot", {
                    "format": "png", "captureBeyondViewport": True, "clip": clip})
                path = out_dir / f"report-{name}.png"
                path.write_bytes(base64.b64decode(shot["data"]))
                written.append(path)
        finally:
            driver.quit()
    return written


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("index", nargs="?", type=Path, default=REPO / "out" / "demo" / "index.html")
    ap.add_argument("--out", type=Path, default=REPO / "docs" / "img")
    ap.add_argument("--width", type=int, default=1280, help="browser width in CSS pixels")
    args = ap.parse_args()
    if not args.index.is_file():
        print(f"{args.index}: no report (run `prefilter demo` first)", file=sys.stderr)
        return 2
    for p in screenshot_sections(args.index, args.out, args.width):
        print(f"wrote {p}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
