"""``prefilter bake roughness``: roughness mip levels from a normal map (a thin layer over
:func:`prefilter.roughness.bake.bake_roughness` and :mod:`prefilter.roughness.outputs`).

Flags follow Filament's ``roughness-prefilter`` (``-r/--roughness``, ``-m/--roughness-map``,
``-f/--format``); roughness in and out is perceptual (``sqrt(alpha)``) unless
``--output-roughness alpha``.
"""

from __future__ import annotations

import click

from prefilter.cliparams import OutputDir


@click.command("roughness")
@click.argument("normalmap")
@click.option("-o", "--out", type=OutputDir(), required=True,
              help="Output folder: roughness_L<k>.exr/.png per level, roughness.dds, "
                   "roughness.ktx2 (orm_* with --pack-orm) and roughness.json.")
@click.option("--method", type=click.Choice(["toksvig", "lean", "ltc"]), default="ltc",
              show_default=True,
              help="Toksvig 2005 (mean-normal length), LEAN (Olano & Baker 2010, slope "
                   "variance) or multi-scale LTC alpha_total (Tao et al. 2021).")
@click.option("-r", "--roughness", type=click.FloatRange(0.0, 1.0), default=None,
              help="Constant perceptual roughness of the surface [default: 0.5].")
@click.option("-m", "--roughness-map", type=click.Path(dir_okay=False),
              help="Perceptual roughness map (first channel, linear), the normal map's size.")
@click.option("-f", "--format", "formats", multiple=True,
              type=click.Choice(["exr", "png", "dds", "ktx2"]),
              help="Output format; repeat for several [default: all four].")
@click.option("--output-roughness", type=click.Choice(["perceptual", "alpha"]),
              default="perceptual", show_default=True,
              help="Store perceptual roughness sqrt(alpha) or GGX alpha.")
@click.option("--pack-orm", is_flag=True,
              help="Write the roughness into the green channel of an occlusion-roughness-metal "
                   "texture (R occlusion, B metal: from --orm, else 1 and 0).")
@click.option("--orm", "orm_path", type=click.Path(dir_okay=False),
              help="ORM image whose R and B channels --pack-orm keeps (box-filtered per level).")
@click.option("--convention", type=click.Choice(["opengl", "directx"]), default="opengl",
              show_default=True, help="Green channel of a PNG / EXR normal map: up or down.")
@click.option("--float-bits", type=click.Choice(["16", "32"]), default="16", show_default=True,
              help="Bits per channel of the EXR, DDS and KTX2 texels.")
@click.option("--png-bits", type=click.Choice(["8", "16"]), default="8", show_default=True,
              help="Bits per channel of the PNG levels.")
@click.option("--zstd", is_flag=True, help="Zstandard-supercompress the KTX2 levels.")
def bake_roughness_cmd(normalmap, out, method, roughness, roughness_map, formats,
                       output_roughness, pack_orm, orm_path, convention, float_bits, png_bits,
                       zstd):
    """Bake the roughness mip chain of NORMALMAP (PNG / EXR colours, .npy vectors, or
    procedural:KIND:SIZE[:SEED]) that keeps its highlights at a distance."""
    from prefilter.errors import PrefilterError

    if roughness is not None and roughness_map is not None:
        raise PrefilterError("--roughness and --roughness-map: expected one of them, got both")
    if orm_path is not None and not pack_orm:
        raise PrefilterError("--orm: expected together with --pack-orm")
    _bake(normalmap, out, method, roughness, roughness_map, formats or None, output_roughness,
          pack_orm, orm_path, convention, int(float_bits), int(png_bits), zstd)


def _read(path: str, what: str):
    from pathlib import Path

    from prefilter.errors import PrefilterError
    from prefilter.texture.io import read_image

    if not Path(path).is_file():
        raise PrefilterError(f"{what}: no such file {path!r}")
    return read_image(path)


def _bake(normalmap, out, method, roughness, roughness_map, formats, space, pack_orm, orm_path,
          convention, float_bits, png_bits, zstd):
    from pathlib import Path

    import numpy as np

    from prefilter.fileio import save_json_atomic
    from prefilter.roughness.bake import bake_roughness, load_normals
    from prefilter.roughness.outputs import FORMATS, pack_orm as pack, to_space, write_levels

    normals = load_normals(normalmap, convention)
    if roughness_map is not None:
        perceptual = _read(roughness_map, "--roughness-map")[..., 0]
    else:
        perceptual = 0.5 if roughness is None else roughness
    alpha = np.square(perceptual)
    levels = to_space(bake_roughness(normals, alpha, method, name=normalmap), space)
    stem = "roughness"
    if pack_orm:
        orm = _read(orm_path, "--orm") if orm_path is not None else None
        levels, stem = pack(levels, orm), "orm"
    files = write_levels(levels, out, stem=stem, formats=formats or FORMATS,
                         float_bits=float_bits, png_bits=png_bits,
                         supercompression="zstd" if zstd else None)
    save_json_atomic(Path(out) / "roughness.json", {
        "source": normalmap, "method": method, "roughness": space,
        "channel": "G" if pack_orm else "R", "base_roughness": (
            roughness_map if roughness_map is not None else float(perceptual)),
        "levels": [list(np.shape(a)[:2]) for a in levels]})
    click.echo(f"wrote {len(files)} files ({len(levels)} levels, {method}, {space}) to {out}")
