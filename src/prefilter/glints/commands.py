"""``prefilter bake glints``, ``glints-wang`` and ``glints-wave``: thin CLIs over the bakes."""

from __future__ import annotations

import json
import math
from pathlib import Path

import click
import numpy as np

from prefilter.cliparams import SEED, SEED_MAX, OutputFile, scheduler_options
from prefilter.errors import PrefilterError
from prefilter.fileio import bake_lock
from prefilter.glints.bake import BAKE_SETTINGS, CELL, bake, bake_settings, cache_path
from prefilter.glints.wave.bake import WAVE_SETTINGS


def load_normal_map(spec: str) -> np.ndarray:
    """Normals ``(H, W, 3)`` from a file or a ``procedural:KIND[:SIZE[:SEED]]`` spec."""
    if spec.startswith("procedural:"):
        from prefilter.texture.procedural import normal_map

        parts = spec.split(":")[1:]
        try:
            size = int(parts[1]) if len(parts) > 1 else 512
            seed = int(parts[2]) if len(parts) > 2 else 0
        except ValueError as exc:
            raise PrefilterError(
                f"NORMAL_MAP: expected procedural:KIND[:SIZE[:SEED]], got {spec!r}") from exc
        if not 0 <= seed <= SEED_MAX:
            raise PrefilterError(f"NORMAL_MAP: expected a SEED in [0, 2**63) in "
                                 f"procedural:KIND[:SIZE[:SEED]], got {spec!r}")
        return normal_map(parts[0], size=size, seed=seed)
    path = Path(spec)
    if not path.is_file():
        raise PrefilterError(f"NORMAL_MAP: no such file {spec!r}")
    from prefilter.glints.pndf import as_normal_map
    from prefilter.texture.io import read_image
    from prefilter.texture.normalmap import decode_normals

    img = read_image(path)  # file errors name the file
    try:
        # .npy holds unit normals as they are; images are [0, 1]-encoded (OpenGL convention)
        with np.errstate(over="ignore"):  # huge values: lengths overflow to inf, then rejected
            return as_normal_map(img if path.suffix.lower() == ".npy" else decode_normals(img))
    except PrefilterError as exc:
        raise PrefilterError(f"{path}: {exc}") from None


class FiniteFloat(click.FloatRange):
    """A finite number in a range (``click.FloatRange`` lets NaN through: NaN compares false)."""

    name = "finite float"

    def convert(self, value, param, ctx):
        v = super().convert(value, param, ctx)
        if not math.isfinite(v):
            self.fail(f"expected a finite number, got {value!r}", param, ctx)
        return v


_POSITIVE = FiniteFloat(0.0, min_open=True)

# Options both bakes declare: click declarations, fixed keyword arguments and help.
_SHARED_OPTIONS = {
    "ndf_res": (("--ndf-res",), dict(show_default=True, type=click.IntRange(1)),
                "NDF image resolution."),
    "block": (("--block",), dict(show_default=True, type=click.IntRange(1)),
              "Block size B of the NDF images."),
    "support": (("--support",), dict(show_default=True, type=_POSITIVE),
                "Half-width of the NDF images in projected normals s."),
    "roughness": (("--roughness",), dict(show_default=True, type=_POSITIVE),
                  "Intrinsic roughness sigma_r."),
    "iters": (("--iters",), dict(show_default=True, type=click.IntRange(1)),
              "Max CP iterations per group."),
    "seed": (("--seed",), dict(show_default=True, type=SEED), None),
    "wait": (("--wait",), dict(is_flag=True),
             "If another bake is writing the same output, wait for it (default: fail at once, "
             "naming it)."),
    "quiet": (("--quiet",), dict(is_flag=True), "No progress bar."),
}


def shared_options(**defaults):
    """Decorator adding the bakes' shared options in the order of ``defaults``, each with this
    command's default; a value ``(default, help)`` replaces the shared help text.

    ``@shared_options(ndf_res=128, block=16)`` == the two ``click.option`` lines in that order."""
    def decorate(f):
        for name, value in reversed(defaults.items()):  # click lists the last-applied first
            decls, kwargs, help_ = _SHARED_OPTIONS[name]
            default, help_ = value if isinstance(value, tuple) else (value, help_)
            f = click.option(*decls, default=default, help=help_, **kwargs)(f)
        return f
    return decorate


