"""``glints-wang`` against ``glints`` on the glints measurement scene (docs/glints-wang.md,
section "Cost and accuracy").

Per light kind (``--lights``, default point, quad and environment) and distance (``--distances``,
default 0.5 / 2 / 8: near / mid / far; ``prefilter.glints.render.measurement_scene``, flakes
128^2 exemplar, 64 x 48 pixels):

* frame times (wall and process CPU) of ``glints-wang`` (implicit tiling) and ``glints`` (the
  exemplar's periodic pyramid), ``--repeats`` frames each, interleaved, after one warm-up frame
  of each (bakes, loading and compilation outside the timing); the ratio of the medians;
* FLIP of ``glints-wang`` on an explicit periodic 4 x 4 tile index map
  (``wang.periodic_index_map``, a valid Wang tiling across the wrap) against ``glints-direct``
  on the assembled 128^2 map (the same surface at the same texel scale), both seed 0;
* memory: ``TiledNDF.nbytes`` (what the queries hold) against the cache file's size, and the
  resident-set growth of loading the file and packing it in a fresh process (``--rss``,
  ``/proc/self/statm`` before and after, the modules imported before).

The machine is shared: the load average is printed with each row (``os.getloadavg``). Run
nice'd: ``nice python benchmarks/bench_glints_wang.py [--repeats 3] [--lights point]
[--distances 0.5 2 8] [--no-flip] [--rss] [--breakdown]`` (``--breakdown``: the frame's NDF
queries by regime, CPU time with and without the dependent texels). One JSON line per row on
stdout, then a markdown table.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np


def _frames(sc, methods, repeats):
    from prefilter.render.driver import render

    wall = {m: [] for m in methods}
    cpu = {m: [] for m in methods}
    for m in methods:
        render(sc, m)  # warm-up: bake / load / compile
    for _ in range(repeats):
        for m in methods:
            w, c = time.perf_counter(), time.process_time()
            render(sc, m)
            wall[m].append(time.perf_counter() - w)
            cpu[m].append(time.process_time() - c)
    return wall, cpu


def _assembled_flip(d, kind, tmp):
    """FLIP of glints-wang (periodic index map) vs glints-direct (assembled map), seed 0."""
    from prefilter.glints import wang_render
    from prefilter.glints.render import measurement_scene
    from prefilter.glints.wang import assemble, periodic_index_map
    from prefilter.render.driver import render
    from prefilter.render.methods import RenderSettings
    from prefilter.render.metrics import flip
    from prefilter.render.scene import load_scene
    from prefilter.texture.normalmap import encode_normals

    sc = load_scene(measurement_scene(d, lights=kind))
    nm = sc.objects[0].material.normal_map.load()
    wn = wang_render.baked_tiles(nm)
    ny = nm.shape[0] // wn.wang.size
    idx = periodic_index_map(ny, ny, rng=0)
    path = tmp / "assembled.npy"
    np.save(path, encode_normals(assemble(wn.wang, idx)))
    spec = measurement_scene(d, lights=kind)
    spec["objects"][0]["material"]["normal_map"] = str(path)
    a = wang_render.render_wang(sc, RenderSettings(seed=0), index=idx)
    b = render(load_scene(spec), "glints-direct", seed=0)
    return float(flip(a, b).mean)


_RSS = """
import os, sys
from prefilter.glints.wang_store import load_tiles
def rss():
    with open("/proc/self/statm") as f:
        return int(f.read().split()[1]) * os.sysconf("SC_PAGE_SIZE")
