"""Glints part 1: constant-cost queries vs the direct P-NDF, bake time scaling, rank study.

    python benchmarks/bench_glints.py                 # queries + bake scaling (a few minutes)
    python benchmarks/bench_glints.py --ranks         # also ratio/error per map and rank 8-64
    python benchmarks/bench_glints.py --size 256      # map size of the query benchmark
    NUMBA_NUM_THREADS=1 python benchmarks/bench_glints.py --map m.npz --scaling "" --cpu
                                                      # queries in process CPU time (loaded box)
    python benchmarks/bench_glints.py --map f.npz --bake-kind flakes --size 512 \
        --level-rank level --scaling ""               # bake f.npz first if missing (512^2)
    python benchmarks/bench_glints.py --map m.npz --rss   # only: resident memory of a loaded map
    NUMBA_NUM_THREADS=1 python benchmarks/bench_glints.py --cpu --compare a.npz b.npz
                                                      # only: query cost of maps, interleaved
    python benchmarks/bench_glints.py --frames        # only: glints frame time at 3 distances
    python benchmarks/bench_glints.py --frames --direct   # also glints-direct, speed-up, FLIP
    python benchmarks/bench_glints.py --frames --runs 3 --interp trilinear --nearest \
        --bake-rank 16  # the evaluation and bake of the previous version
    python benchmarks/bench_glints.py --frames --stride0 2 --sigma0 2  # finer level 0 (bakes)
    python benchmarks/bench_glints.py --breakdown     # frame CPU time: queries, taps, fallback
    python benchmarks/bench_glints.py --breakdown --lights quad  # quad frames: range, MIS, kernels
    git archive c576186 src | tar -x -C /tmp/old && python benchmarks/bench_glints.py --frames \
        --lights quad --cpu --runs 6 --baseline /tmp/old/src   # before/after, alternating runs

The machine is shared, so every ratio is computed from timings of the same run; the absolute
numbers are only indicative. Footprint "width" is 2 sigma_p (texels).
"""

from __future__ import annotations

import argparse
import os
import tempfile
import time
from pathlib import Path

import numpy as np

from prefilter.glints.pndf import pndf
from prefilter.glints.bake import bake
from prefilter.glints.pndf import elements
from prefilter.glints.query import point, range_mean
from prefilter.glints.store import load
from prefilter.texture.procedural import normal_map

WIDTHS = [1, 4, 16, 64, 256, 512, 1024]


def _best(fn, repeat=3, clock=time.perf_counter):
    best = np.inf
    for _ in range(repeat):
        t = clock()
        fn()
        best = min(best, clock() - t)
    return best


def level_footprint(gm):
    """Per pyramid level: images, groups, mean rank of the kept blocks' groups and the MB a
    random-order query stream at that level reads from, in the packed layout the kernels use
    (8-bit code rows ``cq``; per group: uint8 factors, uint16 prefix sums, float32 scales) and,
    for comparison, in the float32 arrays ``A``, ``Bp``, ``C`` (padded to the largest rank):
    the cause of the per-level spread of the query time (see docs/glints.md)."""
    from prefilter.glints.query import _group_ranks, _n_prefetch, packed

    pyr = gm.pyramid
    nb = gm.block_index.shape[1]
    ranks = _group_ranks(gm)
    pa, _, (cq, wsc, fa, _), _, _, _ = packed(gm)
    per_comp = 2 * (pa.itemsize * pa.shape[1] + fa.itemsize * gm.block) + wsc.itemsize
    # the float32 arrays' sizes without decoding them (loaded maps decode them on first access)
    row_c = gm.rank * 4
    row_g = 2 * gm.rank * (gm.block + 1) * 4
    n_pf = _n_prefetch(gm)
    print(f"{'level':>5} {'images':>7} {'groups':>7} {'mean rank':>9} {'codes MB':>9} "
          f"{'factors MB':>10} {'float C MB':>10} {'A+Bp MB':>8} prefetched")
    for lv in np.arange(pyr.n_levels):
        lv = int(lv)
        img = np.arange(pyr.offsets[lv], pyr.offsets[lv + 1])
        k = gm.block_index[img]
        g = (gm.image_cell[img, None, None].astype(np.int64) * nb * nb
             + np.arange(nb * nb).reshape(nb, nb))[k >= 0]
        ug = np.unique(g)
        print(f"{lv:5d} {img.size:7d} {ug.size:7d} {ranks[g].mean() if g.size else 0:9.1f} "
              f"{ranks[g].sum() * cq.itemsize / 1e6:9.2f} "
              f"{ranks[ug].sum() * per_comp / 1e6:10.2f} "
              f"{(k >= 0).sum() * row_c / 1e6:10.1f} {ug.size * row_g / 1e6:8.1f} "
              f"{'yes' if img[0] < n_pf else 'no'}")


