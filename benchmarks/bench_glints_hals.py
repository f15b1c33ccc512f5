"""HALS column sweeps (``prefilter.glints.cp.HALS_SWEEPS``) against one sweep per iteration.

    python benchmarks/bench_glints_hals.py

One level-0 cell (8 x 8 footprints, rows/columns 8-15 of centres) of the docs example's
256^2 gaussian map, its NDF images at the render bake's settings
(:data:`prefilter.glints.bake.BAKE_SETTINGS`), cut into the bake's block groups; each group
fitted at rank 24 (half the render's budget: the first pass) by ``nn_cp_batch`` on one BLAS
thread. Prints the relative L2 error over all groups and the fit time for each
(sweeps, iterations); the ratios within one run are what to compare (the machine is shared).
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from bench_glints_cold import docs_example_maps  # noqa: E402

from prefilter.glints import cp as cpmod  # noqa: E402
from prefilter.glints.bake import bake_settings  # noqa: E402
from prefilter.glints.pndf import pndf_image  # noqa: E402
from prefilter.glints.pyramid import plan  # noqa: E402


def cell_tensors():
    """The kept-block tensors ``(B, B, K_g)`` of the cell's groups."""
    nm = docs_example_maps()["gaussian"]
    st = bake_settings(nm.shape)
    pyr = plan(nm.shape[0], nm.shape[1], st["stride0"], None, None)
    imgs = pndf_image(nm, pyr.centers(0)[8:16, 8:16], pyr.sigma(0), st["ndf_res"], st["support"],
                      st["intrinsic_roughness"], ndf_truncation=st["ndf_truncation"],
                      footprint_truncation=st["footprint_truncation"]).reshape(
                          -1, st["ndf_res"], st["ndf_res"])
    B = st["block"]
    blocks = cpmod.cut_blocks(imgs, B)
    blank = cpmod.blank_mask(blocks, imgs.max(axis=(1, 2)), st["blank_tol"])
    nb = st["ndf_res"] // B
    out = []
    for bi in range(nb):
        for bj in range(nb):
            keep = np.flatnonzero(~blank[:, bi, bj])
            if len(keep):
                out.append(np.ascontiguousarray(blocks[keep, bi, bj].transpose(1, 2, 0)))
    return out


def main() -> None:
    tensors = cell_tensors()
    w = np.array([np.sum(t * t) for t in tensors])
    print(f"{len(tensors)} groups, rank 24")
    default = cpmod.HALS_SWEEPS
    with cpmod.single_threaded_blas():
        cpmod.nn_cp_batch(tensors[:2], 24, n_iter_max=2, tol=0.0)  # compile
        for sweeps, iters in ((1, 50), (default, 20), (default, 30), (default, 50)):
            cpmod.HALS_SWEEPS = sweeps
            t0 = time.perf_counter()
            fits = cpmod.nn_cp_batch(tensors, 24, n_iter_max=iters, tol=0.0, seed=0)
            dt = time.perf_counter() - t0
            e = np.array([f[3] for f in fits])
            print(f"sweeps {sweeps}, {iters} iterations: relative L2 "
                  f"{100 * np.sqrt(np.sum(e**2 * w) / w.sum()):.2f} %, {dt:.2f} s")
    cpmod.HALS_SWEEPS = default


if __name__ == "__main__":
    main()
