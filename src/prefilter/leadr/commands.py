"""``prefilter bake leadr``: bake LEADR moment maps (a thin layer over
:func:`prefilter.leadr.moments` and :func:`prefilter.leadr.io.write_maps`)."""

from __future__ import annotations

import click

from prefilter.cliparams import OutputDir, scheduler_options


@click.command("leadr")
@click.argument("height", type=click.Path(exists=True, dir_okay=False))
@click.option("-o", "--out", type=OutputDir(), required=True,
              help="Output directory: leadr_L<level>.exr (channels E_x E_y E_xx E_yy E_xy) and "
                   "leadr.json.")
@click.option("--texel-size", type=float, default=1.0, show_default=True,
              help="Texel spacing in height units (heights in texels: 1).")
@click.option("--base-roughness", type=float, default=0.0, show_default=True,
              help="Slope std per axis below the texel scale (recorded in leadr.json).")
@click.option("--normal-map", is_flag=True,
              help="HEIGHT is a tangent-space normal map (RGB in [-1, 1] for EXR/.npy, "
                   "[0, 1]-encoded for PNG) instead of a height map.")
@click.option("--level0-only", is_flag=True, help="Write level 0 only (moments mip by box filter).")
@click.option("--wait", is_flag=True,
              help="If another bake is writing the same output, wait for it (default: fail at "
                   "once, naming it).")
@click.option("--band-rows", type=click.IntRange(1, 1 << 20), default=256, show_default=True,
              help="Rows of level 0 per task when the bake runs as tasks (--scheduler / "
                   "--workers; a power of two). The maps are the same bytes either way.")
@scheduler_options
def bake_leadr(height, out, texel_size, base_roughness, normal_map, level0_only, wait, band_rows,
               scheduler, workers):
    """Bake the slope moments of HEIGHT (EXR/PNG/.npy height map, first channel) into EXR maps.

    Dupuy et al. 2013; slopes s = grad h by periodic central differences."""
    from prefilter.errors import PrefilterError
    from prefilter.fileio import bake_lock
    from prefilter.leadr.maps import _positive_float

    # the numbers first: refused before the map is read
    _positive_float(texel_size, "texel_size")
    _positive_float(base_roughness, "base_roughness", closed=True)
    if band_rows & (band_rows - 1):
        raise PrefilterError(f"band_rows: expected a power of two, got {band_rows}")
    with bake_lock(out, wait=wait):
        _bake(height, out, texel_size, base_roughness, normal_map, level0_only,
              band_rows=band_rows, scheduler=scheduler, workers=workers)


def _bake(height, out, texel_size, base_roughness, normal_map, level0_only, *,
          band_rows=None, scheduler=None, workers=None):
    from pathlib import Path

    from prefilter.distributed import SYNCHRONOUS, Engine, resolve_scheduler
    from prefilter.leadr.io import write_maps
    from prefilter.leadr.maps import moments
    from prefilter.texture.io import read_image

    a = read_image(height)
    if normal_map:
        data = a[..., :3]
        if Path(height).suffix.lower() == ".png":
            data = 2.0 * data - 1.0
    else:
        data = a[..., 0]
    if resolve_scheduler(scheduler, workers) == SYNCHRONOUS:
        maps = moments(data, texel_size, base_roughness)
    else:
        # the bands are independent tasks (map_fn), each a level-0 band and its mips
        with Engine(scheduler, workers=workers) as engine:
            maps = moments(data, texel_size, base_roughness, band_rows=band_rows,
                           map_fn=engine.imap)
    files = write_maps(maps, out, all_levels=not level0_only,
                       meta={"source": str(height), "texel_size": texel_size})
    click.echo(f"wrote {len(files)} levels to {out}")
