"""The tile-type shares regime of ``glints-wang`` against the direct P-NDF: with the in-tile
moments (``wang_ndf.type_moments``, the default), with the shares alone (``moment_sat=None``) and
the expected tiling, NDF image relative L2 error, mean (max) over random footprint centres.

Maps and settings of docs/glints-wang.md's "Measurements": ``hf`` =
``tests/glints/maps.gaussian_heightfield(128, corr=3, slope_std=0.15, seed=2)``, ``sin`` =
``sinusoid(64, 0.25, 0.2, 16, 8)``; ``synthesize(tile=T, band=T/8, rng=1)``, support 0.5,
sigma_r 0.01, R = 2T, uncompressed; ``--centres`` random centres in [-1000, 1000]^2 (seed 0).

Run: ``python benchmarks/study_glints_wang_shares.py [--centres 6]`` (~2 min): one markdown row
per (map, T, footprint std).
"""

from __future__ import annotations

import argparse
import sys
from dataclasses import replace
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests" / "glints"))


def main(argv=None):
    from maps import gaussian_heightfield, sinusoid

    from prefilter.glints.wang import pndf_image_implicit, synthesize
    from prefilter.glints.wang_ndf import bake_tiles, ndf_image

    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--centres", type=int, default=6)
    args = ap.parse_args(argv)
    maps = {"hf": gaussian_heightfield(128, corr=3.0, slope_std=0.15, seed=2)[0],
            "sin": sinusoid(64, 0.25, 0.2, 16, 8)}
    print("| map, T | sigma_p | moments (default) | shares alone | expected tiling |")
    print("|---|---|---|---|---|")
    for name, T in (("hf", 16), ("sin", 16), ("hf", 32)):
        wt = synthesize(maps[name], tile=T, band=T / 8, rng=1)
        R = 2 * T
        wn = bake_tiles(wt, ndf_res=R, support=0.5, intrinsic_roughness=0.01, wide_tiles=0.25,
                        uniform_tiles=64.0)
        plain = replace(wn, moment_sat=None)
        rng = np.random.default_rng(0)
        for frac in (0.25, 0.375, 0.5, 1.0, 2.0):
            sp = frac * T
            errs = {"m": [], "s": [], "u": []}
            for c in rng.uniform(-1000, 1000, (args.centres, 2)):
                d = pndf_image_implicit(wt, c, sp, R, 0.5, 0.01)
                nd = np.linalg.norm(d)
                errs["m"].append(np.linalg.norm(ndf_image(wn, c, sp) - d) / nd)
                errs["s"].append(np.linalg.norm(ndf_image(plain, c, sp) - d) / nd)
                errs["u"].append(np.linalg.norm(wn.mean - d) / nd)
            cells = [f"{np.mean(v):.3f} ({np.max(v):.3f})" for v in errs.values()]
            print(f"| {name}, {T} | {frac:g} T | " + " | ".join(cells) + " |", flush=True)


if __name__ == "__main__":
    main()
