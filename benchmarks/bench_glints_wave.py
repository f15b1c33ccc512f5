"""``glints-wave`` against ``glints-wave-direct``: FLIP and speed-up at near / mid / far.

The geometric methods' measurement plane (:func:`prefilter.glints.render.measurement_scene`,
point light, 64x48, 1 spp) with the heightfield ``procedural:noise:128:0`` (0.25 um texels, 50 nm
rms heights, 4-texel correlation) in ``extras.glints_wave``. Each method renders once untimed
(bake, level-0 images and kernels compiled), then ``--runs`` timed frames (best kept; process CPU
time with ``--cpu``). FLIP: HDR-FLIP (:func:`prefilter.render.metrics.flip`), frame mean.

    python benchmarks/bench_glints_wave.py --json out.json
"""

from __future__ import annotations

import argparse
import json
import time

DISTANCES = {"near": 0.5, "mid": 2.0, "far": 8.0}
TARGET = 0.05
HEIGHTFIELD = "procedural:noise:128:0"


def scene(distance: float, width: int = 64, height: int = 48, heightfield: str = HEIGHTFIELD):
    from prefilter.glints.render import measurement_scene

    sc = measurement_scene(distance, "gaussian", width=width, height=height)
    sc["extras"] = {"glints_wave": {"heightfield": heightfield}}
    return sc


def timed(fn, runs: int, cpu: bool):
    clock = time.process_time if cpu else time.perf_counter
    best, out = float("inf"), None
    for _ in range(runs):
        t0 = clock()
        out = fn()
        best = min(best, clock() - t0)
    return best, out


def main(argv=None):
    from prefilter.render.driver import render
    from prefilter.render.metrics import flip
    from prefilter.render.scene import load_scene

    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--runs", type=int, default=3)
    ap.add_argument("--cpu", action="store_true")
    ap.add_argument("--width", type=int, default=64)
    ap.add_argument("--height", type=int, default=48)
    ap.add_argument("--json")
    a = ap.parse_args(argv)
    rows = []
    for name, d in DISTANCES.items():
        sc = load_scene(scene(d, a.width, a.height))
        render(sc, "glints-wave")
        render(sc, "glints-wave-direct")
        tw, img = timed(lambda: render(sc, "glints-wave"), a.runs, a.cpu)
        td, ref = timed(lambda: render(sc, "glints-wave-direct"), 1, a.cpu)
        fl = float(flip(img, ref).mean)
        rows.append(dict(distance=name, flip=fl, ms_wave=1e3 * tw, ms_direct=1e3 * td,
                         speedup=td / tw, within_target=fl <= TARGET))
        r = rows[-1]
        print(f"{name:4s}: FLIP {fl:.4f}  glints-wave {r['ms_wave']:8.1f} ms  glints-wave-direct "
              f"{r['ms_direct']:9.1f} ms  speed-up {r['speedup']:7.1f}x", flush=True)
    if a.json:
        with open(a.json, "w") as fh:
            json.dump(rows, fh, indent=1)
    return rows


if __name__ == "__main__":
    main()
