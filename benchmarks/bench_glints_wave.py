"""``glints-wave`` against ``glints-wave-direct``: FLIP and speed-up at near / mid / far.

The geometric methods' measurement plane (:func:`prefilter.glints.render.measurement_scene`,
point light, ``--lights quad`` or ``environment``, 64x48, 1 spp) with the heightfield
``procedural:noise:128:0`` (0.25 um texels, 50 nm rms heights, 4-texel correlation) in
``extras.glints_wave``. Each method
renders once untimed (bake, level-0 images and kernels compiled), then ``--runs`` timed frames
(best kept; process CPU time with ``--cpu``, all threads). FLIP: HDR-FLIP
(:func:`prefilter.render.metrics.flip`), frame mean, ``glints-wave`` against
``glints-wave-direct``.

``--split`` also renders the frame from the **uncompressed** pyramid
(:class:`prefilter.glints.wave.direct.PyramidWave`: the direct model's coherence-area images
filtered into the pyramid levels, queried with the same Gaussian resampling weights and bilinear
NDF lookup as ``glints-wave``) and reports FLIP of it against ``glints-wave-direct``
(what the pyramid costs by itself) and of ``glints-wave`` against it (the compression alone).
``--settings JSON``: bake settings other than the render's (e.g. ``'{"rank": 32}'``), baked into
the glints cache.

    python benchmarks/bench_glints_wave.py --cpu --split --json out.json
"""

from __future__ import annotations

import argparse
import json
import time

import numpy as np

DISTANCES = {"near": 0.5, "mid": 2.0, "far": 8.0}
TARGET = 0.05
HEIGHTFIELD = "procedural:noise:128:0"


def scene(distance: float, width: int = 64, height: int = 48, heightfield: str = HEIGHTFIELD,
          lights: str = "point"):
    from prefilter.glints.render import measurement_scene

    sc = measurement_scene(distance, "gaussian", width=width, height=height, lights=lights)
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
    from prefilter.glints.wave import render as wrender
    from prefilter.render.driver import render
    from prefilter.render.metrics import flip
    from prefilter.render.scene import load_scene

    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--runs", type=int, default=3)
    ap.add_argument("--cpu", action="store_true")
    ap.add_argument("--width", type=int, default=64)
    ap.add_argument("--height", type=int, default=48)
    ap.add_argument("--lights", choices=["point", "quad", "environment"], default="point")
    ap.add_argument("--split", action="store_true")
    ap.add_argument("--settings", default=None)
    ap.add_argument("--json")
    a = ap.parse_args(argv)
    settings = json.loads(a.settings) if a.settings else None
    if settings:
        real_map = wrender.wave_map

        def wave_map(hf, st=None, progress=False):
            return real_map(hf, dict(settings, **(st or {})), progress)

        wrender.wave_map = wave_map
    hf = wrender.as_heightfield_spec(HEIGHTFIELD)
    wm = wrender.wave_map(hf, progress=True)
    print(f"map: {wm.compressed_bytes / 2**20:.2f} MiB, settings {settings or 'render defaults'}")
    rows = []
    for name, d in DISTANCES.items():
        sc = load_scene(scene(d, a.width, a.height, lights=a.lights))
        render(sc, "glints-wave")
        ref = render(sc, "glints-wave-direct")
        tw, img = timed(lambda: render(sc, "glints-wave"), a.runs, a.cpu)
        td, ref = timed(lambda: render(sc, "glints-wave-direct"), 1, a.cpu)
        fl = float(flip(img, ref).mean)
        sp = []
        real_shade = wrender.footprints

        def record(g, shape, spp):
            c, s = real_shade(g, shape, spp)
            sp.append(s)
            return c, s

        wrender.footprints = record
        try:
            render(sc, "glints-wave-direct")
        finally:
            wrender.footprints = real_shade
        row = dict(distance=name, median_sigma_p=float(np.median(np.concatenate(sp))), flip=fl,
                   ms_wave=1e3 * tw, ms_direct=1e3 * td, speedup=td / tw,
                   within_target=fl <= TARGET, mean_ratio=float(img.mean() / ref.mean()))
        msg = ""
        if a.split:
            from prefilter.glints.wave.direct import PyramidWave

            real_direct = wrender.direct_model
            unc = PyramidWave(real_direct(hf), wm.pyramid)
            wrender.direct_model = lambda hf_, st=None: unc
            try:
                up = render(sc, "glints-wave-direct")
            finally:
                wrender.direct_model = real_direct
            row.update(flip_uncompressed_vs_direct=float(flip(up, ref).mean),
                       flip_wave_vs_uncompressed=float(flip(img, up).mean))
            msg = (f"  [uncompressed vs direct {row['flip_uncompressed_vs_direct']:.4f}, "
                   f"glints-wave vs uncompressed {row['flip_wave_vs_uncompressed']:.4f}]")
        rows.append(row)
        print(f"{name:4s}: median sigma_p {row['median_sigma_p']:5.1f}  FLIP {fl:.4f}  glints-wave "
              f"{row['ms_wave']:7.1f} ms  glints-wave-direct {row['ms_direct']:8.1f} ms  "
              f"speed-up {row['speedup']:6.1f}x  mean ratio {row['mean_ratio']:.3f}{msg}",
              flush=True)
    if a.json:
        with open(a.json, "w") as fh:
            json.dump(rows, fh, indent=1)
    return rows


if __name__ == "__main__":
    main()
