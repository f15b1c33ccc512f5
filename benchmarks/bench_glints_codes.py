"""Environment range queries vs the factor code widths.

    python benchmarks/bench_glints_codes.py [--kind flakes] [--distance 2.0] [--repeat 7]

Captures the ``query.range_multi`` call of one ``glints`` environment frame (the measurement
plane, render bake) and replays it, alternating, on the same map baked with other code widths
(:data:`prefilter.glints.bake.BAKE_SETTINGS` otherwise): all 8-bit; all 16-bit; 16-bit with
its ``a`` / ``b`` codes rescaled to 65535 steps of their maximum (uncapped code sums: uint32
prefix sums); and the render default (16-bit ``a``, ``b``, 8-bit ``c``). Prints
the best and median milliseconds per replay; run with ``NUMBA_NUM_THREADS=1`` for the kernel
alone on one core. Bakes go to the render cache (``$PREFILTER_GLINTS_CACHE``), ~2 min each when
missing.
"""

from __future__ import annotations

import argparse
import dataclasses
import time

import numpy as np


def _max_scaled(gm):
    """``gm`` with its ``a`` / ``b`` codes at 65535 steps of each row's maximum (the uncapped
    encoding of 16-bit rows; the loader's renormalisation makes it the same NDF)."""
    codes = dict(gm.codes)
    for k in ("a", "b"):
        f = codes[k].astype(np.float64)
        codes[k] = np.rint(65535 * f / np.maximum(f.max(axis=1, keepdims=True), 1.0)).astype(
            np.uint16)
    return dataclasses.replace(gm, codes=codes)


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--kind", default="flakes")
    ap.add_argument("--distance", type=float, default=2.0)
    ap.add_argument("--repeat", type=int, default=7)
    a = ap.parse_args()

    import prefilter.glints.envlight as envlight
    import prefilter.glints.render as gr
    from prefilter.glints.query import packed, range_multi
    from prefilter.render.driver import render
    from prefilter.render.scene import load_scene

    calls = []

    def capture(*args, **kw):
        calls.append((args, kw))
        return range_multi(*args, **kw)

    sc = load_scene(gr.measurement_scene(a.distance, a.kind, lights="environment"))
    envlight.range_multi = capture
    try:
        render(sc, "glints")
    finally:
        envlight.range_multi = range_multi
    (args, kw), = calls[-1:]
    nm = sc.objects[0].material.normal_map.load()
    maps = {"8-bit a, b, c": gr.baked_surface(nm, settings=dict(code_bits=8, c_bits=8)).gm}
    m16 = gr.baked_surface(nm, settings=dict(code_bits=16, c_bits=16)).gm
    maps["16-bit, a / b scaled to their maximum (uint32 prefix sums)"] = _max_scaled(m16)
    maps["16-bit a, b, c"] = m16
    maps["16-bit a, b, 8-bit c (render default)"] = gr.baked_surface(nm).gm
    times = {k: [] for k in maps}
    for gm in maps.values():
        range_multi(gm, *args[1:], **kw)  # compile and pack outside the timing
    for _ in range(a.repeat):
        for k, gm in maps.items():
            t0 = time.perf_counter()
            range_multi(gm, *args[1:], **kw)
            times[k].append(time.perf_counter() - t0)
    n, K = args[3].shape[:2]
    print(f"range_multi of one {a.kind} environment frame at distance {a.distance:g}: {n} "
          f"footprints x {K} rectangles, best / median of {a.repeat} (ms)")
    for k, gm in maps.items():
        pa = packed(gm)[0]
        print(f"  {k:58s} prefix {str(pa.dtype):6s} {1e3 * min(times[k]):7.1f} / "
              f"{1e3 * np.median(times[k]):7.1f}")


if __name__ == "__main__":
    main()