class _IntOrNone(click.ParamType):
    """An integer >= ``lo``, or ``none``."""

    name = "integer|none"

    def __init__(self, lo: int):
        self.lo = lo

    def convert(self, value, param, ctx):
        if value is None or isinstance(value, int):
            return value
        if str(value).lower() == "none":
            return None
        try:
            v = int(value)
        except ValueError:
            self.fail(f"expected an integer >= {self.lo} or 'none', got {value!r}", param, ctx)
        if v < self.lo:
            self.fail(f"expected an integer >= {self.lo} or 'none', got {v}", param, ctx)
        return v


_D = BAKE_SETTINGS


@click.command("glints")
@click.argument("normal_map")
@click.option("-o", "--out", default=None, type=OutputFile(),
              help="Output .npz (written atomically; parts in OUT.parts/ make it resumable) "
                   "[default: the render cache, where the glints render method finds it].")
@click.option("--rank", default=_D["rank"], show_default=True, type=click.IntRange(1),
              help="Mean CP rank per group: the storage budget, spent where the error drops most "
                   "per byte (paper: a fixed rank 16, 32 for flakes).")
@click.option("--max-rank", default=None, type=click.IntRange(1),
              help="Largest rank of a group (the width of the in-memory factors, which sets the "
                   "query cost) [default: 3 x rank].")
@click.option("--level-rank", default="global", show_default=True,
              type=click.Choice(["global", "level", "uniform"]),
              help="How the rank budget is spread: over all groups, per pyramid level (equal "
                   "query work at every footprint size), or every group at --rank.")
@click.option("--error-weight", default=0.0, show_default=True, type=FiniteFloat(0.0, 2.0),
              help="The allocation weighs each group's squared error by its squared norm to "
                   "this power's negative: 0 minimises the total error, 1 evens the groups' "
                   "relative errors (more rank for the NDF images' dim blocks).")
@shared_options(ndf_res=_D["ndf_res"], block=_D["block"], support=_D["support"],
                roughness=(_D["intrinsic_roughness"],
                           "Intrinsic roughness sigma_r of the model; the map is baked sharper "
                           "by the bilinear lookup's blur (glints.bake.bilinear_bake_roughness)."))
@click.option("--stride0", default=_D["stride0"], show_default=True, type=click.IntRange(1),
              help="Level-0 footprint stride (texels).")
@click.option("--sigma0", default=None, type=_POSITIVE,
              help="Level-0 footprint std [default: stride0].")
@click.option("--cell", default=None, type=click.IntRange(min=1),
              help=f"Spatial cell of a group at level 0 (texels; doubles with each level) "
                   f"[default: {CELL}, at most the map's side].")
@click.option("--converge", default=0.01, show_default=True, type=FiniteFloat(0.0),
              help="Stop adding levels when one differs from the previous by less (rel. L2).")
@click.option("--blank-tol", default=_D["blank_tol"], show_default=True,
              type=FiniteFloat(0.0, 1.0, max_open=True),
              help="Drop NDF blocks whose maximum is below this fraction of their image's.")
@click.option("--ndf-truncation", default=_D["ndf_truncation"], show_default=True, type=_POSITIVE,
              help="Stds at which each texel's Gaussian in s is cut.")
@click.option("--footprint-truncation", default=_D["footprint_truncation"], show_default=True,
              type=_POSITIVE,
              help="Stds at which the footprint weights are cut.")
@click.option("--code-bits", default=str(_D["code_bits"]), show_default=True,
              type=click.Choice(["8", "16"]),
              help="Bits per stored factor value: 16 doubles the file and removes the 8-bit "
                   "rounding that shows in the NDF tails.")
@click.option("--c-bits", default=str(_D["c_bits"]), show_default=True,
              type=click.Choice(["8", "16"]), help="Bits of the per-image factor c.")
@click.option("--exact-from-level", default=str(_D["exact_from_level"]), show_default=True,
              type=_IntOrNone(0),
              help="Store the groups of pyramid levels >= this exactly (no CP fit; outside the "
                   "rank budget); 'none': fit every level.")
@click.option("--exact-cell", default=str(_D["exact_cell"]), show_default=True,
              type=_IntOrNone(1),
              help="Footprint centres per side of the cells of those exact levels ('none': "
                   "cell / stride0); 1 makes every image a group (exact ranks <= block instead "
                   "of block^2: faster queries).")
