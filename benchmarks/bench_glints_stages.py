"""Where a render bake's time goes: timers around the stages of one map's bake (docs/glints.md).

    python benchmarks/bench_glints_stages.py                  # the docs example's gaussian map
    python benchmarks/bench_glints_stages.py --map flakes     # its flakes map
    python benchmarks/bench_glints_stages.py --bake '{"n_iter_max": 20}'

Bakes one normal map of docs/scenes.md's "A full example" with the render's settings
(:func:`prefilter.glints.bake.bake_settings`) into a temporary folder, in this process, after a
32^2 bake of the same settings that compiles the kernels (not timed). Wraps the bake's
functions with timers: per stage the summed wall seconds of its calls and the CPU seconds of the
calling threads (``time.thread_time``; a parallel kernel's helper threads are not counted, so
the level-0 images' CPU is their wall time under the bake's lock at most twice). Tasks run on two
threads at once, so stage walls add up to about twice the bake's wall; the CP rows split by rank
and by pass (``cold``: pass 1 at the base rank, ``warm``: the final fit continued from it).
Prints the bake's wall and process CPU time and the table; ``--json`` writes both.
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
import threading
import time
from collections import defaultdict
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from bench_glints_cold import docs_example_maps  # noqa: E402


class Timers:
    """Summed wall and thread-CPU seconds and call counts per key, from any thread."""

    def __init__(self):
        self.wall, self.cpu, self.calls = defaultdict(float), defaultdict(float), defaultdict(int)
        self.lock = threading.Lock()

    def wrap(self, owner, name: str, key=None) -> None:
        """Replace ``owner.name`` by a timed wrapper (``key(*args, **kw)`` names the row)."""
        fn = getattr(owner, name)

        def timed(*args, **kw):
            t0, c0 = time.perf_counter(), time.thread_time()
            try:
                return fn(*args, **kw)
            finally:
                k = key(*args, **kw) if key else name
                with self.lock:
                    self.wall[k] += time.perf_counter() - t0
                    self.cpu[k] += time.thread_time() - c0
                    self.calls[k] += 1

        setattr(owner, name, timed)

    def clear(self) -> None:
        for d in (self.wall, self.cpu, self.calls):
            d.clear()

    def rows(self) -> list[dict]:
        return [dict(stage=k, wall=round(self.wall[k], 2), cpu=round(self.cpu[k], 2),
                     calls=self.calls[k]) for k in sorted(self.wall, key=lambda k: -self.wall[k])]


def instrument(timers: Timers) -> None:
    from prefilter.glints import bake as gb
    from prefilter.glints import cp as cpmod
    from prefilter.glints import pyramid as gp

    def cp_key(tensors, rank, **kw):
        kind = "warm" if kw.get("init") is not None else "cold"
        return f"CP rank {rank:3d} {kind}, {kw.get('n_iter_max')} iterations"

    timers.wrap(cpmod, "nn_cp_batch", cp_key)
    timers.wrap(cpmod, "exact_cp", lambda *a, **k: "exact CP (levels stored exactly)")
    timers.wrap(gb, "pndf_image", lambda *a, **k: "level-0 NDF images (under the lock)")
    timers.wrap(gb, "cell_images", lambda *a, **k: "cell images (level 0 incl. lock wait; "
                                                   "coarser cells: their files)")
    timers.wrap(gb, "image_tensors", lambda *a, **k: "blocks and group tensors")
    timers.wrap(gb, "encode", lambda *a, **k: "encoding")
    timers.wrap(gb, "decode", lambda *a, **k: "decoding (error measurement)")
    timers.wrap(gb, "refit_cell", lambda *a, **k: "final fit, encoding, error (all)")
    timers.wrap(gp.LevelStream, "add", lambda *a, **k: "streamed filter: add (main thread)")
    timers.wrap(gb.BakeJob, "write_cell_rows",
                lambda *a, **k: "coarser cells' rows to files (main thread)")
    timers.wrap(gb, "save", lambda *a, **k: "saving the file")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--map", default="gaussian", help="procedural kind of the docs example")
    ap.add_argument("--bake", default=None, help="JSON overrides of the render bake settings")
    ap.add_argument("--json", default=None, help="write the results here")
    a = ap.parse_args()

    from prefilter.glints import bake as gb
    maps = docs_example_maps()
    if a.map not in maps:
        ap.error(f"--map: expected one of {sorted(maps)}, got {a.map!r}")
    nm = maps[a.map]
    extra = json.loads(a.bake) if a.bake else {}
    timers = Timers()
    instrument(timers)
    with tempfile.TemporaryDirectory() as tmp:
        small = np.ascontiguousarray(nm[:32, :32])
        gb.bake_if_missing(small, Path(tmp) / "warmup.npz", progress=False,
                           **gb.bake_settings(small.shape, extra))
        timers.clear()
        t0, c0 = time.perf_counter(), time.process_time()
        gb.bake_if_missing(nm, Path(tmp) / "map.npz", progress=False,
                           **gb.bake_settings(nm.shape, extra))
        wall, cpu = time.perf_counter() - t0, time.process_time() - c0
    rows = timers.rows()
    print(f"{a.map} {nm.shape[0]}^2: bake wall {wall:.1f} s, process CPU {cpu:.1f} s")
    print("| stage | wall s (summed over threads) | thread CPU s | calls |")
    print("|---|---|---|---|")
    for r in rows:
        print(f"| {r['stage']} | {r['wall']:.1f} | {r['cpu']:.1f} | {r['calls']} |")
    if a.json:
        Path(a.json).write_text(json.dumps(dict(map=a.map, wall=wall, cpu=cpu, stages=rows,
                                                settings=extra), indent=1))


if __name__ == "__main__":
    main()
