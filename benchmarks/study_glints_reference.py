"""Issue #9 acceptance, point-light cells: ``glints`` and ``glints-direct`` against
``glints-reference``, and the glint look against a smooth lobe (NDF images).

    python benchmarks/study_glints_reference.py --expectation --out ref_point.jsonl  # resumes
    python benchmarks/study_glints_reference.py --expectation --shrink 0.3 --distances near \
        --out ref_point.jsonl                                   # + the finer expectation
    python benchmarks/study_glints_reference.py --table ref_point.jsonl  # table only
    python benchmarks/study_glints_reference.py --check --shapes plane --distances near \
        --kinds flakes                      # the expectation vs Monte Carlo at a few pixels

Cells: those of ``study_glints_scenes.py --lights point`` (plane and sphere, the four glint maps
at 128^2, near / mid / far; 64x48). Per cell:

1. **Images.** HDR FLIP (:func:`prefilter.render.metrics.flip`) of ``glints`` and of
   ``glints-direct`` (1 spp, as shipped) against ``glints-reference`` at ``--spp N`` (seed 0) and
   against the mean of two N-spp references (seeds 0 and 1, i.e. 2N); a value that falls from N
   to 2N is noise-limited. ``noise`` = FLIP between the two N-spp references.
   ``--expectation``: also the reference's expectation without sampling,
   :func:`reference_expectation` ``E(shrink)``: the pixel Gaussian as a quadrature of sub-pixel
   nodes, each with the closed-form isotropic P-NDF (Yan et al. 2016, linear in the footprint
   weights). ``E(1)`` splits off only the anisotropy of the pixel's texel ellipse (both methods
   use the isotropic Gaussian of the same area, :func:`prefilter.glints.render.footprints`), so
   FLIP(``glints-direct``, ``E(1)``) is that approximation's error alone; smaller ``shrink`` also
   lets the half vector vary across the pixel, as it does in ``glints-reference`` (both methods
   take it at the pixel centre; on the sphere's curvature ``E(0.3)`` is not converged yet).
   No registered method renders a plain smooth microfacet BRDF of
   these materials (``ltc``, ``reference`` and ``leadr-point`` shade GGX with the material's
   ``alpha`` and normal or height mip levels, not the glint map's footprint NDF), so the smooth
   comparison is on NDF images (2).
2. **NDF images** at ``--pixels`` hit pixels (half the brightest of the ``glints-direct`` image,
   half random, seeded per cell): relative L2 error, against the direct P-NDF image
   (:func:`prefilter.glints.pndf_image`, pixel averages, 256^2 over ``[-1, 1]^2``, the render
   cache's intrinsic roughness), of (a) ``glints``' own NDF query at the pixel centres
   (:func:`prefilter.glints.brdf.glint_ndf` on the render's surface: resampled pyramid, bilinear
   lookup, truncated direct fallback below ``sigma_min``) and (b) the smooth lobe with the
   footprint NDF's mean and covariance (as ``study_glints_frames.ndf_errors``). Point
   values vs pixel averages put a floor of a few % under (a) (below ``sigma_min`` (a) is that
   floor). The glint look is preserved when (a) << (b).

Rows are appended to ``--out`` as JSON lines as cells finish; cells already there are skipped.
CPU times are process times.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
import zlib
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from study_glints_scenes import (DISTANCES, KINDS, _flip_pair, _pair, coverage,  # noqa: E402
                                 scene)

REF_SPP = 1024
N_PIXELS = 8


# --------------------------------------------------------------------------------- NDF images


def ndf_grid(resolution: int, support: float):
    """Pixel centres ``X, Y (R, R)`` of an NDF image over ``[-support, support]^2`` and the
    pixel pitch (the layout of :func:`prefilter.glints.pndf_image`)."""
    h = 2.0 * support / resolution
    x = (np.arange(resolution) + 0.5) * h - support
    X, Y = np.meshgrid(x, x)
    return X, Y, h


def rel_l2(a, ref):
    """Relative L2 error ``(K,)`` of images ``a`` against ``ref`` (both ``(K, R, R)``)."""
    k = ref.shape[0]
    return (np.linalg.norm((a - ref).reshape(k, -1), axis=1)
            / np.linalg.norm(ref.reshape(k, -1), axis=1))


def ndf_image_errors(normal_map, surf, center, sigma_p, *, resolution: int = 256,
                     support: float = 1.0, roughness: float | None = None):
    """Relative L2 errors ``(compressed (K,), smooth (K,))`` of footprint NDF images against
    the direct P-NDF images (Yan et al. 2016; glints paper sec. 5.1 for the query).

    ``center (K, 2)`` texels, ``sigma_p (K,)`` texels; ``surf``: the :class:`GlintSurface`
    ``glints`` renders with (its point query, truncated direct fallback below ``sigma_min``);
    ``roughness``: the model's intrinsic roughness (default ``surf.intrinsic_roughness``)."""
    from prefilter.glints import pndf_image
    from prefilter.glints.brdf import FALLBACK_TRUNCATION, glint_ndf
    from study_glints_frames import matched_lobe

    sr = surf.intrinsic_roughness if roughness is None else roughness
    X, Y, h = ndf_grid(resolution, support)
    c = np.asarray(center, dtype=np.float64).reshape(-1, 2)
    sp = np.asarray(sigma_p, dtype=np.float64).reshape(-1)
    ref = pndf_image(normal_map, c, sp, resolution, support, sr)
    s = np.stack([X, Y], -1)
    got = np.stack([glint_ndf(surf, c[k], sp[k], s, fallback_truncation=FALLBACK_TRUNCATION)
                    for k in range(len(sp))])
    return rel_l2(got, ref), rel_l2(matched_lobe(ref, X, Y, h), ref)


