"""The demo report: every section present, every image it references written, failures noted."""

from __future__ import annotations

import re

import numpy as np
import pytest

from prefilter.report.demo import (DemoSettings, HIDDEN_COLOUR, _section, _viewer_section,
                                   _visible_reference, run_demo)
from prefilter.report.report import Report

SECTIONS = (
    "Isotropic GGX LTC table vs Monte Carlo",
    "Showcase: area-light methods vs reference at three distances",
    "Anisotropic LTC: brushed metal",
    "Multi-scale LTC: normal maps near and far",
    "LEADR: point light on height-mapped surfaces",
    "Colour-map filtering: cases a-d",
    "Glints (part 1): NDF images of footprints",
    "Glints (part 2): rendered frames, compressed vs direct",
    "Glints (part 3): Wang tiles",
    "Roughness mip chains from a normal map",
    "Colour-map filtering under lights (colormap-lit)",
    "Glints under wave optics",
    "Path tracing: the glint paper's scenes and indirect glints",
    "Real-time viewer: WebGL2 against Python",
    "Summary",
)

TINY = DemoSettings(width=48, height=30, reference_spp=4, flicker_frames=2, table_configs=20,
                    table_samples=2000, distances=(1.0, 16.0), section_width=40,
                    section_height=24, section_spp=4, colormap_size=16, colormap_nref=4,
                    leadr_size=32, leadr_blocks=(8,), leadr_shifts=1, leadr_rays=8,
                    glints_map=32, glints_ndf_res=16, glints_rank=4, glints_render_map=16,
                    glints_render_size=(16, 12), glints_render_distances=(2.0,),
                    glints_wang=(("ndf_res", 16), ("rank", 0)),
                    methods=("ltc", "ltc-multiscale", "leadr-point"), multiscale_maps=("flakes",),
                    colormap_configs=(("plane", 70.0, 1500.0, "far"),), viewer=False)


def test_quick_demo_writes_every_section_with_existing_images(tmp_path, monkeypatch):
    monkeypatch.setenv("PREFILTER_GLINTS_CACHE", str(tmp_path / "glints_cache"))
    lines = []
    index = run_demo(tmp_path / "demo", quick=True, settings=TINY, log=lines.append)
    page = index.read_text(encoding="utf-8")
    headings = re.findall(r"<h2 id=\"[^\"]+\">([^<]+)</h2>", page)
    assert [h.replace("&#x27;", "'") for h in headings] == list(SECTIONS)
    sources = re.findall(r'<img src="([^"]+)"', page)
    assert len(sources) > 40  # comparison rows, FLIP maps, colour cases, NDF images, plot
    for src in sources:
        f = index.parent / src
        assert f.is_file() and f.stat().st_size > 0, src
        assert f.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n", src
    # every method section ran to the end: the summary table reports no failed section
    summary = page.split(">Summary</h2>")[1]
    assert "failed" not in summary, summary[:2000]
    assert "Not available" not in page
    assert any("demo total" in ln for ln in lines)
    # a point-light-only method in the area-light showcase is listed as skipped, not a crash
    showcase = page.split(f">{SECTIONS[1]}</h2>")[1].split(f">{SECTIONS[2]}</h2>")[0]
    assert "<code>leadr-point</code>" in showcase and "ltc-multiscale" in showcase
    glints = page.split(f">{SECTIONS[7]}</h2>")[1].split(f">{SECTIONS[8]}</h2>")[0]
    assert "glints-direct" in glints and "speed-up" in glints
    wang = page.split(f">{SECTIONS[8]}</h2>")[1].split(f">{SECTIONS[9]}</h2>")[0]
    assert "glints-wang" in wang and "FLIP wang vs direct" in wang
    # the methods that reject the quad-lit showcase: one sentence, not a list of error messages
    assert "<li>" not in showcase and "PrefilterError" not in showcase
    assert showcase.count("Not shown here") == 1
    # the LTC table check: its statistics block is preformatted, its table in percent like it
    table = page.split(f">{SECTIONS[0]}</h2>")[1].split(f">{SECTIONS[1]}</h2>")[0]
    assert re.search(r"<pre><code>relative error over \d+ configurations.*\n.*\n", table)
    assert "median rel. error (%)" in table
    cells = re.findall(r"<td>(\d+\.\d\d|-)</td>", table)
    assert cells and all(c == "-" or 0 <= float(c) <= 1e4 for c in cells)
    # inline code is rendered in captions too; no literal backticks, no issue numbers
    body = page.split("</style>")[1]
    assert "`" not in body and not re.search(r"issue|#\d", body, re.I)
    assert "compilation" in showcase  # the times say what they measure


