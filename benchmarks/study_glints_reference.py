"""Issue #9 acceptance, point-light cells: ``glints`` and ``glints-direct`` against
``glints-reference``, and the glint look against a smooth lobe (NDF images).

    python benchmarks/study_glints_reference.py --shapes plane --out ref_point.jsonl  # resumes
    python benchmarks/study_glints_reference.py --table ref_point.jsonl               # table only

Cells: those of ``study_glints_scenes.py --lights point`` (plane and sphere, the four glint maps
at 128^2, near / mid / far; 64x48). Per cell:

1. **Images.** HDR FLIP (:func:`prefilter.render.metrics.flip`) of ``glints`` and of
   ``glints-direct`` (1 spp, as shipped) against ``glints-reference`` at ``--spp N`` (seed 0) and
   against the mean of two N-spp references (seeds 0 and 1, i.e. 2N); a value that falls from N to
   2N is noise-limited. ``noise`` = FLIP between the two N-spp references. ``glints-reference``
   samples the *true* pixel Gaussian (an ellipse in texel space), while both methods use the
   isotropic Gaussian of the same area (:func:`prefilter.glints.render.footprints`); to separate
   that approximation from the methods' own errors, ``iso`` is a Monte Carlo reference of the
   isotropic footprint: the same point P-NDF (``sigma_p = 0``) at ``N`` texel positions drawn
   from the isotropic footprint Gaussian, with the pixel centre's view and light directions. Its
   expectation is ``glints-direct``'s closed form, so FLIP(``glints-direct``, ``iso``) is noise
   only. No registered method renders a plain smooth microfacet BRDF of these materials (``ltc``,
   ``reference`` and ``leadr-point`` shade GGX with the material's ``alpha`` and normal or height
   mip levels, not the glint map's footprint NDF), so the smooth comparison is on NDF images (2).
2. **NDF images** at ``--pixels`` hit pixels (half the brightest of the ``glints-direct`` image,
   half random, seeded): relative L2 error, against the direct P-NDF image
   (:func:`prefilter.glints.pndf_image`, pixel averages, 256^2 over ``[-1, 1]^2``, the render
   cache's intrinsic roughness), of (a) ``glints``' own NDF query at the pixel centres
   (:func:`prefilter.glints.brdf.glint_ndf` on the render's surface: resampled pyramid, bilinear
   lookup, truncated direct fallback below ``sigma_min``) and (b) the smooth lobe with the
   footprint NDF's mean and covariance (as :func:`prefilter.glints.render.ndf_errors`). Point
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
from study_glints_scenes import DISTANCES, KINDS, TARGET, coverage, scene  # noqa: E402

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


def matched_lobe(ref, X, Y, h):
    """Gaussian NDFs ``(K, R, R)`` with the mass, mean and covariance of the images ``ref
    (K, R, R)``: a plain smooth microfacet lobe with the footprint's moments (``ndf_errors``)."""
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


def line_nodes(J, spacing: float = 1.0, span: float = 4.0, max_nodes: int = 128):
    """Quadrature of the pixel Gaussian's texel ellipse as a line of isotropic Gaussians.

    The pixel Gaussian (std ``PIXEL_SIGMA`` px) maps through ``J (N, 2, 2)`` (texels per pixel)
    to the covariance ``PIXEL_SIGMA^2 J J^T = s_min^2 I + s_line^2 u1 u1^T`` (``J = U S V^T``,
    ``s_min = PIXEL_SIGMA S_1``, ``s_line = PIXEL_SIGMA sqrt(S_0^2 - S_1^2)``): the isotropic
    footprint of std ``s_min`` convolved with a 1D Gaussian along the major axis, which is
    reached by moving the sub-pixel position along ``v1`` by ``t / S_0`` pixels. The trapezoid
    rule over ``t`` in ``+-span s_line`` with nodes ``spacing sqrt(s_min^2 + sigma_h^2)`` apart
    (the P-NDF is smooth at that scale in the footprint centre) converges geometrically
    (plane, near brushed and mid gaussian: spacing 1 vs 0.25, FLIP 1e-4 / 4e-4).

    Returns ``pixel (M,)`` (index into ``J``), ``offset (M, 2)`` pixels, ``weight (M,)`` (sum 1
    per pixel) and ``s_min (N,)`` texels."""
    from prefilter.glints.pndf import SIGMA_H
    from prefilter.glints.render import PIXEL_SIGMA

    U, S, Vt = np.linalg.svd(J)
    s_min = PIXEL_SIGMA * S[:, 1]
    s_line = PIXEL_SIGMA * np.sqrt(np.maximum(S[:, 0] ** 2 - S[:, 1] ** 2, 0.0))
    h = spacing * np.sqrt(s_min**2 + SIGMA_H**2)
    k = np.clip(np.ceil(2.0 * span * s_line / h).astype(int) + 1, 1, max_nodes)
    pixel = np.repeat(np.arange(len(J)), k)
    start = np.cumsum(k) - k
    j = np.arange(pixel.size) - start[pixel]
    x = np.where(k[pixel] > 1, -span + 2.0 * span * j / np.maximum(k[pixel] - 1, 1), 0.0)
    w = np.exp(-0.5 * x * x)
    w /= np.bincount(pixel, w)[pixel]
    a = x * s_line[pixel] / np.maximum(S[pixel, 0], 1e-300)
    return pixel, a[:, None] * Vt[pixel, 0, :], w, s_min


