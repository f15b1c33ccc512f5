"""A small, dependency-free HTML report: sections, image rows, tables, plots and text.

Build it in order, then :meth:`Report.write` a directory holding ``index.html`` and its PNG assets
(``fig-NNN-<slug>.png``, next to ``index.html``). Content is captured when added (arrays are
encoded, figures rendered, files read), so later changes to the inputs do not leak in. Every file is
written atomically and ``index.html`` last, so a reader never sees a page pointing at missing files.
The page has inline CSS only: no JavaScript, no CDN, readable offline.

Float images are linear RGB and are displayed with :func:`~prefilter.render.metrics.to_srgb8`
(ACES tone curve, the one HDR-FLIP assumes); ``uint8`` images are taken as already sRGB-encoded.
"""

from __future__ import annotations

import html
import io
import os
import re
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from prefilter.fileio import atomic_path
from prefilter.validation import as_float_array, as_positive_int
from prefilter.errors import PrefilterError
from prefilter.render.metrics import to_srgb8
from prefilter.texture.io import png_bytes

IMAGE_SUFFIXES = {".png", ".jpg", ".jpeg", ".gif", ".svg", ".webp"}

CSS = """
body { font-family: system-ui, -apple-system, "Segoe UI", sans-serif; margin: 2em auto;
       max-width: 1400px; padding: 0 1em; color: #222; background: #fff; line-height: 1.45; }
h1 { border-bottom: 2px solid #ddd; padding-bottom: .3em; }
h2 { margin-top: 2em; border-bottom: 1px solid #eee; }
nav ul { columns: 2; }
code { background: #f4f4f4; padding: 0 .25em; border-radius: 3px; }
pre { background: #f4f4f4; padding: .6em .8em; border-radius: 3px; overflow-x: auto;
      line-height: 1.3; }
pre code { padding: 0; background: none; }
.row { margin: 1em 0; }
.row-label { font-weight: 600; margin-bottom: .3em; }
.images { display: flex; flex-wrap: wrap; gap: .8em; align-items: flex-start; }
figure { margin: 0; }
figure img { max-width: 100%; height: auto; image-rendering: pixelated; border: 1px solid #ccc; }
figcaption { font-size: .9em; color: #555; text-align: center; }
figure.plot { display: inline-block; }
.plot img { image-rendering: auto; }
table { border-collapse: collapse; margin: 1em 0; font-variant-numeric: tabular-nums; }
th, td { border: 1px solid #ccc; padding: .25em .7em; }
th { background: #f4f4f4; text-align: left; }
td.num { text-align: right; }
caption { caption-side: bottom; font-size: .9em; color: #555; padding-top: .3em; }
"""


@dataclass
class _Asset:
    stem: str
    suffix: str
    data: bytes
    width: int | None = None
    height: int | None = None
    name: str = field(default="")


