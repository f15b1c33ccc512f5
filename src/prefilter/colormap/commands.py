"""``prefilter bake colormap``: bake a pre-convolved colour-map table (a thin layer over
:func:`prefilter.colormap.table.prefilter_table`, computed in checkpointed chunks of rows by
:func:`bake_table` so that a killed bake of a large table resumes)."""

from __future__ import annotations

import click

from prefilter.cliparams import OutputFile, scheduler_options


def load_colormap_image(path, *, srgb: bool = True):
    """Colour-map samples ``(N, C)`` from an image: a single row or column is taken as is; a
    larger image is averaged over its rows (a horizontal gradient), left = ``value_range[0]``.
    An alpha channel is dropped."""
    import numpy as np

    from prefilter.errors import PrefilterError
    from prefilter.texture.io import read_image

    a = read_image(path, srgb=srgb)
    if a.shape[2] in (2, 4):
        a = a[..., :-1]
    if a.shape[0] == 1:
        c = a[0]
    elif a.shape[1] == 1:
        c = a[:, 0]
    else:
        c = a.mean(axis=0)
    if c.shape[0] < 2:
        raise PrefilterError(f"{path}: expected a colour map at least 2 texels long, got {a.shape}")
    return np.ascontiguousarray(c)


def table_rows(c, sigmas, edge: str) -> dict:
    """One task of :func:`bake_table`: ``{"rows": prefilter_rows(c, sigmas, edge)}``."""
    from prefilter.colormap.table import prefilter_rows

    return {"rows": prefilter_rows(c, sigmas, edge)}


def bake_table(colormap, value_range, sigma_max, *, size: int, edge: str, n_sigma=None,
               out, chunk: int = 32, scheduler: str | None = None, workers: int | None = None,
               progress: bool = False):
    """:func:`~prefilter.colormap.table.prefilter_table`, computed ``chunk`` sigma rows at a time
    with each chunk checkpointed in ``<out>.parts/`` (a large table takes minutes; a killed bake
    resumes). The rows are the same computation as ``prefilter_table`` (``prefilter_rows``
    computes each row on its own), so the table is bit-identical to it. The chunks are
    independent tasks (:func:`table_rows`) run by :class:`prefilter.distributed.Engine` on
    ``scheduler`` / ``workers``."""
    import numpy as np

    from prefilter.distributed import Engine
    from prefilter.fileio import Checkpoints, array_digest
    from prefilter.colormap.table import ColormapTable, prefilter_table

    # two rows validate the arguments and resample the map exactly as the full table does
    head = prefilter_table(colormap, value_range, sigma_max, size=size, edge=edge, n_sigma=2)
    c = head.table[0]
    lo, hi = head.value_range
    n_sigma = size if n_sigma is None else n_sigma
    sig = np.linspace(0.0, head.sigma_max, n_sigma) / (hi - lo)
    ck = Checkpoints(out, {"format": "colormap-rows", "colormap_sha256": array_digest({"c": c}),
                           "range": [lo, hi], "sigma_max": head.sigma_max, "edge": head.edge,
                           "size": size, "n_sigma": n_sigma, "chunk": chunk})
    tasks = [(c, sig[start:start + chunk], head.edge) for start in range(0, n_sigma, chunk)]
    with Engine(scheduler, workers=workers) as engine:
        engine.run(table_rows, tasks, ck, progress=progress, desc="colormap rows")
    table = np.concatenate([ck.load(k)["rows"] for k in range(len(tasks))])
    table[0] = c  # the sigma = 0 row is the colour map itself, bit for bit (as prefilter_table)
    return ColormapTable(table, (lo, hi), head.sigma_max, head.edge), ck


@click.command("colormap")
@click.argument("colormap", type=click.Path(exists=True, dir_okay=False))
@click.option("--sigma-max", type=float, required=True,
              help="Largest std of the driving function (value units) the table serves.")
@click.option("--range", "value_range", type=float, nargs=2, default=(0.0, 1.0),
              show_default=True, help="Values spanned by the colour map (left to right).")
@click.option("--size", default=256, show_default=True, type=click.IntRange(2, 8192),
              help="Table columns (means); the map is resampled exactly if its length differs.")
@click.option("--n-sigma", default=None, type=click.IntRange(2, 8192),
              help="Table rows (stds); default: --size.")
@click.option("--edge", type=click.Choice(["clamp", "mirror", "periodic"]), default="clamp",
              show_default=True, help="How the colour map continues outside --range.")
@click.option("--linear", is_flag=True,
              help="The PNG holds linear values (default: sRGB-encoded colours are decoded).")
@click.option("-o", "--out", type=OutputFile(), required=True,
              help="Output table (.exr, .npy or .png); metadata goes next to it as .json.")
@click.option("--glsl", "glsl_out", type=OutputFile(), default=None,
              help="Also write the GLSL lookup snippet for this table.")
@click.option("--wait", is_flag=True,
              help="If another bake is writing the same output, wait for it (default: fail at "
                   "once, naming it).")
@scheduler_options
def bake_colormap(colormap, sigma_max, value_range, size, n_sigma, edge, linear, out, glsl_out,
                  wait, scheduler, workers):
    """Pre-convolve COLORMAP (an image) with Gaussians of std 0..SIGMA_MAX (Heitz et al. 2013,
    eq. 10). Writes the table (rows = sigma, columns = mean) and TABLE.json with its layout,
    switched together (a killed bake leaves the previous pair or the new one)."""
    import hashlib
    from pathlib import Path

    from prefilter.fileio import bake_lock, write_text_atomic
    from prefilter.colormap.glsl import glsl_snippet

    c = load_colormap_image(colormap, srgb=not linear)
    digest = hashlib.sha256(Path(colormap).read_bytes()).hexdigest()
    with bake_lock(out, wait=wait):
        table, ck = bake_table(c, value_range, sigma_max, size=size, edge=edge,
                               n_sigma=n_sigma, out=out, scheduler=scheduler, workers=workers)
        out, side = table.save(out, meta=dict(source=str(colormap), source_sha256=digest,
                                              source_encoding="linear" if linear else "srgb"))
        ck.clear()
    meta = table.metadata()
    click.echo(f"wrote {out} ({table.n_sigma} x {table.n_mean} x {table.table.shape[2]}) and "
               f"{side.name}")
    if glsl_out:
        write_text_atomic(glsl_out, glsl_snippet(meta))
        click.echo(f"wrote {glsl_out}")