@shared_options(iters=_D["n_iter_max"], seed=_D["seed"], wait=False, quiet=False)
@scheduler_options
def bake_glints(normal_map, out, rank, max_rank, level_rank, error_weight, ndf_res, block, support,
                roughness, stride0, sigma0, cell, converge, blank_tol, ndf_truncation,
                footprint_truncation, code_bits, c_bits, exact_from_level, exact_cell, iters, seed,
                wait, quiet, scheduler, workers):
    """Precompute and compress the NDF pyramid of NORMAL_MAP (glints paper, sec. 4).

    NORMAL_MAP is an image (PNG/EXR, OpenGL convention), a .npy of unit normals (H, W, 3), or
    'procedural:KIND[:SIZE[:SEED]]' (prefilter.texture.procedural.normal_map). The defaults make
    the map the glints render method uses (prefilter.glints.bake.BAKE_SETTINGS); without -o it
    is written to the render cache, where that method finds it.
    """
    nm = load_normal_map(normal_map)
    settings = dict(rank=rank, ndf_res=ndf_res, block=block, support=support,
                    stride0=stride0, intrinsic_roughness=roughness, n_iter_max=iters, seed=seed,
                    blank_tol=blank_tol, ndf_truncation=ndf_truncation,
                    footprint_truncation=footprint_truncation, code_bits=int(code_bits),
                    c_bits=int(c_bits), exact_from_level=exact_from_level, exact_cell=exact_cell)
    if cell is not None:
        settings["cell"] = cell
    # arguments outside BAKE_SETTINGS enter the settings (and the cache key) only when given
    for k, v, default in (("max_rank", max_rank, None), ("level_rank", level_rank, "global"),
                          ("error_weight", error_weight, 0.0),
                          ("sigma0", sigma0, None), ("converge", converge, 0.01)):
        if v != default:
            settings[k] = v
    st = bake_settings(nm.shape, settings)
    if out is None:
        out = cache_path(nm, st)
        Path(out).parent.mkdir(parents=True, exist_ok=True)
    from prefilter.distributed import Engine

    # the tasks (level-0 chunks, CP cells) share the checkpoint folder beside OUT: workers on
    # other machines need it on a shared file system
    with bake_lock(out, wait=wait), Engine(scheduler, workers=workers) as engine:
        if not quiet and not engine.synchronous:
            click.echo(f"glints bake: tasks on {engine.describe()}", err=True)
        summary = bake(nm, out, progress=not quiet,
                       map_fn=None if engine.synchronous else engine.imap, **st)
    s = summary
    click.echo(f"images {s['n_images']}, blocks kept {s['blocks_kept']}/{s['blocks_total']}")
    click.echo(f"raw {s['raw_bytes'] / 2**20:.1f} MiB, compressed "
               f"{s['compressed_bytes'] / 2**20:.2f} MiB, ratio {100 * s['ratio']:.2f} %")
    click.echo(f"ranks: mean {s['mean_rank']:.1f} per group, {s['mean_rank_per_byte']:.1f} per "
               f"byte, max {s['max_rank']}; " + ", ".join(f"{v} x {k}" for k, v in
                                                        s["rank_histogram"].items()))
    click.echo("bytes: " + ", ".join(f"{k} {v / 2**20:.2f} MiB" for k, v in s["bytes"].items()))
    click.echo(f"relative L2 error {100 * s['rel_l2_error']:.2f} % (per level: "
               + ", ".join(f"{100 * e:.1f}" for e in s["rel_l2_error_per_level"]) + "; the "
               f"fit alone, before the codes' rounding: {100 * s['rel_l2_error_fit']:.2f} %)")
    click.echo(f"time {s['seconds']:.1f} s -> {out}")
    click.echo(json.dumps(summary))


@click.command("glints-wang")
@click.argument("normal_map")
@click.option("-o", "--out", required=True, type=OutputFile(),
              help="Output .npz (written atomically; prefilter.glints.wang_store format).")
@click.option("--tile", default=32, show_default=True, type=click.IntRange(2),
              help="Tile size T in texels (even).")
@click.option("--band", default=4.0, show_default=True, type=FiniteFloat(0.0),
              help="Width of the diagonal seams' cross-fade in texels.")
@click.option("--rank", default=16, show_default=True, type=click.IntRange(0),
              help="CP rank of every (tile, level, angular block); 0 stores the images "
                   "uncompressed.")
@shared_options(block=8, ndf_res=64, support=0.5, roughness=0.005)
@click.option("--stride0", default=None, type=click.IntRange(1),
              help="Level-0 footprint stride (texels) [default: tile / 8].")
@click.option("--wide-tiles", default=0.5, show_default=True, type=_POSITIVE,
              help="Footprint std (in tiles) from which the tile-type shares replace the pyramids.")
@click.option("--uniform-tiles", default=8.0, show_default=True, type=_POSITIVE,
              help="Footprint std (in tiles) from which the expected tiling is used.")
@click.option("--code-bits", default="8", show_default=True, type=click.Choice(["0", "8", "16"]),
              help="Bits per stored CP factor code (file version 3, with the vertex and coarse "
                   "pyramids); 0 stores float32 factors (version 1, without them). "
                   "Uncompressed pyramids (--rank 0) are always float32.")
