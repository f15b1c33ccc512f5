"""Glint bake cost against map size: time, peak memory, stored bytes, temporary disk, query time
(docs/glints.md, "Cost model").

    python benchmarks/bench_glints_cost.py                          # 128^2 .. 1024^2
    python benchmarks/bench_glints_cost.py --sizes 128 256 --ndf-res 512 --block 32  # render NDFs

Each size is baked in a subprocess (``prefilter.glints.bake.bake`` of the procedural ``gaussian``
map, seed 1, into an empty folder) that records its wall and CPU seconds and peak RSS
(``os.wait4``; the bake's own peak, before the file is loaded and queried, from ``getrusage``
in the child); the parent polls the parts folder (the bake's temporary disk) every 0.2 s. The
child then loads the file and times 200 000 point queries at random footprints (``query.point``,
one call, after a warm-up call). Power laws ``y = a n^p`` (``n`` texels) are fitted by least
squares in log-log over the measured sizes and extrapolated to 4096^2 and 8192^2; the bake's
peak memory, a fixed part plus a part per texel, gets an affine fit ``y = a + b n`` as well.
``--rows JSON`` prints the fits again from the rows a ``--json`` run wrote.

Defaults: NDF images of 64^2 pixels (blocks 16, rank budget 16, the bake's other defaults), so
that 1024^2 runs on a 2-core machine; the render's 512^2 images cost ~60x more per image and
store ~40x more per image, at the same exponents in the map size (each image's cost does not
depend on it). The machine may be shared: the load average is printed with each row.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

CHILD = r"""
import json, resource, sys, time
import numpy as np
from prefilter.glints.bake import bake
from prefilter.glints.store import load
from prefilter.glints import query
from prefilter.texture.procedural import normal_map

size, out, kw = int(sys.argv[1]), sys.argv[2], json.loads(sys.argv[3])
nm = normal_map("gaussian", size=size, seed=1)
t = time.perf_counter()
s = bake(nm, out, progress=False, **kw)
bake_s = time.perf_counter() - t
bake_rss = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024  # before load and queries
gm = load(out)
rng = np.random.default_rng(0)
n = 200_000
c = rng.uniform(0, size, (n, 2))
sp = np.exp(rng.uniform(np.log(4.0), np.log(size / 4), n))
q = rng.normal(0.0, 0.15, (n, 2))
query.point(gm, c[:1000], sp[:1000], q[:1000])  # compilation, packing
t = time.perf_counter()
query.point(gm, c, sp, q)
ns = (time.perf_counter() - t) / n * 1e9
print(json.dumps(dict(bake_s=bake_s, bake_rss=bake_rss, stored=s["compressed_bytes"],
                      raw=s["raw_bytes"], err=s["rel_l2_error"], query_ns=ns,
                      levels=len(s["rel_l2_error_per_level"]))))