def test_a_failing_section_leaves_a_note_and_the_rest_continues(tmp_path):
    report = Report("t")
    status = []

    def broken(_report):
        raise RuntimeError("no such kernel")

    def fine(r):
        r.add_image_row("ok", [("x", np.zeros((2, 2, 3)))])

    _section(report, status, "Broken", "intro", broken, log=lambda s: None)
    _section(report, status, "Fine", "", fine, log=lambda s: None)
    page = report.write(tmp_path).read_text(encoding="utf-8")
    assert "Not available" in page and "no such kernel" in page
    assert status[0][1].startswith("failed: RuntimeError") and status[1][1] == "ok"
    assert page.index("no such kernel") < page.index(">Fine</h2>")


def test_viewer_section_without_chromium_leaves_a_note(monkeypatch, tmp_path):
    import prefilter.viewer.browser as browser

    monkeypatch.setattr(browser, "CHROMIUM", str(tmp_path / "no-chromium"))
    report = Report("t")
    report.add_section("viewer")
    _viewer_section(report, DemoSettings.quick(), 0, log=lambda s: None)
    page = report.write(tmp_path / "out").read_text(encoding="utf-8")
    assert "Headless Chromium is missing" in page and "no-chromium" in page
    assert "<img" not in page


@pytest.mark.slow
def test_viewer_section_screenshots_and_pixel_match(tmp_path):
    """With Chromium: a screenshot per mode and the pixel-match rows, each under the 1 % bound
    (the browser tests in tests/viewer check the same at other sizes)."""
    from prefilter.viewer import METHODS

    report = Report("t")
    report.add_section("viewer")
    settings = DemoSettings(viewer_size=(96, 72), viewer_match_size=(48, 36))
    _viewer_section(report, settings, 0, log=lambda s: None)
    page = report.write(tmp_path / "out").read_text(encoding="utf-8")
    assert len(re.findall(r"<img src=", page)) == len(METHODS) + 1
    rel = [float(x) for x in re.findall(r"<td[^>]*>(\d\.\d\de-\d\d)</td>\s*<td[^>]*>"
                                        r"\d\.\d\de-\d\d</td>\s*<td[^>]*>\d\.\d\de-\d\d</td>",
                                        page)]
    # f32 and f16 rows per mode, the colour-map modes f32 only
    assert len(rel) == 2 * len(METHODS) - 2 and max(rel) <= 0.01, rel


def test_skipped_methods_are_logged_as_skipped_with_the_reason(monkeypatch, tmp_path):
    """A method that cannot render the showcase is a note ("x: skipped: <reason>"), not a line
    that reads like an error; the same for the viewer section without Chromium."""
    import prefilter.render.driver as driver
    import prefilter.viewer.browser as browser
    from prefilter.errors import PrefilterError
    from prefilter.report.demo import _render_all

    def render(scene, method, **kw):
        if method == "point-only":
            raise PrefilterError("method 'point-only' renders point lights only")
        return np.zeros((2, 3, 3))

    monkeypatch.setattr(driver, "render", render)
    lines = []
    settings = DemoSettings(width=3, height=2, flicker_frames=2, distances=(1.0,))
    _render_all(settings, ["ltc", "point-only"], 0, lines.append)
    assert "distance 1: point-only: skipped: method 'point-only' renders point lights only" \
        in lines, lines
    assert not any("failed" in ln or "error" in ln.lower() for ln in lines), lines

    monkeypatch.setattr(browser, "CHROMIUM", str(tmp_path / "no-chromium"))
    lines = []
    report = Report("t")
    report.add_section("viewer")
    _viewer_section(report, DemoSettings.quick(), 0, log=lines.append)
    assert lines and lines[0].startswith("viewer section: skipped: "), lines


def test_colormap_reference_marks_pixels_without_a_visible_sample():
    """A covered pixel whose reference weights are all zero (every microfacet faces away) reads
    0 / 0 as black; it is marked, and left out of the errors, instead."""
    ref = np.full((2, 3, 3), 0.4)
    ref[0, 1] = 0.0  # covered, no visible sample
    ref[1, 2] = 0.0  # not covered (background): black in every image
    filtered = np.full((2, 3, 3), 0.5)
    filtered[1, 2] = 0.0
    shown, hidden = _visible_reference({"reference": ref, "filtered": filtered,
                                        "naive": filtered})
    assert hidden.tolist() == [[False, True, False], [False, False, False]]
    assert tuple(shown[0, 1]) == HIDDEN_COLOUR and tuple(shown[1, 2]) == (0.0, 0.0, 0.0)
    assert np.array_equal(shown[~hidden], ref[~hidden])
