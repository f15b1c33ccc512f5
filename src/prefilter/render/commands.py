"""Command-line entry points of ``prefilter.render`` (loaded lazily by ``prefilter.cli``).

Commands: ``compare`` (image metrics).
"""

from __future__ import annotations

from pathlib import Path

import click
import numpy as np

from prefilter.errors import PrefilterError

# ------------------------------------------------------------------------------------- compare


def _read_image(path: Path) -> tuple[np.ndarray, bool]:
    """``(linear RGB float64 (H, W, 3), is_hdr)`` from an EXR (linear) or PNG/JPEG (sRGB) file."""
    if path.suffix.lower() == ".exr":
        return _read_exr(path), True
    try:
        from PIL import Image

        with Image.open(path) as im:
            rgb8 = np.asarray(im.convert("RGB"))
    except (OSError, ValueError) as exc:
        raise PrefilterError(f"{path}: cannot read the image: {exc}") from exc
    from prefilter.render.metrics import from_srgb8

    return from_srgb8(rgb8), False


def _read_exr(path: Path) -> np.ndarray:
    # TODO(h6): switch to prefilter.texture.io once it lands.
    import OpenEXR

    try:
        with OpenEXR.File(str(path), separate_channels=True) as f:
            ch = {k: np.asarray(v.pixels, dtype=np.float64) for k, v in f.channels().items()}
    except Exception as exc:  # the bindings raise plain RuntimeError/Exception on bad files
        raise PrefilterError(f"{path}: cannot read the EXR image: {exc}") from exc
    if all(c in ch for c in "RGB"):
        return np.stack([ch["R"], ch["G"], ch["B"]], axis=-1)
    if "Y" in ch:
        return np.repeat(ch["Y"][..., None], 3, axis=-1)
    raise PrefilterError(f"{path}: expected R, G, B (or Y) channels, got {sorted(ch)}")


def compare_images(test_path, reference_path, *, eps: float = 1e-2) -> dict:
    """RMSE, relative MSE and FLIP of the image file ``test_path`` against ``reference_path``.

    EXR files are compared as linear radiance with HDR-FLIP; PNG/JPEG files are decoded from sRGB
    to linear for RMSE/relMSE and compared with LDR-FLIP. Returns a JSON-ready dict; the FLIP
    error map is under ``"flip_map"`` (removed before JSON output).
    """
    from prefilter.render.metrics import flip, linear_to_srgb, relmse, rmse

    test_path, reference_path = Path(test_path), Path(reference_path)
    test, test_hdr = _read_image(test_path)
    ref, ref_hdr = _read_image(reference_path)
    if test_hdr != ref_hdr:
        raise PrefilterError(
            f"{test_path}, {reference_path}: expected two EXR images or two display images "
            f"(PNG/JPEG), got one of each"
        )
    for path, img in ((test_path, test), (reference_path, ref)):
        if not np.all(np.isfinite(img)):
            raise PrefilterError(f"{path}: expected finite pixel values, got NaN or inf")
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
@click.option("--heatmap", type=click.Path(dir_okay=False, path_type=Path),
              help="Write the FLIP error map as a magma heat map PNG.")
@click.option("--json", "json_path", type=click.Path(dir_okay=False, path_type=Path),
              help="Write the metrics as JSON.")
@click.option("--eps", type=float, default=1e-2, show_default=True,
              help="Regulariser of relMSE = mean((a-b)^2 / (b^2 + eps)).")
def compare(test: Path, reference: Path, heatmap: Path | None, json_path: Path | None,
            eps: float) -> None:
    """Compare image TEST against REFERENCE: RMSE, relative MSE and FLIP.

    EXR inputs are linear (HDR-FLIP); PNG/JPEG inputs are sRGB (LDR-FLIP).
    """
    from prefilter._io import save_json_atomic
    from prefilter.render.metrics import flip_heatmap
    from prefilter.render.report import save_png

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