"""


def parts_bytes(parts: Path) -> int:
    total = 0
    for root, _, files in os.walk(parts):
        for name in files:
            try:
                total += os.stat(os.path.join(root, name)).st_blocks * 512
            except OSError:
                pass
    return total


def measure(size: int, kw: dict) -> dict:
    """Bake and query a ``size^2`` map in a subprocess; its costs."""
    root = Path(tempfile.mkdtemp(prefix="bench-glints-cost-"))
    out = root / "m.npz"
    peak, done = [0], threading.Event()

    def poll():
        while not done.is_set():
            peak[0] = max(peak[0], parts_bytes(Path(str(out) + ".parts")))
            done.wait(0.2)

    watcher = threading.Thread(target=poll, daemon=True)
    load0 = os.getloadavg()[0]
    t0 = time.perf_counter()
    proc = subprocess.Popen([sys.executable, "-c", CHILD, str(size), str(out), json.dumps(kw)],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    watcher.start()
    _, status, usage = os.wait4(proc.pid, 0)
    wall = time.perf_counter() - t0
    done.set()
    watcher.join()
    stdout, stderr = proc.stdout.read(), proc.stderr.read()
    if os.waitstatus_to_exitcode(status):
        sys.exit(f"size {size} failed:\n{stderr.decode(errors='replace')}")
    row = json.loads(stdout.decode().strip().splitlines()[-1])
    import shutil

    shutil.rmtree(root, ignore_errors=True)
    return dict(row, size=size, wall=wall, cpu=usage.ru_utime + usage.ru_stime,
                rss=usage.ru_maxrss * 1024, temp=peak[0], load=load0)


def power_law(n, y):
    """``(a, p)`` of ``y = a n^p`` (least squares in log-log)."""
    import numpy as np

    p, log_a = np.polyfit(np.log(n), np.log(y), 1)
    return float(np.exp(log_a)), float(p)


def affine(n, y):
    """``(a, b)`` of ``y = a + b n`` (least squares)."""
    import numpy as np

    b, a = np.polyfit(np.asarray(n, float), np.asarray(y, float), 1)
    return float(a), float(b)


def print_fits(rows: list) -> dict:
    """The power-law (and, for the bake's memory, affine) fits of ``rows``, printed as tables."""
    mib = 2**20
    n = [r["size"] ** 2 for r in rows]
    print("\n| cost | exponent p (y ~ texels^p) | 4096^2 | 8192^2 |")
    print("|---|---|---|---|")
    fits = {}
    for key, unit, scale in (("cpu", "s CPU", 1.0), ("wall", "s wall", 1.0),
                             ("bake_rss", "MiB peak RSS of the bake", mib),
                             ("rss", "MiB peak RSS with queries", mib),
                             ("temp", "MiB temp disk", mib),
                             ("stored", "MiB stored", mib), ("query_ns", "ns per query", 1.0)):
        y = [max(r[key], 1e-9) / scale for r in rows]
        c, p = power_law(n, y)
        fits[key] = dict(a=c, p=p)
        print(f"| {unit} | {p:.2f} | {c * 4096.0 ** (2 * p):.4g} | {c * 8192.0 ** (2 * p):.4g} |")
    a0, b = affine(n, [r["bake_rss"] for r in rows])
    fits["bake_rss_affine"] = dict(a=a0, b=b)
    print(f"\nbake peak RSS ~ {a0 / mib:.0f} MiB + {b:.0f} B a texel: "
          f"4096^2 {(a0 + b * 4096.0**2) / 2**30:.2f} GiB, "
          f"8192^2 {(a0 + b * 8192.0**2) / 2**30:.2f} GiB")
    return fits


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sizes", type=int, nargs="+", default=[128, 256, 512, 1024])
    ap.add_argument("--ndf-res", type=int, default=64)
    ap.add_argument("--block", type=int, default=16)
    ap.add_argument("--rank", type=int, default=16)
    ap.add_argument("--json", type=Path, help="also write the rows and fits here")
    ap.add_argument("--rows", type=Path, help="print the fits of a --json run's rows, bake nothing")
    a = ap.parse_args()
    if a.rows:
        print_fits(json.loads(a.rows.read_text())["rows"])
        return
    kw = dict(ndf_res=a.ndf_res, block=a.block, rank=a.rank)
    print(f"bake settings {kw} (bake()'s defaults otherwise); {os.cpu_count()} cores")
    rows = []
    mib = 2**20
    print("| map | wall s | CPU s | peak RSS MiB (bake / with queries) | temp disk MiB | "
          "stored MiB | query ns | load |")
    print("|---|---|---|---|---|---|---|---|")
    for size in a.sizes:
        r = measure(size, kw)
        rows.append(r)
        print(f"| {size}^2 | {r['wall']:.1f} | {r['cpu']:.1f} | "
              f"{r['bake_rss'] / mib:.0f} / {r['rss'] / mib:.0f} | "
              f"{r['temp'] / mib:.0f} | {r['stored'] / mib:.2f} | {r['query_ns']:.0f} | "
              f"{r['load']:.1f} |", flush=True)
    if len(rows) < 2:
        return
    fits = print_fits(rows)
    if a.json:
        a.json.write_text(json.dumps(dict(settings=kw, rows=rows, fits=fits), indent=1))


if __name__ == "__main__":
    main()
