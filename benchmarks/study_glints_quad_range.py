"""Issue #9: the error of ``glints``' quad-light range path alone, variant by variant.

    python benchmarks/study_glints_quad_range.py --kind flakes --distance mid \
        --variants shipped-s4,resample-box,trilinear,final

For the plane of ``study_glints_scenes.py`` under its quad light: the specular radiance of
:func:`prefilter.glints.render.quad_range` (with the renderer's 2x2 then 4x4 patches) at the pixel
centres where it is valid, the deterministic reference elsewhere, against the reference: FLIP of
the range pixels alone, no Monte Carlo in either image. References
(:func:`prefilter.glints.reference.render_converged`): ``converged`` (direct P-NDF) and
``compressed`` (``glints``' point queries), cached as ``.npy`` in ``--cache`` (the plane's
``base_color`` is 0: they are the specular quad term). A variant sets render-module constants:
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import numpy as np

from study_glints_scenes import DISTANCES, scene

#: render-module constants per variant (the others as shipped)
VARIANTS = {
    "shipped-s4": dict(QUAD_INTERP="trilinear", QUAD_RECT="box", FILL_MIN=0.5),
    "trilinear": dict(QUAD_INTERP="trilinear", QUAD_RECT="equal-area", FILL_MIN=0.5),
    "resample-box": dict(QUAD_INTERP="resample", QUAD_RECT="box", FILL_MIN=0.5),
    "resample-fill0.5": dict(QUAD_INTERP="resample", QUAD_RECT="equal-area", FILL_MIN=0.5),
    "resample-4x4": dict(QUAD_INTERP="resample", QUAD_RECT="equal-area", FILL_MIN=0.5,
                         QUAD_SUB=4),
    "final": {},
}
__doc__ += "".join(f"``{k}``: {v or 'as shipped'}; " for k, v in VARIANTS.items())


def references(sc, key: str, cache: Path) -> dict:
    from prefilter.glints.reference import render_converged

    out = {}
    for ndf in ("direct", "compressed"):
        p = cache / f"{key}-{ndf}.npy"
        if not p.exists():
            p.parent.mkdir(parents=True, exist_ok=True)
            np.save(p, render_converged(sc, ndf=ndf))
        out["converged" if ndf == "direct" else ndf] = np.load(p)
    return out


def range_image(sc):
    """Range-path radiance ``(H, W, 3)`` at the pixel centres, its validity ``(H, W)`` and CPU
    seconds (the 2x2 patches, then 4x4 where those are too large, as ``shade_glints``)."""
    from prefilter.glints import render as R
    from prefilter.sphere.sampling import to_local
    from prefilter.render.camera import gbuffer_at

    cam = sc.camera
    xy = np.stack(np.meshgrid(np.arange(cam.width) + 0.5, np.arange(cam.height) + 0.5), -1)
    g0 = gbuffer_at(sc, xy).reshape(-1)
    g = g0.select(g0.hit)
    mat = sc.objects[0].material
    surf = R.baked_surface(mat.normal_map.load())
    c, sp = R.footprints(g, surf.shape)
    flp = np.where(np.sum(g.view * g.normal, -1) < 0.0, -1.0, 1.0)[:, None]
    t, b, n = g.tangent, g.bitangent * flp, g.normal * flp
    wo = to_local(g.view, t, b, n)
    wo /= np.linalg.norm(wo, axis=-1, keepdims=True)
    ql = sc.light_set().quads[0]
    corners = np.stack([to_local(v - g.position, t, b, n) for v in ql.vertices], 1)
    f0 = np.asarray(mat.f0, dtype=np.float64)
    t0 = time.process_time()
    val, done = R.quad_range(surf, c, sp, wo, corners, ql.radiance, f0)
    r = np.flatnonzero(~done & (sp >= surf.sigma_min))
    if r.size:
        v4, d4 = R.quad_range(surf, c[r], sp[r], wo[r], corners[r], ql.radiance, f0,
                              n_sub=2 * R.QUAD_SUB)
        val[r[d4]] = v4[d4]
        done[r[d4]] = True
    dt = time.process_time() - t0
    img = np.zeros((g0.hit.size, 3))
    m = np.zeros(g0.hit.size, bool)
    img[g0.hit], m[g0.hit] = val, done
    return img.reshape(cam.height, cam.width, 3), m.reshape(cam.height, cam.width), dt


def run(kind: str, dist: str, variant: str, cache: Path) -> dict:
    from prefilter.glints import render as R
    from prefilter.render.metrics import flip
    from prefilter.render.scene import load_scene

    sc = load_scene(scene("plane", DISTANCES[dist], kind, "quad"))
    refs = references(sc, f"plane-{dist}-{kind}", cache)
    old = {k: getattr(R, k) for k in VARIANTS[variant]}
    try:
        for k, v in VARIANTS[variant].items():
            setattr(R, k, v)
        range_image(sc)  # compile outside the timing
        img, m, dt = range_image(sc)
    finally:
        for k, v in old.items():
            setattr(R, k, v)
    row = dict(kind=kind, distance=dist, variant=variant, range_pixels=float(m.mean()),
               cpu_range=dt)
    for name, ref in refs.items():
        hyb = np.where(m[..., None], img, ref).astype(np.float32)
        row[f"flip_vs_{name}"] = float(flip(hyb, ref).mean)
        row[f"mean_vs_{name}"] = float(img[m].mean() / ref[m].mean())
    row["flip_compressed_vs_converged"] = float(flip(refs["compressed"], refs["converged"]).mean)
    return row


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--kind", default="flakes")
    ap.add_argument("--distance", default="mid", choices=list(DISTANCES))
    ap.add_argument("--variants", default=",".join(VARIANTS))
    ap.add_argument("--cache", default="quad_range_refs", help="directory of the references")
    a = ap.parse_args()
    for v in a.variants.split(","):
        print(json.dumps(run(a.kind, a.distance, v, Path(a.cache))), flush=True)


if __name__ == "__main__":
    main()
