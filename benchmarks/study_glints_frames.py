"""Frame times and accuracy of the glint render methods on the measurement scenes, and the NDF
error of the compressed query against the direct P-NDF and a smooth lobe.

    python benchmarks/study_glints_frames.py frames [KIND [LIGHTS]]  # glints vs glints-direct
    python benchmarks/study_glints_frames.py ndf                     # NDF images, smooth lobe

Scenes: :func:`prefilter.glints.render.measurement_scene` (a glinty plane at several distances).
"""

from __future__ import annotations

import json
import time

import numpy as np

from prefilter.glints import pndf_image
from prefilter.glints.bake import BAKE_SETTINGS
from prefilter.glints.brdf import glint_ndf
from prefilter.glints.render import baked_surface, measurement_scene, pixel_footprints
from prefilter.render.metrics import flip
from prefilter.render.driver import render
from prefilter.render.scene import load_scene
from prefilter.texture.procedural import normal_map


def measure(distances=(0.5, 2.0, 8.0), kind: str = "flakes", size: int = 128,
            ref_spp: int = 64, lights: str = "point") -> list[dict]:
    """Frame times (best of 2) of ``glints`` and ``glints-direct`` at each distance in one run,
    FLIP between them and against ``glints-reference`` (``ref_spp``)."""
    rows = []
    for d in distances:
        sc = load_scene(measurement_scene(d, kind, size, lights=lights))
        render(sc, "glints")  # bake / compile outside the timing
        t = {}
        img = {}
        for m in ("glints", "glints-direct"):
            best = np.inf
            for _ in range(2 if m == "glints" else 1):
                t0 = time.perf_counter()
                img[m] = render(sc, m)
                best = min(best, time.perf_counter() - t0)
            t[m] = best
        img["ref"] = render(sc, "glints-reference", spp=ref_spp)
        _, sp, _ = pixel_footprints(sc, (size, size))
        rows.append(dict(distance=d, sigma_p_median=float(np.median(sp)),
                         t_glints=t["glints"], t_direct=t["glints-direct"],
                         speedup=t["glints-direct"] / t["glints"],
                         flip_glints_direct=float(flip(img["glints"], img["glints-direct"]).mean),
                         flip_glints_ref=float(flip(img["glints"], img["ref"]).mean),
                         flip_direct_ref=float(flip(img["glints-direct"], img["ref"]).mean),
                         mean_ratio=float(img["glints"].mean() / img["glints-direct"].mean())))
        print(json.dumps(rows[-1]), flush=True)
    return rows


def matched_lobe(ref, X, Y, h):
    """Gaussian NDFs ``(K, R, R)`` with the mass, mean and covariance of the NDF images ``ref
    (K, R, R)`` (pixel centres ``X, Y (R, R)``, pitch ``h``): a plain smooth microfacet lobe with
    the footprint's moments, the comparison of "the glint look preserved" (issue #9)."""
    w = ref * h * h
    m = w.sum((1, 2))
    mx = (w * X).sum((1, 2)) / m
    my = (w * Y).sum((1, 2)) / m
    dx, dy = X - mx[:, None, None], Y - my[:, None, None]
    cxx = ((w * dx * dx).sum((1, 2)) / m)[:, None, None]
    cyy = ((w * dy * dy).sum((1, 2)) / m)[:, None, None]
    cxy = ((w * dx * dy).sum((1, 2)) / m)[:, None, None]
    det = cxx * cyy - cxy**2
    q = (cyy * dx * dx - 2.0 * cxy * dx * dy + cxx * dy * dy) / det
    return m[:, None, None] * np.exp(-0.5 * q) / (2.0 * np.pi * np.sqrt(det))


def ndf_errors(kinds=("gaussian", "brushed", "flakes", "scratches"), size: int = 64,
               sigmas=(4.0, 8.0, 16.0), n: int = 6, seed: int = 0) -> list[dict]:
    """Relative L2 error of NDF images against the direct P-NDF images (pixel averages) for
    ``n`` random footprints per size: the compressed query as ``glints`` renders it
    (:func:`prefilter.glints.brdf.glint_ndf` on the render cache's surface), and a smooth lobe (a
    Gaussian NDF of ``s`` with the footprint's mean and covariance: a plain microfacet model with
    matched moments)."""
    R, S = BAKE_SETTINGS["ndf_res"], BAKE_SETTINGS["support"]
    sr, h = BAKE_SETTINGS["intrinsic_roughness"], 2 * BAKE_SETTINGS["support"] / R
    x = (np.arange(R) + 0.5) * h - S
    X, Y = np.meshgrid(x, x)
    grid = np.stack([X, Y], -1)
    rng = np.random.default_rng(seed)
    rows = []
    for kind in kinds:
        nm = normal_map(kind, size=size, seed=1)
        surf = baked_surface(nm)
        row = {"map": kind, "bake_error": surf.gm.header["summary"]["rel_l2_error"]}
        for sp in sigmas:
            c = rng.uniform(0, size, (n, 2))
            ref = pndf_image(nm, c, sp, R, S, sr)
            got = glint_ndf(surf, c[:, None, None], sp, grid[None])
            smooth = matched_lobe(ref, X, Y, h)

            def err(a):
                d = np.linalg.norm((a - ref).reshape(n, -1), axis=1)
                return float(np.mean(d / np.linalg.norm(ref.reshape(n, -1), axis=1)))

            row[f"sigma_p={sp:g}"] = {"glints": err(got), "smooth": err(smooth)}
        print(json.dumps(row), flush=True)
        rows.append(row)
    return rows


if __name__ == "__main__":  # python benchmarks/study_glints_frames.py [frames KIND [LIGHTS] | ndf]
    import sys

    if len(sys.argv) > 1 and sys.argv[1] == "ndf":
        ndf_errors()
    else:
        measure(kind=sys.argv[2] if len(sys.argv) > 2 else "flakes",
                lights=sys.argv[3] if len(sys.argv) > 3 else "point")
