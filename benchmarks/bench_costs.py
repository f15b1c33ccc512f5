"""Cost model of the bakes, and 1 vs 2 worker scaling of the distributed tasks.

``python benchmarks/bench_costs.py`` (also run by ``make bench``): for each bake and size, in a
fresh subprocess, the wall time, the peak resident memory above the process's level before the
bake (``resource.getrusage`` high-water marks) and the bytes written:

- ``ltc-iso``: the isotropic LTC table fit (:func:`prefilter.ltc.fit_iso.bake_table`, default
  fitting settings) for tables of 4^2, 8^2, 16^2 entries (size = entries);
- ``leadr``: ``prefilter bake leadr``'s work (:func:`prefilter.leadr.maps.moments` and
  :func:`prefilter.leadr.io.write_maps`, all levels) on N^2 height maps, N = 128..2048;
- ``colormap``: ``prefilter bake colormap``'s work (checkpointed rows, then the EXR and its JSON)
  for N x N tables of a 256-sample map, sigma_max 0.25, N = 128..2048.

A power law ``cost = a size^b`` is fitted to each column over the three largest sizes (least
squares in log-log; the smaller sizes measure start-up costs) and extrapolated to 4096^2 and
8192^2 (LTC tables: 64^2 and 128^2 entries). Results: ``out/bench/costs.json``, the Markdown
table on stdout, the plot ``docs/img/distributed_costs.png`` (``--no-plot`` to skip it).

``--only scaling`` and the default run also time the distributed tasks on a local cluster of 1
and of 2 worker processes (clusters started and warmed first, start-up timed apart; the workers'
Numba kernels on one thread each): an LTC table of 8^2 entries (8 row tasks) and a reference
render of the ``plane-and-sphere`` example at 160 x 90, 64 spp (bands of 8 rows), and a glint
bake (``--glint-size``, its level-0 chunks and CP cells as tasks); speed-up =
t1 / t2, efficiency = speed-up / 2. On a machine shared with other jobs these ratios understate
what two idle cores give: rerun on an idle machine.

``--only overheads``: the engine's own cost per task (an empty task on 2 local workers) and per
checkpoint part written by the client.

Options: ``--only costs|scaling|overheads``, ``--sizes 128,256`` (map sizes),
``--ltc-sizes 4,8``, ``--glint-size 1024`` (the glint bake of the scaling part; default 256).
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
MAP_SIZES = (128, 256, 512, 1024, 2048)
LTC_SIZES = (4, 8, 16)
EXTRAPOLATE = {"leadr": (4096, 8192), "colormap": (4096, 8192), "ltc-iso": (64, 128)}


def _rss_mb() -> float:
    """Peak resident memory of this process so far (MB; Linux reports KB)."""
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0


def _stored(path: Path) -> int:
    """Bytes of the files under ``path`` (links not followed twice)."""
    if path.is_file():
        return path.stat().st_size
    return sum(f.stat().st_size for f in path.rglob("*") if f.is_file() and not f.is_symlink())


def child(kind: str, n: int, tmp: Path) -> dict:
    """One measurement in this (fresh) process."""
    if kind == "ltc-iso":
        from prefilter.ltc.fit_iso import FitSettings, bake_table

        settings = FitSettings(res_theta=n, res_alpha=n)
        out = tmp / "ltc.npz"
        base = _rss_mb()
        t0 = time.perf_counter()
        bake_table(out, settings, progress=False)
    elif kind == "leadr":
        from prefilter.leadr.io import write_maps
        from prefilter.leadr.maps import moments

        height = np.random.default_rng(0).standard_normal((n, n))
        out = tmp / "leadr"
        base = _rss_mb()
        t0 = time.perf_counter()
        write_maps(moments(height), out)
    elif kind == "colormap":
        from prefilter.colormap.commands import bake_table

        c = np.random.default_rng(0).random((256, 3))
        out = tmp / "cmap.exr"
        base = _rss_mb()
        t0 = time.perf_counter()
        table, ck = bake_table(c, (0.0, 1.0), 0.25, size=n, edge="clamp", out=out)
        table.save(out)
        ck.clear()
    else:
        raise SystemExit(f"unknown kind {kind}")
    seconds = time.perf_counter() - t0
    peak = _rss_mb()
    return {"kind": kind, "n": n, "size": n * n, "seconds": seconds, "peak_mb": peak,
            "bake_mb": max(peak - base, 0.0), "stored_bytes": _stored(out)}


def measure(kind: str, n: int) -> dict:
    with tempfile.TemporaryDirectory() as tmp:
        env = dict(os.environ, PYTHONPATH=str(ROOT / "src"))
        proc = subprocess.run([sys.executable, __file__, "--child", kind, str(n), tmp],
                              capture_output=True, text=True, env=env)
        if proc.returncode:
            raise RuntimeError(proc.stderr)
        return json.loads(proc.stdout.strip().splitlines()[-1])


#: Points of the power-law fits: the largest sizes (small ones measure fixed start-up costs).
FIT_POINTS = 3


def power_law(sizes, values) -> tuple[float, float]:
    """``(a, b)`` of ``value = a size^b``: least squares on the logs of the positive values of
    the :data:`FIT_POINTS` largest sizes."""
    order = np.argsort(sizes)[-FIT_POINTS:]
    x = np.log(np.asarray(sizes, float)[order])
    y = np.asarray(values, float)[order]
    ok = y > 0
    b, log_a = np.polyfit(x[ok], np.log(y[ok]), 1)
    return float(np.exp(log_a)), float(b)


COLUMNS = (("seconds", "time (s)"), ("bake_mb", "peak RSS above start (MB)"),
           ("stored_bytes", "stored (MB)"))


def cost_table(rows: list[dict]) -> tuple[str, dict]:
    """Markdown table (measured and extrapolated rows) and the fitted laws."""
    lines = ["| bake | size | time (s) | peak RSS above start (MB) | stored (MB) |",
             "|---|---|---|---|---|"]
    laws = {}
    for kind in ("ltc-iso", "leadr", "colormap"):
        rs = [r for r in rows if r["kind"] == kind]
        if not rs:
            continue
        sizes = [r["size"] for r in rs]
        laws[kind] = {c: power_law(sizes, [r[c] for r in rs]) for c, _ in COLUMNS}
        for r in rs:
            lines.append(f"| {kind} | {r['n']}^2 | {r['seconds']:.3g} | {r['bake_mb']:.0f} | "
                         f"{r['stored_bytes'] / 1e6:.3g} |")
        for n in EXTRAPOLATE[kind]:
            v = {c: a * (n * n) ** b for c, (a, b) in laws[kind].items()}
            lines.append(f"| {kind} | {n}^2 (fit) | {v['seconds']:.3g} | {v['bake_mb']:.0f} | "
                         f"{v['stored_bytes'] / 1e6:.3g} |")
        exps = ", ".join(f"{name.split(' (')[0]} ~ size^{laws[kind][c][1]:.2f}"
                         for c, name in COLUMNS)
        lines.append(f"| {kind} | exponents | {exps} | | |")
    return "\n".join(lines), laws


def plot(rows: list[dict], laws: dict, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 3, figsize=(13, 3.8))
    for ax, (col, name) in zip(axes, COLUMNS):
        for kind, colour in (("ltc-iso", "C0"), ("leadr", "C1"), ("colormap", "C2")):
            rs = [r for r in rows if r["kind"] == kind]
            if not rs:
                continue
            x = np.array([r["size"] for r in rs], float)
            y = np.array([r[col] for r in rs], float)
            if col == "stored_bytes":
                y = y / 1e6
            ax.loglog(x, np.maximum(y, 1e-3), "o", color=colour, label=kind)
            a, b = laws[kind][col]
            xe = np.geomspace(x.min(), max(EXTRAPOLATE[kind]) ** 2, 50)
            ye = a * xe ** b / (1e6 if col == "stored_bytes" else 1.0)
            ax.loglog(xe, ye, "--", color=colour, lw=1, label=f"size^{b:.2f}")
        ax.set_xlabel("size (texels or table entries)")
        ax.set_title(name)
        ax.grid(True, which="both", alpha=0.3)
        ax.legend(fontsize=7)
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110)


# -- scaling -------------------------------------------------------------------------------------


def scaling(glint_size: int = 256, glint_ndf_res: int | None = None) -> list[dict]:
    """1 vs 2 workers on the LTC rows, the reference bands and a glint bake of a
    ``glint_size``^2 flakes map at the render's settings, or with NDF images of
    ``glint_ndf_res``^2 pixels (blocks 16, rank budget 16: the cost model's settings of
    ``bench_glints_cost.py``) (this process is the client). Each
    worker runs its Numba kernels on one thread, so that 1 worker is one core; the glint bake's
    stages between its task passes (coarser levels, rank allocation) run in the client, also
    on one thread, and are included in its time."""
    os.environ["NUMBA_NUM_THREADS"] = "1"  # inherited by the workers the engine spawns
    from prefilter.distributed import Engine
    from prefilter.ltc.fit_iso import FitSettings, fit_row
    from prefilter.render.scene import load_scene
    from prefilter.render.tiles import render_band, tile_bounds

    settings = FitSettings(res_theta=8, res_alpha=8)
    axis_t, _ = settings.axes()
    ltc_tasks = [(float(t), settings, i) for i, t in enumerate(axis_t)]
    scene = load_scene("example:plane-and-sphere")
    from dataclasses import replace

    scene = replace(scene, camera=replace(scene.camera, width=160, height=90))
    bands = tile_bounds(90, 8)
    ref_tasks = [(scene, "reference", b, 64, 0, (0.0, 0.0), None, {}, 1 << 18) for b in bands]
    out = []
    for workers in (1, 2):
        t0 = time.perf_counter()
        with Engine("local", workers=workers) as engine:
            start = time.perf_counter() - t0
            # warm-up: imports and Numba cache loads on every worker
            engine.map(fit_row, [(0.1, FitSettings(res_theta=2, res_alpha=2, n_fit=4,
                                                   quad_nodes=8), 0)] * workers)
            engine.map(render_band, [(scene, "reference", (0, 1), 4, 0, (0.0, 0.0), None, {},
                                      1 << 18)] * workers)
            for name, func, tasks in (("ltc-iso rows (8 x 8 table)", fit_row, ltc_tasks),
                                      ("reference bands (160x90, 64 spp)", render_band,
                                       ref_tasks)):
                t1 = time.perf_counter()
                engine.map(func, tasks)
                out.append({"job": name, "workers": workers, "tasks": len(tasks),
                            "seconds": time.perf_counter() - t1, "cluster_start_s": start})
            if glint_size:
                out.append(_glint_bake_timed(engine, glint_size, workers, start,
                                             glint_ndf_res))
    return out


def _glint_bake_timed(engine, size: int, workers: int, start: float,
                      ndf_res: int | None = None) -> dict:
    """A whole glint bake (:data:`prefilter.glints.bake.BAKE_SETTINGS`, or the cost model's
    settings with ``ndf_res``^2 NDF images) on ``engine``, from nothing, into a temporary folder;
    the number of tasks counted through ``map_fn``."""
    from prefilter.glints.bake import BAKE_SETTINGS, bake, bake_settings
    from prefilter.texture.procedural import normal_map

    nm = normal_map("flakes", size, seed=1)
    n_tasks = 0

    def counted(fn, *iterables):
        nonlocal n_tasks
        args = list(zip(*iterables))
        n_tasks += len(args)
        return engine.imap(fn, *zip(*args)) if args else iter(())

    with tempfile.TemporaryDirectory() as tmp:
        t1 = time.perf_counter()
        over = dict(BAKE_SETTINGS)
        if ndf_res:
            over.update(ndf_res=ndf_res, block=16, rank=16)
        bake(nm, Path(tmp) / "map.npz", progress=False, map_fn=counted,
             **bake_settings(nm.shape, over))
        seconds = time.perf_counter() - t1
    print(f"  glint bake {size}^2 on {workers} worker(s): {seconds:.1f} s", file=sys.stderr,
          flush=True)
    what = f"{ndf_res}^2 NDF images, rank 16" if ndf_res else "render settings"
    return {"job": f"glint bake ({size}^2 flakes, {what})", "workers": workers,
            "tasks": n_tasks, "seconds": seconds, "cluster_start_s": start}


def overheads() -> dict:
    """Per-task costs of the engine itself: an empty task through a local cluster of 2 workers
    (submit, schedule, run, gather), and the client's atomic write of one checkpoint part of a
    16 x 1920 band of RGB float32 (fsync included)."""
    import operator

    from prefilter.distributed import Engine
    from prefilter.fileio import Checkpoints

    n = 400
    with Engine("local", workers=2) as engine:
        engine.map(operator.add, [(1, 2)] * 4)
        t0 = time.perf_counter()
        engine.map(operator.add, [(i, 1) for i in range(n)])
        per_task = (time.perf_counter() - t0) / n
    band = np.zeros((16, 1920, 3), np.float32)
    with tempfile.TemporaryDirectory() as tmp:
        ck = Checkpoints(Path(tmp) / "img.exr", {"bench": 1})
        t0 = time.perf_counter()
        for i in range(20):
            ck.save(i, image=band)
        per_write = (time.perf_counter() - t0) / 20
    return {"empty_task_ms": 1e3 * per_task, "part_write_ms": 1e3 * per_write,
            "part_bytes": band.nbytes}


def scaling_table(rows: list[dict]) -> str:
    lines = ["| job | tasks | 1 worker (s) | 2 workers (s) | speed-up | efficiency |",
             "|---|---|---|---|---|---|"]
    for job in dict.fromkeys(r["job"] for r in rows):
        t = {r["workers"]: r for r in rows if r["job"] == job}
        s = t[1]["seconds"] / t[2]["seconds"]
        lines.append(f"| {job} | {t[1]['tasks']} | {t[1]['seconds']:.2f} | "
                     f"{t[2]['seconds']:.2f} | {s:.2f}x | {s / 2:.0%} |")
    starts = ", ".join(f"{w} worker(s) {r['cluster_start_s']:.1f} s" for w, r in
                       {r["workers"]: r for r in rows}.items())
    lines.append(f"\ncluster start-up: {starts}")
    return "\n".join(lines)


def main() -> None:
    if len(sys.argv) > 1 and sys.argv[1] == "--child":
        print(json.dumps(child(sys.argv[2], int(sys.argv[3]), Path(sys.argv[4]))))
        return
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--only", choices=("costs", "scaling", "overheads"))
    p.add_argument("--sizes", default=",".join(map(str, MAP_SIZES)))
    p.add_argument("--ltc-sizes", default=",".join(map(str, LTC_SIZES)))
    p.add_argument("--glint-size", type=int, default=256,
                   help="side of the normal map of the glint bake timed on 1 and 2 workers "
                        "(0: skip it)")
    p.add_argument("--glint-ndf-res", type=int, default=None,
                   help="NDF image side of that bake (default: the render's settings; 64: the "
                        "cost model's, which makes a 1024^2 bake minutes instead of hours)")
    p.add_argument("--no-plot", action="store_true")
    p.add_argument("--replot", action="store_true",
                   help="table and plot from out/bench/costs.json, measuring nothing")
    args = p.parse_args()
    out_dir = ROOT / "out" / "bench"
    out_dir.mkdir(parents=True, exist_ok=True)
    if args.replot:
        rows = json.loads((out_dir / "costs.json").read_text())["costs"]
        table, laws = cost_table(rows)
        print(table)
        plot(rows, laws, ROOT / "docs" / "img" / "distributed_costs.png")
        return
    result = {}
    print(f"machine: {os.cpu_count()} cores, load average {os.getloadavg()[0]:.1f}")
    if args.only in (None, "costs"):
        rows = []
        for kind, sizes in (("ltc-iso", args.ltc_sizes), ("leadr", args.sizes),
                            ("colormap", args.sizes)):
            for n in map(int, sizes.split(",")):
                rows.append(measure(kind, n))
                print(f"  {kind} {n}: {rows[-1]['seconds']:.3g} s", file=sys.stderr,
                      flush=True)
        table, laws = cost_table(rows)
        print(table)
        result.update(costs=rows, laws=laws)
        if not args.no_plot:
            plot(rows, laws, ROOT / "docs" / "img" / "distributed_costs.png")
    if args.only in (None, "scaling"):
        sc = scaling(args.glint_size, args.glint_ndf_res)
        print(scaling_table(sc))
        result.update(scaling=sc)
    if args.only in (None, "scaling", "overheads"):
        oh = overheads()
        print(f"engine overhead: {oh['empty_task_ms']:.2f} ms per empty task (2 workers), "
              f"{oh['part_write_ms']:.2f} ms per checkpoint part of {oh['part_bytes'] / 1e3:.0f} "
              f"kB written by the client")
        result.update(overheads=oh)
    # a partial run (--only) keeps the other parts of the last full one
    path = out_dir / "costs.json"
    previous = json.loads(path.read_text()) if path.is_file() else {}
    path.write_text(json.dumps({**previous, **result}, indent=1))


if __name__ == "__main__":
    main()
