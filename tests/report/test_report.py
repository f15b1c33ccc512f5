"""The HTML report: well-formed, self-contained, each referenced file exists and holds its image."""

from __future__ import annotations

from html.parser import HTMLParser

import numpy as np
import pytest
from PIL import Image

from prefilter.errors import PrefilterError
from prefilter.report.report import Report, line_plot
from prefilter.texture.io import png_bytes, save_png

VOID = {"meta", "img", "br", "hr", "link", "input"}


class _Checker(HTMLParser):
    """Checks nesting of non-void elements and collects references and text."""

    def __init__(self):
        super().__init__(convert_charrefs=True)
        self.stack, self.errors, self.srcs, self.hrefs, self.tags = [], [], [], [], []
        self.text = []

    def handle_starttag(self, tag, attrs):
        a = dict(attrs)
        self.tags.append((tag, a))
        if tag == "img":
            self.srcs.append(a.get("src"))
        if tag in ("a", "link") and "href" in a:
            self.hrefs.append(a["href"])
        if tag == "script":
            self.errors.append("script tag")
        if tag not in VOID:
            self.stack.append(tag)

    def handle_endtag(self, tag):
        if not self.stack or self.stack[-1] != tag:
            self.errors.append(f"unexpected </{tag}> with open {self.stack[-3:]}")
        else:
            self.stack.pop()

    def handle_data(self, data):
        self.text.append(data)


def _check(index):
    page = index.read_text(encoding="utf-8")
    assert page.startswith("<!DOCTYPE html>")
    c = _Checker()
    c.feed(page)
    c.close()
    assert not c.errors, c.errors
    assert not c.stack, f"unclosed {c.stack}"
    return page, c


def _sample_report(tmp_path):
    rng = np.random.default_rng(0)
    ref = rng.uniform(0, 2, (12, 16, 3))
    existing = tmp_path / "given.png"
    Image.fromarray(np.full((5, 7, 3), 200, np.uint8)).save(existing)
    fig = line_plot([1, 2, 4], {"LTC": [0.1, 0.05, 0.02], "MIS": [0.2, 0.1, 0.09]},
                    xlabel="distance", ylabel="RMSE", logy=True)
    r = Report("Demo <report> & friends")
    r.add_section("Area lights", "Compares **LTC** against a *Monte Carlo* reference; see `eq. 3`.")
    r.add_image_row("plane, roughness 0.3", [("reference", ref), ("LTC", ref * 0.9),
                                              ("FLIP", np.zeros((12, 16), np.uint8)),
                                              ("given", existing)])
    r.add_table(["method", "RMSE", "FLIP", "samples"],
                [["LTC", 0.0123456, np.float32(0.25), 1], ["MIS <ref>", 0.0, 0.0, 4096]],
                caption="lower is better")
    r.add_section("Error vs distance")
    r.add_plot(fig, caption="RMSE vs distance")
    r.add_text("- first item\n- second with [a link](https://example.org/?a=1&b=2)")
    return r, ref, existing


def test_report_writes_valid_self_contained_html(tmp_path):
    r, ref, existing = _sample_report(tmp_path)
    out = tmp_path / "out" / "demo"
    index = r.write(out)
    assert index == out / "index.html"
    page, c = _check(index)
    # every image is a local file written next to index.html
    assert len(c.srcs) == 5
    for src in c.srcs:
        assert "/" not in src and (out / src).is_file(), src
    assert not any(h.startswith("http") for _, a in c.tags for h in [a.get("src", "")])
    assert "<script" not in page and "cdn" not in page.lower()
    # user text is escaped, markdown-ish markup is rendered
    assert "Demo &lt;report&gt; &amp; friends" in page
    assert "<strong>LTC</strong>" in page and "<em>Monte Carlo</em>" in page
    assert "<code>eq. 3</code>" in page
    assert any(t == "li" for t, _ in c.tags) and "https://example.org/?a=1&b=2" in c.hrefs
    assert "MIS &lt;ref&gt;" in page and "0.01235" in page and "4096" in page
    # two sections: a table of contents links to both anchors
    ids = {a["id"] for t, a in c.tags if "id" in a}
    assert {h[1:] for h in c.hrefs if h.startswith("#")} == ids and len(ids) == 2


def test_report_images_hold_the_pixels(tmp_path):
    r, ref, existing = _sample_report(tmp_path)
    out = tmp_path / "site"
    r.write(out)
    _, c = _check(out / "index.html")
    with Image.open(out / c.srcs[0]) as im:
        shown = np.asarray(im)
    # float images are tone mapped with the ACES curve and sRGB-encoded (closed forms)
    x = ref
    aces = np.clip(x * (2.51 * x + 0.03) / (x * (2.43 * x + 0.59) + 0.14), 0, 1)
    srgb = np.where(aces <= 0.0031308, 12.92 * aces, 1.055 * aces ** (1 / 2.4) - 0.055)
    np.testing.assert_array_equal(shown, np.round(srgb * 255).astype(np.uint8))
    # uint8 greyscale is shown as is; files are copied byte for byte
    with Image.open(out / c.srcs[2]) as im:
        assert np.all(np.asarray(im) == 0) and im.size == (16, 12)
    assert (out / c.srcs[3]).read_bytes() == existing.read_bytes()
    with Image.open(out / c.srcs[4]) as im:
        assert im.format == "PNG" and im.size[0] > 100  # the rendered plot


