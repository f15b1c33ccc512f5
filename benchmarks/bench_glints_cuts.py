"""Element and footprint cuts of the level-0 NDF images: their cost and what they change.

    python benchmarks/bench_glints_cuts.py

One level-0 cell (8 x 8 footprints, rows / columns 8-15 of centres) of each normal map of
docs/scenes.md's "A full example", its NDF images at the render bake's resolution and roughness
(:func:`prefilter.glints.bake.bake_settings`) for several ``(ndf_truncation,
footprint_truncation)`` pairs (float32 sums, as the bakes). Prints per pair the wall time of the
64 images (the kernel is parallel) and, against the pair of ``BAKE_SETTINGS``, the relative L2
difference of the images and their largest pixel difference over the image's peak. The numbers
behind ``BAKE_SETTINGS``' cuts (``footprint_truncation`` 5: the images move by < 1e-6; the
element cut moves them by ~1e-3 at any value, as its line nodes move with it).
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from bench_glints_cold import docs_example_maps  # noqa: E402

PAIRS = ((6.0, 6.0), (6.0, 5.0), (6.0, 4.0), (5.0, 5.0), (4.5, 5.0), (7.0, 5.0))


def main() -> None:
    from prefilter.glints.bake import BAKE_SETTINGS, bake_settings
    from prefilter.glints.pndf import pndf_image
    from prefilter.glints.pyramid import plan

    ref_pair = (BAKE_SETTINGS["ndf_truncation"], BAKE_SETTINGS["footprint_truncation"])
    for kind, nm in docs_example_maps().items():
        st = bake_settings(nm.shape)
        pyr = plan(nm.shape[0], nm.shape[1], st["stride0"], None, None)
        centres = pyr.centers(0)[8:16, 8:16]

        def images(nt, ft):
            return pndf_image(nm, centres, pyr.sigma(0), st["ndf_res"], st["support"],
                              st["intrinsic_roughness"], ndf_truncation=nt,
                              footprint_truncation=ft, dtype=np.float32)

        images(*ref_pair)  # compile outside the timing
        ref = images(*ref_pair).astype(np.float64)
        peak = ref.max(axis=(-1, -2), keepdims=True)
        print(f"{kind} {nm.shape[0]}^2, one level-0 cell (64 images); "
              f"against the render bake's cuts {ref_pair[0]:g} / {ref_pair[1]:g}:")
        print("| element / footprint cut (stds) | wall s | rel. L2 | max / peak |")
        print("|---|---|---|---|")
        for nt, ft in PAIRS:
            t0 = time.perf_counter()
            im = images(nt, ft).astype(np.float64)
            dt = time.perf_counter() - t0
            rel = np.linalg.norm(im - ref) / np.linalg.norm(ref)
            worst = np.max(np.abs(im - ref) / peak)
            print(f"| {nt:g} / {ft:g} | {dt:.2f} | {rel:.1e} | {worst:.1e} |")


if __name__ == "__main__":
    main()
