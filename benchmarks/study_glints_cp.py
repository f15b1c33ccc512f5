"""Glint CP compression: storage ratio and reconstruction error per map and rank budget.

    python benchmarks/study_glints_cp.py                        # 4 maps x ranks 8/16/32/64, 128^2
    python benchmarks/study_glints_cp.py --size 512 --maps gaussian --ranks 16
    python benchmarks/study_glints_cp.py --max-rank-factor 2    # max rank 2 x rank (default 3)

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


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--size", type=int, default=128)
    ap.add_argument("--maps", default="gaussian,brushed,flakes,scratches")
    ap.add_argument("--ranks", default="8,16,32,64")
    ap.add_argument("--max-rank-factor", type=int, default=3)
    ap.add_argument("--cache", default=None, help="directory for the shared pyramids")
    ap.add_argument("--json", default=None, help="also write the rows here")
    a = ap.parse_args(argv)
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
                rows.append(dict(map=kind, rank=rank, seconds=dt, **s))
    if a.json:
        Path(a.json).write_text(json.dumps(rows, indent=1))


if __name__ == "__main__":
    main()