class Report:
    """An HTML report assembled block by block; see the module docstring.

    Parameters
    ----------
    title : str
        Page title and top heading.
    exposure : float
        Exposure (stops) applied to float images before display encoding.
    tonemap : {"aces", "reinhard", "clamp"}
        Tone curve for float images.
    """

    def __init__(self, title: str, *, exposure: float = 0.0, tonemap: str = "aces"):
        self.title = str(title)
        self.exposure = exposure
        self.tonemap = tonemap
        to_srgb8(np.zeros(3), exposure=exposure, method=tonemap)  # validate the settings now
        self._blocks: list[tuple] = []
        self._assets: list[_Asset] = []
        self._sections: list[tuple[str, str]] = []

    # ------------------------------------------------------------------------------ building
    def add_section(self, title: str, text: str | None = None) -> "Report":
        """Start a new section with a heading (and an optional paragraph)."""
        anchor = f"s{len(self._sections) + 1}-{_slug(title)}"
        self._sections.append((anchor, str(title)))
        self._blocks.append(("section", anchor, str(title)))
        if text:
            self.add_text(text)
        return self

    def add_text(self, text: str) -> "Report":
        """A markdown-ish paragraph: blank lines split paragraphs, ``- `` starts list items,
        a fenced block (lines between two ```` ``` ```` lines) is kept verbatim,
        ``**bold**``, ``*italic*``, `` `code` `` and ``[text](url)`` are recognised."""
        self._blocks.append(("html", _markdownish(str(text))))
        return self

    def add_image_row(self, label: str, items, *, scale: int = 1) -> "Report":
        """A row of captioned images shown side by side, each pixel as ``scale`` x ``scale``
        screen pixels (nearest neighbour, so aliasing stays visible). The label and captions
        take the inline markup of :meth:`add_text` (`` `code` ``, ``**bold**``, ...).

        ``items``: sequence of ``(caption, image)`` with ``image`` a float linear RGB array
        ``(H, W, 3)`` (tone mapped for display), a ``uint8`` sRGB array ``(H, W, 3)`` or ``(H, W)``,
        or the path of an existing PNG/JPEG/GIF/SVG/WebP file (copied next to ``index.html``).
        """
        scale = as_positive_int(scale, "scale")
        figures = []
        for i, item in enumerate(items):
            if not (isinstance(item, (tuple, list)) and len(item) == 2
                    and isinstance(item[0], str)):
                raise PrefilterError(
                    f"items[{i}]: expected a (caption, image) pair with a str caption, got "
                    f"{type(item).__name__}"
                )
            caption, image = item
            asset = self._add_asset(f"{label}-{caption}", image, f"items[{i}]")
            figures.append((caption, asset, scale))
        if not figures:
            raise PrefilterError(f"items: expected at least one (caption, image) for row {label!r}")
        self._blocks.append(("images", str(label), figures))
        return self

    def add_comparison(self, label: str, reference, methods: dict, *, hdr: bool = True,
                       scale: int = 1, eps: float = 1e-2,
                       reference_name: str = "reference") -> list[dict]:
        """Reference and methods side by side, then their FLIP heat maps; returns the metrics.

        ``reference`` and each ``methods[name]`` are linear RGB ``(H, W, 3)`` (sRGB in [0, 1]
        with ``hdr=False``); ``reference_name`` captions the reference image. Returns one dict
        per method (``method``, ``rmse``, ``relmse``, ``flip``) for the caller's table, so rows
        from several comparisons share one table.
        """
        from prefilter.render.metrics import flip, flip_heatmap, relmse, rmse

        if not methods:
            raise PrefilterError(f"methods: expected at least one image to compare in {label!r}")
        rows, maps = [], []
        for name, image in methods.items():
            f = flip(image, reference, hdr=hdr)
            rows.append({"method": str(name), "rmse": rmse(image, reference),
                         "relmse": relmse(image, reference, eps=eps), "flip": f.mean})
            maps.append((f"{name}: FLIP {f.mean:.4f}", flip_heatmap(f.error_map)))
        self.add_image_row(label, [(str(reference_name), reference)]
                           + [(str(n), im) for n, im in methods.items()], scale=scale)
        self.add_image_row(f"{label}: FLIP error (magma, 0 to 1)", maps, scale=scale)
        return rows

    def add_table(self, header, rows, *, caption: str | None = None,
                  float_format: str = "{:.4g}") -> "Report":
        """A table; float cells are formatted with ``float_format``, everything else with str().
        The caption takes the inline markup of :meth:`add_text`."""
        header = [str(h) for h in header]
        body = []
        for i, row in enumerate(rows):
            row = list(row)
            if len(row) != len(header):
                raise PrefilterError(
                    f"rows[{i}]: expected {len(header)} cells to match the header, got {len(row)}"
                )
            body.append([_cell(c, float_format) for c in row])
        self._blocks.append(("table", header, body, caption))
        return self

    def add_plot(self, plot, *, caption: str | None = None, dpi: int = 100) -> "Report":
        """A matplotlib figure (rendered to PNG now) or the path of an image file."""
        if hasattr(plot, "savefig"):
            buf = io.BytesIO()
            plot.savefig(buf, format="png", dpi=dpi, metadata={"Software": None})
            asset = self._new_asset(caption or "plot", ".png", buf.getvalue())
        else:
            asset = self._add_asset(caption or "plot", plot, "plot")
        self._blocks.append(("plot", asset, caption))
        return self

    # ------------------------------------------------------------------------------- writing
    def to_html(self) -> str:
        """The page as a string (asset names are assigned by the order of addition)."""
        out = [
            "<!DOCTYPE html>",
            '<html lang="en">',
            "<head>",
            '<meta charset="utf-8">',
            '<meta name="viewport" content="width=device-width, initial-scale=1">',
            f"<title>{_esc(self.title)}</title>",
            f"<style>{CSS}</style>",
            "</head>",
            "<body>",
            f"<h1>{_esc(self.title)}</h1>",
        ]
        if len(self._sections) > 1:
            out.append("<nav><ul>")
            out += [f'<li><a href="#{a}">{_esc(t)}</a></li>' for a, t in self._sections]
            out.append("</ul></nav>")
        for block in self._blocks:
            out.append(_render_block(block))
        out += ["</body>", "</html>", ""]
        return "\n".join(out)

    def write(self, directory: str | os.PathLike) -> Path:
        """Write ``index.html`` and its assets into ``directory``; returns the index path."""
        directory = Path(directory)
        try:
            directory.mkdir(parents=True, exist_ok=True)
        except OSError as exc:
            raise PrefilterError(f"directory: cannot create {str(directory)!r}: {exc}") from exc
        page = self.to_html()
        for asset in self._assets:
            target = directory / asset.name
            if target.exists() and target.read_bytes() == asset.data:
                continue  # unchanged: keep the file (and its timestamp)
            with atomic_path(target, suffix=asset.suffix) as tmp:
                tmp.write_bytes(asset.data)
        index = directory / "index.html"
        with atomic_path(index, suffix=".html") as tmp:
            tmp.write_text(page, encoding="utf-8")
        return index

    # ------------------------------------------------------------------------------- assets
    def _new_asset(self, stem: str, suffix: str, data: bytes, size=(None, None)) -> _Asset:
        asset = _Asset(stem, suffix, data, width=size[0], height=size[1])
        asset.name = f"fig-{len(self._assets) + 1:03d}-{_slug(stem)}{suffix}"
        self._assets.append(asset)
        return asset

    def _add_asset(self, stem: str, image, name: str) -> _Asset:
        if isinstance(image, (str, os.PathLike)):
            path = Path(image)
            suffix = path.suffix.lower()
            if suffix not in IMAGE_SUFFIXES:
                raise PrefilterError(
                    f"{name}: expected an image file a browser shows ({sorted(IMAGE_SUFFIXES)}), "
                    f"got {str(path)!r}; pass EXR images as arrays"
                )
            try:
                data = path.read_bytes()
            except OSError as exc:
                raise PrefilterError(f"{name}: cannot read {str(path)!r}: {exc}") from exc
            return self._new_asset(stem, ".jpg" if suffix == ".jpeg" else suffix, data)
        rgb = self._display(image, name)
        return self._new_asset(stem, ".png", png_bytes(rgb), size=(rgb.shape[1], rgb.shape[0]))

    def _display(self, image, name: str) -> np.ndarray:
        a = np.asarray(image)
        if a.ndim == 2:
            a = np.repeat(a[..., None], 3, axis=-1)
        if a.ndim != 3 or a.shape[-1] != 3 or a.shape[0] == 0 or a.shape[1] == 0:
            raise PrefilterError(f"{name}: expected an image (H, W, 3) or (H, W), got {a.shape}")
        if a.dtype == np.uint8:
            return a
        if not np.issubdtype(a.dtype, np.number) or np.issubdtype(a.dtype, np.complexfloating):
            raise PrefilterError(f"{name}: expected a real image array, got dtype {a.dtype}")
        return to_srgb8(as_float_array(a, name), exposure=self.exposure, method=self.tonemap)


