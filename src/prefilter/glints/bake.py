"""Bake a normal map into a compressed NDF pyramid (glints paper, secs. 4.1-4.2).

Stages, each resumable through :class:`prefilter._io.Checkpoints` (``<out>.parts/``):

1. level 0 NDF images by the direct P-NDF, one row of spatial cells per chunk, into a float32
   memory-mapped array;
2. levels 1.. by exact Gaussian filtering of the level below (``pyramid.next_level``), until a level
   differs from the one below by less than ``converge`` (relative L2) or the top is reached;
3. per cell (``k x k`` footprint centres of ONE level, ``k = cell / stride0``: ``cell * 2^l``
   texels at level ``l``): blocks, blank blocks dropped, one ``(B, B, K)`` tensor per angular
   block position ``(bi, bj)``, non-negative CP of all of the cell's tensors in one batch, factors
   encoded in float16 (``store.encode``) and the error measured on what the loader decodes;
4. the final ``.npz`` written atomically, then the parts removed.

Grouping deviates from the paper (which mixes all levels' blocks of a spatial cell in one tensor):
blocks at the same ``(bi, bj)`` of overlapping footprints are alike, and a group of one level is
not fit at the expense of the others (with all levels in one group, the sharp, high-energy level-0
blocks dominated and the upper levels had ~10 % error). Measurements in docs/glints.md.
"""

from __future__ import annotations

import hashlib
import os
import time
from concurrent.futures import ThreadPoolExecutor

import numpy as np

from prefilter._io import Checkpoints
from prefilter._validate import as_positive_int
from prefilter.errors import PrefilterError
from prefilter.glints import cp as cpmod
from prefilter.glints.pndf import (DEFAULT_ROUGHNESS, SIGMA_H, _as_roughness, _as_support,
                                   as_normal_map, elements, pndf_image)
from prefilter.glints.pyramid import level_difference, next_level, plan
from prefilter.glints.store import GlintsMap, decode, encode, save

LEVEL0_CHUNK = 0
LEVEL_CHUNK = 10_000
CELL_CHUNK = 100_000


def _memmap(path, shape):
    """The float32 array at ``path``, reopened if present (partial results of a killed bake are
    kept; which chunks are valid is recorded by the checkpoints), else created."""
    if path.exists():
        try:
            arr = np.load(path, mmap_mode="r+")
            if arr.shape == tuple(shape) and arr.dtype == np.float32:
                return arr
        except (ValueError, OSError, EOFError):
            pass  # killed while the file was being created: start it again
    return np.lib.format.open_memmap(path, mode="w+", dtype=np.float32, shape=shape)