@shared_options(iters=100,
                seed=(0, "Seeds the tile synthesis (patches, hashing seed) and the CP fits."),
                wait=False, quiet=False)
def bake_glints_wang(normal_map, out, tile, band, rank, block, ndf_res, support, roughness,
                     stride0, wide_tiles, uniform_tiles, code_bits, iters, seed, wait, quiet):
    """Synthesise 16 Wang tiles from NORMAL_MAP and precompute their per-tile NDF pyramids
    (glints paper, sec. 5.5; docs/glints-wang.md).

    NORMAL_MAP is an image (PNG/EXR, OpenGL convention), a .npy of unit normals (H, W, 3), or
    'procedural:KIND[:SIZE[:SEED]]'. Load the result with prefilter.glints.wang_store.load_tiles.
    """
    import os
    import time

    from prefilter.glints.wang import synthesize
    from prefilter.glints.wang_ndf import bake_tiles
    from prefilter.glints.wang_store import load_tiles, save_tiles

    if rank < 0:
        raise PrefilterError(f"--rank: expected a CP rank >= 0 (0: uncompressed), got {rank}")
    t0 = time.perf_counter()
    with bake_lock(out, wait=wait):
        wt = synthesize(load_normal_map(normal_map), tile=tile, band=band, rng=seed)
        wn = bake_tiles(wt, ndf_res=ndf_res, support=support, intrinsic_roughness=roughness,
                        stride0=stride0, wide_tiles=wide_tiles, uniform_tiles=uniform_tiles,
                        rank=rank or None, block=block, n_iter_max=iters, seed=seed,
                        progress=not quiet)
        save_tiles(wn, out, code_bits=int(code_bits))
    # what a renderer holds: the file's pyramids as loaded (versions 2, 3: the integer codes)
    wn = load_tiles(out)
    summary = dict(tiles=16, tile=wt.size, levels=wn.n_levels,
                   crops=[wn.crop(lv) for lv in range(wn.n_levels)],
                   rank=rank, block=wn.block, code_bits=int(code_bits) if wn.block else 0,
                   memory_bytes=wn.nbytes,
                   file_bytes=os.path.getsize(out), cp_error=list(wn.cp_error),
                   vertex_cp_error=list(wn.vertex_cp_error),
                   seconds=time.perf_counter() - t0)
    click.echo(f"16 tiles of {wt.size}^2 texels, {wn.n_levels} levels (centres per axis "
               + ", ".join(str(n) for n in summary["crops"]) + ")")
    click.echo(f"storage {wn.nbytes / 2**20:.2f} MiB in memory, file "
               f"{summary['file_bytes'] / 2**20:.2f} MiB"
               + ("" if not wn.block else ", CP rel. L2 error per level "
                  + ", ".join(f"{100 * e:.1f} %" for e in wn.cp_error))
               + ("" if not wn.vertex_cp_error else "; vertex pyramids "
                  + ", ".join(f"{100 * e:.1f} %" for e in wn.vertex_cp_error)))
    click.echo(f"time {summary['seconds']:.1f} s -> {out}")
    click.echo(json.dumps(summary))


def load_heightfield(spec: str, texel_size: float | None, units: str = "m"):
    """The :class:`~prefilter.glints.wave.heightfield.Heightfield` of ``prefilter bake
    glints-wave``'s HEIGHTFIELD: ``procedural:KIND[:SIZE[:SEED]]`` (``texel_size`` default the
    built-in's) or a file (``.npy`` or image, first channel; heights in ``units``, metres by
    default; ``texel_size`` required), as the scene field ``extras.glints_wave`` reads it."""
    from prefilter.glints.wave.bake import as_heightfield_spec
    from prefilter.glints.wave.heightfield import UNITS, read_heightfield

    if units not in UNITS:
        raise PrefilterError(f"--units: expected one of {', '.join(UNITS)}, got {units!r}")
    if spec.startswith("procedural:"):
        if units != "m":
            raise PrefilterError("--units: procedural heightfields are in metres; --units "
                                 "applies to files")
        return as_heightfield_spec(spec, texel_size)
    path = Path(spec)
    if not path.is_file():
        raise PrefilterError(f"HEIGHTFIELD: no such file {spec!r}")
    if texel_size is None:
        raise PrefilterError(f"--texel-size: expected metres per texel for heightfield {spec!r}, "
                             "got none")
    try:
        return read_heightfield(path, texel_size, units)
    except PrefilterError as exc:
        raise PrefilterError(f"{path}: {exc}") from None


