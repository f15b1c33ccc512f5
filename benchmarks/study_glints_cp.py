"""Glint CP compression: storage ratio and reconstruction error per map and rank budget.

    python benchmarks/study_glints_cp.py                        # 4 maps x ranks 8/16/32/64, 128^2
    python benchmarks/study_glints_cp.py --size 512 --maps gaussian --ranks 16
    python benchmarks/study_glints_cp.py --max-rank-factor 2    # max rank 2 x rank (default 3)
    python benchmarks/study_glints_cp.py --queries A.npz B.npz  # query time of baked maps

Each row is one `prefilter.glints.bake.bake` with the defaults except the rank (the mean rank
budget; groups get ranks from rank/2 to max-rank by predicted error drop per byte). The
uncompressed pyramid of a map is computed once and shared by its ranks (``--cache``), so the
times are the compression only (plus the assembly). Ratio = bytes of the stored arrays / float32
pyramid; error = relative L2 over all NDF images of the pyramid, on the decoded 8-bit factors.
"""

from __future__ import annotations

import argparse
import json
import tempfile
import time
from pathlib import Path

from prefilter.glints.bake import bake
from prefilter.texture.procedural import normal_map


def compare_queries(paths, n=50_000, widths=(4, 64, 512), repeat=5):
    """Point and range query time (us per query, best of ``repeat``, maps interleaved) of baked
    maps: the cost follows the in-memory rank ``gm.rank`` (the largest group rank)."""
    import numpy as np

    from prefilter.glints.query import point, range_mean
    from prefilter.glints.store import load

    maps = {p: load(p) for p in paths}
    for p, gm in maps.items():
        print(f"{p}: version {gm.header['version']}, in-memory rank {gm.rank}, "
              f"C {gm.C.nbytes / 2**20:.0f} MiB, A + Bp {2 * gm.A.nbytes / 2**20:.0f} MiB")
    rng = np.random.default_rng(0)
    for width in widths:
        c = rng.uniform(0, 512, (n, 2))
        s = rng.uniform(-0.3, 0.3, (n, 2))
        for name, fn in (("point", lambda gm: point(gm, c, width / 2, s)),
                         ("range", lambda gm: range_mean(gm, c, width / 2, s - 0.02, s + 0.02))):
            best = {p: np.inf for p in maps}
            for _ in range(repeat):
                for p, gm in maps.items():
                    t = time.perf_counter()
                    fn(gm)
                    best[p] = min(best[p], time.perf_counter() - t)
            print(f"width {width:4d} {name}: " + ", ".join(f"{1e6 * b / n:.2f} us"
                                                         for b in best.values()))


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--size", type=int, default=128)
    ap.add_argument("--maps", default="gaussian,brushed,flakes,scratches")
    ap.add_argument("--ranks", default="8,16,32,64")
    ap.add_argument("--max-rank-factor", type=int, default=3)
    ap.add_argument("--cache", default=None, help="directory for the shared pyramids")
    ap.add_argument("--json", default=None, help="also write the rows here")
    ap.add_argument("--queries", nargs="+", default=None,
                    help="only compare the query time of these baked maps")
    a = ap.parse_args(argv)
    if a.queries:
        compare_queries(a.queries)
        return
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        cache = Path(a.cache or tmp)
        cache.mkdir(parents=True, exist_ok=True)
        print(f"{'map':>10} {'rank':>5} {'ratio %':>8} {'rel L2 %':>9}  per level %"
              f"{'':>24} mean/max rank  seconds")
        for kind in a.maps.split(","):
            nm = normal_map(kind, size=a.size, seed=0)
            for rank in (int(r) for r in a.ranks.split(",")):
                t = time.perf_counter()
                s = bake(nm, Path(tmp) / f"{kind}_{rank}.npz", rank=rank, progress=False,
                         max_rank=a.max_rank_factor * rank,
                         levels_dir=cache / f"levels_{kind}{a.size}")
                dt = time.perf_counter() - t
                lv = " / ".join(f"{100 * e:.1f}" for e in s["rel_l2_error_per_level"])
                print(f"{kind:>10} {rank:5d} {100 * s['ratio']:8.2f} "
                      f"{100 * s['rel_l2_error']:9.2f}  {lv:<34} "
                      f"{s['mean_rank_per_byte']:5.1f}/{s['max_rank']:<3d} {dt:8.1f}", flush=True)
                rows.append(dict(s, map=kind, rank=rank, wall_seconds=dt))
    if a.json:
        Path(a.json).write_text(json.dumps(rows, indent=1))


if __name__ == "__main__":
    main()
