"""Command-line entry points of ``prefilter.render`` (loaded lazily by ``prefilter.cli``).

Commands: ``compare`` (image metrics), ``render``, ``export-mitsuba`` (a Mitsuba 3 scene).
"""

from __future__ import annotations

from pathlib import Path

import click
import numpy as np

from prefilter.cliparams import SEED, OutputFile, scheduler_options
from prefilter.errors import PrefilterError

# ------------------------------------------------------------------------------------- compare


def _read_image(path: Path) -> tuple[np.ndarray, bool]:
    """``(linear RGB float64 (H, W, 3), is_hdr)``: EXR/.npy are linear, PNG is sRGB-encoded."""
    from prefilter.texture.io import read_image

    hdr = path.suffix.lower() != ".png"
    img = read_image(path, srgb=not hdr)
    c = img.shape[2]
    if c in (1, 2):  # grey (+ alpha): the same value in R, G and B
        return np.repeat(img[..., :1], 3, axis=-1), hdr
    return img[..., :3], hdr  # alpha does not enter the comparison


def compare_images(test_path, reference_path, *, eps: float = 1e-2) -> dict:
    """RMSE, relative MSE and FLIP of the image file ``test_path`` against ``reference_path``.

    EXR (and ``.npy``) files are compared as linear radiance with HDR-FLIP; PNG files are decoded
    from sRGB to linear for RMSE/relMSE and compared with LDR-FLIP. Alpha is ignored, grey images
    count as R = G = B. Returns a JSON-ready dict; the FLIP
    error map is under ``"flip_map"`` (removed before JSON output).
    """
    from prefilter.render.metrics import flip, linear_to_srgb, relmse, rmse

    test_path, reference_path = Path(test_path), Path(reference_path)
    test, test_hdr = _read_image(test_path)
    ref, ref_hdr = _read_image(reference_path)
    if test_hdr != ref_hdr:
        raise PrefilterError(
            f"{test_path}, {reference_path}: expected two linear images (EXR/.npy) or two "
            f"sRGB PNGs, got one of each"
        )
    if test.shape != ref.shape:
        raise PrefilterError(
            f"{test_path}, {reference_path}: expected images of the same size, got "
            f"{test.shape[1]}x{test.shape[0]} and {ref.shape[1]}x{ref.shape[0]} (W x H)"
        )
    if test_hdr:
        # HDR-FLIP needs radiance >= 0; negative EXR values (filter ringing) count as black
        fl = flip(np.maximum(test, 0.0), np.maximum(ref, 0.0), hdr=True)
    else:
        fl = flip(linear_to_srgb(test), linear_to_srgb(ref), hdr=False)
    return {
        "test": str(test_path),
        "reference": str(reference_path),
        "width": int(test.shape[1]),
        "height": int(test.shape[0]),
        "rmse": rmse(test, ref),
        "relmse": relmse(test, ref, eps=eps),
        "relmse_eps": eps,
        "flip": fl.mean,
        "flip_settings": fl.settings,
        "flip_map": fl.error_map,
    }


@click.command("compare")
@click.argument("test", type=click.Path(exists=True, dir_okay=False, path_type=Path))
@click.argument("reference", type=click.Path(exists=True, dir_okay=False, path_type=Path))
@click.option("--heatmap", type=OutputFile(path_type=Path),
              help="Write the FLIP error map as a magma heat map PNG.")
@click.option("--json", "json_path", type=OutputFile(path_type=Path),
              help="Write the metrics as JSON.")
@click.option("--eps", type=float, default=1e-2, show_default=True,
              help="Regulariser of relMSE = mean((a-b)^2 / (b^2 + eps)).")
def compare(test: Path, reference: Path, heatmap: Path | None, json_path: Path | None,
            eps: float) -> None:
    """Compare image TEST against REFERENCE: RMSE, relative MSE and FLIP.

    EXR/.npy inputs are linear (HDR-FLIP); PNG inputs are sRGB (LDR-FLIP).
    """
    from prefilter.fileio import save_json_atomic
    from prefilter.render.metrics import flip_heatmap
    from prefilter.texture.io import save_png

    result = compare_images(test, reference, eps=eps)
    flip_map = result.pop("flip_map")
    s = result["flip_settings"]
    kind = "HDR-FLIP" if s["hdr"] else "LDR-FLIP"
    detail = f"{kind}, {s['ppd']:.1f} ppd"
    if s["hdr"]:
        detail += (f", {s['tonemapper'].upper()} exposures {s['start_exposure']:+.2f}.."
                   f"{s['stop_exposure']:+.2f} ({s['num_exposures']} steps)")
    click.echo(f"RMSE    {result['rmse']:.6g}")
    click.echo(f"relMSE  {result['relmse']:.6g}  (eps {eps:g})")
    click.echo(f"FLIP    {result['flip']:.6g}  ({detail})")
    if heatmap is not None:
        save_png(heatmap, flip_heatmap(flip_map))
        click.echo(f"heat map: {heatmap}")
    if json_path is not None:
        save_json_atomic(json_path, result)
        click.echo(f"metrics: {json_path}")


# -------------------------------------------------------------------------------------- render