before = rss()
wn = load_tiles(sys.argv[1])
wn.pack
print(rss() - before, wn.nbytes)
"""


def _memory(path, rss: bool) -> dict:
    from prefilter.glints.wang_store import load_tiles

    out = dict(file_bytes=os.path.getsize(path), held_bytes=load_tiles(path).nbytes)
    if rss:
        env = dict(os.environ)
        res = subprocess.run([sys.executable, "-c", _RSS, str(path)], capture_output=True,
                             text=True, env=env, check=True)
        out["rss_growth_bytes"] = int(res.stdout.split()[0])
    return out


def _breakdown(sc, repeats):
    """CPU seconds of the NDF queries of one ``glints-wang`` frame by regime (``ndf_points``
    and ``wang_range.ndf_ranges`` calls recorded during the frame, re-run on their footprints
    of each regime, best of ``repeats``), with and without the dependent texels (a copy of the
    ``TiledNDF`` without them and their vertex pyramids: what the tiles' pyramids alone
    cost)."""
    from dataclasses import replace

    from prefilter.glints import wang_ndf, wang_range, wang_render
    from prefilter.render.driver import render

    calls = []
    points, ranges = wang_render.ndf_points, wang_range.ndf_ranges

    def rec_points(wn, c, sp, s, **kw):
        calls.append(("points", wn, np.asarray(c), np.asarray(sp), (np.asarray(s),), kw))
        return points(wn, c, sp, s, **kw)

    def rec_ranges(wn, c, sp, lo, hi, **kw):
        calls.append(("ranges", wn, np.asarray(c), np.asarray(sp), (lo, hi), kw))
        return ranges(wn, c, sp, lo, hi, **kw)

    wang_render.ndf_points, wang_range.ndf_ranges = rec_points, rec_ranges
    try:
        render(sc, "glints-wang")
    finally:
        wang_render.ndf_points, wang_range.ndf_ranges = points, ranges
    out = {}
    for kind, wn, c, sp, args, kw in calls:
        fn = points if kind == "points" else ranges
        reg = np.vectorize(lambda x: wang_ndf.footprint_regime(wn, float(x)))(sp)
        alone = replace(wn, dependent=np.zeros((0, 2), np.int64), vertex_images=(),
                        vertex_packed=None,
                        coarse=None if wn.coarse is None else replace(
                            wn.coarse, vertex_images=(), vertex_packed=None))
        for name in ("direct", "tiles", "shares", "uniform"):
            sel = reg == name
            if not sel.any() or (kind == "ranges" and name == "direct"):
                continue
            sub = [a[sel] for a in args]
            kws = {k: (v[sel] if isinstance(v, np.ndarray) and v.shape[:sp.ndim] == sp.shape
                       else v) for k, v in kw.items()}
            for label, w in (("", wn), ("_pyramids_alone", alone)):
                fn(w, c[sel], sp[sel], *sub, **kws)  # compile / cache
                best = float("inf")
                for _ in range(repeats):
                    t0 = time.process_time()
                    fn(w, c[sel], sp[sel], *sub, **kws)
                    best = min(best, time.process_time() - t0)
                key = f"{kind}_{name}{label}_s"
                out[key] = round(out.get(key, 0.0) + best, 4)
            out[f"{kind}_{name}_n"] = out.get(f"{kind}_{name}_n", 0) + int(sel.sum())
    return out


def main(argv=None):
    from prefilter.glints import wang_render
    from prefilter.glints.render import measurement_scene
    from prefilter.render.scene import load_scene

    ap = argparse.ArgumentParser()
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--distances", type=float, nargs="+", default=[0.5, 2.0, 8.0])
    ap.add_argument("--lights", nargs="+", default=["point", "quad", "environment"],
                    choices=["point", "quad", "environment"])
    ap.add_argument("--no-flip", action="store_true")
    ap.add_argument("--rss", action="store_true")
    ap.add_argument("--breakdown", action="store_true",
                    help="also the frame's NDF query time by regime, with and without the "
                         "dependent texels")
    args = ap.parse_args(argv)
    tmp = Path(tempfile.mkdtemp())
    rows = []
    for kind in args.lights:
        for d in args.distances:
            sc = load_scene(measurement_scene(d, lights=kind))
            wall, cpu = _frames(sc, ["glints-wang", "glints"], args.repeats)
            nm = sc.objects[0].material.normal_map.load()
            med = {m: statistics.median(v) for m, v in cpu.items()}
            row = dict(lights=kind, distance=d,
                       wang_wall_s=[round(x, 4) for x in wall["glints-wang"]],
                       glints_wall_s=[round(x, 4) for x in wall["glints"]],
                       wang_cpu_s=[round(x, 4) for x in cpu["glints-wang"]],
                       glints_cpu_s=[round(x, 4) for x in cpu["glints"]],
                       cpu_ratio=round(med["glints-wang"] / med["glints"], 2),
                       loadavg=[round(x, 2) for x in os.getloadavg()])
            if args.breakdown:
                row.update(_breakdown(sc, args.repeats))
            if not args.no_flip:
                row["flip_wang_vs_direct_assembled"] = round(_assembled_flip(d, kind, tmp), 4)
            if not rows:
                row.update(_memory(wang_render.cache_path(nm), args.rss))
            print(json.dumps(row), flush=True)
            rows.append(row)
    print("\n| lights | d | glints-wang CPU s (median) | glints CPU s | ratio | FLIP vs direct "
          "(assembled) | load avg |")
    print("|---|---|---|---|---|---|---|")
    for r in rows:
        print(f"| {r['lights']} | {r['distance']} | {statistics.median(r['wang_cpu_s']):.3f} | "
              f"{statistics.median(r['glints_cpu_s']):.3f} | {r['cpu_ratio']} | "
              f"{r.get('flip_wang_vs_direct_assembled', '-')} | {r['loadavg'][0]} |")


if __name__ == "__main__":
    main()