def test_report_is_deterministic_and_atomic(tmp_path):
    r1, _, _ = _sample_report(tmp_path)
    r2, _, _ = _sample_report(tmp_path)
    a, b = r1.write(tmp_path / "a"), r2.write(tmp_path / "b")
    assert a.read_bytes() == b.read_bytes()
    for f in sorted((tmp_path / "a").iterdir()):
        assert (tmp_path / "b" / f.name).read_bytes() == f.read_bytes(), f.name
    # no temporary files are left behind, rewriting is idempotent
    r1.write(tmp_path / "a")
    names = sorted(p.name for p in (tmp_path / "a").iterdir())
    assert not [n for n in names if n.startswith(".")]
    assert names == sorted(p.name for p in (tmp_path / "b").iterdir())


def test_report_captures_arrays_when_added(tmp_path):
    img = np.zeros((2, 2, 3))
    r = Report("t")
    r.add_image_row("row", [("black", img)])
    img[:] = 1.0  # later edits must not change the report
    r.write(tmp_path)
    _, c = _check(tmp_path / "index.html")
    with Image.open(tmp_path / c.srcs[0]) as im:
        assert np.all(np.asarray(im) == 0)


@pytest.mark.parametrize(
    "call, match",
    [
        (lambda r: r.add_table(["a", "b"], [[1, 2, 3]]), "rows\\[0\\]"),
        (lambda r: r.add_image_row("x", []), "at least one"),
        (lambda r: r.add_image_row("x", [np.zeros((2, 2, 3))]), "caption"),
        (lambda r: r.add_image_row("x", [("c", np.zeros((2, 2, 4)))]), "\\(H, W, 3\\)"),
        (lambda r: r.add_image_row("x", [("c", np.full((2, 2, 3), np.nan))]), "finite"),
        (lambda r: r.add_image_row("x", [("c", "missing.png")]), "missing.png"),
        (lambda r: r.add_image_row("x", [("c", "image.exr")]), "arrays"),
        (lambda r: r.add_plot("nope.png"), "nope.png"),
    ],
)
def test_report_rejects_bad_input(call, match):
    with pytest.raises(PrefilterError, match=match):
        call(Report("t"))


def test_report_rejects_bad_display_settings():
    with pytest.raises(PrefilterError, match="method"):
        Report("t", tonemap="filmic")


def test_save_png_roundtrip(tmp_path):
    rgb = np.arange(2 * 3 * 3, dtype=np.uint8).reshape(2, 3, 3) * 10
    p = save_png(tmp_path / "sub" / "x.png", rgb)
    with Image.open(p) as im:
        np.testing.assert_array_equal(np.asarray(im), rgb)
    assert p.read_bytes() == png_bytes(rgb)
    with pytest.raises(PrefilterError, match="uint8"):
        save_png(tmp_path / "y.png", rgb.astype(float))


def test_line_plot_checks_series_shape():
    with pytest.raises(PrefilterError, match="series"):
        line_plot([1, 2, 3], {"a": [1, 2]}, xlabel="x", ylabel="y")


def test_add_comparison_metrics_and_heatmaps(tmp_path):
    ref = np.random.default_rng(3).uniform(0.2, 1.5, (10, 12, 3))
    r = Report("cmp")
    rows = r.add_comparison("scene", ref, {"exact": ref.copy(), "offset": ref + 0.1}, scale=3)
    assert [row["method"] for row in rows] == ["exact", "offset"]
    assert rows[0]["rmse"] == 0.0 and rows[0]["flip"] == 0.0
    assert rows[1]["rmse"] == pytest.approx(0.1)
    assert rows[1]["relmse"] == pytest.approx(np.mean(0.01 / (ref**2 + 0.01)))
    assert rows[1]["flip"] > 0.0
    r.write(tmp_path)
    _, c = _check(tmp_path / "index.html")
    imgs = [a for t, a in c.tags if t == "img"]
    assert len(imgs) == 5  # reference + 2 methods, then 2 heat maps
    assert all(a["width"] == "36" and a["height"] == "30" for a in imgs)
    with Image.open(tmp_path / imgs[3]["src"]) as im:  # heat map of the exact method: magma(0)
        np.testing.assert_allclose(np.asarray(im).reshape(-1, 3), [[0, 0, 4]] * 120, atol=1)


def test_fenced_block_keeps_its_lines():
    """A fenced block (a plain-text table) is preformatted, not joined into one paragraph."""
    r = Report("t")
    r.add_text("Numbers:\n\n```\nmedian  p90\n\n  3.47%  <29%\n```\nafter the `block`")
    page = r.to_html()
    assert "<pre><code>median  p90\n\n  3.47%  &lt;29%</code></pre>" in page
    assert "<p>Numbers:</p>" in page and "<p>after the <code>block</code></p>" in page
    assert "```" not in page


def test_captions_and_labels_render_inline_code(tmp_path):
    r = Report("t")
    r.add_image_row("row of `ltc`", [("`ltc` <b>", np.zeros((2, 2, 3)))])
    r.add_table(["a"], [[1]], caption="`glints.point` at **centres**")
    r.add_plot(_png(tmp_path), caption="see `x`")
    page = r.to_html()
    assert "`" not in page.replace('alt="', "")
    assert '<div class="row-label">row of <code>ltc</code></div>' in page
    assert "<figcaption><code>ltc</code> &lt;b&gt;</figcaption>" in page
    assert 'alt="ltc &lt;b&gt;"' in page  # alt text: the words without the marks
    assert "<caption><code>glints.point</code> at <strong>centres</strong></caption>" in page
    assert "<figcaption>see <code>x</code></figcaption>" in page


def _png(tmp_path):
    p = tmp_path / "p.png"
    save_png(p, np.zeros((2, 2, 3), np.uint8))
    return p
