"""Bake a normal map into a compressed NDF pyramid (glints paper, secs. 4.1-4.2).

Stages, each resumable through :class:`prefilter.fileio.Checkpoints` (``<out>.parts/``):

1. level 0 NDF images by the direct P-NDF, one row of spatial cells per chunk, into a float32
   memory-mapped array;
2. levels 1.. by exact Gaussian filtering of the level below (``pyramid.next_level``), until a level
   differs from the one below by less than ``converge`` (relative L2) or the top is reached;
3. per cell (``k x k`` footprint centres of ONE level, ``k = cell / stride0``: ``cell * 2^l``
   texels at level ``l``): blocks, blank blocks dropped, one ``(B, B, K)`` tensor per angular
   block position ``(bi, bj)`` (a group); (a) non-negative CP of every group at rank
   ``rank // 2``, all of a cell's groups in one batch; (b) ranks per group under the storage
   budget of ``rank`` on average (``cp.allocate_ranks``: largest predicted error drop per byte
   first, up to ``max_rank``); (c) the promoted groups refitted at their rank, warm-started from
   (a), the factors encoded in 8 bits (``store.encode``) and the error measured on what the
   loader decodes;
4. the final ``.npz`` written atomically, then the parts removed.

Stages 1 and 3 run as tasks (:func:`level0_task`, :func:`fit_cell_task`,
:func:`refit_cell_task`) through ``bake(map_fn=...)``: any ``map`` (threads, processes, a
cluster) gives the same bytes.

A bake holds an exclusive lock on ``<out>.lock`` (and on a shared ``levels_dir``) while it runs:
a second process baking the same output waits, then bakes again (``bake``) or finds the output
and returns (``bake_if_missing``, what the renderer's cache uses).

Grouping deviates from the paper (which mixes all levels' blocks of a spatial cell in one tensor):
blocks at the same ``(bi, bj)`` of overlapping footprints are alike, and a group of one level is
not fit at the expense of the others (with all levels in one group, the sharp, high-energy level-0
blocks dominated and the upper levels had ~10 % error). Measurements in docs/glints.md.
"""

from __future__ import annotations

import dataclasses
import functools
import hashlib
import json
import math
import os
import shutil
import sys
import threading
import time
from collections import deque
from concurrent.futures import ThreadPoolExecutor
from contextlib import ExitStack, contextmanager
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from prefilter.fileio import Checkpoints, atomic_path, bake_lock, exclusive_lock
from prefilter.jit import release_heap
from prefilter.validation import as_positive_int, check_scalar
from prefilter.errors import PrefilterError
from prefilter.glints import cp as cpmod
from prefilter.glints.pndf import (DEFAULT_ROUGHNESS, SIGMA_H, TRUNCATION, as_intrinsic_roughness,
                                   as_ndf_truncation, as_normal_map, as_support, elements,
                                   IMAGE_VERSION, map_digest, pndf_image)
from prefilter.glints.levels import LevelFile, over_peaks
from prefilter.glints.pyramid import (LevelStream, Pyramid, filter_taps, next_level_rows, plan,
                                      strip_plan)
from prefilter.glints.store import CODE_BITS, GlintsMap, decode, encode, pack_mask, save

LEVEL0_CHUNK = 0
LEVEL_CHUNK = 10_000
ALLOC_CHUNK = 99_999
CELL_CHUNK = 100_000
FINAL_CHUNK = 500_000
#: relative steps of the candidate ranks above the pass-1 rank ``base = rank // 2``
RANK_STEPS = (1.0, 1.5, 2.0, 2.5, 3.0, 4.0, 6.0)
#: how the rank budget is split (``bake(level_rank=...)``): over the whole map, per pyramid
#: level, or not at all (every group at ``rank``)
LEVEL_RANK = ("global", "level", "uniform")
#: allocation marker of the groups stored exactly (``bake(exact_from_level=...)``)
EXACT = -1
#: How a bake with exact levels spends the rank budget: 2, over the fitted groups only (1: over
#: all groups, the exact ones then replacing theirs). Bakes with exact levels key their
#: checkpoints, and the render cache its files, on it (:func:`code_versions`).
EXACT_BUDGET_RULE = 2
#: Level-0 cells whose pass-1 errors set a one-pass bake's rank multiplier (spread over the map).
SAMPLE_CELLS = 4
#: Version of what a one-pass bake computes (its sample, the order of its filter's sums, the
#: float16 files of the fitted levels' cells: 2); its checkpoints and the render cache key on it
#: (:func:`code_versions`).
ONE_PASS_VERSION = 2
#: Numba's default threading layer is not thread-safe: the bake's parallel kernels (level-0
#: images, the streamed filter) run under this lock when tasks run on threads.
PARALLEL = threading.Lock()


def code_versions(settings: dict) -> dict:
    """The versions of the code a bake with ``settings`` depends on beyond the settings
    themselves: the CP fit's (``cp_fit``, :data:`prefilter.glints.cp.FIT_VERSION`), the NDF
    images' (``ndf_images``, :data:`prefilter.glints.pndf.IMAGE_VERSION`) and, with exact
    levels, the budget rule's (``exact_budget``). The bake's checkpoints and the render and
    Wang-tile caches key on them, so parts and files made by other code are not reused."""
    out = {"cp_fit": cpmod.FIT_VERSION, "ndf_images": IMAGE_VERSION}
    if settings.get("exact_from_level") is not None:
        out["exact_budget"] = EXACT_BUDGET_RULE
    if settings.get("one_pass"):
        out["one_pass"] = ONE_PASS_VERSION
    return out


#: The bake of ``prefilter bake glints`` and of the ``glints`` render method (one definition: the
#: command writes, by default into the render cache, what the renderer reads; :func:`bake_settings`
#: completes it for a map). ``intrinsic_roughness`` is the model's (direct P-NDF, fallback,
#: reference), twice Yan et al.'s 0.005 so that the NDF pixels resolve the intrinsic lobe; with the
#: bilinear lookup the map is baked with :func:`bilinear_bake_roughness` of it. ``support`` 1: the
#: images cover the whole disk of projected half vectors. ``rank`` 48: the adaptive-rank storage
#: budget at which the measurement scene's FLIP vs ``glints-direct`` stays <= 0.05 at every
#: distance. ``blank_tol`` 1e-6: coarser thresholds drop the dim lines and flakes next to a bright
#: peak that a point light sees at mid and far distance. ``ndf_truncation`` 6 /
#: ``footprint_truncation`` 5: HDR-FLIP of the mostly black brushed plane exposes the element and
#: footprint tails beyond 4 stds (4 / 4 gave 0.101 / 0.097 at mid / far, 6 / 6 0.078 / 0.079);
#: cutting the footprints at 5 instead of 6 changes a level-0 cell's images of the docs example's
#: maps by 7e-7 / 8e-7 relative L2 (at most 4e-6 of an image's peak) and makes them 1.4-1.6x /
#: 1.3-1.5x faster (the elements' cut at 5 changes them by 1e-3: the line nodes move;
#: ``benchmarks/bench_glints_cuts.py``). ``code_bits`` 16 / ``c_bits`` 8: 8-bit ``a``, ``b``
#: rounding shows in the NDF tails, 8-bit ``c`` does not and keeps range queries as fast as
#: all-8-bit codes. ``ndf_res`` 512 with ``block`` 32: the environment's brushed plane needs 512^2
#: images; 32-pixel blocks keep the blocks a range query spans (and the frame time) low.
#: ``stride0`` 8 with levels >= 2 stored exactly, each image its own group (``exact_cell`` 1: exact
#: ranks <= ``block``, faster queries): footprints below level 0's spacing are shaded by the direct
#: P-NDF, so the many small CP fits of a fine level 0 are not made; on the docs' example scene
#: (``benchmarks/bench_glints_cold.py``) stride 4 with exact levels >= 3 took 391 s cold and gave
#: HDR-FLIP 0.053 against ``glints-direct``, stride 8 with exact levels >= 2 259 s and 0.030, and
#: the point-light matrix's worst cell 0.047 and 0.038. The price: footprints of 4-8 texels are
#: shaded directly, so mid-distance frames take about twice the others (frame time max/min 2.1-2.8
#: against 1.4-1.5, docs/glints-part2.md). ``one_pass``: no uncompressed pyramid on disk
#: (:func:`one_pass_stages`). ``n_iter_max`` 30 (with :data:`prefilter.glints.cp.HALS_SWEEPS` and
#: :func:`pass1_iters`): with ``stride0`` 4 the brushed plane at mid distance, then the
#: measurement scene's hardest cell under a point light, gave FLIP 0.051 / 0.061 /
#: 0.047 at 20 / 24 / 30 iterations (not monotonic: which dim glints a fit keeps decides this cell;
#: ``study_glints_scenes.py --shapes plane --kinds brushed --bake '{"n_iter_max": N}'``). Where a
#: bake's time goes: ``benchmarks/bench_glints_stages.py``. Measurements: docs/glints-part2.md,
#: ``benchmarks/study_glints_scenes.py``.
BAKE_SETTINGS = dict(rank=48, ndf_res=512, block=32, support=1.0, stride0=8,
                     intrinsic_roughness=2 * DEFAULT_ROUGHNESS, n_iter_max=30, seed=0,
                     blank_tol=1e-6, ndf_truncation=6.0, footprint_truncation=5.0,
                     code_bits=16, c_bits=8, exact_from_level=2, exact_cell=1, one_pass=True)
