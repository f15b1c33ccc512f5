"""Render-bake cost: splats, level-0 NDF images and a whole bake (docs/glints-part2.md).

    python benchmarks/bench_glints_bake.py                   # all three, flakes 128^2
    NUMBA_NUM_THREADS=1 python benchmarks/bench_glints_bake.py --no-bake   # kernels, one core
    PYTHONPATH=/tmp/old/src python benchmarks/bench_glints_bake.py         # another tree

1. ``pndf.splat``: nanoseconds per isotropic splat at the render's NDF resolution, intrinsic
   roughness and cut (6 stds), at 200 000 random positions.
2. Level-0 NDF images (``pndf_image``, the bake's first stage): CPU milliseconds per image of 16
   level-0 footprints (std ``stride0`` texels, the render bake's cuts) of the flakes and
   brushed maps, at 256^2 and 512^2.
3. A whole bake of the map with the render's settings (``render.baked_surface`` into an empty
   temporary cache): wall seconds and the file's size; for two-pass settings also the CP passes
   (fit at the base rank, refit) and the rest (mostly the level-0 images).

Run the script with another tree on ``PYTHONPATH`` (e.g. from ``git archive``) for a before /
after comparison; the machine is shared, so compare runs made one after the other.
"""

from __future__ import annotations

import argparse
import os
import tempfile
import time

import numpy as np


def bench_splat(R: int, siso: float, n: int = 200_000) -> float:
    """Nanoseconds per ``pndf.splat`` call at random positions of an ``R^2`` image."""
    from numba import njit

    from prefilter.glints.pndf import splat

    @njit(cache=False)
    def many(img, px, py, mx, my):
        for k in range(mx.size):
            splat(img, px, py, mx[k], my[k], siso, 0.7, -1.0, 2.0 / R, 6.0)

    rng = np.random.default_rng(0)
    mx, my = rng.normal(0.0, 0.3, (2, n))
    img, px, py = np.zeros((R, R)), np.zeros(R), np.zeros(R)
    many(img, px, py, mx[:10], my[:10])  # compile outside the timing
    t = time.perf_counter()
    many(img, px, py, mx, my)
    return (time.perf_counter() - t) / n * 1e9


def bench_level0(kind: str, R: int, sr: float) -> float:
    """CPU milliseconds per level-0 NDF image (16 footprints of the render bake's level-0 std,
    ``stride0`` texels)."""
    from prefilter.glints.pndf import pndf_image
    from prefilter.texture.procedural import normal_map

    nm = normal_map(kind, size=128, seed=1)
    c = np.stack(np.meshgrid(np.arange(4) * 32 + 2.0, np.arange(4) * 32 + 2.0), -1).reshape(-1, 2)
    from prefilter.glints.bake import BAKE_SETTINGS

    kw = {k: BAKE_SETTINGS[k] for k in ("ndf_truncation", "footprint_truncation")}
    sigma0 = float(BAKE_SETTINGS["stride0"])
    pndf_image(nm, c[:1], sigma0, R, 1.0, sr, **kw)  # compile outside the timing
    t = time.process_time()
    pndf_image(nm, c, sigma0, R, 1.0, sr, **kw)
    return (time.process_time() - t) / len(c) * 1e3


def bench_bake(kind: str) -> dict:
    """The render bake of ``kind`` (128^2) into an empty cache: its summary and wall time."""
    import prefilter.glints.bake as gb
    from prefilter.glints.bake import BAKE_SETTINGS
    import prefilter.glints.render as gr
    from prefilter.render.scene import load_scene

    summaries = []

    def capture(normal_map, out, **kw):  # bake_if_missing, keeping the bake's summary
        summaries.append(gb.bake(normal_map, out, **kw))
        return True

    nm = load_scene(gr.measurement_scene(2.0, kind)).objects[0].material.normal_map.load()
    os.environ["PREFILTER_GLINTS_CACHE"] = tempfile.mkdtemp(prefix="bench-bake-")
    gr.bake_if_missing, saved = capture, gr.bake_if_missing  # what baked_surface calls
    try:
        t = time.perf_counter()
        gr.baked_surface(nm)
        wall = time.perf_counter() - t
    finally:
        gr.bake_if_missing = saved
    s = summaries[0]
    return dict(wall=wall, cp1=s["seconds_cp"][0], cp2=s["seconds_cp"][1],
                rest=s["seconds"] - sum(s["seconds_cp"]), mb=s["compressed_bytes"] / 1e6,
                pct=100 * s["ratio"], one_pass=bool(BAKE_SETTINGS.get("one_pass")))


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--kind", default="flakes", help="map of the whole bake")
    ap.add_argument("--no-bake", action="store_true", help="only the splat and level-0 timings")
    a = ap.parse_args()

    from prefilter.glints.bake import bilinear_bake_roughness
    from prefilter.glints.bake import BAKE_SETTINGS

    R = BAKE_SETTINGS["ndf_res"]
    sr = bilinear_bake_roughness(BAKE_SETTINGS["intrinsic_roughness"], BAKE_SETTINGS["support"],
                                 R)
    print(f"threads {os.environ.get('NUMBA_NUM_THREADS', 'all')}; render bake: NDF {R}^2, "
          f"block {BAKE_SETTINGS['block']}, baked roughness {sr:.4f}")
    print(f"splat at {R}^2: {bench_splat(R, sr):.0f} ns")
    for kind in ("flakes", "brushed"):
        ms = [bench_level0(kind, r, sr) for r in (256, 512)]
        print(f"level-0 NDF image, {kind}: {ms[0]:.1f} ms at 256^2, {ms[1]:.1f} ms at 512^2 "
              "(CPU per image)")
    if not a.no_bake:
        b = bench_bake(a.kind)
        # a one-pass bake interleaves its stages: no split (bench_glints_stages.py times them)
        split = ("" if b["one_pass"] else
                 f"; CP fit {b['cp1']:.1f} s, refit {b['cp2']:.1f} s, rest (mostly level-0 "
                 f"images) {b['rest']:.1f} s")
        print(f"render bake of {a.kind} 128^2: {b['wall']:.1f} s wall{split}; "
              f"{b['mb']:.1f} MB ({b['pct']:.2f} % of the uncompressed pyramid)")


if __name__ == "__main__":
    main()
