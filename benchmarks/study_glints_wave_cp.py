"""Joint vs separate CP compression of the colour channels of a wave-optics NDF pyramid.

Reads the uncompressed per-channel pyramids a bake kept (``bake_wave(..., levels_dir=L)``:
``L.R.parts/level*.npy`` ...), samples cells of each level (the bake's grouping: ``k x k``
footprint centres of one level and one angular block position per group) and fits, per group,

* separate: one non-negative CP per channel, ``(B, B, K_c)`` at rank ``r`` (the bake's layout);
* joint: one CP of ``(B, B, K_R + K_G + K_B)`` (the channel in the image mode: shared ``a``,
  ``b``), at the rank whose bytes match the separate fits' (8-bit codes: ``2 B + K`` bytes and a
  float32 scale per component).

Prints the relative L2 error of both (blank blocks counted as error) and their bytes.

    python benchmarks/study_glints_wave_cp.py /tmp/wavework/b512/levels --ranks 8,16
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from prefilter.glints import cp as cpmod
from prefilter.glints.wave.bake import CHANNELS


def level_files(levels):
    out = []
    lv = 0
    while True:
        try:
            arrs = [np.load(f"{levels}.{c}.parts/level{lv}.npy", mmap_mode="r") for c in CHANNELS]
        except FileNotFoundError:
            return out
        out.append(arrs)
        lv += 1


def groups_of_cell(arrs, y0, x0, k, B, blank_tol=1e-4):
    """Per channel: the cell's blocks ``(K, nb, nb, B, B)`` and blank masks."""
    blocks, blank = [], []
    for a in arrs:
        imgs = np.asarray(a[y0:y0 + k, x0:x0 + k], np.float64).reshape(-1, *a.shape[2:])
        b = cpmod.cut_blocks(imgs, B)
        blocks.append(b)
        blank.append(cpmod.blank_mask(b, imgs.max(axis=(1, 2)), blank_tol))
    return blocks, blank


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("levels")
    ap.add_argument("--ranks", default="8,16")
    ap.add_argument("--block", type=int, default=16)
    ap.add_argument("--cell", type=int, default=8, help="footprint centres per cell side")
    ap.add_argument("--cells-per-level", type=int, default=6)
    ap.add_argument("--iters", type=int, default=50)
    ap.add_argument("--seed", type=int, default=0)
    a = ap.parse_args(argv)
    B, k = a.block, a.cell
    rng = np.random.default_rng(a.seed)
    files = level_files(a.levels)
    print(f"{len(files)} levels, level 0 {files[0][0].shape}")
    for rank in [int(r) for r in a.ranks.split(",")]:
        tot = {"separate": [0.0, 0.0, 0], "joint": [0.0, 0.0, 0]}  # err2, norm2, bytes
        t_sep = t_joint = 0.0
        for arrs in files:
            ny, nx = arrs[0].shape[:2]
            kk = min(k, ny, nx)
            cells = [(int(rng.integers(0, ny // kk)) * kk, int(rng.integers(0, nx // kk)) * kk)
                     for _ in range(min(a.cells_per_level, (ny // kk) * (nx // kk)))]
            for y0, x0 in cells:
                blocks, blank = groups_of_cell(arrs, y0, x0, kk, B)
                nb = blocks[0].shape[1]
                sep_t, joint_t = [], []
                for bi in range(nb):
                    for bj in range(nb):
                        per = []
                        for c in range(3):
                            keep = np.flatnonzero(~blank[c][:, bi, bj])
                            # blank blocks are dropped: their energy is error in both layouts
                            drop = blocks[c][blank[c][:, bi, bj], bi, bj]
                            for key in tot:
                                tot[key][0] += float((drop ** 2).sum())
                            full = blocks[c][:, bi, bj]
                            for key in tot:
                                tot[key][1] += float((full ** 2).sum())
                            per.append(np.ascontiguousarray(
                                blocks[c][keep, bi, bj].transpose(1, 2, 0)))
                        sep_t.extend(t for t in per if t.shape[2])
                        if sum(t.shape[2] for t in per):
                            joint_t.append(np.concatenate(per, axis=2))
                # bytes of the separate fits at rank r; the joint rank with the same bytes
                sep_bytes = sum((2 * B + t.shape[2]) * rank + 4 * rank for t in sep_t)
                joint_unit = sum(2 * B + t.shape[2] + 4 for t in joint_t)
                rj = max(1, round(sep_bytes / max(joint_unit, 1)))
                t0 = time.perf_counter()
                for t, (_, _, _, e) in zip(sep_t, cpmod.nn_cp_batch(
                        sep_t, rank, n_iter_max=a.iters, seed=a.seed)):
                    tot["separate"][0] += e ** 2 * float((t ** 2).sum())
                t_sep += time.perf_counter() - t0
                t0 = time.perf_counter()
                for t, (_, _, _, e) in zip(joint_t, cpmod.nn_cp_batch(
                        joint_t, rj, n_iter_max=a.iters, seed=a.seed)):
                    tot["joint"][0] += e ** 2 * float((t ** 2).sum())
                t_joint += time.perf_counter() - t0
                tot["separate"][2] += sep_bytes
                tot["joint"][2] += rj * joint_unit
        for key, (e2, n2, nbytes) in tot.items():
            print(f"rank {rank:3d} {key:8s}: rel. L2 {100 * np.sqrt(e2 / n2):6.2f} %, "
                  f"{nbytes / 2**20:7.2f} MiB on the sampled cells, CP "
                  f"{t_sep if key == 'separate' else t_joint:6.1f} s")


if __name__ == "__main__":
    main()
