"""Bake a heightfield's wave-optics NDF pyramid: one compressed map per colour channel.

Stages (glint paper secs. 4.1-4.2 with coloured NDF images):

1. level-0 RGB images (:func:`prefilter.glints.wave.ndf.rgb_images`, 8 wavelengths), one row of
   cells per checkpoint of ``<out>.parts/`` (:class:`prefilter.fileio.Checkpoints`) into a
   float32 level file ``(ny, nx, 3, R, R)``; the spectral integral is the longest stage and is
   computed once for the three channels;
2. per channel ``c`` in R, G, B: :func:`prefilter.glints.bake.bake` with ``level0`` reading that
   channel (the same pyramid, blocks, groups, rank budget, CP, codes, checkpoints, locks and
   atomic output as the geometric bake) into ``<stem>.<c>.npz``;
3. the parts removed.

The channels are compressed separately; compressing them jointly (the channel as part of the
image mode of each group) is measured by ``benchmarks/study_glints_wave_cp.py``
(docs/glints-wave.md). The map of the heightfield's geometric normals (its size and digest) is
what each channel bake records as its normal map; the heightfield's digest, texel size and
wavelengths key the level-0 images.
"""

from __future__ import annotations

import json
import sys
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from prefilter.errors import PrefilterError, TableFileError
from prefilter.fileio import Checkpoints, bake_lock
from prefilter.glints.bake import bake
from prefilter.glints.levels import LevelFile
from prefilter.glints.pyramid import plan
from prefilter.glints.store import GlintsMap, load
from prefilter.glints.wave.cmf import WAVELENGTHS
from prefilter.glints.wave.heightfield import Heightfield, heightfield, normal_map
from prefilter.glints.wave.ndf import as_wavelengths, rgb_images
from prefilter.validation import as_positive_int

CHANNELS = ("R", "G", "B")
#: version of the level-0 wave images (keys the checkpoints)
WAVE_VERSION = 1
#: defaults: 64^2 images over s in [-0.25, 0.25]^2 (pitch 1/128, as the geometric default), a
#: rank budget of 32 per channel allocated by relative error (``error_weight`` 1: the speckle
#: images' dim blocks get rank too): near-camera FLIP 0.049 against ``glints-wave-direct``
#: (0.087 at rank 16 by total error, 0.076 at rank 16 by relative error) at 5 % of the
#: pyramid's bytes (docs/glints-wave.md)
WAVE_SETTINGS = dict(rank=32, error_weight=1.0, ndf_res=64, support=0.25, block=16, stride0=4,
                     cell=32)


def wave_settings(shape, settings: dict | None = None) -> dict:
    """The keyword arguments of :func:`bake_wave` that make the render methods' map of a
    heightfield of ``shape (H, W)``: :data:`WAVE_SETTINGS` updated by ``settings``, ``cell`` at
    most the heightfield's side unless given (as the geometric ``bake_settings``)."""
    st = dict(WAVE_SETTINGS, **(settings or {}))
    if "cell" not in (settings or {}):
        st["cell"] = min(st["cell"], int(shape[0]), int(shape[1]))
    return st


def cache_path(hf: Heightfield, settings: dict) -> Path:
    """Where the render methods keep the map of ``hf`` baked with ``settings`` (the full
    :func:`wave_settings`): ``wave-<key>.npz`` in the glints cache
    (:func:`prefilter.glints.bake.cache_dir`), keyed by the heights' digest, the settings,
    :data:`WAVE_VERSION` and the CP fit's version (:data:`prefilter.glints.cp.FIT_VERSION`: a
    map fitted by other code is not reused); the channels are :func:`channel_paths` of it."""
    import hashlib

    from prefilter.glints import cp
    from prefilter.glints.bake import cache_dir

    key = json.dumps(dict(settings, heights=hf.digest, version=WAVE_VERSION,
                          cp_fit=cp.FIT_VERSION), sort_keys=True)
    return cache_dir() / f"wave-{hashlib.sha1(key.encode()).hexdigest()[:16]}.npz"


def channel_paths(out) -> list[Path]:
    """The files of the channels of map ``out`` (``x.npz`` -> ``x.R.npz``, ``x.G.npz``,
    ``x.B.npz``)."""
    out = Path(out)
    stem = out.with_suffix("") if out.suffix == ".npz" else out
    return [Path(f"{stem}.{c}.npz") for c in CHANNELS]


