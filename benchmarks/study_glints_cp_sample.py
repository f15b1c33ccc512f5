"""Glint CP on sampled cells: error per group vs rank, rank allocation, 8-bit rounding.

    python benchmarks/study_glints_cp.py --size 512 --maps gaussian --ranks 16 --cache C
    python benchmarks/study_glints_cp_sample.py --levels C/levels_gaussian512

The numbers behind the layout-3 design in docs/glints.md: on a few random cells of each of the
first pyramid levels (default 4 of level 0, 2 of level 1, 1 of level 2, weighted by their
level's number of cells), every group is fitted at ranks 8..48 and the script prints (1) the
error at a uniform rank, (2) how concentrated the squared error is over the groups, (3) the
slope ``p`` of ``log e^2`` vs ``log r``, (4) the error of the allocation that ``bake`` makes
(predicted from rank-8 errors, ``cp.allocate_ranks``) and of the best allocation from the
measured curves, at the same bytes, and (5) the error added by rounding the factors.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from prefilter.glints import cp as cpmod

RANKS = (8, 12, 16, 20, 24, 32, 48)


def sample_cells(levels, per_level, k=8, block=16, blank_tol=1e-4, seed=1):
    rng = np.random.default_rng(seed)
    cells = []
    for lv, n in enumerate(per_level):
        L = np.load(Path(levels) / f"level{lv}.npy", mmap_mode="r")
        ncy, ncx = L.shape[0] // k, L.shape[1] // k
        for c in rng.choice(ncy * ncx, n, replace=False):
            cy, cx = divmod(int(c), ncx)
            imgs = np.asarray(L[cy * k:(cy + 1) * k, cx * k:(cx + 1) * k],
                              dtype=np.float64).reshape(-1, L.shape[2], L.shape[3])
            blocks = cpmod.cut_blocks(imgs, block)
            blank = cpmod.blank_mask(blocks, imgs.max(axis=(1, 2)), blank_tol)
            nb = blank.shape[1]
            for bi in range(nb):
                for bj in range(nb):
                    keep = np.flatnonzero(~blank[:, bi, bj])
                    if len(keep):
                        t = np.ascontiguousarray(blocks[keep, bi, bj].transpose(1, 2, 0))
                        cells.append((lv, ncy * ncx / n, t))
    return cells


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--levels", required=True, help="a bake's levels_dir (level<l>.npy files)")
    ap.add_argument("--per-level", default="4,2,1")
    ap.add_argument("--budget", type=float, default=16.0)
    a = ap.parse_args(argv)
    levels = a.levels if a.levels.endswith(".parts") else a.levels + ".parts"
    groups = sample_cells(levels, [int(x) for x in a.per_level.split(",")])
    w = np.array([g[1] for g in groups])
    T = [g[2] for g in groups]
    n2 = np.array([np.sum(t * t) for t in T])
    K = np.array([t.shape[2] for t in T])
    unit = K + 2 * T[0].shape[0] + 4.0
    E, fits = {}, {}
    with cpmod.single_threaded_blas():
        for r in RANKS:
            out = cpmod.nn_cp_batch(T, r, n_iter_max=50, tol=1e-4, seed=0)
            E[r] = np.array([o[3] ** 2 for o in out]) * n2
            fits[r] = out
    tot = float(w @ n2)
    print(f"{len(T)} groups; relative L2 error at a uniform rank:")
    print("  " + ", ".join(f"{r}: {100 * np.sqrt(w @ E[r] / tot):.2f} %" for r in RANKS))
    e16 = np.sort(w * E[16])[::-1]
    cs = np.cumsum(e16) / e16.sum()
    print("share of the squared error at rank 16 in the worst groups: " + ", ".join(
        f"{int(f * 100)} %: {100 * cs[int(f * len(cs))]:.1f} %" for f in (0.05, 0.1, 0.2, 0.5)))
    big = w * E[16] >= np.percentile(w * E[16], 70)
    p = np.log(E[8] / np.maximum(E[32], 1e-300)) / np.log(4)
    print(f"slope p of log e^2 vs log r (ranks 8-32), 30 % largest-error groups: median "
          f"{np.median(p[big]):.2f}, quartiles {np.percentile(p[big], 25):.2f} / "
          f"{np.percentile(p[big], 75):.2f}")
    budget = a.budget * float(w @ unit)
    # the bake's allocation: predicted from the rank-8 errors (weights: cells not sampled)
    r_pred = cpmod.allocate_ranks(w * E[8], w * unit, 8, RANKS, budget)
    got = sum(w[g] * E[int(r)][g] for g, r in enumerate(r_pred))
    # the best allocation from the measured curves (convex hull of each group's points)
    def measured(log_lam):
        cost = np.stack([w * E[r] + np.exp(log_lam) * w * unit * r for r in RANKS])
        j = np.argmin(cost, axis=0)
        return j, float(np.sum(w * unit * np.array(RANKS)[j]))

    lo, hi = -120.0, 120.0  # bisection on log lambda: bytes used fall as lambda grows
    for _ in range(200):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if measured(mid)[1] > budget else (lo, mid)
    choice = measured(hi)[0]
    best = sum(w[g] * E[RANKS[j]][g] for g, j in enumerate(choice))
    uniform = 100 * np.sqrt(w @ E[int(a.budget)] / tot) if int(a.budget) in E else np.nan
    print(f"budget {a.budget:g}: predicted allocation {100 * np.sqrt(got / tot):.2f} %, best "
          f"from the measured curves {100 * np.sqrt(best / tot):.2f} %, uniform {uniform:.2f} %")
    # rounding of the rank-24 factors (store.encode's 8-bit codes and alternatives)
    def rel(transform):
        e2 = 0.0
        for wg, t, (fa, fb, fc, _) in zip(w, T, fits[24]):
            d = cpmod.reconstruct(*transform(fa, fb, fc)) - t
            e2 += wg * np.sum(d * d)
        return 100 * np.sqrt(e2 / tot)

    def q_ab(f, bits=8):
        m = f.max(axis=0, keepdims=True)
        q = np.rint(np.divide(f, m, out=np.zeros_like(f), where=m > 0) * (2**bits - 1))
        s = q.sum(axis=0, keepdims=True)
        return np.divide(q, s, out=np.zeros_like(q), where=s > 0)

    def q_c(c, bits=8, sqrt=False):
        m = c.max(axis=0, keepdims=True)
        x = np.divide(c, m, out=np.zeros_like(c), where=m > 0)
        L = 2**bits - 1
        return ((np.rint(np.sqrt(x) * L) / L) ** 2 if sqrt else np.rint(x * L) / L) * m

    def f16(x):
        return x.astype(np.float16).astype(np.float64)

    def f16_c(c):  # layout 2: float16 in units of the component's maximum
        m = c.max(axis=0, keepdims=True)
        return f16(np.divide(c, m, out=np.zeros_like(c), where=m > 0)) * m

    variants = (
        ("float64", lambda a_, b_, c_: (a_, b_, c_)),
        ("float16", lambda a_, b_, c_: (f16(a_), f16(b_), f16_c(c_))),
        ("8-bit a, b, c", lambda a_, b_, c_: (q_ab(a_), q_ab(b_), q_c(c_))),
        ("8-bit, sqrt code for c", lambda a_, b_, c_: (q_ab(a_), q_ab(b_), q_c(c_, 8, True))),
        ("6-bit a, b", lambda a_, b_, c_: (q_ab(a_, 6), q_ab(b_, 6), q_c(c_))),
        ("6-bit c", lambda a_, b_, c_: (q_ab(a_), q_ab(b_), q_c(c_, 6))),
    )
    print("rank 24, relative L2 error with the factors rounded: "
          + ", ".join(f"{name} {rel(fn):.3f} %" for name, fn in variants))

if __name__ == "__main__":
    main()
