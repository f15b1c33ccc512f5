"""Lit colour maps (``colormap-lit``): far-field error of the filtered and naive colours against
32 x 32 supersampling of the same lit shading, per driver (texture, noise, height, slope and the
section-6 linear / product combinations) and light rig (``sun``: a directional and a point light;
``quad``; ``env``: an environment map), on the plane at 0 and 70 degrees and the sphere of
``prefilter.studies.colormap`` (30-50 texels per pixel). Prints a Markdown table; targets from
Heitz et al. 2013: filtered error <= 0.25x naive for textures and noise, <= 0.5x for heights,
slopes and their combinations. No assertions.

    python benchmarks/bench_colormap_lit.py [--size 32] [--nref 32] [--rigs sun,quad,env]
"""

from __future__ import annotations

import argparse
import time

from prefilter.report.colormap_lit import DRIVERS, FAR_CONFIGS, format_rows, measure


def main(argv=None) -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--size", type=int, default=32, help="image side (pixels)")
    p.add_argument("--nref", type=int, default=32, help="reference samples per pixel side")
    p.add_argument("--rigs", default="sun,quad,env", help="light rigs, comma-separated")
    p.add_argument("--drivers", default=",".join(DRIVERS), help="drivers, comma-separated")
    a = p.parse_args(argv)
    t0 = time.perf_counter()
    rows = measure(FAR_CONFIGS, tuple(a.drivers.split(",")), tuple(a.rigs.split(",")),
                   size=a.size, n_ref=a.nref,
                   log=lambda r: print(f"# {r['shape']} {r['view_deg']:.0f} {r['rig']} "
                                       f"{r['driver']}: ratio {r['ratio']:.3f}", flush=True))
    print(format_rows(rows))
    print(f"\n{a.size} x {a.size} pixels, {a.nref} x {a.nref} reference samples per pixel; "
          f"{time.perf_counter() - t0:.0f} s")


if __name__ == "__main__":
    main()