_W = WAVE_SETTINGS


@click.command("glints-wave")
@click.argument("heightfield")
@click.option("-o", "--out", default=None, type=OutputFile(),
              help="Output map: OUT.npz names the three channel files OUT.R.npz, OUT.G.npz, "
                   "OUT.B.npz (each written atomically; parts in OUT.parts/ make it resumable) "
                   "[default: the render cache, where the glints-wave render method finds it].")
@click.option("--texel-size", default=None, type=_POSITIVE,
              help="Metres per texel (required for files) [default for procedural "
                   "heightfields: their own, 0.25 um].")
@click.option("--units", default="m", show_default=True, type=click.Choice(["m", "texel"]),
              help="Units of a file's heights: metres, or texel units (times --texel-size).")
@click.option("--rank", default=_W["rank"], show_default=True, type=click.IntRange(1),
              help="Mean CP rank per group and channel: the storage budget.")
@click.option("--error-weight", default=_W["error_weight"], show_default=True,
              type=FiniteFloat(0.0, 2.0),
              help="The rank allocation's weight of each group's squared error: its squared "
                   "norm to this power's negative (0: the total error; 1: relative errors, "
                   "more rank for the dim speckle blocks, lower FLIP near the camera).")
@shared_options(ndf_res=_W["ndf_res"], block=_W["block"], support=_W["support"])
@click.option("--stride0", default=_W["stride0"], show_default=True, type=click.IntRange(1),
              help="Level-0 footprint (coherence area) stride (texels).")
@click.option("--sigma0", default=None, type=_POSITIVE,
              help="Level-0 footprint (coherence area) std [default: stride0].")
@click.option("--cell", default=None, type=click.IntRange(min=1),
              help=f"Spatial cell of a group at level 0 (texels) [default: {_W['cell']}, at most "
                   "the heightfield's side].")
@shared_options(wait=False, quiet=False)
def bake_glints_wave(heightfield, out, texel_size, units, rank, error_weight, ndf_res, block,
                     support, stride0, sigma0, cell, wait, quiet):
    """Precompute and compress the wave-optics RGB NDF pyramid of HEIGHTFIELD (glint paper sec.
    4.1 with Yan et al. 2018's NDF; docs/glints-wave.md).

    HEIGHTFIELD is 'procedural:KIND[:SIZE[:SEED]]' (KIND noise or scratches) or a file (.npy or
    image, first channel) of heights with --texel-size. The defaults make the map the
    glints-wave render method uses (prefilter.glints.wave.bake.WAVE_SETTINGS); without -o it is
    written to the render cache, where that method finds it.
    """
    import time

    from prefilter.glints.wave.bake import (bake_wave, cache_path, channel_paths, load_wave,
                                            wave_settings)

    t0 = time.perf_counter()
    hf = load_heightfield(heightfield, texel_size, units)
    settings = dict(rank=rank, ndf_res=ndf_res, block=block, support=support, stride0=stride0)
    if cell is not None:
        settings["cell"] = cell
    if sigma0 is not None:
        settings["sigma0"] = sigma0
    settings["error_weight"] = error_weight
    st = wave_settings(hf.shape, settings)
    if out is None:
        out = cache_path(hf, st)
        Path(out).parent.mkdir(parents=True, exist_ok=True)
    with bake_lock(out, wait=wait):
        s = bake_wave(hf, out, progress=not quiet, **st)
        wm = load_wave(out)  # the three files validated together, as the render loads them
    H, W = hf.shape
    click.echo(f"heightfield {H}x{W}, {hf.texel_size * 1e6:g} um texels (sha1 {hf.digest[:12]}), "
               f"{wm.pyramid.n_levels} levels, NDF images {wm.resolution}^2 over "
               f"[-{wm.support:g}, {wm.support:g}]^2")
    for c, path in zip(s["channels"], channel_paths(out)):
        ch = s["channels"][c]
        click.echo(f"{c}: compressed {ch['compressed_bytes'] / 2**20:.2f} MiB "
                   f"({100 * ch['ratio']:.2f} %), relative L2 error "
                   f"{100 * ch['rel_l2_error']:.2f} % -> {path}")
    click.echo(f"raw {s['raw_bytes'] / 2**20:.1f} MiB, compressed "
               f"{s['compressed_bytes'] / 2**20:.2f} MiB, ratio {100 * s['ratio']:.2f} %")
    click.echo(f"time {time.perf_counter() - t0:.1f} s (level-0 images "
               f"{s['seconds_level0']:.1f} s)")
    click.echo(json.dumps(s))