def _summary(description: str, width: int) -> str:
    """The first clause of a method's description, cut to at most ``width`` characters at a
    clause boundary when there is one, else at a word."""
    text = description.split("; ")[0]
    if len(text) <= width:
        return text
    cuts = [i for i in range(width // 2, width) if text[i:i + 2] in (": ", ", ", " (")
             and text[:i].count("(") == text[:i].count(")")]
    return text[:max(cuts)] if cuts else text[:width - 3].rsplit(" ", 1)[0] + "..."


def methods_epilog(width: int = 76) -> str:
    """Every registered method with the first clause of its description, one line each (click
    keeps the lines of a paragraph that starts with ``\\b``)."""
    from prefilter.render.methods import available, describe

    names = available()
    w = max(map(len, names))
    lines = [f"  {n:<{w}}  {_summary(describe(n), width - w - 4)}".rstrip() for n in names]
    return ("\b\nMethods (--method; prefilter.render.methods.describe(name) has the full "
            "descriptions):\n" + "\n".join(lines))


class _RenderCommand(click.Command):
    """``render``: the method list in its help is read from the registry when the help is shown,
    so methods registered after import (plugins, tests) are listed too."""

    def format_epilog(self, ctx, formatter):
        self.epilog = methods_epilog()
        super().format_epilog(ctx, formatter)


@click.command("render", cls=_RenderCommand)
@click.argument("scene", type=click.Path(dir_okay=False, path_type=Path))  # or example:NAME
@click.option("--method", default="ltc", show_default=True,
              help="Shading method: one of the methods listed below.")
@click.option("--spp", type=int, default=1, show_default=True, help="Samples per pixel.")
@click.option("--seed", type=SEED, default=0, show_default=True,
              help="Seed of all random numbers (same seed -> same image bytes).")
@click.option("--out", "out", required=True, type=OutputFile(path_type=Path),
              help="Output image, linear radiance (.exr; .npy also works).")
@click.option("--png", "png", type=OutputFile(path_type=Path),
              help="Also write an sRGB 8-bit PNG (values clipped to [0, 1]).")
@click.option("--jitter", type=float, nargs=2, default=(0.0, 0.0), show_default=True,
              help="Camera offset in pixels (dx dy).")
@click.option("--table", "table_path", type=click.Path(exists=True, dir_okay=False,
                                                       path_type=Path),
              help="LTC table file (default: the shipped table).")
@click.option("--param", "params", multiple=True, metavar="KEY=VALUE",
              help="A variant setting of the method (repeatable), e.g. footprint=paper for "
                   "ltc-multiscale; `prefilter.render.methods.method_params(name)` lists them.")
@click.option("--tile-rows", type=click.IntRange(1), default=None,
              help="Render in bands of this many image rows, each a task checkpointed beside "
                   "--out (a killed render resumes); default with --scheduler/--workers: "
                   "16. Methods on the driver's row chunks only (e.g. reference).")
@scheduler_options
@click.option("--quiet", is_flag=True, help="No progress bar.")
def render(scene: Path, method: str, spp: int, seed: int, out: Path, png: Path | None,
           jitter: tuple[float, float], table_path: Path | None, params: tuple[str, ...],
           tile_rows: int | None, scheduler: str | None, workers: int | None,
           quiet: bool) -> None:
    """Render SCENE (JSON, see docs/scenes.md; `example:NAME` for a shipped example, see
    `prefilter examples`) with a shading method to an EXR image.

    With --scheduler, --workers or --tile-rows the image is rendered by bands of rows, each an
    independent task on a local or Dask cluster (docs/distributed.md), with the same bytes."""
    import time

    from prefilter.distributed import SYNCHRONOUS, resolve_scheduler
    from prefilter.render.methods import check_params
    from prefilter.render.driver import render as render_image
    from prefilter.texture.io import write_image

    params = check_params(method, params)  # fail on bad input before loading the scene
    t0 = time.perf_counter()
    if tile_rows is not None or resolve_scheduler(scheduler, workers) != SYNCHRONOUS:
        from prefilter.render.tiles import TILE_ROWS, render_tiled

        image = render_tiled(scene, method, out=out, spp=spp, seed=seed, jitter=jitter,
                             table=table_path, params=params, tile_rows=tile_rows or TILE_ROWS,
                             scheduler=scheduler, workers=workers, progress=not quiet)
    else:
        image = render_image(scene, method, spp=spp, seed=seed, jitter=jitter,
                             progress=not quiet, table=table_path, params=params)
        write_image(out, image)
    seconds = time.perf_counter() - t0
    click.echo(f"{method}: {image.shape[1]}x{image.shape[0]}, {spp} spp, {seconds:.2f} s -> {out}")
    if png is not None:
        write_image(png, image, srgb=True)
        click.echo(f"sRGB preview: {png}")


# ------------------------------------------------------------------------------ export-mitsuba


@click.command("export-mitsuba")
@click.argument("scene", type=click.Path(dir_okay=False, path_type=Path))  # or example:NAME
@click.option("--out", "out", required=True, type=click.Path(file_okay=False, path_type=Path),
              help="Directory for scene.xml, meshes/*.ply and env*.exr.")
@click.option("--spp", type=int, default=64, show_default=True, help="Mitsuba's samples per pixel.")
@click.option("--bounces", type=int, default=4, show_default=True,
              help="Path vertices (as `path --param bounces=N`; Mitsuba's max_depth is N + 1).")
def export_mitsuba(scene: Path, out: Path, spp: int, bounces: int) -> None:
    """Write SCENE as a Mitsuba 3 scene (XML, meshes as PLY); conventions in
    docs/pathtracing.md. Render it with `mitsuba OUT/scene.xml` or `mi.load_file`."""
    from prefilter.render.mitsuba_export import export_mitsuba as export

    path = export(str(scene), out, spp=spp, bounces=bounces)
    click.echo(f"Mitsuba scene: {path}")