def line_plot(x, series: dict, *, xlabel: str, ylabel: str, title: str | None = None,
              logx: bool = False, logy: bool = False, size=(6.0, 3.6)):
    """A matplotlib Figure with one line per ``series`` entry (name -> y values over ``x``).

    Built without pyplot (no global state, no GUI backend), e.g. error vs distance per method.
    """
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    x = np.asarray(x, dtype=np.float64)
    fig = Figure(figsize=size, layout="constrained")
    FigureCanvasAgg(fig)
    ax = fig.add_subplot()
    for name, y in series.items():
        y = np.asarray(y, dtype=np.float64)
        if y.shape != x.shape:
            raise PrefilterError(f"series[{name!r}]: expected shape {x.shape}, got {y.shape}")
        ax.plot(x, y, marker="o", markersize=3, label=str(name))
    ax.set_xlabel(xlabel)
    ax.set_ylabel(ylabel)
    if title:
        ax.set_title(title)
    if logx:
        ax.set_xscale("log")
    if logy:
        ax.set_yscale("log")
    ax.grid(True, alpha=0.3)
    if series:
        ax.legend()
    return fig


# ------------------------------------------------------------------------------------ helpers


def _esc(s) -> str:
    return html.escape(str(s), quote=True)


def _slug(s: str) -> str:
    slug = re.sub(r"[^a-z0-9]+", "-", str(s).lower()).strip("-")
    return slug[:40].rstrip("-") or "x"