class _Channel:
    """``bake``'s ``level0`` for one channel of the level-0 RGB file."""

    def __init__(self, rgb: LevelFile, c: int, key: str):
        self.rgb, self.c, self.key = rgb, c, f"{key}:{CHANNELS[c]}"

    def __call__(self, y, centers, sigma):
        return self.rgb.read(y, y + 1)[:, :, self.c].astype(np.float64)


def bake_wave(hf: Heightfield, out, *, rank: int = 32, error_weight: float = 1.0,
              ndf_res: int = 64, support: float = 0.25,
              block: int = 16, stride0: int = 4, sigma0: float | None = None, cell: int = 32,
              wavelengths=WAVELENGTHS, progress: bool = True, levels_dir=None,
              keep_parts: bool = False, **bake_kwargs) -> dict:
    """Bake heightfield ``hf`` into ``channel_paths(out)``; returns the summary (per channel:
    :func:`prefilter.glints.bake.bake`'s; totals: bytes, ratio, relative L2 error, seconds).

    ``levels_dir``: keep each channel's uncompressed pyramid in ``<levels_dir>.<c>.parts``
    (shared by bakes at several ranks and by the joint-compression study). ``keep_parts``: keep
    the checkpoints (level-0 images, each channel's). ``rank``, ``error_weight``: the rank budget
    per channel and its allocation (:func:`prefilter.glints.bake.bake`; the defaults are
    :data:`WAVE_SETTINGS`'). Other keywords go to
    :func:`prefilter.glints.bake.bake` (``max_rank``, ``code_bits``, ``n_iter_max`` ...).
    """
    from tqdm import tqdm

    if not isinstance(hf, Heightfield):
        raise PrefilterError(f"hf: expected a Heightfield (prefilter.glints.wave.heightfield), "
                             f"got {type(hf).__name__}")
    t0 = time.perf_counter()
    R = as_positive_int(ndf_res, "ndf_res")
    lams = as_wavelengths(wavelengths)
    out = Path(out)
    H, W = hf.shape
    pyr = plan(H, W, stride0, sigma0)
    cell = as_positive_int(cell, "cell")
    if cell % pyr.stride0 or H % cell or W % cell:
        raise PrefilterError(f"cell: expected a multiple of stride0 dividing {H}x{W}, got {cell}")
    nm = normal_map(hf)
    key = json.dumps(dict(heights=hf.digest, texel_size=hf.texel_size, ndf_res=R,
                          support=float(support), stride0=pyr.stride0, sigma0=pyr.sigma0,
                          wavelengths=[float(v) for v in lams], version=WAVE_VERSION),
                     sort_keys=True)
    summary = dict(channels={})
    with bake_lock(out, wait=True):
        ck = Checkpoints(out, dict(key=key))
        ny0, nx0 = pyr.shape(0)
        rows = cell // pyr.stride0
        rgb = LevelFile(ck.dir / "level0_rgb.npy", (ny0, nx0, 3, R, R))
        centers0 = pyr.centers(0)
        t_l0 = time.perf_counter()
        if progress:
            files = ", ".join(map(str, channel_paths(out)))
            tqdm.write(f"glints-wave bake: heightfield {H}x{W} ({hf.texel_size * 1e6:g} um "
                       f"texels, sha1 {hf.digest[:12]}) -> {files}"
                       f"\n  {ny0 * nx0} level-0 RGB NDF images of {R}^2 ({lams.size} "
                       f"wavelengths); resumable parts in {ck.dir}", file=sys.stderr)
        with tqdm(total=ny0 * nx0, desc="level 0 wave NDF images", unit="img",
                  disable=not progress, file=sys.stderr) as bar:
            for ch in range(ny0 // rows):
                if not ck.done(ch):
                    for y in range(ch * rows, (ch + 1) * rows):
                        rgb.write_rows(y, rgb_images(hf, centers0[y:y + 1], pyr.sigma(0), R,
                                                     support, lams).astype(np.float32))
                        bar.update(nx0)
                    ck.save(ch, done=np.array(1))
                else:
                    bar.update(rows * nx0)
        summary["seconds_level0"] = time.perf_counter() - t_l0
        def channel(c, **kw):
            ldir = None if levels_dir is None else f"{levels_dir}.{CHANNELS[c]}"
            summary["channels"][CHANNELS[c]] = bake(
                nm, channel_paths(out)[c], rank=rank, ndf_res=R, block=block, support=support,
                stride0=pyr.stride0, sigma0=pyr.sigma0, cell=cell, progress=progress,
                levels_dir=ldir, level0=_Channel(rgb, c, key), keep_parts=keep_parts,
                error_weight=error_weight, **dict(bake_kwargs, **kw))

        for c in range(len(CHANNELS)):
            channel(c)
        # each channel stops adding levels where its own images converge; the three must share
        # one pyramid: those that stopped early are baked again up to the tallest
        n_levels = [len(summary["channels"][c]["rel_l2_error_per_level"]) for c in CHANNELS]
        for c, n in enumerate(n_levels):
            if n < max(n_levels):
                channel(c, max_levels=max(n_levels), converge=0.0)
        if not keep_parts:
            ck.clear()
    ch = list(summary["channels"].values())
    summary["raw_bytes"] = sum(s["raw_bytes"] for s in ch)
    summary["compressed_bytes"] = sum(s["compressed_bytes"] for s in ch)
    summary["ratio"] = summary["compressed_bytes"] / summary["raw_bytes"]
    summary["rel_l2_error_per_channel"] = [s["rel_l2_error"] for s in ch]
    summary["seconds"] = time.perf_counter() - t0
    return summary


@dataclass(frozen=True)
class WaveMap:
    """The three channel maps (R, G, B) of a baked heightfield."""

    channels: tuple[GlintsMap, GlintsMap, GlintsMap]

    @property
    def pyramid(self):
        return self.channels[0].pyramid

    @property
    def resolution(self) -> int:
        return self.channels[0].resolution

    @property
    def support(self) -> float:
        return self.channels[0].support

    @property
    def level0_key(self) -> str:
        return self.channels[0].header["settings"]["level0"].rsplit(":", 1)[0]

    @property
    def compressed_bytes(self) -> int:
        return sum(gm.compressed_bytes for gm in self.channels)


def load_wave(out) -> WaveMap:
    """Load and validate the three channel maps of ``out``: each as
    :func:`prefilter.glints.store.load` does, and together (the same heightfield, wavelengths,
    pyramid and NDF geometry, channels in order); else ``TableFileError`` naming the file."""
    maps = []
    for c, path in zip(CHANNELS, channel_paths(out)):
        if not path.exists():
            raise TableFileError(f"glints-wave map {out}: missing channel file {path}")
        gm = load(path)
        lv0 = gm.header.get("settings", {}).get("level0")
        if not isinstance(lv0, str) or not lv0.endswith(f":{c}"):
            raise TableFileError(f"glints-wave map {path}: settings.level0: expected the wave "
                                 f"NDF of channel {c}, got {lv0!r}")
        maps.append(gm)
    first = maps[0].header
    for path, gm in zip(channel_paths(out)[1:], maps[1:]):
        h = gm.header
        if (h["pyramid"] != first["pyramid"] or h["ndf"]["resolution"] != first["ndf"]["resolution"]
                or h["ndf"]["support"] != first["ndf"]["support"]
                or h["settings"]["level0"].rsplit(":", 1)[0]
                != first["settings"]["level0"].rsplit(":", 1)[0]):
            raise TableFileError(f"glints-wave map {path}: pyramid, NDF geometry or heightfield "
                                 f"differ from channel R's")
    return WaveMap(tuple(maps))


def as_heightfield_spec(spec, texel_size=None) -> Heightfield:
    """A heightfield from a :class:`Heightfield`, ``procedural:KIND[:SIZE[:SEED]]`` or a file
    (heights in metres; ``texel_size`` metres, required for files)."""
    from prefilter.glints.wave.heightfield import procedural, read_heightfield

    if isinstance(spec, Heightfield):
        return spec
    s = str(spec)
    if s.startswith("procedural:"):
        hf = procedural(s.removeprefix("procedural:"))
        return hf if texel_size is None else heightfield(hf.heights, texel_size)
    if texel_size is None:
        raise PrefilterError(f"texel_size: expected metres per texel for heightfield {s!r}, "
                             "got none")
    return read_heightfield(s, texel_size)