def pick_pixels(image, hit, n: int, seed: int) -> np.ndarray:
    """Flat indices ``(<= n,)`` of hit pixels: the ``n // 2`` brightest of ``image (H, W, 3)``
    (the glints), then random other hit pixels (``seed``)."""
    lum = image.mean(-1).ravel()
    idx = np.flatnonzero(hit.ravel())
    bright = idx[np.argsort(lum[idx])[::-1][:n // 2]]
    rest = np.setdiff1d(idx, bright)
    rng = np.random.default_rng(seed)
    k = min(n - bright.size, rest.size)
    return np.concatenate([bright, rng.choice(rest, k, replace=False)])


# ------------------------------------------------------------------------------------- images


def pixel_nodes(J, shrink: float = 1.0, spacing: float = 1.0, span: float = 4.0,
                max_nodes: int = 4096):
    """Quadrature of the pixel Gaussian as a grid of sub-pixel nodes, each carrying an isotropic
    texel Gaussian (the closed-form P-NDF's footprint).

    The pixel Gaussian ``N(0, p^2 I)`` (``p = PIXEL_SIGMA`` px) maps through ``J (N, 2, 2)``
    (texels per pixel, ``J = U S V^T``) to the texel covariance ``p^2 J J^T``. Split it into an
    isotropic residual of std ``s_res = shrink p S_1`` texels and node offsets in pixels along
    ``v1`` / ``v2`` of stds ``p sqrt(1 - shrink^2 S_1^2 / S_0^2)`` / ``p sqrt(1 - shrink^2)``
    (the two add up to ``p^2 J J^T`` exactly). ``shrink = 1``: one line of nodes along the major
    axis (the anisotropy only); smaller: a 2D grid, so that the half vector, which the closed
    form holds fixed over the residual, varies between nodes as in ``glints-reference``
    (within the residual it spans ``shrink`` of the pixel's range). Nodes on the trapezoid grid
    ``+-span`` stds, ``spacing sqrt(s_res^2 + sigma_h^2)`` texels apart (the P-NDF is smooth at
    that scale in the footprint centre): converges geometrically (plane, near brushed and mid
    gaussian, ``shrink = 1``: spacing 1 vs 0.25, FLIP 1e-4 / 4e-4).

    Returns ``pixel (M,)`` (index into ``J``), ``offset (M, 2)`` pixels, ``weight (M,)`` (sum 1
    per pixel) and ``s_res (N,)`` texels."""
    from prefilter.glints.pndf import SIGMA_H
    from prefilter.glints.render import PIXEL_SIGMA

    _, S, Vt = np.linalg.svd(J)
    S0, S1 = S[:, 0], S[:, 1]
    s_res = PIXEL_SIGMA * shrink * S1
    a1 = PIXEL_SIGMA * np.sqrt(np.maximum(1.0 - (shrink * S1 / np.maximum(S0, 1e-300))**2, 0.0))
    a2 = np.full_like(S0, PIXEL_SIGMA * np.sqrt(max(1.0 - shrink * shrink, 0.0)))
    h = spacing * np.sqrt(s_res**2 + SIGMA_H**2)
    k1 = np.ceil(2.0 * span * S0 * a1 / h).astype(int) + 1
    k2 = np.ceil(2.0 * span * S1 * a2 / h).astype(int) + 1
    k2 = np.clip(k2, 1, max_nodes)
    k1 = np.clip(k1, 1, max_nodes // k2)
    k = k1 * k2
    pixel = np.repeat(np.arange(len(J)), k)
    j = np.arange(pixel.size) - (np.cumsum(k) - k)[pixel]

    def grid(i, n):  # trapezoid abscissae in stds
        return np.where(n > 1, -span + 2.0 * span * i / np.maximum(n - 1, 1), 0.0)

    x1, x2 = grid(j // k2[pixel], k1[pixel]), grid(j % k2[pixel], k2[pixel])
    w = np.exp(-0.5 * (x1 * x1 + x2 * x2))
    w /= np.bincount(pixel, w)[pixel]
    off = ((x1 * a1[pixel])[:, None] * Vt[pixel, 0, :]
           + (x2 * a2[pixel])[:, None] * Vt[pixel, 1, :])
    return pixel, off, w, s_res


def reference_expectation(sc, shrink: float = 1.0, chunk: int = 1 << 15,
                          **nodes) -> np.ndarray:
    """``(H, W, 3)``: the expectation of ``glints-reference`` without sampling, for point and
    directional lights (Yan et al. 2016's P-NDF is linear in the footprint weights): per pixel,
    :func:`pixel_nodes` positions (the exact G-buffer there: position, ``uv``, view and light
    directions), each shaded with the closed-form isotropic P-NDF of std ``s_min``. Left out:
    the variation of the half vector within the isotropic part and the curvature of ``uv``
    across the pixel."""
    from prefilter.glints.render import shade_glints
    from prefilter.render.camera import gbuffer_at

    cam = sc.camera
    xy = np.stack(np.meshgrid(np.arange(cam.width) + 0.5, np.arange(cam.height) + 0.5), -1)
    g0 = gbuffer_at(sc, xy).reshape(-1)
    hit = np.flatnonzero(g0.hit)
    out = np.zeros((cam.height * cam.width, 3))
    # texel Jacobians per pixel (each object's map size sets texel units)
    J = np.zeros((hit.size, 2, 2))
    oid = g0.object_id[hit]
    for j in np.unique(oid):
        hh, ww = sc.objects[int(j)].material.normal_map.load().shape[:2]
        J[oid == j] = g0.dudv[hit][oid == j] * np.array([ww, hh], dtype=np.float64)[:, None]
    pixel, off, w, s_min = pixel_nodes(J, shrink, **nodes)
    for k0 in range(0, pixel.size, chunk):
        p = pixel[k0:k0 + chunk]
        g = gbuffer_at(sc, xy.reshape(-1, 2)[hit[p]] + off[k0:k0 + chunk])
        m = g.hit & (g.object_id == oid[p])  # nodes off the object (or on another) are dark
        if np.any(m):
            rad = shade_glints(sc, g.select(m), mode="direct", sigma=s_min[p][m])
            np.add.at(out, hit[p[m]], rad * w[k0:k0 + chunk][m][:, None])
    return out.reshape(cam.height, cam.width, 3).astype(np.float32)


def pixel_mc(sc, pixels, samples: int, seed: int = 0):
    """``glints-reference``'s estimator at flat pixel indices ``pixels (K,)`` with ``samples``
    sub-pixel samples each: mean and standard error ``(K, 3)`` (a check of the expectation)."""
    from prefilter.glints.render import PIXEL_SIGMA, shade_glints
    from prefilter.render.camera import gbuffer_at

    rng = np.random.default_rng(seed)
    W = sc.camera.width
    mean, err = [], []
    for p in pixels:
        xy = np.array([p % W + 0.5, p // W + 0.5]) + rng.normal(0.0, PIXEL_SIGMA, (samples, 2))
        g = gbuffer_at(sc, xy)
        v = np.zeros((samples, 3))
        v[g.hit] = shade_glints(sc, g.select(g.hit), mode="direct", sigma=0.0)
        mean.append(v.mean(0))
        err.append(v.std(0) / np.sqrt(samples))
    return np.array(mean), np.array(err)


def half_vector_spread(sc) -> np.ndarray:
    """``|s(x + 0.5 e_x) - s(x)|`` and the same along ``y`` combined in quadrature ``(M,)`` at
    the hit pixel centres: how far the projected half vector moves over one std of the pixel
    Gaussian (``glints`` and ``glints-direct`` hold it at the centre); first point light."""
    from prefilter.render.camera import gbuffer_at

    cam = sc.camera
    xy = np.stack(np.meshgrid(np.arange(cam.width) + 0.5, np.arange(cam.height) + 0.5),
                  -1).reshape(-1, 2)
    light = np.asarray(sc.light_set().points[0].position, dtype=np.float64)

    def s_at(q):
        g = gbuffer_at(sc, q)
        wi = light - g.position
        h = wi / np.linalg.norm(wi, axis=-1, keepdims=True) + g.view
        h /= np.linalg.norm(h, axis=-1, keepdims=True)
        return np.stack([np.sum(h * g.tangent, -1), np.sum(h * g.bitangent, -1)], -1), g.hit

    s0, hit = s_at(xy)
    d2 = sum(np.sum((s_at(xy + e)[0] - s0) ** 2, -1) for e in ([0.5, 0.0], [0.0, 0.5]))
    return np.sqrt(d2[hit])


def check(shape: str, dist_name: str, kind: str, shrinks=(1.0, 0.5, 0.3), n: int = 8,
          samples: int = 20000) -> None:
    """Print, at the ``n // 2`` brightest pixels of ``E(min shrink)`` and ``n - n // 2`` random
    ones, ``glints-direct``, ``E(shrink)`` for each shrink and :func:`pixel_mc` (green)."""
    from prefilter.render.driver import render
    from prefilter.render.scene import load_scene

    sc = load_scene(scene(shape, DISTANCES[dist_name], kind, "point"))
    ds = half_vector_spread(sc)
    print(f"change of s over 0.5 px (x, y combined), hit pixels: median {np.median(ds):.4f}, "
          f"90 % {np.quantile(ds, 0.9):.4f}", flush=True)
    d = render(sc, "glints-direct")
    E = {}
    for sh in shrinks:
        t0 = time.process_time()
        E[sh] = reference_expectation(sc, sh)
        print(f"E({sh:g}): CPU {time.process_time() - t0:.1f} s", flush=True)
    _, hit = coverage(sc)
    pix = pick_pixels(E[min(shrinks)], hit, n, 0)
    mc, se = pixel_mc(sc, pix, samples)
    for k, p in enumerate(pix):
        y, x = divmod(int(p), sc.camera.width)
        es = " ".join(f"E({sh:g}) {E[sh][y, x, 1]:.4g}" for sh in shrinks)
        print(f"pixel ({x}, {y}): direct {d[y, x, 1]:.4g} {es} MC {mc[k, 1]:.4g} +- "
              f"{se[k, 1]:.2g}", flush=True)


def cell(shape: str, dist_name: str, kind: str, spp: int = REF_SPP, n_pixels: int = N_PIXELS,
         expectation: bool = False, shrink: float = 1.0, seed: int = 0) -> dict:
    """One point-light cell (see the module docstring); FLIP values are ``[frame, object]``."""
    from prefilter.glints.render import baked_surface, footprints
    from prefilter.render.camera import gbuffer_at
    from prefilter.render.driver import render
    from prefilter.render.scene import load_scene

    sc = load_scene(scene(shape, DISTANCES[dist_name], kind, "point"))
    render(sc, "glints")  # bake (disk cache) and compile outside the timing
    sp_med, hit = coverage(sc)
    img, cpu = {}, {}
    jobs = [("glints", lambda: render(sc, "glints")),
            ("direct", lambda: render(sc, "glints-direct")),
            ("ref0", lambda: render(sc, "glints-reference", spp=spp, seed=0)),
            ("ref1", lambda: render(sc, "glints-reference", spp=spp, seed=1))]
    if expectation:
        jobs.append(("exp", lambda: reference_expectation(sc, shrink)))
    for name, job in jobs:
        t0 = time.process_time()
        img[name] = job()
        cpu[name] = time.process_time() - t0
    img["ref2"] = 0.5 * (img["ref0"] + img["ref1"])
    row = dict(lights="point", shape=shape, distance=dist_name, map=kind, spp=spp,
               expectation=expectation, shrink=shrink if expectation else None,
               sigma_p_median=sp_med, object_pixels=float(hit.mean()),
               noise=_flip_pair(img["ref1"], img["ref0"], hit),
               flip_glints_direct=_flip_pair(img["glints"], img["direct"], hit), cpu=cpu)
    refs = ("ref0", "ref2", "exp") if expectation else ("ref0", "ref2")
    for m in ("glints", "direct"):
        for r in refs:
            row[f"flip_{m}_{r}"] = _flip_pair(img[m], img[r], hit)
            row[f"mean_{m}_{r}"] = float(img[m].mean() / img[r].mean())
    if expectation:
        row["flip_ref0_exp"] = _flip_pair(img["ref0"], img["exp"], hit)
        row["flip_ref2_exp"] = _flip_pair(img["ref2"], img["exp"], hit)
        row["mean_ref2_exp"] = float(img["ref2"].mean() / img["exp"].mean())
    # NDF images at a few footprints of the frame
    t0 = time.process_time()
    nm = sc.objects[0].material.normal_map.load()
    surf = baked_surface(nm)
    salt = zlib.crc32(f"{shape} {dist_name} {kind}".encode())
    pix = pick_pixels(img["direct"], hit, n_pixels, salt + seed)
    W = sc.camera.width
    g = gbuffer_at(sc, np.stack([pix % W + 0.5, pix // W + 0.5], -1).astype(np.float64))
    c, sp = footprints(g, surf.shape)
    comp, smooth = ndf_image_errors(nm, surf, c, sp)
    row.update(ndf_pixels=[int(p) for p in pix], ndf_sigma_p=[float(x) for x in sp],
               ndf_compressed=[float(x) for x in comp], ndf_smooth=[float(x) for x in smooth],
               ndf_compressed_median=float(np.median(comp)),
               ndf_smooth_median=float(np.median(smooth)), sigma_min=float(surf.sigma_min))
    cpu["ndf"] = time.process_time() - t0
    return row


# -------------------------------------------------------------------------------------- table


def _cells(rows):
    """Per cell ``(row, fine)``: the row with the line expectation (``shrink = 1``; else the
    last), and the row with the smallest ``shrink < 1`` (or None)."""
    by, fine = {}, {}
    for r in rows:
        k = (r["shape"], r["map"], r["distance"])
        sh = r.get("shrink") or 1.0
        if sh < 1.0:
            if k not in fine or sh <= fine[k]["shrink"]:
                fine[k] = r
        elif k not in by or r.get("expectation") or not by[k].get("expectation"):
            by[k] = r
    for k, r in fine.items():
        by.setdefault(k, r)
    order = {d: i for i, d in enumerate(DISTANCES)}
    keys = sorted(by, key=lambda k: (k[0] != "plane", KINDS.index(k[1]), order[k[2]]))
    return [(by[k], fine.get(k)) for k in keys]


def table(rows: list[dict]) -> str:
    """Markdown: one row per cell; FLIP ``frame (object pixels)`` where the background shows,
    bold over the 0.05 target; NDF errors are medians over the cell's footprints."""
    out = ["| shape | map | d | sigma_p | glints vs ref N / 2N | glints-direct vs ref N / 2N | "
           "ref noise (N vs N) | glints vs direct | direct vs E(1) | glints / direct / ref 2N "
           "vs E(s) | mean glints / direct vs ref 2N | mean ref 2N vs E(1) / E(s) | "
           "NDF err compressed / smooth (median) "
           "| CPU s: glints / direct / ref N / E(1) / E(s) |",
           "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for r, f in _cells(rows):
        obj = r["object_pixels"] < 0.999
        c = r["cpu"]

        def p(k, r=r):
            return _pair(r.get(k), obj)

        line = r.get("expectation") and (r.get("shrink") or 1.0) == 1.0
        e1 = p("flip_direct_exp") if line else "-"
        if f is not None:
            es = (f"{p('flip_glints_exp', f)} / {p('flip_direct_exp', f)} / "
                  f"{p('flip_ref2_exp', f)} (s={f['shrink']:g})")
        else:
            es = "-"
        mean = f"{r['mean_glints_ref2']:.3f} / {r['mean_direct_ref2']:.3f}"
        mean_e = ((f"{r['mean_ref2_exp']:.3f}" if line else "-") + " / "
                  + (f"{f['mean_ref2_exp']:.3f}" if f is not None else "-"))
        cpu = (f"{c['glints']:.2f} / {c['direct']:.1f} / {c['ref0']:.0f} / "
               + (f"{c['exp']:.0f}" if line else "-") + " / "
               + (f"{f['cpu']['exp']:.0f}" if f is not None else "-"))
        out.append(
            f"| {r['shape']} | {r['map']} | {r['distance']} | {r['sigma_p_median']:.1f} | "
            f"{p('flip_glints_ref0')} / {p('flip_glints_ref2')} | "
            f"{p('flip_direct_ref0')} / {p('flip_direct_ref2')} | {p('noise')} | "
            f"{p('flip_glints_direct')} | {e1} | {es} | {mean} | {mean_e} | "
            f"{100 * r['ndf_compressed_median']:.1f} % / {100 * r['ndf_smooth_median']:.0f} % | "
            f"{cpu} |")
    return "\n".join(out)


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--shapes", default="plane,sphere")
    ap.add_argument("--kinds", default=",".join(KINDS))
    ap.add_argument("--distances", default="near,mid,far")
    ap.add_argument("--spp", type=int, default=REF_SPP, help="glints-reference samples per pixel")
    ap.add_argument("--pixels", type=int, default=N_PIXELS, help="NDF footprints per cell")
    ap.add_argument("--expectation", action="store_true",
                    help="also the deterministic expectation of glints-reference (costly far)")
    ap.add_argument("--shrink", type=float, default=1.0,
                    help="--expectation: residual share of the pixel (1: anisotropy only)")
    ap.add_argument("--out", default="glints_reference.jsonl")
    ap.add_argument("--table", default=None, help="only print the table of this .jsonl")
    ap.add_argument("--check", action="store_true",
                    help="print E(1), E(0.5), E(0.3) and a Monte Carlo of glints-reference's "
                         "estimator at a few pixels of the first cell, then exit")
    a = ap.parse_args()
    if a.table:
        print(table([json.loads(x) for x in Path(a.table).read_text().splitlines() if x]))
        return
    if a.check:
        check(a.shapes.split(",")[0], a.distances.split(",")[0], a.kinds.split(",")[0])
        return
    out = Path(a.out)
    done = set()
    if out.exists():
        done = {(r["shape"], r["map"], r["distance"], r["spp"], r["expectation"],
                 r.get("shrink", 1.0)) for r in
                (json.loads(x) for x in out.read_text().splitlines() if x)}
    for shape in a.shapes.split(","):
        for kind in a.kinds.split(","):
            for dn in a.distances.split(","):
                if (shape, kind, dn, a.spp, a.expectation, a.shrink) in done:
                    continue
                r = cell(shape, dn, kind, a.spp, a.pixels, a.expectation, a.shrink)
                print(json.dumps(r), flush=True)
                with out.open("a") as fh:
                    fh.write(json.dumps(r) + "\n")
    print(table([json.loads(x) for x in out.read_text().splitlines() if x]))


if __name__ == "__main__":
    main()