#: Bytes of the window of x-filtered rows that building a coarser level holds
#: (:func:`prefilter.glints.pyramid.next_level_rows`); wider levels are built in column strips.
LEVEL_RING_BYTES = 512 << 20


def strip_width(ny: int, R: int, cap: int, sigma_over_stride: float = 1.0) -> int:
    """Output columns per strip of a coarser level built from a level of ``ny`` rows of
    ``R^2`` images, so that the filter's window of rows (one row per tap, at most ``ny``) holds
    at most ``cap`` bytes (at least one column); ``sigma_over_stride`` sets the filter's taps
    (:func:`prefilter.glints.pyramid.filter_taps`)."""
    taps, _ = filter_taps(sigma_over_stride)
    slots = min(len(taps), ny)
    return max(1, cap // (slots * R * R * 4) - (len(taps) // 2 + 1))


#: Spatial cell of a group at level 0 (texels), at most the map's side.
CELL = 32


def bake_settings(shape, settings: dict | None = None, *, bilinear: bool = True) -> dict:
    """The keyword arguments of :func:`bake` that make the render methods' map of a normal map
    of ``shape (H, W, ...)``: :data:`BAKE_SETTINGS` updated by ``settings``, ``cell`` at most the
    map's side (:data:`CELL`), and, for the bilinear NDF lookup (``bilinear``), the intrinsic
    roughness sharpened by :func:`bilinear_bake_roughness`."""
    st = dict(BAKE_SETTINGS, **(settings or {}))
    st.setdefault("cell", min(CELL, int(shape[0]), int(shape[1])))
    if bilinear:
        st["intrinsic_roughness"] = bilinear_bake_roughness(st["intrinsic_roughness"],
                                                            st["support"], st["ndf_res"])
    return st


def settings_key(settings: dict) -> str:
    """The cache key (12 hex digits) of complete bake ``settings``: their JSON and the code
    versions they depend on (:func:`code_versions`: the CP fit's and, with exact levels, the budget
    rule's), so files made before a change to either are not reused."""
    return hashlib.sha1(json.dumps(dict(settings, **code_versions(settings)), sort_keys=True)
                        .encode()).hexdigest()[:12]


def cache_dir() -> Path:
    """The render cache of baked maps: ``$PREFILTER_GLINTS_CACHE`` or
    ``~/.cache/prefilter/glints``."""
    d = os.environ.get("PREFILTER_GLINTS_CACHE")
    return Path(d) if d else Path.home() / ".cache" / "prefilter" / "glints"


def cache_path(normal_map, settings: dict) -> Path:
    """The render cache's file of ``normal_map`` baked with complete ``settings``
    (:func:`bake_settings`): named by the SHA-1 of the normals and :func:`settings_key`."""
    digest = map_digest(as_normal_map(normal_map))
    return cache_dir() / f"{digest[:20]}-{settings_key(settings)}.npz"


def bilinear_bake_roughness(intrinsic_roughness: float, support: float, ndf_res: int) -> float:
    """Intrinsic roughness to bake with so that the bilinear lookup reproduces ``sigma_r``.

    A bilinear interpolation of pixel averages (pitch ``h = 2 support / ndf_res``) blurs the NDF
    by the pixel box (variance ``h^2 / 12``) and the tent (``h^2 / 6``), i.e. adds ``(h / 2)^2``
    to the variance of every element's Gaussian: baking with ``sqrt(sigma_r^2 - (h/2)^2)`` puts it
    back (not below ``sigma_r / 2`` when the pixels are too coarse for that)."""
    sr = as_intrinsic_roughness(intrinsic_roughness)
    hh = float(support) / int(ndf_res)
    return max(math.sqrt(max(sr * sr - hh * hh, 0.0)), 0.5 * sr)


@contextmanager
def _locked(out, levels_dir):
    """Exclusive locks on ``<out>.lock`` and on the shared ``levels_dir``: two processes baking
    the same output wait for each other instead of sharing (and deleting) checkpoint parts."""
    with ExitStack() as locks:
        locks.enter_context(bake_lock(out, wait=True))
        if levels_dir is not None:
            locks.enter_context(exclusive_lock(str(levels_dir).removesuffix(".parts") + ".lock"))
        yield


def _serialised(fn):
    """Run a bake under :func:`_locked` (``fn.__wrapped__`` is the unlocked bake)."""
    @functools.wraps(fn)
    def locked(normal_map, out, **kwargs):
        try:
            with _locked(out, kwargs.get("levels_dir")):
                return fn(normal_map, out, **kwargs)
        finally:
            release_heap()  # what the bake's threads freed: the render after it needs it
    return locked


def bake_if_missing(normal_map, out, **kwargs) -> bool:
    """:func:`bake` into ``out`` unless it exists, also when another process is baking it right
    now (the check is made under the bake's lock). Returns whether this call baked."""
    out = Path(out)
    if out.exists():
        return False
    with _locked(out, kwargs.get("levels_dir")):
        if out.exists():  # baked by the process that held the lock
            return False
        try:
            bake.__wrapped__(normal_map, out, **kwargs)
        finally:
            release_heap()
    return True


# ---------------------------------------------------------------------------------------------
# the bake's tasks: top-level, picklable, deterministic functions of a BakeJob and a chunk or
# cell number, each writing its result as a checkpoint part (so any map may run them: in this
# process, in threads, or on a cluster's workers sharing the parts folder)


@dataclass(frozen=True)
class BakeJob:
    """What a bake's tasks share: the checkpoint folders (``ck``: the bake's, ``lk``: the
    levels'), the pyramid, the NDF and CP settings and the cells. No arrays but ``cells``; the
    normal map is read from ``lk.dir / "normal_map.npy"``."""

    ck: Checkpoints
    lk: Checkpoints
    pyr: Pyramid
    R: int
    S: float
    sr: float
    nt: float
    ft: float
    B: int
    blank_tol: float
    base: int
    n_iter_max: int
    tol: float
    seed: int
    code_bits: int
    c_bits: int
    rows_per_chunk: int
    exact_from_level: int | None
    #: ``(n_cells, 5)`` int64: level, rows ``y0:y1`` and columns ``x0:x1`` of centres per cell
    cells: np.ndarray
    #: the bake's ``level0`` callable (None: the direct P-NDF of the stored normal map)
    level0: object = None
    #: one-pass bakes (:func:`cell_task`): the rank budget, its split, the candidate ranks and
    #: the multiplier estimated from the sample cells (:func:`prefilter.glints.cp.ranks_for`)
    rank: int = 0
    level_rank: str = "global"
    #: the allocation's weight of each group's squared error: its squared norm to this power's
    #: negative (``bake(error_weight=...)``)
    error_weight: float = 0.0
    candidates: tuple = ()
    lam: float = 0.0

    @property
    def nb(self) -> int:
        return self.R // self.B

    def level(self, lv: int) -> LevelFile:
        return LevelFile(self.lk.dir / f"level{lv}.npy", self.pyr.shape(lv) + (self.R, self.R))

    def exact(self, lv: int) -> bool:
        return self.exact_from_level is not None and lv >= self.exact_from_level

    def cell_file(self, cid: int) -> Path:
        """The images of a coarser level's cell in a one-pass bake (:func:`cell_task`)."""
        return self.ck.dir / f"cell{cid}.npy"

    def cell_files(self, cid: int) -> tuple[LevelFile, LevelFile | None]:
        """The files a coarser level's cell waits in for its task (:func:`cell_task`): its
        images and, at the fitted levels, their peaks. Fitted levels wait as float16 images over
        their peaks (:func:`prefilter.glints.levels.over_peaks`: rounding 5e-4, a hundredth of
        the fits' error; at the end of a bake the waiting cells are most of its temporary disk),
        the exact levels as float32."""
        lv, y0, y1, x0, x1 = (int(v) for v in self.cells[cid])
        shape, path = (y1 - y0, x1 - x0), self.cell_file(cid)
        if self.exact(lv):
            return LevelFile(path, shape + (self.R, self.R)), None
        return (LevelFile(path, shape + (self.R, self.R), np.float16),
                LevelFile(self.cell_peaks_file(cid), shape))

    def cell_peaks_file(self, cid: int) -> Path:
        """The peaks of a fitted level's cell images (:meth:`cell_files`)."""
        return self.ck.dir / f"cell{cid}-peaks.npy"

    def write_cell_rows(self, cid: int, y: int, images: np.ndarray) -> None:
        """Row ``y`` (cell-relative) of cell ``cid``'s images ``(1, k, R, R)`` into its
        :meth:`cell_files`."""
        imgs, peaks = self.cell_files(cid)
        if peaks is None:
            imgs.write_rows(y, images)
            return
        scaled, peak = over_peaks(images)
        peaks.write_rows(y, peak)
        imgs.write_rows(y, scaled)

    def remove_cell_files(self, cid: int) -> None:
        """Delete :meth:`cell_files` (after the cell's task)."""
        self.cell_file(cid).unlink(missing_ok=True)
        self.cell_peaks_file(cid).unlink(missing_ok=True)


def cell_bounds(pyr: Pyramid, k_sides) -> np.ndarray:
    """Cells ``(n, 5)`` int64 ``(level, y0, y1, x0, x1)``: squares of ``k_sides[level]`` centres
    per side, in row-major order per level; the last row and column of cells take the centres
    left over (a level with fewer centres than ``k`` per side is one cell)."""
    out = []
    for lv in range(pyr.n_levels):
        k = int(k_sides[lv])
        ny, nx = pyr.shape(lv)
        ncy, ncx = max(1, ny // k), max(1, nx // k)
        for cy in range(ncy):
            for cx in range(ncx):
                out.append((lv, cy * k, ny if cy == ncy - 1 else (cy + 1) * k,
                            cx * k, nx if cx == ncx - 1 else (cx + 1) * k))
    return np.array(out, np.int64).reshape(-1, 5)


def level0_task(job: BakeJob, ch: int) -> int:
    """Level-0 NDF images of chunk ``ch`` (a row of cells), a row of centres per
    :func:`prefilter.glints.pndf.pndf_image` call (the images of a whole chunk took 1 GB at
    512^2), written into the level file; then its checkpoint part."""
    if job.lk.done(LEVEL0_CHUNK + ch):
        return ch
    lev, centers, sigma = job.level(0), job.pyr.centers(0), job.pyr.sigma(0)
    if job.level0 is None:
        nm = np.load(job.lk.dir / "normal_map.npy")
        el = elements(nm)
    for y in range(ch * job.rows_per_chunk, (ch + 1) * job.rows_per_chunk):
        lev.write_rows(y, pndf_image(nm, centers[y:y + 1], sigma, job.R, job.S, job.sr,
                                     elements_=el, ndf_truncation=job.nt,
                                     footprint_truncation=job.ft, dtype=np.float32)
                       if job.level0 is None
                       else job.level0(y, centers[y:y + 1], sigma))
    job.lk.save(LEVEL0_CHUNK + ch, done=np.array(1))
    return ch


def cell_tensors(job: BakeJob, cid: int):
    """Images ``(n, R, R)`` float64 of cell ``cid`` (row-major centres), their blocks
    ``(n, nb, nb, B, B)``, the blank mask ``(n, nb, nb)``, one ``(B, B, K_g)`` tensor of the kept
    blocks per group ``g = bi nb + bj`` and the images ``(K_g,)`` they come from."""
    lv, y0, y1, x0, x1 = (int(v) for v in job.cells[cid])
    imgs = job.level(lv).read(y0, y1, x0, x1).astype(np.float64).reshape(-1, job.R, job.R)
    return (imgs,) + image_tensors(job, imgs)


def image_tensors(job: BakeJob, imgs: np.ndarray):
    """:func:`cell_tensors` of the images ``imgs (n, R, R)`` float64 of a cell: blocks, blank
    mask, tensors and the images of each tensor's blocks."""
    blocks = cpmod.cut_blocks(imgs, job.B)
    blank = cpmod.blank_mask(blocks, imgs.max(axis=(1, 2)), job.blank_tol)
    tensors, where = [], []
    for bi in range(job.nb):
        for bj in range(job.nb):
            keep = np.flatnonzero(~blank[:, bi, bj])
            where.append(keep)
            tensors.append(np.ascontiguousarray(blocks[keep, bi, bj].transpose(1, 2, 0)))
    return blocks, blank, tensors, where


def fit_cell_task(job: BakeJob, cid: int) -> int:
    """Pass 1 of cell ``cid``: every fitted group at rank ``base``; its error drives the
    allocation (the groups stored exactly are not fitted)."""
    if job.ck.done(CELL_CHUNK + cid):
        return cid
    imgs, blocks, blank, tensors, where = cell_tensors(job, cid)
    stats = cell_stats(job, imgs, blocks, blank)
    del imgs, blocks
    fit_cell(job, cid, stats, blank, tensors, where)
    return cid


def cell_stats(job: BakeJob, imgs, blocks, blank) -> dict:
    """What the assembly needs of a cell's images ``(n, R, R)`` besides its fits: the squared
    norm of its blank blocks and of its images, the kept blocks, each image's mass."""
    sq = np.einsum("nabij,nabij->nab", blocks, blocks)
    return dict(blank2=np.array(sq[blank].sum()), norm2=np.array(sq.sum()),
                kept=np.array((~blank).sum()),
                mass=imgs.sum(axis=(1, 2)) * (2 * job.S / job.R) ** 2)


def fit_cell(job: BakeJob, cid: int, stats: dict, blank, tensors, where,
             save: bool = True) -> dict:
    """Pass 1 of cell ``cid`` on its :func:`cell_tensors` (``stats``: :func:`cell_stats`): its
    checkpoint part's arrays, saved unless ``save`` is false."""
    nb, B, base = job.nb, job.B, job.base
    live = [g for g, t in enumerate(tensors) if t.shape[2] > 0]
    exact = job.exact(int(job.cells[cid, 0]))
    fit = [] if exact else live
    res = dict(zip(fit, cpmod.nn_cp_batch([tensors[g] for g in fit], base,
                                          n_iter_max=pass1_iters(job.n_iter_max), tol=job.tol,
                                          seed=job.seed + cid)))
    rows = np.concatenate([[0], np.cumsum([len(w) for w in where])]).astype(np.int64)
    local = np.full(blank.shape, -1, np.int32)
    width = 0 if exact else base  # no factors to keep for the exact groups
    a = np.zeros((nb * nb, width, B), np.float32)
    b = np.zeros_like(a)
    c = np.zeros((rows[-1], width), np.float32)
    err2_g = np.zeros(nb * nb)
    for g in live:
        bi, bj = divmod(g, nb)
        local[where[g], bi, bj] = rows[g] + np.arange(len(where[g]), dtype=np.int32)
    for g, (ag, bg, cg, e) in res.items():
        a[g], b[g], c[rows[g]:rows[g + 1]] = ag.T, bg.T, cg
        # the allocation's error of the group: squared, times its squared norm ** -error_weight
        err2_g[g] = e**2 * np.einsum("ijk,ijk->", tensors[g], tensors[g]) ** (
            1.0 - job.error_weight)
    part = dict(a=a, b=b, c=c, rows=rows, local=local, err2_g=err2_g, **stats)
    if save:
        job.ck.save(CELL_CHUNK + cid, **part)
    return part


def pass1_iters(n_iter_max: int) -> int:
    """CP iterations of pass 1 (every group at ``base``) out of a bake's ``n_iter_max``: half
    (at least one). Its errors rank the groups for the allocation; the final fit continues every
    group from them at its rank for the rest (at least one), so each group gets ``n_iter_max``
    iterations in all and the promoted groups spend half of theirs at the cheaper base rank.
    Point-light FLIP of the brushed plane vs ``glints-direct`` (near / mid / far, ``n_iter_max``
    30, ``benchmarks/study_glints_scenes.py --shapes plane --kinds brushed``): 0.032 / 0.047 /
    0.036 with half, 0.032 / 0.051 / 0.034 with a third (``FIT_VERSION`` 5)."""
    return max(1, int(n_iter_max) // 2)


def refit_cell_task(job: BakeJob, cid: int) -> int:
    """Pass 2 of cell ``cid``: every fitted group continued from pass 1 at its allocated rank
    (:func:`pass1_iters`), those stored exactly; encoding; the error measured on what the loader
    decodes."""
    if job.ck.done(FINAL_CHUNK + cid):
        return cid
    nb = job.nb
    r_cell = job.ck.load(ALLOC_CHUNK)["ranks"][cid * nb * nb:(cid + 1) * nb * nb]
    refit_cell(job, cid, cell_tensors(job, cid)[3], job.ck.load(CELL_CHUNK + cid), r_cell)
    return cid


def refit_cell(job: BakeJob, cid: int, tensors, p1, r_cell) -> None:
    """Pass 2 of cell ``cid`` on its tensors, pass-1 part ``p1`` and ranks ``r_cell (nb^2,)``,
    saved as its final checkpoint part."""
    nb, B = job.nb, job.B
    rows = p1["rows"]
    first = {g: (p1["a"][g].T.astype(np.float64), p1["b"][g].T.astype(np.float64),
                 p1["c"][rows[g]:rows[g + 1]].astype(np.float64)) for g in range(nb * nb)}
    fits: dict = {}
    for g in np.flatnonzero(r_cell == EXACT):
        fits[g] = cpmod.exact_cp(tensors[g])[:3]
    more = max(1, job.n_iter_max - pass1_iters(job.n_iter_max))
    for r in sorted(set(r_cell.tolist()) - {0, EXACT}):
        gs = [g for g in range(nb * nb) if r_cell[g] == r]
        out = cpmod.nn_cp_batch([tensors[g] for g in gs], int(r), n_iter_max=more,
                                tol=job.tol, seed=job.seed + cid, init=[first[g] for g in gs])
        fits.update({g: o[:3] for g, o in zip(gs, out)})
    groups = [(fits[g][0].T, fits[g][1].T, fits[g][2]) if r_cell[g] else
              (np.zeros((0, B)), np.zeros((0, B)), np.zeros((rows[g + 1] - rows[g], 0)))
              for g in range(nb * nb)]
    enc = encode(groups, job.code_bits, job.c_bits)
    A_, B_, C_ = decode(**enc, group_rows=rows)
    a_s, b_s = np.diff(A_.astype(np.float64), axis=2), np.diff(B_.astype(np.float64), axis=2)
    err2_g = np.zeros(nb * nb)
    # the fit's own error too (before the codes' rounding): with 8-bit c codes the rounding
    # dominates the stored error while no rendered frame shows it
    fit2_g = np.zeros(nb * nb)
    for g in range(nb * nb):
        if rows[g + 1] > rows[g]:
            d = cpmod.reconstruct(a_s[g].T, b_s[g].T,
                                  C_[rows[g]:rows[g + 1]].astype(np.float64)) - tensors[g]
            err2_g[g] = np.einsum("ijk,ijk->", d, d)
            a, b, c = groups[g]
            d = cpmod.reconstruct(a.T, b.T, c) - tensors[g]
            fit2_g[g] = np.einsum("ijk,ijk->", d, d)
    job.ck.save(FINAL_CHUNK + cid, **enc, err2_g=err2_g, fit2_g=fit2_g)


def cell_images(job: BakeJob, cid: int) -> np.ndarray:
    """Images ``(n, R, R)`` float32 of cell ``cid`` of a one-pass bake: at level 0 the direct
    P-NDF of its centres (or the bake's ``level0`` rows), above it the cell's file written by the
    streamed filter."""
    lv, y0, y1, x0, x1 = (int(v) for v in job.cells[cid])
    R = job.R
    if lv > 0:
        imgs, peaks = job.cell_files(cid)
        out = imgs.read(0, y1 - y0)
        if peaks is not None:
            out = out.astype(np.float32) * peaks.read(0, y1 - y0)[..., None, None]
        return out.reshape(-1, R, R)
    centers, sigma = job.pyr.centers(0), job.pyr.sigma(0)
    if job.level0 is not None:
        return np.concatenate([np.asarray(job.level0(y, centers[y:y + 1], sigma),
                                          np.float32)[0, x0:x1] for y in range(y0, y1)])
    nm = np.load(job.lk.dir / "normal_map.npy")
    with PARALLEL:
        # float32 sums: what the level files store, ~1.5x faster than float64
        imgs = pndf_image(nm, centers[y0:y1, x0:x1], sigma, R, job.S, job.sr,
                          ndf_truncation=job.nt, footprint_truncation=job.ft, dtype=np.float32)
    return imgs.reshape(-1, R, R)


def cell_ranks(job: BakeJob, cid: int, p1) -> np.ndarray:
    """Ranks ``(nb^2,)`` of cell ``cid``'s groups in a one-pass bake: from their pass-1 errors
    (part ``p1``) and the multiplier ``job.lam`` (:func:`prefilter.glints.cp.ranks_for`),
    ``rank`` for a uniform split, :data:`EXACT` at the exact levels, 0 without kept blocks."""
    counts = np.diff(p1["rows"])
    if job.exact(int(job.cells[cid, 0])):
        r = np.full(len(counts), EXACT, np.int64)
    elif job.level_rank == "uniform":
        r = np.full(len(counts), job.rank, np.int64)
    else:
        unit = (job.c_bits // 8) * counts + 2 * job.B * (job.code_bits // 8) + 4
        r = cpmod.ranks_for(p1["err2_g"], unit, job.base, job.candidates, job.lam)
    return np.where(counts > 0, r, 0).astype(np.int64)


def sample_cell_task(job: BakeJob, cid: int) -> int:
    """Pass 1 of a sample cell of a one-pass bake (its errors set the rank multiplier)."""
    if not job.ck.done(CELL_CHUNK + cid):
        imgs = cell_images(job, cid).astype(np.float64)
        blocks, blank, tensors, where = image_tensors(job, imgs)
        stats = cell_stats(job, imgs, blocks, blank)
        del imgs, blocks
        fit_cell(job, cid, stats, blank, tensors, where)
    return cid


def cell_task(job: BakeJob, cid: int):
    """Cell ``cid`` of a one-pass bake while its images are in memory: pass 1 (unless its
    part exists), its ranks (:func:`cell_ranks`), the refit, encoding and error. Returns the
    level-0 images ``(k, k, R, R)`` float32 (the coarser levels are filtered from them), None
    for the other levels."""
    lv, y0, y1, x0, x1 = (int(v) for v in job.cells[cid])
    done = job.ck.done(FINAL_CHUNK + cid)
    if done and lv > 0:
        return None
    imgs = cell_images(job, cid)
    out = imgs.reshape(y1 - y0, x1 - x0, job.R, job.R) if lv == 0 else None
    if not done:
        imgs = imgs.astype(np.float64)
        blocks, blank, tensors, where = image_tensors(job, imgs)
        stats = cell_stats(job, imgs, blocks, blank)
        del imgs, blocks
        p1 = job.ck.load(CELL_CHUNK + cid) if job.ck.done(CELL_CHUNK + cid) else {}
        if "a" not in p1:  # not a sample cell's part (with the factors the refit starts from)
            p1 = fit_cell(job, cid, stats, blank, tensors, where, save=False)
        # the assembly needs no pass-1 factors: the part without them (~2 MB less per cell of
        # the render's maps), saved before the final part (a resumed bake refits from pass 1)
        job.ck.save(CELL_CHUNK + cid, **{k: v for k, v in p1.items() if k not in ("a", "b", "c")})
        refit_cell(job, cid, tensors, p1, cell_ranks(job, cid, p1))
    return out


def sample_cells(cells: np.ndarray, n: int = SAMPLE_CELLS) -> list[int]:
    """Ids of ``n`` level-0 cells on a diagonal of the map's cells (all when there are fewer)."""
    lvl0 = np.flatnonzero(cells[:, 0] == 0)
    if len(lvl0) <= n:
        return [int(c) for c in lvl0]
    ys, xs = np.unique(cells[lvl0, 1]), np.unique(cells[lvl0, 3])
    out = []
    for i in range(n):
        y, x = ys[(2 * i + 1) * len(ys) // (2 * n)], xs[(2 * i + 1) * len(xs) // (2 * n)]
        out.append(int(lvl0[(cells[lvl0, 1] == y) & (cells[lvl0, 3] == x)][0]))
    return sorted(set(out))


def one_pass_stages(job: BakeJob, converge: float, k_sides, map_fn, progress: bool):
    """Stages 1-3 of a one-pass bake: returns the pyramid cut at convergence, the level
    differences and the job with its cells.

    (a) The rank multiplier from the pass-1 errors of :func:`sample_cells` (a checkpoint part);
    (b) the level-0 cells, one row of cells after the other, each fitted, given its ranks and
    refitted while its images are in memory (:func:`cell_task`), its images then filtered into
    the next level (:class:`prefilter.glints.pyramid.LevelStream`, a stream per level), whose
    completed rows fill the cells of that level, which run as tasks too once complete. Nothing
    of the pyramid is stored but the accumulators the filter spills and the files of the
    coarser cells waiting for their task. The first row of cells processed is the second one:
    the rows of level 1 that the periodic filter wraps around then all fall into its first row
    of cells (and so on up), which completes last."""
    from tqdm import tqdm

    pyr, ck, R = job.pyr, job.ck, job.R
    cells = job.cells
    spill = ck.dir / "stream"
    shutil.rmtree(spill, ignore_errors=True)
    spill.mkdir()
    sample = sample_cells(cells) if (job.level_rank == "global" and not job.exact(0)) else []
    with cpmod.single_threaded_blas(), \
            tqdm(total=len(sample) + len(cells), desc="NDF images and CP, one pass",
                 unit="cell", disable=not progress, file=sys.stderr) as bar:
        if sample:
            if not ck.done(ALLOC_CHUNK):
                _run(map_fn or thread_map, sample_cell_task, job, sample, bar)
                err2, unit = [], []
                for cid in sample:
                    p1 = ck.load(CELL_CHUNK + cid)
                    counts = np.diff(p1["rows"])
                    err2.append(p1["err2_g"])
                    unit.append(np.where(counts > 0, (job.c_bits // 8) * counts
                                         + 2 * job.B * (job.code_bits // 8) + 4, 0.0))
                err2, unit = np.concatenate(err2), np.concatenate(unit)
                lam = cpmod.budget_multiplier(err2, unit, job.base, job.candidates,
                                              job.rank * unit.sum())
                ck.save(ALLOC_CHUNK, lam=np.array(lam))
            else:
                bar.update(len(sample))
            job = dataclasses.replace(job, lam=float(ck.load(ALLOC_CHUNK)["lam"]))
        streams = [LevelStream(pyr.shape(lv), pyr.sigma0 / pyr.stride0, (R, R), spill,
                               f"l{lv + 1}") for lv in range(pyr.n_levels - 1)]
        rows_left = {int(c): int(cells[c, 2] - cells[c, 1]) for c in range(len(cells))}
        at_row: dict = {}
        for c in range(len(cells)):
            lv, y0, y1 = (int(v) for v in cells[c, :3])
            for y in range(y0, y1):
                at_row.setdefault((lv, y), []).append(c)
        ready: list[int] = []

        def completed(lv, rows):
            for y, imgs in rows:
                for cid in at_row[(lv, y)]:
                    _, y0, y1, x0, x1 = (int(v) for v in cells[cid])
                    if not ck.done(FINAL_CHUNK + cid):
                        job.write_cell_rows(cid, y - y0, imgs[None, x0:x1])
                    rows_left[cid] -= 1
                    if rows_left[cid] == 0:
                        ready.append(cid)
                if lv + 1 < pyr.n_levels:
                    with PARALLEL:
                        streams[lv].add(y, 0, imgs)
                    completed(lv + 1, streams[lv].arrived([y]))

        def consume(cid, imgs):
            if imgs is None:
                job.remove_cell_files(cid)
            elif streams:
                _, y0, _, x0, _ = (int(v) for v in cells[cid])
                for i, row in enumerate(imgs):
                    with PARALLEL:
                        streams[0].add(y0 + i, x0, row)
            bar.update(1)

        def row_done(ch):
            if streams:
                completed(1, streams[0].arrived(range(ch * k, (ch + 1) * k)))
            for st in streams:
                st.spill()

        k = int(k_sides[0])
        n_chunks = pyr.shape(0)[0] // k
        lvl0 = np.flatnonzero(cells[:, 0] == 0)
        rows0 = [(ch, [int(c) for c in lvl0 if cells[c, 1] == ch * k])
                 for ch in list(range(1, n_chunks)) + [0]]
        if map_fn is None:
            ordered_stream(rows0, ready, consume, row_done, job)
        else:
            def run(batch):
                for cid, imgs in zip(batch, map_fn(cell_task, [job] * len(batch), batch)):
                    consume(cid, imgs)

            for ch, row in rows0:
                # the waiting coarser cells first: their files go before new rows fill others
                batch, ready[:] = ready + row, []
                run(batch)
                row_done(ch)
            while ready:
                batch, ready[:] = list(ready), []
                run(batch)
    shutil.rmtree(spill, ignore_errors=True)
    diffs = [st.difference for st in streams]
    n_keep = pyr.n_levels
    for i, d in enumerate(diffs):
        if d < converge:
            n_keep = i + 2
            break
    pyr = pyr.with_levels(n_keep)
    return pyr, diffs[:n_keep - 1], dataclasses.replace(
        job, pyr=pyr, cells=cell_bounds(pyr, k_sides[:n_keep]))


def ordered_stream(rows0, ready: list, consume, row_done, job: BakeJob) -> None:
    """The cell tasks of a one-pass bake on a pool of ``os.cpu_count()`` threads, their results
    consumed (``consume(cid, result)``) in the order they were submitted, so the filter's sums
    and the files are the same bytes as with any ``map_fn``; ``row_done(ch)`` after the last
    cell of each row ``ch`` of level-0 cells in ``rows0`` (``(ch, cell ids)``); the coarser
    cells it makes ``ready`` are queued before the remaining level-0 cells (their files go
    first).

    At most one task more than the threads is in flight: a thread starts the next cell while
    the caller filters a finished one and no thread idles at the end of a row (the per-row
    batches of a ``map_fn`` wait for their slowest cell). What is queued depends only on the
    results consumed so far, so the order is deterministic."""
    ends = {row[-1]: ch for ch, row in rows0 if row}
    queue = deque(c for _, row in rows0 for c in row)
    threads = max(1, os.cpu_count() or 1)
    with ThreadPoolExecutor(threads) as pool:
        flight: deque = deque()
        while queue or flight or ready:
            queue.extendleft(reversed(ready))
            ready.clear()
            while queue and len(flight) <= threads:
                cid = queue.popleft()
                flight.append((cid, pool.submit(cell_task, job, cid)))
            cid, fut = flight.popleft()
            consume(cid, fut.result())
            if cid in ends:
                row_done(ends[cid])


def significant(x, digits: int = 10):
    """``x`` (nested dicts and lists) with its floats rounded to ``digits`` significant digits.

    The file's summary statistics are sums of float64 errors over thousands of groups; a bake on
    a cluster was seen to differ from the same bake in one process in their last bit (the stored
    arrays identical; cause not found), which broke the byte identity of the file. Ten digits
    are all the statistics mean."""
    if isinstance(x, dict):
        return {k: significant(v, digits) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [significant(v, digits) for v in x]
    if isinstance(x, float) and math.isfinite(x):
        return float(f"{x:.{digits}g}")
    return x


def thread_map(fn, *iterables):
    """``map(fn, *iterables)`` on a pool of ``os.cpu_count()`` threads, results in order: the
    CP kernels release the GIL (the default map of the bake's CP passes)."""
    args = list(zip(*iterables))
    with ThreadPoolExecutor(max(1, min(os.cpu_count() or 1, len(args)))) as pool:
        yield from pool.map(lambda a: fn(*a), args)


def _run(map_fn, fn, job: BakeJob, ids, bar, step: int = 1) -> None:
    """``map_fn(fn, [job] * n, ids)``, counting ``step`` on ``bar`` per finished task."""
    ids = [int(i) for i in ids]
    for _ in map_fn(fn, [job] * len(ids), ids):
        bar.update(step)


def split_budget(err2, unit, group_level, rank, base, candidates, level_rank="global"):
    """Ranks ``(G,)`` of the groups under the budget of ``rank`` per byte on average
    (:func:`prefilter.glints.cp.allocate_ranks`), over the whole map or per pyramid level
    (``level_rank``, see :func:`bake`). ``err2 (G,)``: squared error of each group at rank
    ``base``; ``unit (G,)``: its bytes per rank; ``group_level (G,)``: its pyramid level."""
    if level_rank == "uniform":
        return np.full(len(unit), rank, np.int64)
    if level_rank == "global":
        return cpmod.allocate_ranks(err2, unit, base, candidates, budget=rank * unit.sum())
    out = np.zeros(len(unit), np.int64)
    for lv in np.unique(group_level):
        # each level's bytes at rank ``rank``: the levels' mean ranks per byte are all ``rank``
        sel = group_level == lv
        out[sel] = cpmod.allocate_ranks(err2[sel], unit[sel], base, candidates,
                                        budget=rank * unit[sel].sum())
    return out


@_serialised
def bake(normal_map, out, *, rank: int = 16, ndf_res: int = 128, block: int = 16,
         support: float = 0.5, intrinsic_roughness: float = DEFAULT_ROUGHNESS, stride0: int = 4,
         sigma0: float | None = None, cell: int = 32, converge: float = 0.01,
         max_levels: int | None = None, blank_tol: float = 1e-4, n_iter_max: int = 50,
         tol: float = 1e-4, seed: int = 0, progress: bool = True, keep_parts: bool = False,
         levels_dir=None, max_rank: int | None = None, level_rank: str = "global",
         error_weight: float = 0.0, ndf_truncation: float = TRUNCATION,
         footprint_truncation: float = TRUNCATION,
         code_bits: int = 8, c_bits: int | None = None,
         exact_from_level: int | None = None, exact_cell: int | None = None,
         map_fn=None, level0=None, one_pass: bool = False) -> dict:
    """Bake ``normal_map (H, W, 3)`` into ``out`` (.npz); returns the summary dict.

    Parameters mirror ``prefilter bake glints``; ``support`` is the half-width of the NDF images in
    ``s`` (default 0.5: 128 pixels at the pitch of a 256-pixel image of the whole disk).
    ``levels_dir``: keep the uncompressed pyramid there (keyed by the NDF settings only) so bakes
    at several ranks share it; it is not removed at the end.

    ``rank`` is the storage budget: the mean rank per group weighted by the group's bytes per rank
    (``b (K_g + 2 B) + 4``: ``b = code_bits / 8`` bytes per code, ``K_g`` codes of ``c`` (one per
    kept block) and ``2 B`` of ``a``, ``b``, four for the scale), i.e. the bytes a uniform rank
    ``rank`` would take. Groups get ranks between ``rank // 2`` and ``max_rank`` (default ``3
    rank``; it is the width of the in-memory factors, so it sets the query cost). The summary
    reports the resulting mean and histogram.

    ``level_rank`` (query cost vs footprint size): ``"global"`` spends the budget
    where the predicted error drop per byte is largest over the whole map (level-0 groups end up
    with about twice the rank of the top levels'); ``"level"`` gives every pyramid level its own
    budget of ``rank`` per byte (the same total, the same mean rank per byte at every level);
    ``"uniform"`` gives every group rank ``rank`` (``max_rank`` is then unused).

    ``error_weight`` (in ``[0, 2]``): the allocation weighs each group's squared error by its
    squared norm to the power ``-error_weight``. 0 (default) minimises the total squared error,
    so the bright blocks of the NDF images take most of the rank; 1 weighs the groups' relative
    errors alike, giving the dim blocks (the NDF images' tails) more. The same bytes; on the
    wave-optics speckle images 0.75 lowers the near frame's FLIP (docs/glints-wave.md).

    ``ndf_truncation`` / ``footprint_truncation``: stds at which each element's Gaussian in ``s``
    / the footprint weights are cut in the level-0 NDF images
    (:func:`prefilter.glints.pndf.pndf_image`); the renderer bakes with 6 / 5
    (:data:`BAKE_SETTINGS`).

    ``code_bits``: 8 (default) or 16 bits per stored factor value (:func:`store.encode`). The
    budget ``rank`` keeps its meaning (the bytes per rank double, so the file about doubles);
    16 bits remove the rounding that shows in the NDF tails.
    ``c_bits``: bits of the per-image factor ``c`` (default ``code_bits``); 16-bit ``a``, ``b``
    with 8-bit ``c`` are as accurate as all-16-bit codes on the brushed map's scenes and as fast
    to query as 8-bit ones.

    ``exact_from_level``: the groups of pyramid levels ``>=`` this are stored as their exact
    non-negative CP (:func:`prefilter.glints.cp.exact_cp`: ranks up to ``B^2``, beyond
    ``max_rank``) instead of a fit, outside the budget (``rank`` is then the mean rank per byte
    of the fitted groups). The
    levels above the finest few hold few images, so this costs little storage and removes the
    compression error that far footprints see.

    ``exact_cell``: footprint centres per side of the cells of those exact levels (default: as
    at the other levels, ``cell / stride0``). A group's exact rank is at most the number of its
    non-zero pixels, rows or columns over its ``K`` images (``min(B^2, B K)``), and a query reads
    all of it: ``exact_cell=1`` (one image per group) bounds it by ``B`` instead of ``B^2``, at
    the cost of ``a``, ``b`` factors per image instead of per cell.

    ``map_fn``: runs the bake's independent tasks, ``map_fn(task, jobs, ids)`` with the
    semantics of ``builtins.map`` (results in order): the level-0 chunks (:func:`level0_task`),
    then each CP pass's cells (:func:`fit_cell_task`, :func:`refit_cell_task`). The tasks are
    top-level functions of a picklable :class:`BakeJob` and an int, deterministic, and write
    their results as checkpoint parts (workers must share the parts folder), so a pool of
    processes or a cluster's ``map`` gives the same bytes. Default: the level-0 chunks one after
    the other in this process (their kernel is parallel), the cells on a pool of threads
    (:func:`thread_map`; a one-pass bake's cells through :func:`ordered_stream`, which keeps the
    threads busy across rows of cells: the same bytes).

    ``level0``: a callable ``level0(y, centers (1, nx, 2), sigma) -> (1, nx, R, R)`` giving the
    images of level-0 row ``y`` instead of the direct P-NDF of ``normal_map`` (which then gives
    only the map's size and digest); its string attribute ``key`` names what it computes (it
    keys the checkpoints and is recorded as ``settings["level0"]``). Used for the colour
    channels of wave-optics NDFs (:mod:`prefilter.glints.wave.bake`).

    ``one_pass``: the images of each cell are fitted, given their ranks and refitted while they
    are in memory, and the coarser levels are filtered from them as they come
    (:func:`one_pass_stages`): no level is stored, so the temporary disk holds the filter's
    spilled rows and the coarser cells' images waiting for their task instead of the whole
    uncompressed pyramid. The rank multiplier of the ``"global"`` budget is estimated from the
    pass-1 errors of :data:`SAMPLE_CELLS` level-0 cells (the budget is then met on them, not
    exactly on the whole map); tasks: :func:`sample_cell_task`, :func:`cell_task` (level-0 cells
    return their images to the calling process, which runs the filter). A resumed one-pass
    bake skips the CP of the finished cells but computes the level-0 images again (the filter's
    state is not saved). Not with ``levels_dir`` or ``level_rank="level"`` (those bake in two
    passes).
    """
    from tqdm import tqdm

    t_start = time.perf_counter()
    nm = as_normal_map(normal_map)
    H, W = nm.shape[:2]
    rank = as_positive_int(rank, "rank")
    R = as_positive_int(ndf_res, "ndf_res")
    B = as_positive_int(block, "block")
    if R % B:
        raise PrefilterError(f"block: expected a divisor of ndf_res {R}, got {B}")
    S = as_support(support)
    sr = as_intrinsic_roughness(intrinsic_roughness)
    nt = as_ndf_truncation(ndf_truncation)
    ft = as_ndf_truncation(footprint_truncation, "footprint_truncation")
    if code_bits not in CODE_BITS:
        raise PrefilterError(f"code_bits: expected one of {CODE_BITS}, got {code_bits!r}")
    c_bits = code_bits if c_bits is None else c_bits
    if c_bits not in CODE_BITS:
        raise PrefilterError(f"c_bits: expected one of {CODE_BITS}, got {c_bits!r}")
    code_bytes, c_bytes = code_bits // 8, c_bits // 8
    if exact_from_level is not None:
        exact_from_level = as_positive_int(exact_from_level, "exact_from_level", lo=0)
    if exact_cell is not None:
        if exact_from_level is None:
            raise PrefilterError("exact_cell: only with exact_from_level (the cells of the "
                                 "levels stored exactly)")
        exact_cell = as_positive_int(exact_cell, "exact_cell")
    cell = as_positive_int(cell, "cell")
    pyr = plan(H, W, stride0, sigma0, max_levels)
    if cell % pyr.stride0 or H % cell or W % cell:
        raise PrefilterError(f"cell: expected a multiple of stride0 dividing {H}x{W}, got {cell}")
    nb = R // B
    max_rank = 3 * rank if max_rank is None else as_positive_int(max_rank, "max_rank")
    if max_rank < rank:
        raise PrefilterError(f"max_rank: expected at least rank = {rank}, got {max_rank}")
    if level_rank not in LEVEL_RANK:
        raise PrefilterError(f"level_rank: expected one of {LEVEL_RANK}, got {level_rank!r}")
    error_weight = check_scalar(error_weight, "error_weight", lo=0.0, hi=2.0)
    # pass 1 fits every group at rank // 2; the budget (rank per group on average, weighted by
    # bytes) is then spent where the predicted error drop per byte is largest
    base = max(1, rank // 2)
    candidates = sorted({min(max_rank, max(base, round(base * f))) for f in RANK_STEPS}
                        | {max_rank})
    # per rank: a, b (codes), c_scale (float32); + c_bytes per block (c)
    unit_bytes_group = 2 * B * code_bytes + 4
    settings = dict(rank=rank, ndf_res=R, block=B, support=S, intrinsic_roughness=sr,
                    stride0=pyr.stride0, sigma0=pyr.sigma0, cell=cell, converge=converge,
                    max_levels=max_levels, blank_tol=blank_tol, n_iter_max=n_iter_max, tol=tol,
                    seed=seed, layout=3, max_rank=max_rank, level_rank=level_rank)
    # files and checkpoints of the default cuts keep their old settings
    if nt != TRUNCATION:
        settings["ndf_truncation"] = nt
    if ft != TRUNCATION:
        settings["footprint_truncation"] = ft
    if code_bits != 8:
        settings["code_bits"] = code_bits
    if c_bits != code_bits:
        settings["c_bits"] = c_bits
    if exact_from_level is not None:
        settings["exact_from_level"] = exact_from_level
    if error_weight:
        settings["error_weight"] = error_weight
    if exact_cell is not None:
        settings["exact_cell"] = exact_cell
    if level0 is not None:
        settings["level0"] = str(level0.key)
    # a one-pass bake keeps no level (levels_dir asks for them) and has one rank multiplier
    one_pass = bool(one_pass) and levels_dir is None and level_rank != "level"
    if one_pass:
        settings["one_pass"] = True
    digest = map_digest(nm)
    # parts made by another version of the fit or budget rule are not resumed from
    ck = Checkpoints(out, dict(settings, map_sha1=digest, shape=[H, W], **code_versions(settings)))
    ndf_keys = ("ndf_res", "support", "intrinsic_roughness", "stride0", "sigma0", "converge",
                "max_levels") + tuple(k for k in ("ndf_truncation", "footprint_truncation",
                                                  "level0") if k in settings)
    lk = ck if levels_dir is None else Checkpoints(
        str(levels_dir).removesuffix(".parts"),
        dict({k: settings[k] for k in ndf_keys}, map_sha1=digest, shape=[H, W]))
    if progress:
        tqdm.write(f"glints bake: normal map {H}x{W} (sha1 {digest[:12]}) -> {out}\n"
                   f"  {pyr.shape(0)[0] * pyr.shape(0)[1]} level-0 NDF images of {R}^2 "
                   f"(the longest stage), up to {pyr.n_levels - 1} coarser levels, CP per "
                   f"{B}^2 block group at a mean rank {rank}; resumable parts in {ck.dir}",
                   file=sys.stderr)

    # 1. level 0, one row of cells per chunk (level0_task); the normal map is stored beside the
    # levels for tasks run in other processes
    map_file = lk.dir / "normal_map.npy"
    if not map_file.exists():
        with atomic_path(map_file, suffix=".npy") as tmp:
            np.save(tmp, nm)
    ny0, nx0 = pyr.shape(0)
    rows_per_chunk = cell // pyr.stride0
    n_chunks = ny0 // rows_per_chunk
    job = BakeJob(ck=ck, lk=lk, pyr=pyr, R=R, S=S, sr=sr, nt=nt, ft=ft, B=B,
                  blank_tol=blank_tol, base=base, n_iter_max=n_iter_max, tol=tol, seed=seed,
                  code_bits=code_bits, c_bits=c_bits, rows_per_chunk=rows_per_chunk,
                  exact_from_level=exact_from_level, cells=np.zeros((0, 5), np.int64),
                  level0=level0, rank=rank, level_rank=level_rank, error_weight=error_weight,
                  candidates=tuple(int(c) for c in candidates))
    if one_pass:
        k_sides = [exact_cell if job.exact(lv) and exact_cell is not None
                   else cell // pyr.stride0 for lv in range(pyr.n_levels)]
        t_cp = time.perf_counter()
        job = dataclasses.replace(job, cells=cell_bounds(pyr, k_sides))
        pyr, diffs, job = one_pass_stages(job, converge, k_sides, map_fn, progress)
        t_cp1 = t_cp2 = time.perf_counter()
    else:
        levels = [LevelFile(lk.dir / "level0.npy", (ny0, nx0, R, R))]
        pending = [ch for ch in range(n_chunks) if not lk.done(LEVEL0_CHUNK + ch)]
        with tqdm(total=ny0 * nx0, initial=(n_chunks - len(pending)) * rows_per_chunk * nx0,
                  desc="level 0 NDF images", unit="img", disable=not progress,
                  file=sys.stderr) as bar:
            # the level-0 kernel is itself parallel (and Numba's default threading layer is not
            # thread-safe): in this process the chunks run one after the other
            _run(map_fn or map, level0_task, job, pending, bar, step=rows_per_chunk * nx0)
        lk.save(LEVEL0_CHUNK + n_chunks, done=np.array(1))

        # 2. upper levels by filtering, streamed row by row (pyramid.next_level_rows), in column
        # strips when the filter's window of rows would exceed LEVEL_RING_BYTES (pyramid.strip_plan)
        diffs = []
        for lv in tqdm(range(1, pyr.n_levels), desc="coarser levels", unit="level",
                       disable=not progress, file=sys.stderr):
            key = LEVEL_CHUNK + lv
            below = levels[-1]
            arr = LevelFile(lk.dir / f"level{lv}.npy", pyr.shape(lv) + (R, R))
            if not lk.done(key):
                d2 = np.zeros(2)  # squared norms of (level - level below at its centres), level
                ny, nx = below.shape[:2]
                for xo0, xo1, start in strip_plan(nx, pyr.sigma0 / pyr.stride0,
                                                  strip_width(ny, R, LEVEL_RING_BYTES,
                                                              pyr.sigma0 / pyr.stride0)):
                    n_in = nx if xo1 - xo0 == nx // 2 else 2 * (xo1 - xo0 + 2 * xo0 - start)
                    off = xo0 - start // 2

                    def write_row(yo, images, arr=arr, below=below, d2=d2, xo0=xo0, xo1=xo1,
                                  off=off):
                        images = images[off:off + xo1 - xo0]
                        arr.write_columns(yo, xo0, images)
                        c = images.astype(np.float64).ravel()
                        d = c - below.read(2 * yo, 2 * yo + 1, 2 * xo0, 2 * xo1,
                                           step=2).astype(np.float64).ravel()
                        d2 += [np.dot(d, d), np.dot(c, c)]

                    next_level_rows(lambda y, below=below, start=start, n_in=n_in:
                                    below.read_periodic(y, start, n_in), (ny, n_in),
                                    pyr.sigma0 / pyr.stride0, write_row, (R, R))
                lk.save(key, diff=np.array(math.sqrt(d2[0]) / max(math.sqrt(d2[1]), 1e-300)))
            levels.append(arr)
            diffs.append(float(lk.load(key)["diff"]))
            if diffs[-1] < converge:
                break
        pyr = pyr.with_levels(len(levels))
        offsets = pyr.offsets

        # 3. compression per cell: a cell is a square of k x k footprint centres of ONE level
        # (k = cell / stride0, i.e. cell * 2^l texels at level l), so every group holds blocks
        # of footprints of the same size and about the same number of them at every level; a
        # level's fit is not dominated by the sharper, higher-energy blocks of the levels below.
        k_sides = [exact_cell if job.exact(lv) and exact_cell is not None else cell // pyr.stride0
                   for lv in range(pyr.n_levels)]
        job = dataclasses.replace(job, pyr=pyr, cells=cell_bounds(pyr, k_sides))
        n_cells = len(job.cells)

        def run(fn, chunk, desc):
            pending = [c for c in range(n_cells) if not ck.done(chunk + c)]
            with cpmod.single_threaded_blas(), \
                    tqdm(total=n_cells, initial=n_cells - len(pending), desc=desc, unit="cell",
                         disable=not progress, file=sys.stderr) as bar:
                _run(map_fn or thread_map, fn, job, pending, bar)

        t_cp = time.perf_counter()
        run(fit_cell_task, CELL_CHUNK, f"CP fit at rank {base}")
        t_cp1 = time.perf_counter()
        # allocation: predicted error drop per byte over all groups of the map (cp.allocate_ranks)
        if not ck.done(ALLOC_CHUNK):
            err2_all, counts = [], []
            for cid in range(n_cells):
                p1 = ck.load(CELL_CHUNK + cid)
                err2_all.append(p1["err2_g"])
                counts.append(np.diff(p1["rows"]))
            counts = np.concatenate(counts)
            unit = np.where(counts > 0, c_bytes * counts + unit_bytes_group, 0.0)
            group_level = np.repeat(job.cells[:, 0], nb * nb)
            # the budget is the fitted groups' (the exact ones were not fitted: no error to weigh)
            fitted = (group_level < exact_from_level if exact_from_level is not None
                      else np.ones(len(unit), bool))
            ranks_ = np.full(len(unit), EXACT, np.int64)
            if fitted.any():
                ranks_[fitted] = split_budget(np.concatenate(err2_all)[fitted], unit[fitted],
                                              group_level[fitted], rank, base, candidates,
                                              level_rank)
            ck.save(ALLOC_CHUNK, ranks=np.where(counts > 0, ranks_, 0).astype(np.int64))
        run(refit_cell_task, FINAL_CHUNK, "CP refit, encoding")
        t_cp2 = time.perf_counter()
    offsets = pyr.offsets
    n_cells = len(job.cells)

    # 4. assemble
    parts = {k: [] for k in ("ranks", "a", "b", "c", "c_scale")}
    block_index = np.full((pyr.n_images, nb, nb), -1, np.int32)
    image_cell = np.zeros(pyr.n_images, np.int32)
    group_rows = [np.zeros(1, np.int64)]
    err2 = np.zeros(pyr.n_levels)
    norm2 = np.zeros(pyr.n_levels)
    kept, masses, k0, err2_groups = 0, [], 0, []
    fit2 = 0.0
    for cid in range(n_cells):
        p1, part = ck.load(CELL_CHUNK + cid), ck.load(FINAL_CHUNK + cid)
        lv, y0, y1, x0, x1 = (int(v) for v in job.cells[cid])
        iy, ix = np.meshgrid(np.arange(y0, y1), np.arange(x0, x1), indexing="ij")
        flat = offsets[lv] + iy.ravel() * pyr.shape(lv)[1] + ix.ravel()
        loc = p1["local"]
        block_index[flat] = np.where(loc >= 0, loc + k0, -1)
        image_cell[flat] = cid
        group_rows.append(p1["rows"][1:] + k0)
        k0 += int(p1["rows"][-1])
        for k in parts:
            parts[k].append(part[k])
        err2[lv] += float(part["err2_g"].sum() + p1["blank2"])
        err2_groups.append(part["err2_g"])
        # parts without the fit's error: the stored one bounds it
        fit2 += float(part.get("fit2_g", part["err2_g"]).sum() + p1["blank2"])
        norm2[lv] += float(p1["norm2"])
        kept += int(p1["kept"])
        masses.append(p1["mass"])
    raw_bytes = pyr.n_images * R * R * 4
    elapsed = time.perf_counter() - t_start
    per_level = np.sqrt(err2 / np.maximum(norm2, 1e-300))
    enc = {k: np.concatenate(v) for k, v in parts.items()}
    width = int(enc["ranks"].max(initial=0))
    on_disk = dict(enc, block_mask=pack_mask(block_index >= 0), image_cell=image_cell)
    # only saved: the float arrays are never decoded here
    gm = GlintsMap(header={}, A=None, Bp=None, C=None, block_index=block_index,
                   image_cell=image_cell, stored_bytes=sum(v.nbytes for v in on_disk.values()),
                   ranks=enc["ranks"].astype(np.int32),
                   codes=dict(enc, group_rows=np.concatenate(group_rows)))
    live = enc["ranks"] > 0
    unit = c_bytes * np.diff(np.concatenate(group_rows)) + unit_bytes_group
    e2g = np.concatenate(err2_groups)
    top = np.sort(e2g)[::-1]
    summary = dict(
        raw_bytes=int(raw_bytes), compressed_bytes=gm.compressed_bytes,
        ratio=gm.compressed_bytes / raw_bytes,
        rel_l2_error=float(np.sqrt(err2.sum() / norm2.sum())),
        rel_l2_error_fit=float(np.sqrt(fit2 / norm2.sum())),
        rel_l2_error_per_level=[float(x) for x in per_level], level_differences=diffs,
        blocks_kept=kept, blocks_total=int(pyr.n_images * nb * nb),
        mean_mass_in_support=float(np.concatenate(masses).mean()), n_images=pyr.n_images,
        mean_rank=float(enc["ranks"][live].mean()) if live.any() else 0.0,
        mean_rank_per_byte=float(unit[live] @ enc["ranks"][live] / max(unit[live].sum(), 1)),
        max_rank=width,
        rank_histogram={int(r): int(n) for r, n in zip(*np.unique(enc["ranks"][live],
                                                                 return_counts=True))},
        bytes={k: int(v.nbytes) for k, v in on_disk.items()},
        err2_share_top10pct_groups=float(top[:max(1, live.sum() // 10)].sum()
                                         / max(top.sum(), 1e-300)),
        seconds=elapsed, seconds_cp=[t_cp1 - t_cp, t_cp2 - t_cp1],  # pass 1, pass 2
    )
    # the wall time stays out of the file: the same bake must give the same bytes
    gm.header = dict(pyramid=pyr.to_dict(), ndf=dict(resolution=R, support=S, block=B, rank=width,
                                                     intrinsic_roughness=sr, sigma_h=SIGMA_H),
                     settings=settings, map_sha1=digest,
                     summary=significant({k: v for k, v in summary.items()
                                          if not k.startswith("seconds")}))
    save(out, gm, enc)
    if not keep_parts:
        ck.clear()
    if progress:
        size = Path(out).stat().st_size
        tqdm.write(f"glints bake: {time.perf_counter() - t_start:.0f} s, "
                   + (f"{size / 2**20:.1f} MiB" if size >= 2**20 else f"{size / 2**10:.1f} KiB")
                   + f" -> {out}", file=sys.stderr)
    return summary