def _cell(c, float_format: str) -> tuple[str, bool]:
    if isinstance(c, (bool, np.bool_)):
        return str(bool(c)), False
    if isinstance(c, (float, np.floating)):
        return float_format.format(float(c)), True
    if isinstance(c, (int, np.integer)):
        return str(int(c)), True
    return str(c), False


_INLINE = [
    (re.compile(r"\*\*([^*]+)\*\*"), r"<strong>\1</strong>"),
    (re.compile(r"\*([^*]+)\*"), r"<em>\1</em>"),
    (re.compile(r"\[([^\]]+)\]\(([^)\s]+)\)"), r'<a href="\2">\1</a>'),
]


def _inline(text: str) -> str:
    # escape first, so user text can never inject markup; the patterns only add known tags
    parts = re.split(r"(`[^`]+`)", _esc(text))
    out = []
    for part in parts:
        if part.startswith("`") and part.endswith("`") and len(part) > 1:
            out.append(f"<code>{part[1:-1]}</code>")  # no emphasis inside code
        else:
            for pattern, repl in _INLINE:
                part = pattern.sub(repl, part)
            out.append(part)
    return "".join(out)


_FENCE = re.compile(r"^[ \t]*```[^\n]*\n(.*?)\n[ \t]*```[ \t]*$", re.S | re.M)


def _markdownish(text: str) -> str:
    out, pos = [], 0
    text = str(text)
    for m in _FENCE.finditer(text):  # fenced blocks first: their blank lines split nothing
        out.append(_paragraphs(text[pos:m.start()]))
        out.append(f"<pre><code>{_esc(m.group(1))}</code></pre>")
        pos = m.end()
    out.append(_paragraphs(text[pos:]))
    return "\n".join(o for o in out if o)


def _paragraphs(text: str) -> str:
    out = []
    for para in re.split(r"\n\s*\n", text.strip()):
        lines = [ln.strip() for ln in para.splitlines() if ln.strip()]
        if lines and all(ln.startswith("- ") for ln in lines):
            out.append("<ul>" + "".join(f"<li>{_inline(ln[2:])}</li>" for ln in lines) + "</ul>")
        elif lines:
            out.append(f"<p>{_inline(' '.join(lines))}</p>")
    return "\n".join(out)


def _plain(text: str) -> str:
    """Inline markup without its marks (for ``alt`` attributes)."""
    return re.sub(r"`([^`]+)`", r"\1", str(text))


def _img_tag(asset: _Asset, alt: str, scale: int = 1) -> str:
    size = ""
    if asset.width is not None:
        size = f' width="{asset.width * scale}" height="{asset.height * scale}"'
    return f'<img src="{_esc(asset.name)}" alt="{_esc(alt)}"{size}>'


def _render_block(block: tuple) -> str:
    kind = block[0]
    if kind == "section":
        _, anchor, title = block
        return f'<h2 id="{_esc(anchor)}">{_esc(title)}</h2>'
    if kind == "html":
        return block[1]
    if kind == "images":
        _, label, figures = block
        figs = "".join(
            f"<figure>{_img_tag(a, _plain(c), k)}<figcaption>{_inline(c)}</figcaption></figure>"
            for c, a, k in figures
        )
        return (f'<div class="row"><div class="row-label">{_inline(label)}</div>'
                f'<div class="images">{figs}</div></div>')
    if kind == "table":
        _, header, body, caption = block
        cap = f"<caption>{_inline(caption)}</caption>" if caption else ""
        head = "".join(f"<th>{_esc(h)}</th>" for h in header)
        rows = "".join(
            "<tr>" + "".join(
                f'<td class="num">{_esc(t)}</td>' if num else f"<td>{_esc(t)}</td>"
                for t, num in row
            ) + "</tr>"
            for row in body
        )
        return f"<table>{cap}<thead><tr>{head}</tr></thead><tbody>{rows}</tbody></table>"
    if kind == "plot":
        _, asset, caption = block
        cap = f"<figcaption>{_inline(caption)}</figcaption>" if caption else ""
        return f'<figure class="plot">{_img_tag(asset, _plain(caption or "plot"))}{cap}</figure>'
    raise AssertionError(kind)  # pragma: no cover