def bench_queries(gm, nm, n_queries=50000, seed=0, coherent=False, clock=time.perf_counter,
                  corner=None):
    """Per-query cost. ``coherent`` sorts the queries by footprint centre (rows of 8 texels), as
    a renderer's neighbouring pixels would be; random order measures cache misses as well.
    ``corner``: centres confined to a ``corner^2`` texel square (the control: the same operations
    on 1/(H/corner)^2 of the finest levels' data).
    ``clock``: ``time.process_time`` (with ``NUMBA_NUM_THREADS=1``) is not charged for the time
    other processes of a loaded machine hold the cores."""
    rng = np.random.default_rng(seed)
    H = nm.shape[0]
    el = elements(nm)
    S = gm.support
    h = 2 * S / gm.resolution
    rows = []
    for w in WIDTHS:
        sp = w / 2.0
        c = rng.uniform(0, corner or H, (n_queries, 2))
        if coherent:
            c = c[np.lexsort((c[:, 0], c[:, 1] // 8))]
        s = rng.normal(0.0, 0.15, (n_queries, 2))
        lo = s - rng.uniform(1, 12, (n_queries, 2)) * h
        hi = s + rng.uniform(1, 12, (n_queries, 2)) * h
        point(gm, c[:10], sp, s[:10])
        range_mean(gm, c[:10], sp, lo[:10], hi[:10])
        tp = _best(lambda: point(gm, c, sp, s), 7, clock) / n_queries
        tr = _best(lambda: range_mean(gm, c, sp, lo, hi), 7, clock) / n_queries
        # direct P-NDF: enough queries for ~0.5 s (its cost grows with the footprint area)
        n_direct = int(max(3, min(20000, 4e6 / (8 * max(sp, 0.5)) ** 2)))
        pndf(nm, c[:2], sp, s[:2], elements_=el)
        td = _best(lambda: pndf(nm, c[:n_direct], sp, s[:n_direct], elements_=el), 2,
                   clock) / n_direct
        rows.append((w, tp, tr, td))
    print(f"query cost per query ({'coherent' if coherent else 'random'} order, map {H}^2, "
          f"{f'centres in a {corner}^2 corner, ' if corner else ''}"
          f"{n_queries} queries, NUMBA threads "
          f"{os.environ.get('NUMBA_NUM_THREADS', 'all')}, clock {clock.__name__})")
    print(f"{'width':>6} {'point us':>9} {'range us':>9} {'direct us':>11} {'direct/point':>13}")
    for w, tp, tr, td in rows:
        print(f"{w:6d} {tp * 1e6:9.3f} {tr * 1e6:9.3f} {td * 1e6:11.1f} {td / tp:13.1f}")
    tps = [r[1] for r in rows]
    trs = [r[2] for r in rows]
    print(f"slowest/fastest footprint: point {max(tps) / min(tps):.2f}, range "
          f"{max(trs) / min(trs):.2f} (target <= 1.5)")
    for w in (64, 512):
        r = next(r for r in rows if r[0] == w)
        print(f"speed-up of the compressed point query over the direct P-NDF at width {w}: "
              f"{r[3] / r[1]:.0f}x")


def bench_compare(paths, n_queries=50000, repeat=15, seed=0, clock=time.process_time,
                  kernel=False):
    """Per-query cost of several maps of the same normal map (e.g. bakes with different
    ``level_rank``) on the same queries, measured interleaved: within every round each width
    times every map back to back, so load changes hit all maps alike; best of ``repeat`` rounds.
    Orders as :func:`bench_queries`: random, coherent, random in a 32^2 corner. ``kernel``: time
    only ``point_weighted`` / ``range_weighted`` on weights computed outside the timing (the
    kernels without the Python side of a call)."""
    from prefilter.glints.query import point_weighted, range_weighted, weights

    if kernel:
        def run_point(gm, c, sp, s, wts):
            return point_weighted(gm, *wts, s)

        def run_range(gm, c, sp, lo, hi, wts):
            return range_weighted(gm, *wts, lo, hi)
    else:
        def run_point(gm, c, sp, s, wts):
            return point(gm, c, sp, s)

        def run_range(gm, c, sp, lo, hi, wts):
            return range_mean(gm, c, sp, lo, hi)
    gms = [load(p) for p in paths]
    H = gms[0].pyramid.height
    h = 2 * gms[0].support / gms[0].resolution
    names = [Path(p).stem for p in paths]
    for order in ("random", "coherent", "corner"):
        rng = np.random.default_rng(seed)
        qs = []
        for w in WIDTHS:
            c = rng.uniform(0, 32 if order == "corner" else H, (n_queries, 2))
            if order == "coherent":
                c = c[np.lexsort((c[:, 0], c[:, 1] // 8))]
            s = rng.normal(0.0, 0.15, (n_queries, 2))
            lo = s - rng.uniform(1, 12, (n_queries, 2)) * h
            hi = s + rng.uniform(1, 12, (n_queries, 2)) * h
            wts = weights(gms[0], c, np.full(n_queries, w / 2.0))[:2] if kernel else None
            qs.append((c, w / 2.0, s, lo, hi, wts))
        t = np.full((len(gms), len(WIDTHS), 2), np.inf)
        for gm in gms:  # compile and build the packed arrays outside the timing
            point(gm, qs[0][0][:10], 1.0, qs[0][2][:10])
            range_mean(gm, qs[0][0][:10], 1.0, qs[0][3][:10], qs[0][4][:10])
        for _ in range(repeat):
            for j, (c, sp, s, lo, hi, wts) in enumerate(qs):
                for i, gm in enumerate(gms):
                    t0 = clock()
                    run_point(gm, c, sp, s, wts)
                    t1 = clock()
                    run_range(gm, c, sp, lo, hi, wts)
                    t[i, j] = np.minimum(t[i, j], [t1 - t0, clock() - t1])
        t *= 1e6 / n_queries
        print(f"{order} order, {'kernels only, ' if kernel else ''}{n_queries} queries, "
              f"best of {repeat} interleaved rounds, "
              f"{clock.__name__}, NUMBA threads {os.environ.get('NUMBA_NUM_THREADS', 'all')}, "
              f"load {os.getloadavg()[0]:.1f}; us per query at widths {WIDTHS}")
        for i, name in enumerate(names):
            for k, kind in enumerate(("point", "range")):
                v = t[i, :, k]
                print(f"  {name:>24} {kind}: " + " ".join(f"{x:6.3f}" for x in v)
                      + f" | slowest/fastest {v.max() / v.min():.2f}", flush=True)


def _vm_rss_mb():
    """Resident set size of this process (MB, /proc/self/status ``VmRSS``)."""
    with open("/proc/self/status") as f:
        return next(int(line.split()[1]) for line in f if line.startswith("VmRSS")) / 1024


def bench_rss(path):
    """Resident memory of a loaded map: after the imports, after :func:`load`, after queries
    (the kernels' packed arrays) and after touching the float arrays ``A``, ``Bp``, ``C`` (which
    version-3 maps decode on first access)."""
    from prefilter.glints import _qkernels  # noqa: F401  (Numba's own memory, before the map)

    base = _vm_rss_mb()
    gm = load(path)
    after_load = _vm_rss_mb()
    rng = np.random.default_rng(0)
    c = rng.uniform(0, gm.pyramid.height, (1000, 2))
    point(gm, c, 8.0, rng.normal(0, 0.15, (1000, 2)))
    after_query = _vm_rss_mb()
    floats = sum(getattr(gm, k).nbytes for k in ("A", "Bp", "C")) / 1e6
    after_floats = _vm_rss_mb()
    print(f"VmRSS MB ({path}): imports {base:.0f}, +load {after_load - base:.0f}, +queries "
          f"{after_query - after_load:.0f}, +A/Bp/C accessed {after_floats - after_query:.0f} "
          f"(their nbytes {floats:.0f} MB); codes on disk {gm.compressed_bytes / 1e6:.1f} MB")


def bench_bake_scaling(sizes, tmp):
    print("bake time (defaults: rank 16, ndf-res 128, block 16, stride0 4, cell 64)")
    for n in sizes:
        nm = normal_map("gaussian", n, seed=0)
        t = time.perf_counter()
        s = bake(nm, Path(tmp) / f"g{n}.npz", progress=False, cell=min(32, n))
        print(f"  {n:4d}^2: {time.perf_counter() - t:7.1f} s, ratio {100 * s['ratio']:.2f} %, "
              f"rel L2 {100 * s['rel_l2_error']:.1f} %, images {s['n_images']}")


def bench_ranks(size, tmp, ranks=(8, 16, 32, 64),
                kinds=("gaussian", "brushed", "flakes", "scratches"), level_rank="global"):
    print(f"rank study: {size}^2 procedural maps, ndf-res 128, block 16, levels shared, "
          f"level_rank {level_rank}")
    print(f"{'map':>10} {'rank':>5} {'ratio %':>8} {'rel L2 %':>9} {'level 0 %':>9} "
          f"{'top %':>6} {'CP s':>6}")
    for kind in kinds:
        nm = normal_map(kind, size, seed=0)
        lv = Path(tmp) / f"levels_{kind}"
        for rank in ranks:
            t = time.perf_counter()
            s = bake(nm, Path(tmp) / f"{kind}_{rank}.npz", rank=rank, progress=False,
                     cell=min(32, size), levels_dir=lv, level_rank=level_rank)
            e = s["rel_l2_error_per_level"]
            print(f"{kind:>10} {rank:5d} {100 * s['ratio']:8.2f} {100 * s['rel_l2_error']:9.2f} "
                  f"{100 * e[0]:9.2f} {100 * e[-1]:6.2f} {time.perf_counter() - t:6.1f}",
                  flush=True)


def bench_frames(distances=(0.5, 2.0, 8.0), kind="flakes", repeat=7, direct=False, lights="point",
                 interp=None, bilinear=None, bake_settings=None, clock=time.perf_counter):
    """Whole-frame time of ``glints`` at several distances in one run (the measurement scene of
    :mod:`prefilter.glints.render`: 64 x 48 pixels, 128^2 map, footprint ~ distance). Rounds are
    interleaved over the distances so that load changes hit all of them; best of ``repeat``.
    ``interp``, ``bilinear``, ``bake_settings``: override the render module's evaluation
    (``INTERP``, ``BILINEAR``) and bake settings (e.g. ``stride0``/``sigma0``). ``clock``:
    ``time.process_time`` counts this process's CPU time (all threads), which a loaded machine
    disturbs far less than the wall time (the render kernels are serial at this size)."""
    from prefilter.glints import render as grender
    from prefilter.glints.bake import BAKE_SETTINGS
    from prefilter.glints.render import measurement_scene

    if interp is not None:
        grender.INTERP = interp
    if bilinear is not None:
        grender.BILINEAR = bilinear
    if bake_settings:
        BAKE_SETTINGS.update(bake_settings)
    from prefilter.render.metrics import flip
    from prefilter.render.driver import render
    from prefilter.render.scene import load_scene

    from prefilter.render.methods import RenderSettings

    def frame(sc):
        return grender.render_glints(sc, RenderSettings())

    scenes = [load_scene(measurement_scene(d, kind, lights=lights)) for d in distances]
    for sc in scenes:  # bake and compile outside the timing
        frame(sc)
    if direct:
        # glints-direct's kernels too: with a cold Numba cache its near frame was mostly
        # compilation (point 714 ms instead of ~70, a 86x "speed-up")
        render(scenes[0], "glints-direct")
    best = [np.inf] * len(scenes)
    for _ in range(repeat):
        for i, sc in enumerate(scenes):
            t = clock()
            frame(sc)
            best[i] = min(best[i], clock() - t)
    print(f"glints frame time ({lights} light, {kind} 128^2 map, 64x48 pixels, best of {repeat}, "
          f"NUMBA threads {os.environ.get('NUMBA_NUM_THREADS', 'all')}, interp "
          f"{grender.INTERP}, bilinear {grender.BILINEAR}, stride0 "
          f"{BAKE_SETTINGS['stride0']}, sigma0 {BAKE_SETTINGS.get('sigma0')}, "
          f"clock {clock.__name__})")
    for d, t in zip(distances, best):
        line = f"  distance {d:4g}: glints {t * 1e3:8.1f} ms"
        if direct:
            sc = scenes[distances.index(d)]
            t0 = clock()  # the same clock as glints' (CPU time with --cpu: all threads)
            img_d = render(sc, "glints-direct")
            td = clock() - t0
            fl = flip(render(sc, "glints"), img_d).mean
            line += f", glints-direct {td * 1e3:9.1f} ms, speed-up {td / t:6.1f}x, FLIP {fl:.3f}"
        print(line, flush=True)
    print(f"max/min over distances: {max(best) / min(best):.2f} (target <= 1.5)")
    return best


def bench_breakdown(distances=(0.5, 2.0, 8.0), kind="flakes", repeat=5):
    """Where a ``glints`` frame's CPU time goes (point light): the compressed point queries
    (resampling kernel: queries per pyramid level, taps per query) and the direct P-NDF fallback
    below the finest level, each re-run alone on the frame's own inputs, vs the whole frame."""
    from prefilter.glints import brdf
    from prefilter.glints.pyramid import resample_weights
    from prefilter.glints.render import measurement_scene
    from prefilter.render.driver import render
    from prefilter.render.scene import load_scene

    calls = {}
    orig = {"point_flat": brdf.point_flat, "direct_ndf": brdf.direct_ndf}

    def spy(name):
        def f(*a, **kw):
            calls[name] = (a, kw)
            return orig[name](*a, **kw)
        return f

    def cpu(fn):
        best = np.inf
        for _ in range(repeat):
            t = time.process_time()
            fn()
            best = min(best, time.process_time() - t)
        return best * 1e3

    brdf.point_flat, brdf.direct_ndf = spy("point_flat"), spy("direct_ndf")
    try:
        print(f"glints frame CPU time breakdown ({kind} 128^2, point light, best of {repeat})")
        for d in distances:
            sc = load_scene(measurement_scene(d, kind))
            calls.clear()
            render(sc, "glints")
            line = f"  distance {d:4g}: frame {cpu(lambda: render(sc, 'glints')):6.1f} ms"
            if "point_flat" in calls:
                (gm, c, sp, q), kw = calls["point_flat"]
                t = cpu(lambda: orig["point_flat"](gm, c, sp, q, **kw))
                idx, w, ok = resample_weights(gm.pyramid, c, sp)
                lv = np.searchsorted(gm.pyramid.offsets, idx[:, 0], side="right") - 1
                taps = (w > 0).sum(1)[ok]
                hist = np.histogram(taps, [0, 20, 40, 80, 120, 200])[0]
                line += (f" | point queries {len(sp)}: {t:5.1f} ms, per level "
                         f"{np.bincount(lv[ok], minlength=gm.pyramid.n_levels).tolist()}, taps "
                         f"mean {taps.mean() if taps.size else 0:.0f}, histogram "
                         f"(<20, <40, <80, <120, <200) {hist.tolist()}")
            if "direct_ndf" in calls:
                (surf, c, sp, q), kw = calls["direct_ndf"]
                t = cpu(lambda: orig["direct_ndf"](surf, c, sp, q, **kw))
                line += f" | direct fallback {len(sp)}: {t:5.1f} ms"
            print(line, flush=True)
    finally:
        brdf.point_flat, brdf.direct_ndf = orig["point_flat"], orig["direct_ndf"]


def bench_breakdown_quad(distances=(0.5, 2.0, 8.0), kind="flakes", repeat=7):
    """Where a ``glints`` quad-light frame's CPU time goes: each distance's frame timed whole
    while the quad lights' functions are timed inside it (range path ``quad_range``; MIS path
    ``quad_mis`` and, within it, the one-walk direct kernel ``direct_mis_k``, the compressed
    sampler ``sample_s_k`` and the direct NDF at K points ``direct_ndf_k``); rounds interleaved
    over the distances, best of ``repeat`` per entry (CPU time of this process)."""
    import functools

    from prefilter.glints import render as grender
    from prefilter.render.methods import RenderSettings
    from prefilter.render.scene import load_scene

    parts = [(grender, "quad_range"), (grender, "quad_mis"), (grender, "direct_mis_k"),
             (grender, "sample_s_k"), (grender, "direct_ndf_k")]
    acc = {}
    depth = {}
    orig = {name: getattr(mod, name) for mod, name in parts}

    def timed(name):
        @functools.wraps(orig[name])
        def f(*a, **kw):
            # quad_range calls itself on a subset: only the outermost call is counted
            depth[name] = depth.get(name, 0) + 1
            t = time.process_time()
            try:
                return orig[name](*a, **kw)
            finally:
                depth[name] -= 1
                if depth[name] == 0:
                    acc[name] = acc.get(name, 0.0) + time.process_time() - t
        return f

    scenes = [load_scene(grender.measurement_scene(d, kind, lights="quad")) for d in distances]
    for mod, name in parts:
        setattr(mod, name, timed(name))
    try:
        for sc in scenes:  # bake and compile outside the timing
            grender.render_glints(sc, RenderSettings())
        best = [{} for _ in distances]
        for _ in range(repeat):
            for i, sc in enumerate(scenes):
                acc.clear()
                t = time.process_time()
                grender.render_glints(sc, RenderSettings())
                acc["frame"] = time.process_time() - t
                for k, v in acc.items():
                    best[i][k] = min(best[i].get(k, np.inf), v)
    finally:
        for mod, name in parts:
            setattr(mod, name, orig[name])
    print(f"glints quad frame CPU ms ({kind} 128^2, 64x48 pixels, best of {repeat} per entry, "
          f"load {os.getloadavg()[0]:.1f})")
    names = ["frame"] + [name for _, name in parts]
    print(f"{'distance':>8} " + " ".join(f"{n:>13}" for n in names))
    for d, b in zip(distances, best):
        print(f"{d:8g} " + " ".join(f"{b[n] * 1e3:13.1f}" if n in b else f"{'-':>13}"
                                     for n in names), flush=True)
    fr = [b["frame"] for b in best]
    print(f"max/min over distances: {max(fr) / min(fr):.2f}")


def bench_frames_baseline(src, lights="point", runs=3, cpu=False):
    """:func:`bench_frames` of another source tree and of this one, alternating, each run in a
    fresh process of its own (``PYTHONPATH=src`` for the other tree: e.g. ``git archive <commit>
    src | tar -x -C /tmp/old`` and ``src = /tmp/old/src``): a before/after comparison under the
    same load. Prints every run and each tree's range per distance and of max/min."""
    import re
    import subprocess
    import sys

    src = Path(src).resolve()
    if not (src / "prefilter" / "__init__.py").is_file():
        raise SystemExit(f"--baseline: expected a source tree containing prefilter/, got {src}")
    cmd = [sys.executable, str(Path(__file__).resolve()), "--frames", "--lights", lights]
    if cpu:
        cmd.append("--cpu")
    trees = [("baseline", {**os.environ, "PYTHONPATH": str(src)}), ("this tree", None)]
    times = {name: [] for name, _ in trees}
    for r in range(runs):
        for name, env in trees:
            out = subprocess.run(cmd, env=env, capture_output=True, text=True, check=True).stdout
            ms = [float(x) for x in re.findall(r"glints\s+([\d.]+) ms", out)]
            times[name].append(ms)
            print(f"run {r + 1} {name:>9}: " + " / ".join(f"{x:6.1f}" for x in ms)
                  + f" ms, max/min {max(ms) / min(ms):.2f} (load {os.getloadavg()[0]:.1f})",
                  flush=True)
    for name, rows in times.items():
        a = np.array(rows)
        rat = a.max(1) / a.min(1)
        print(f"{name:>9}: " + " / ".join(f"{lo:.0f}-{hi:.0f}" for lo, hi in
                                          zip(a.min(0), a.max(0)))
              + f" ms; max/min {rat.min():.2f}-{rat.max():.2f}, median {np.median(rat):.2f}")


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--size", type=int, default=128)
    ap.add_argument("--ranks", action="store_true")
    ap.add_argument("--rank-size", type=int, default=128)
    ap.add_argument("--rank-list", default="8,16,32,64")
    ap.add_argument("--kinds", default="gaussian,brushed,flakes,scratches")
    ap.add_argument("--scaling", default="64,128,256")
    ap.add_argument("--map", default=None, help="use this baked .npz for the query benchmark")
    ap.add_argument("--bake-kind", default=None,
                    help="--map: bake it first if missing, from this procedural map of --size")
    ap.add_argument("--level-rank", default="global",
                    help="--bake-kind and --ranks: the bakes' rank split (global, level or "
                         "uniform)")
    ap.add_argument("--rss", action="store_true", help="only: resident memory of --map loaded")
    ap.add_argument("--compare", nargs="+", default=None,
                    help="only: query cost of these maps measured interleaved (bench_compare)")
    ap.add_argument("--repeat", type=int, default=15, help="--compare: rounds")
    ap.add_argument("--kernel", action="store_true",
                    help="--compare: time the query kernels on precomputed weights only")
    ap.add_argument("--corner", type=int, default=None,
                    help="queries: also a random-order run with centres in a CORNER^2 square")
    ap.add_argument("--frames", action="store_true", help="only the frame-time benchmark")
    ap.add_argument("--direct", action="store_true", help="--frames: also glints-direct + FLIP")
    ap.add_argument("--lights", default="point", help="--frames: point, quad or environment")
    ap.add_argument("--baseline", default=None,
                    help="--frames: alternate each run with a process on this source tree "
                    "(PYTHONPATH; e.g. from git archive) and report both")
    ap.add_argument("--runs", type=int, default=1, help="--frames: repeat the measurement")
    ap.add_argument("--interp", default=None, help="--frames: resample (default) or trilinear")
    ap.add_argument("--nearest", action="store_true", help="--frames: NDF pixel value lookup")
    ap.add_argument("--stride0", type=int, default=None, help="--frames: bake with this stride0")
    ap.add_argument("--sigma0", type=float, default=None, help="--frames: and this sigma0")
    ap.add_argument("--cpu", action="store_true",
                    help="--frames and queries: process CPU time, not wall")
    ap.add_argument("--bake-rank", type=int, default=None, help="--frames: bake rank budget")
    ap.add_argument("--breakdown", action="store_true",
                    help="only: where the frame CPU time goes (queries, taps, fallback; with "
                    "--lights quad: range path, MIS path and its kernels)")
    a = ap.parse_args()
    if a.map and a.bake_kind:
        from prefilter.glints.bake import bake_if_missing

        bake_if_missing(normal_map(a.bake_kind, a.size, seed=0), a.map, progress=False,
                        level_rank=a.level_rank, levels_dir=Path(a.map).with_suffix(".levels"))
    if a.rss:
        bench_rss(a.map)
        return
    if a.compare:
        bench_compare(a.compare, repeat=a.repeat, kernel=a.kernel,
                      clock=time.process_time if a.cpu else time.perf_counter)
        return
    if a.breakdown:
        if a.lights == "quad":
            bench_breakdown_quad()
        else:
            bench_breakdown()
        return
    if a.frames:
        bs = {k: v for k, v in (("stride0", a.stride0), ("sigma0", a.sigma0),
                                ("rank", a.bake_rank)) if v is not None}
        if a.baseline:
            bench_frames_baseline(a.baseline, lights=a.lights, runs=a.runs, cpu=a.cpu)
            return
        ratios = []
        for _ in range(a.runs):
            best = bench_frames(direct=a.direct, lights=a.lights, interp=a.interp,
                                bilinear=False if a.nearest else None, bake_settings=bs,
                                clock=time.process_time if a.cpu else time.perf_counter)
            ratios.append(max(best) / min(best))
        if a.runs > 1:
            print("max/min per run: " + ", ".join(f"{r:.2f}" for r in ratios))
        return
    with tempfile.TemporaryDirectory() as tmp:
        if a.map:
            gm = load(a.map)
            p = gm.pyramid
            nm = normal_map("gaussian", p.height, seed=0)
        else:
            nm = normal_map("gaussian", a.size, seed=0)
            bake(nm, Path(tmp) / "q.npz", progress=False, cell=min(32, a.size))
            gm = load(Path(tmp) / "q.npz")
        clock = time.process_time if a.cpu else time.perf_counter
        level_footprint(gm)
        bench_queries(gm, nm, clock=clock)
        bench_queries(gm, nm, coherent=True, clock=clock)
        if a.corner:
            bench_queries(gm, nm, clock=clock, corner=a.corner)
        if a.scaling:
            bench_bake_scaling([int(x) for x in a.scaling.split(",")], tmp)
        if a.ranks:
            bench_ranks(a.rank_size, tmp, [int(r) for r in a.rank_list.split(",")],
                        a.kinds.split(","), a.level_rank)


if __name__ == "__main__":
    main()