def bake(normal_map, out, *, rank: int = 16, ndf_res: int = 128, block: int = 16,
         support: float = 0.5, intrinsic_roughness: float = DEFAULT_ROUGHNESS, stride0: int = 4,
         sigma0: float | None = None, cell: int = 32, converge: float = 0.01,
         max_levels: int | None = None, blank_tol: float = 1e-4, n_iter_max: int = 50,
         tol: float = 1e-4, seed: int = 0, progress: bool = True, keep_parts: bool = False,
         levels_dir=None) -> dict:
    """Bake ``normal_map (H, W, 3)`` into ``out`` (.npz); returns the summary dict.

    Parameters mirror ``prefilter bake glints``; ``support`` is the half-width of the NDF images in
    ``s`` (default 0.5: 128 pixels at the pitch of a 256-pixel image of the whole disk).
    ``levels_dir``: keep the uncompressed pyramid there (keyed by the NDF settings only) so bakes
    at several ranks share it; it is not removed at the end.
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
    S = _as_support(support)
    sr = _as_roughness(intrinsic_roughness)
    cell = as_positive_int(cell, "cell")
    pyr = plan(H, W, stride0, sigma0, max_levels)
    if cell % pyr.stride0 or H % cell or W % cell:
        raise PrefilterError(f"cell: expected a multiple of stride0 dividing {H}x{W}, got {cell}")
    nb = R // B
    settings = dict(rank=rank, ndf_res=R, block=B, support=S, intrinsic_roughness=sr,
                    stride0=pyr.stride0, sigma0=pyr.sigma0, cell=cell, converge=converge,
                    max_levels=max_levels, blank_tol=blank_tol, n_iter_max=n_iter_max, tol=tol,
                    seed=seed, layout=2)
    digest = hashlib.sha1(np.ascontiguousarray(nm, dtype=np.float64).tobytes()).hexdigest()
    ck = Checkpoints(out, dict(settings, map_sha1=digest, shape=[H, W]))
    ndf_keys = ("ndf_res", "support", "intrinsic_roughness", "stride0", "sigma0", "converge",
                "max_levels")
    lk = ck if levels_dir is None else Checkpoints(
        str(levels_dir).removesuffix(".parts"),
        dict({k: settings[k] for k in ndf_keys}, map_sha1=digest, shape=[H, W]))
    el = elements(nm)

    # 1. level 0, one row of cells per chunk
    ny0, nx0 = pyr.shape(0)
    rows_per_chunk = cell // pyr.stride0
    n_chunks = ny0 // rows_per_chunk
    levels = [_memmap(lk.dir / "level0.npy", (ny0, nx0, R, R))]
    centers0 = pyr.centers(0)
    for ch in tqdm(range(n_chunks), desc="level 0 NDF images", disable=not progress):
        if lk.done(LEVEL0_CHUNK + ch):
            continue
        rows = slice(ch * rows_per_chunk, (ch + 1) * rows_per_chunk)
        levels[0][rows] = pndf_image(nm, centers0[rows], pyr.sigma(0), R, S, sr, elements_=el)
        levels[0].flush()
        lk.save(LEVEL0_CHUNK + ch, done=np.array(1))
    lk.save(LEVEL0_CHUNK + n_chunks, done=np.array(1))

    # 2. upper levels by filtering
    diffs = []
    for lv in range(1, pyr.n_levels):
        key = LEVEL_CHUNK + lv
        arr = _memmap(lk.dir / f"level{lv}.npy", pyr.shape(lv) + (R, R))
        if not lk.done(key):
            next_level(levels[-1], pyr.sigma0 / pyr.stride0, out=arr)
            arr.flush()
            lk.save(key, diff=np.array(level_difference(levels[-1], arr)))
        levels.append(arr)
        diffs.append(float(lk.load(key)["diff"]))
        if diffs[-1] < converge:
            break
    pyr = pyr.with_levels(len(levels))
    offsets = pyr.offsets

    # 3. compression per cell: a cell is a square of k x k footprint centres of ONE level
    # (k = cell / stride0, i.e. cell * 2^l texels at level l), so every group holds blocks of
    # footprints of the same size and about the same number of them at every level; a level's fit
    # is not dominated by the sharper, higher-energy blocks of the levels below it.
    k_side = cell // pyr.stride0
    members = []  # (level, iy, ix) per cell
    for lv in range(pyr.n_levels):
        ny, nx = pyr.shape(lv)
        ncy, ncx = max(1, ny // k_side), max(1, nx // k_side)
        iy, ix = np.meshgrid(np.arange(ny), np.arange(nx), indexing="ij")
        cid = np.minimum(iy // k_side, ncy - 1) * ncx + np.minimum(ix // k_side, ncx - 1)
        order = np.argsort(cid.ravel(), kind="stable")
        bounds = np.searchsorted(cid.ravel()[order], np.arange(ncy * ncx + 1))
        for c0 in range(ncy * ncx):
            sel = order[bounds[c0]:bounds[c0 + 1]]
            members.append([(lv, int(y), int(x)) for y, x in zip(iy.ravel()[sel], ix.ravel()[sel])])
    n_cells = len(members)

    def compress_cell(cid):
        mem = members[cid]
        lv = mem[0][0]
        iy = np.array([m[1] for m in mem])
        ix = np.array([m[2] for m in mem])
        imgs = np.asarray(levels[lv][iy.min():iy.max() + 1, ix.min():ix.max() + 1],
                          dtype=np.float64)[iy - iy.min(), ix - ix.min()]
        blocks = cpmod.cut_blocks(imgs, B)  # (n, nb, nb, B, B)
        blank = cpmod.blank_mask(blocks, imgs.max(axis=(1, 2)), blank_tol)
        tensors, where = [], []
        for bi in range(nb):
            for bj in range(nb):
                keep = np.flatnonzero(~blank[:, bi, bj])
                where.append(keep)
                tensors.append(np.ascontiguousarray(blocks[keep, bi, bj].transpose(1, 2, 0)))
        live = [g for g, t in enumerate(tensors) if t.shape[2] > 0]
        res = dict(zip(live, cpmod.nn_cp_batch([tensors[g] for g in live], rank,
                                               n_iter_max=n_iter_max, tol=tol, seed=seed + cid)))
        a = np.zeros((nb * nb, rank, B))
        b = np.zeros_like(a)
        cs, local = [], np.full(blank.shape, -1, np.int32)
        rows = np.zeros(nb * nb + 1, np.int64)
        for g in range(nb * nb):
            if g in res:
                ag, bg, cg, _ = res[g]
                bi, bj = divmod(g, nb)
                a[g], b[g] = ag.T, bg.T
                local[where[g], bi, bj] = rows[g] + np.arange(len(where[g]), dtype=np.int32)
                cs.append(cg)
            rows[g + 1] = rows[g] + (len(where[g]) if g in res else 0)
        c = np.concatenate(cs) if cs else np.zeros((0, rank))
        enc = encode(a, b, c, rows)
        # the error of what is stored: the float16 factors decoded as the loader does
        A_, B_, C_ = decode(**enc)
        a_s, b_s = np.diff(A_.astype(np.float64), axis=2), np.diff(B_.astype(np.float64), axis=2)
        err2 = np.einsum("nabij,nabij->", blocks, blocks * blank[..., None, None])
        for g in live:
            bi, bj = divmod(g, nb)
            rec = cpmod.reconstruct(a_s[g].T, b_s[g].T, C_[rows[g]:rows[g + 1]].astype(np.float64))
            d = rec - tensors[g]
            err2 += np.einsum("ijk,ijk->", d, d)
        mass = imgs.sum(axis=(1, 2)) * (2 * S / R) ** 2
        ck.save(CELL_CHUNK + cid, **enc, local=local, err2=np.array(err2),
                norm2=np.array(np.einsum("nij,nij->", imgs, imgs)), kept=np.array((~blank).sum()),
                mass=mass)
        return cid

    pending = [cid for cid in range(n_cells) if not ck.done(CELL_CHUNK + cid)]
    workers = max(1, min(os.cpu_count() or 1, len(pending)))
    with cpmod.single_threaded_blas(), ThreadPoolExecutor(workers) as pool, \
            tqdm(total=n_cells, initial=n_cells - len(pending), desc="CP compression",
                 disable=not progress) as bar:
        for _ in pool.map(compress_cell, pending):
            bar.update(1)

    # 4. assemble
    parts = {k: [] for k in ("a", "b", "c", "c_scale")}
    block_index = np.full((pyr.n_images, nb, nb), -1, np.int32)
    image_cell = np.zeros(pyr.n_images, np.int32)
    group_rows = [np.zeros(1, np.int64)]
    err2 = np.zeros(pyr.n_levels)
    norm2 = np.zeros(pyr.n_levels)
    kept, masses, k0 = 0, [], 0
    for cid in range(n_cells):
        part = ck.load(CELL_CHUNK + cid)
        lv = members[cid][0][0]
        flat = np.array([offsets[lv] + iy * pyr.shape(lv)[1] + ix for _, iy, ix in members[cid]],
                        dtype=np.int64)
        loc = part["local"]
        block_index[flat] = np.where(loc >= 0, loc + k0, -1)
        image_cell[flat] = cid
        group_rows.append(part["group_rows"][1:] + k0)
        k0 += part["c"].shape[0]
        for k in parts:
            parts[k].append(part[k])
        err2[lv] += float(part["err2"])
        norm2[lv] += float(part["norm2"])
        kept += int(part["kept"])
        masses.append(part["mass"])
    raw_bytes = pyr.n_images * R * R * 4
    elapsed = time.perf_counter() - t_start
    per_level = np.sqrt(err2 / np.maximum(norm2, 1e-300))
    enc = {k: np.concatenate(v) for k, v in parts.items()}
    enc["group_rows"] = np.concatenate(group_rows)
    A, Bp, C = decode(**enc)
    gm = GlintsMap(header={}, A=A, Bp=Bp, C=C, block_index=block_index, image_cell=image_cell,
                   stored_bytes=sum(v.nbytes for v in enc.values()) + block_index.nbytes
                   + image_cell.nbytes)
    summary = dict(
        raw_bytes=int(raw_bytes), compressed_bytes=gm.compressed_bytes,
        ratio=gm.compressed_bytes / raw_bytes,
        rel_l2_error=float(np.sqrt(err2.sum() / norm2.sum())),
        rel_l2_error_per_level=[float(x) for x in per_level], level_differences=diffs,
        blocks_kept=kept, blocks_total=int(pyr.n_images * nb * nb),
        mean_mass_in_support=float(np.concatenate(masses).mean()), n_images=pyr.n_images,
        seconds=elapsed,
    )
    # the wall time stays out of the file: the same bake must give the same bytes
    gm.header = dict(pyramid=pyr.to_dict(), ndf=dict(resolution=R, support=S, block=B, rank=rank,
                                                     intrinsic_roughness=sr, sigma_h=SIGMA_H),
                     settings=settings, map_sha1=digest,
                     summary={k: v for k, v in summary.items() if k != "seconds"})
    save(out, gm, enc)
    if not keep_parts:
        ck.clear()
    return summary