def reference_expectation(sc, chunk: int = 1 << 15, **nodes) -> np.ndarray:
    """``(H, W, 3)``: the expectation of ``glints-reference`` without sampling, for point and
    directional lights (Yan et al. 2016's P-NDF is linear in the footprint weights): per pixel,
    :func:`line_nodes` positions (the exact G-buffer there: position, ``uv``, view and light
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
    pixel, off, w, s_min = line_nodes(J, **nodes)
    for k0 in range(0, pixel.size, chunk):
        p = pixel[k0:k0 + chunk]
        g = gbuffer_at(sc, xy.reshape(-1, 2)[hit[p]] + off[k0:k0 + chunk])
        m = g.hit & (g.object_id == oid[p])  # nodes off the object (or on another) are dark
        if np.any(m):
            rad = shade_glints(sc, g.select(m), mode="direct", sigma=s_min[p][m])
            np.add.at(out, hit[p[m]], rad * w[k0:k0 + chunk][m][:, None])
    return out.reshape(cam.height, cam.width, 3).astype(np.float32)


def _flip_pair(a, b, hit):
    from prefilter.render.metrics import flip

    f = flip(a, b)
    return [float(f.mean), float(f.error_map[hit].mean())]


def cell(shape: str, dist_name: str, kind: str, spp: int = REF_SPP, n_pixels: int = N_PIXELS,
         expectation: bool = False, seed: int = 0) -> dict:
    """One point-light cell (see the module docstring); FLIP values are ``[frame, object]``."""
    from prefilter.glints.render import baked_surface, footprints
    from prefilter.render.camera import gbuffer_at
    from prefilter.render.pipeline import render
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
        jobs.append(("exp", lambda: reference_expectation(sc)))
    for name, job in jobs:
        t0 = time.process_time()
        img[name] = job()
        cpu[name] = time.process_time() - t0
    img["ref2"] = 0.5 * (img["ref0"] + img["ref1"])
    row = dict(lights="point", shape=shape, distance=dist_name, map=kind, spp=spp,
               expectation=expectation, sigma_p_median=sp_med, object_pixels=float(hit.mean()),
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


def _pair(p, obj: bool) -> str:
    if p is None:
        return "-"
    txt = f"{p[0]:.3f}" + (f" ({p[1]:.3f})" if obj else "")
    return f"**{txt}**" if max(p) > TARGET else txt


def _cells(rows):
    """One row per cell: the one with the expectation if there is one, else the last."""
    by = {}
    for r in rows:
        k = (r["shape"], r["map"], r["distance"])
        if k not in by or r.get("expectation") or not by[k].get("expectation"):
            by[k] = r
    order = {d: i for i, d in enumerate(DISTANCES)}
    return sorted(by.values(), key=lambda r: (r["shape"] != "plane", KINDS.index(r["map"]),
                                              order[r["distance"]]))


def table(rows: list[dict]) -> str:
    """Markdown: one row per cell; FLIP ``frame (object pixels)`` where the background shows,
    bold over the 0.05 target; NDF errors are medians over the cell's footprints."""
    out = ["| shape | map | d | sigma_p | glints vs ref N / 2N | glints-direct vs ref N / 2N | "
           "ref noise (N vs N) | glints vs direct | direct / glints / ref 2N vs expectation | "
           "mean glints / direct / ref 2N vs exp. (or direct vs ref 2N) | "
           "NDF err compressed / smooth (median) | CPU s: glints / direct / ref N / exp. |",
           "|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for r in _cells(rows):
        obj = r["object_pixels"] < 0.999
        p = lambda k, r=r: _pair(r.get(k), obj)  # noqa: E731
        c = r["cpu"]
        if r.get("expectation"):
            ex = f"{p('flip_direct_exp')} / {p('flip_glints_exp')} / {p('flip_ref2_exp')}"
            mean = (f"{r['mean_glints_exp']:.3f} / {r['mean_direct_exp']:.3f} / "
                    f"{r['mean_ref2_exp']:.3f}")
        else:
            ex, mean = "-", f"- / {r['mean_direct_ref2']:.3f} / -"
        out.append(
            f"| {r['shape']} | {r['map']} | {r['distance']} | {r['sigma_p_median']:.1f} | "
            f"{p('flip_glints_ref0')} / {p('flip_glints_ref2')} | "
            f"{p('flip_direct_ref0')} / {p('flip_direct_ref2')} | {p('noise')} | "
            f"{p('flip_glints_direct')} | {ex} | {mean} | "
            f"{100 * r['ndf_compressed_median']:.1f} % / {100 * r['ndf_smooth_median']:.0f} % | "
            f"{c['glints']:.2f} / {c['direct']:.1f} / {c['ref0']:.0f} / "
            + (f"{c['exp']:.0f} |" if "exp" in c else "- |"))
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
    ap.add_argument("--out", default="glints_reference.jsonl")
    ap.add_argument("--table", default=None, help="only print the table of this .jsonl")
    a = ap.parse_args()
    if a.table:
        print(table([json.loads(x) for x in Path(a.table).read_text().splitlines() if x]))
        return
    out = Path(a.out)
    done = set()
    if out.exists():
        done = {(r["shape"], r["map"], r["distance"], r["spp"], r["expectation"]) for r in
                (json.loads(x) for x in out.read_text().splitlines() if x)}
    for shape in a.shapes.split(","):
        for kind in a.kinds.split(","):
            for dn in a.distances.split(","):
                if (shape, kind, dn, a.spp, a.expectation) in done:
                    continue
                r = cell(shape, dn, kind, a.spp, a.pixels, a.expectation)
                print(json.dumps(r), flush=True)
                with out.open("a") as fh:
                    fh.write(json.dumps(r) + "\n")
    print(table([json.loads(x) for x in out.read_text().splitlines() if x]))


if __name__ == "__main__":
    main()
