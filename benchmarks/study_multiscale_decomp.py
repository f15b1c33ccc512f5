"""Where the multi-scale LTC error comes from: the LTC shader's own floor vs the filtering error.

The issue-5 scenes (``bench_multiscale.scene``: the demo plane, 256^2 normal map, one quad light;
near / mid / far = about 1 / 4 / 16 texels per pixel). Besides ``reference`` (true GGX BRDF,
Monte Carlo light, level-0 normals, 2 x ``spp/2`` stratified samples; its own noise is removed from
the RMSEs against it), the study renders

* ``ss``: the ``ltc`` shader with full-resolution (level-0, bilinear) normals, supersampled at
  ``--ss-spp`` stratified positions per pixel. It is what a perfect filter of an LTC shader with
  the micro roughness converges to, so ``RMSE(ss, reference)`` is the floor of the LTC
  approximation itself on the normal-mapped plane (a), and ``RMSE(method, ss)`` is the filtering
  error of a method (b);
* ``flat``: the plane without its normal map, ``ltc`` supersampled the same way vs ``reference``
  (the LTC floor without meso-scale structure) and the 1-spp ``ltc`` flicker (the edge floor);
* the methods: ``ltc`` (naive), ``ltc-multiscale`` (registered default), optionally the paper's
  footprint / formulas.

Flicker (K = 8 jitters): of every method, of ``ss`` (a converged LTC image: what is left is
the pixel integral's dependence on the jitter, zero for a perfect box filter of a smooth image)
and of ``reference`` at ``--ref-flicker-spp`` (its Monte Carlo noise adds to it; reported with
the same-seed noise level).

``python benchmarks/study_multiscale_decomp.py --maps gaussian,brushed,flakes --alphas 0.3
--distances far [--out F.json]``
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

import prefilter.multiscale  # noqa: E402,F401  (registers the ltc-multiscale methods)
from bench_multiscale import scene  # noqa: E402
from prefilter.ltc.table import GGXTable  # noqa: E402
from prefilter.render.metrics import flicker, jitter_offsets, rmse  # noqa: E402
from prefilter.render.driver import render  # noqa: E402

DISTANCES = {"near": 1.0, "mid": 4.0, "far": 16.0}  # texels per pixel


def render_ss(sc, table, spp: int, jitter=(0.0, 0.0)) -> np.ndarray:
    """The ``ltc`` shader with level-0 (full-resolution, bilinear) normals at ``spp`` stratified
    sub-pixel positions: the fused ``ltc`` kernel with the normal-map footprint scaled to nothing
    (``lod = log2(max(0 * major, 1)) = 0``), which equals ``surface_attributes(filtered=False)``
    + ``shade_ltc`` (checked to 4e-16 on the far Gaussian scene)."""
    from prefilter.ltc.render import render_ltc_fused
    from prefilter.render import kernels as kn
    from prefilter.render.methods import RenderSettings
    from prefilter.render.scene import Scene, load_scene

    s = sc if isinstance(sc, Scene) else load_scene(sc)
    read = kn.plain_read(len(s.objects))
    read[:, kn.READ_SCALE] = 0.0
    st = RenderSettings(spp=spp, table=table, jitter=tuple(float(x) for x in jitter))
    img = render_ltc_fused(s, st, s.light_set(), table, read)
    return np.asarray(img, np.float32)


def _ms_footprint(sc, table, jitter=(0.0, 0.0), **kw) -> np.ndarray:
    from prefilter.multiscale.render import render_multiscale
    from prefilter.render.methods import RenderSettings
    from prefilter.render.scene import load_scene

    st = RenderSettings(table=table, jitter=tuple(float(x) for x in jitter))
    return np.asarray(render_multiscale(load_scene(sc), st, **kw), np.float32)


METHODS = {
    "ltc": lambda sc, t, j=(0.0, 0.0): render(sc, "ltc", table=t, jitter=j),
    # ltc-multiscale with the paper's footprint (one isotropic mip level, no LOD bias)
    "ms0": lambda sc, t, j=(0.0, 0.0): _ms_footprint(sc, t, j, lod_bias=0.0,
                                                     lod_bias_start=None, taps=0),
    # the registered footprint before the anisotropic taps (LOD ramp only)
    "ms-notaps": lambda sc, t, j=(0.0, 0.0): _ms_footprint(sc, t, j, taps=0),
    # the anisotropic (multi-tap) footprint over the unnormalised mips, paper's LOD otherwise
    "ms+ewa": lambda sc, t, j=(0.0, 0.0): _ms_footprint(sc, t, j, anisotropic_footprint=True,
                                                        lod_bias=0.0, lod_bias_start=None),
    # a supersampled footprint: 8 x 8 normalised level-0 normals over the pixel (box_taps)
    "ms-box8": lambda sc, t, j=(0.0, 0.0): _ms_footprint(sc, t, j, box_taps=8),
    "ms": lambda sc, t, j=(0.0, 0.0): render(sc, "ltc-multiscale", table=t, jitter=j),
    # compiled anisotropic taps (2-4 along the major axis at the minor axis' LOD) for footprints
    # below 4 texels (where the LOD ramp is off; = the registered default "ms") / 16 / everywhere
    "ms+taps": lambda sc, t, j=(0.0, 0.0): _ms_footprint(sc, t, j, taps=4),
    "ms+taps8": lambda sc, t, j=(0.0, 0.0): _ms_footprint(sc, t, j, taps=8),
    "ms+taps-all": lambda sc, t, j=(0.0, 0.0): _ms_footprint(sc, t, j, taps=4,
                                                             taps_below=np.inf),
    "ms+taps-r2": lambda sc, t, j=(0.0, 0.0): _ms_footprint(sc, t, j, taps=4, taps_ratio=2.0),
    # ... with each tap's level-0 read renormalised (no bilinear shortening)
    "ms+taps-n": lambda sc, t, j=(0.0, 0.0): _ms_footprint(sc, t, j, taps=4,
                                                           taps_normalize=True),
    "ms+taps-all-n": lambda sc, t, j=(0.0, 0.0): _ms_footprint(sc, t, j, taps=4,
                                                               taps_below=np.inf,
                                                               taps_normalize=True),
    "ms+taps16": lambda sc, t, j=(0.0, 0.0): _ms_footprint(sc, t, j, taps=4, taps_below=16.0),
    "ms+taps16-n": lambda sc, t, j=(0.0, 0.0): _ms_footprint(sc, t, j, taps=4, taps_below=16.0,
                                                             taps_normalize=True),
    "ms+taps-all8": lambda sc, t, j=(0.0, 0.0): _ms_footprint(sc, t, j, taps=8,
                                                              taps_below=np.inf),
    "paper": lambda sc, t, j=(0.0, 0.0): render(sc, "ltc-multiscale", table=t, jitter=j,
                                                  params={"footprint": "paper"}),
}


def _debiased(e: float, noise: float) -> float:
    return float(np.sqrt(max(e * e - noise * noise, 0.0)))


def study_scene(table, nm: str, alpha: float, dist: str, *, width: int = 96, height: int = 60,
                spp: int = 1024, ss_spp: int = 256, ref_flicker_spp: int = 0, methods=None,
                extra=None, seed: int = 0, cache=None) -> dict:
    k = 160.0 / height
    sc = scene(DISTANCES[dist] / k, width, height, alpha, nm)
    jit = jitter_offsets(8)
    t0 = time.perf_counter()
    if cache:  # the method-independent part (reference, ss, flat plane) from an earlier run
        # no dots in the stem (alpha 0.03 and 0.3 must not share a file)
        stem = (f"{nm}_{alpha:g}_{dist}_{width}x{height}_{spp}_{ss_spp}_{ref_flicker_spp}_"
                f"{seed}").replace(".", "p")
        npz, meta = Path(cache) / f"{stem}.npz", Path(cache) / f"{stem}.json"
        if npz.exists() and meta.exists():
            with np.load(npz) as z:
                ref, ss = z["ref"], z["ss"]
            row = json.loads(meta.read_text())
            return _methods_into(row, sc, table, ref, ss, row["noise"], jit, methods, extra, t0)
    row, ref, ss = _base_row(table, sc, nm, alpha, dist, width, height, spp, ss_spp,
                             ref_flicker_spp, seed, jit)
    if cache:
        npz.parent.mkdir(parents=True, exist_ok=True)
        np.savez(npz, ref=ref, ss=ss)
        meta.write_text(json.dumps(row))
    return _methods_into(row, sc, table, ref, ss, row["noise"], jit, methods, extra, t0)


def _base_row(table, sc, nm, alpha, dist, width, height, spp, ss_spp, ref_flicker_spp, seed,
              jit):
    k = 160.0 / height
    flat = scene(DISTANCES[dist] / k, width, height, alpha, nm)
    del flat["objects"][0]["material"]["normal_map"]
    r1 = render(sc, "reference", spp=spp // 2, seed=seed)
    r2 = render(sc, "reference", spp=spp // 2, seed=seed + 1)
    ref, noise = 0.5 * (r1 + r2), rmse(r1, r2) / 2.0
    f1 = render(flat, "reference", spp=spp // 2, seed=seed)
    f2 = render(flat, "reference", spp=spp // 2, seed=seed + 1)
    fref, fnoise = 0.5 * (f1 + f2), rmse(f1, f2) / 2.0
    ss = render_ss(sc, table, ss_spp)
    fss = render_ss(flat, table, ss_spp)
    row = {"map": nm, "alpha": alpha, "distance": dist, "noise": noise, "flat_noise": fnoise,
           "mean_ref": float(ref.mean()), "mean_ss": float(ss.mean()),
           "ss_vs_ref": _debiased(rmse(ss, ref), noise),
           "flat_ss_vs_ref": _debiased(rmse(fss, fref), fnoise),
           "flat_ltc_vs_ref": _debiased(rmse(render(flat, "ltc", table=table), fref), fnoise),
           "flicker_ss": flicker(np.stack([render_ss(sc, table, ss_spp, j) for j in jit])),
           "flicker_flat_ltc": flicker(np.stack([render(flat, "ltc", table=table, jitter=j)
                                                 for j in jit])),
           "flicker_flat_ss": flicker(np.stack([render_ss(flat, table, ss_spp, j)
                                                for j in jit]))}
    if ref_flicker_spp:
        frames = np.stack([render(sc, "reference", spp=ref_flicker_spp, seed=seed, jitter=j)
                           for j in jit])
        row["flicker_ref"] = flicker(frames)
        row["ref_flicker_spp"] = ref_flicker_spp
    return row, ref, ss


def _methods_into(row, sc, table, ref, ss, noise, jit, methods, extra, t0) -> dict:
    runs = {m: METHODS[m] for m in (methods or ("ltc", "ms"))}
    runs.update(extra or {})
    for m, fn in runs.items():
        img = fn(sc, table)
        row[m] = {"vs_ref": _debiased(rmse(img, ref), noise), "vs_ss": float(rmse(img, ss)),
                  "mean": float(img.mean()),
                  "flicker": flicker(np.stack([fn(sc, table, tuple(j)) for j in jit]))}
    row["seconds"] = time.perf_counter() - t0
    return row


def render_ms_scaled(sc, table, s: float) -> np.ndarray:
    """``ltc-multiscale`` (registered footprint) with ``alpha_meso`` scaled by ``s`` (its table
    times ``s``): how much meso-scale broadening the images want."""
    from prefilter.ltc.render import render_ltc_fused
    from prefilter.multiscale.kernels import multiscale_samples_kernel
    from prefilter.multiscale.render import (LOD_BIAS, LOD_BIAS_START, TAPS, TAPS_BELOW,
                                             TAPS_RATIO, multiscale_roughness, normal_read)
    from prefilter.render.methods import RenderSettings
    from prefilter.render.scene import load_scene

    sl = load_scene(sc)
    read = normal_read(sl.objects, LOD_BIAS, LOD_BIAS_START, TAPS, TAPS_BELOW, TAPS_RATIO)
    rows, tab = multiscale_roughness(sl.objects, "exact", "fit")
    img = render_ltc_fused(sl, RenderSettings(table=table), sl.light_set(), table, read,
                           multiscale_samples_kernel, (rows, tab * s))
    return np.asarray(img, np.float32)


SCALES = (0.0, 0.25, 0.5, 0.75, 1.0, 1.25, 1.5)
FLAT_ALPHAS = (0.26, 0.3, 0.32, 0.34, 0.36, 0.38, 0.4)


def scan_scene(table, nm: str, alpha: float, dist: str, *, width: int = 96, height: int = 60,
               spp: int = 1024, ss_spp: int = 256, flat_alphas=FLAT_ALPHAS,
               seed: int = 0) -> dict:
    """RMSE against ``reference`` and ``ss`` of (1) ``ltc-multiscale`` with ``alpha_meso``
    scaled by each of :data:`SCALES` and (2) the plane *without* normal map shaded at a single
    roughness ``a`` (``flat_alphas``) by the true GGX BRDF (``reference``, 256 spp) and by the
    LTC table (``ltc`` supersampled): which single lobe the normal-mapped plane looks like under
    the exact BRDF and under the LTC shader."""
    k = 160.0 / height
    sc = scene(DISTANCES[dist] / k, width, height, alpha, nm)
    r1 = render(sc, "reference", spp=spp // 2, seed=seed)
    r2 = render(sc, "reference", spp=spp // 2, seed=seed + 1)
    ref, noise = 0.5 * (r1 + r2), rmse(r1, r2) / 2.0
    ss = render_ss(sc, table, ss_spp)
    row = {"map": nm, "alpha": alpha, "distance": dist, "noise": noise, "scale": {},
           "flat": {}}
    for s in SCALES:
        img = render_ms_scaled(sc, table, s)
        row["scale"][s] = {"vs_ref": _debiased(rmse(img, ref), noise),
                           "vs_ss": float(rmse(img, ss))}
    for a in flat_alphas or ():
        flat = scene(DISTANCES[dist] / k, width, height, a, nm)
        del flat["objects"][0]["material"]["normal_map"]
        g = render(flat, "reference", spp=256, seed=seed + 2)
        lt = render_ss(flat, table, 16)
        row["flat"][a] = {"ggx_vs_ref": float(rmse(g, ref)), "ltc_vs_ref": float(rmse(lt, ref)),
                          "ltc_vs_ss": float(rmse(lt, ss)), "mean_ggx": float(g.mean()),
                          "mean_ltc": float(lt.mean())}
    return row


def print_tables(rows, methods) -> None:
    print("\nRMSE: map alpha dist | noise | (a) flat ss-ref, flat ltc-ref, ss-ref | (b) "
          + " ".join(f"{m}-ss" for m in methods) + " | total " + " ".join(
              f"{m}-ref" for m in methods) + " | means ref ss " + " ".join(methods))
    for r in rows:
        print(f"{r['map']} {r['alpha']} {r['distance']} | {r['noise']:.4f} | "
              f"{r['flat_ss_vs_ref']:.4f} {r['flat_ltc_vs_ref']:.4f} {r['ss_vs_ref']:.4f} | "
              + " ".join(f"{r[m]['vs_ss']:.4f}" for m in methods) + " | "
              + " ".join(f"{r[m]['vs_ref']:.4f}" for m in methods) + " | "
              + f"{r['mean_ref']:.4f} {r['mean_ss']:.4f} "
              + " ".join(f"{r[m]['mean']:.4f}" for m in methods))
    print("\nflicker: map alpha dist | ref(spp) ss flat-ltc flat-ss | " + " ".join(methods))
    for r in rows:
        fr = (f"{r['flicker_ref']:.4f}({r['ref_flicker_spp']})" if "flicker_ref" in r
              else "-")
        print(f"{r['map']} {r['alpha']} {r['distance']} | {fr} {r['flicker_ss']:.4f} "
              f"{r['flicker_flat_ltc']:.4f} {r['flicker_flat_ss']:.4f} | "
              + " ".join(f"{r[m]['flicker']:.4f}" for m in methods))


def print_scan(rows) -> None:
    print("\nalpha_meso scale s: RMSE vs reference / vs ss")
    for r in rows:
        print(f"{r['map']} {r['alpha']} {r['distance']} | " + " ".join(
            f"s{s}: {v['vs_ref']:.4f}/{v['vs_ss']:.4f}" for s, v in r["scale"].items()))
    print("\nflat plane at one roughness a: GGX vs ref | LTC vs ref | LTC vs ss | means GGX LTC")
    for r in rows:
        for a, v in r["flat"].items():
            print(f"{r['map']} {r['alpha']} {r['distance']} a={a} | {v['ggx_vs_ref']:.4f} | "
                  f"{v['ltc_vs_ref']:.4f} | {v['ltc_vs_ss']:.4f} | {v['mean_ggx']:.4f} "
                  f"{v['mean_ltc']:.4f}")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--maps", default="gaussian,brushed,flakes")
    ap.add_argument("--alphas", default="0.3")
    ap.add_argument("--distances", default="far")
    ap.add_argument("--methods", default="ltc,ms")
    ap.add_argument("--spp", type=int, default=1024)
    ap.add_argument("--ss-spp", type=int, default=256)
    ap.add_argument("--ref-flicker-spp", type=int, default=0)
    ap.add_argument("--table", default=None)
    ap.add_argument("--out", default=None)
    ap.add_argument("--cache", default=None,
                    help="directory keeping each scene's reference / ss / flat-plane results")
    ap.add_argument("--scan", action="store_true",
                    help="alpha_meso scale scan and single-lobe flat planes instead")
    args = ap.parse_args()
    table = GGXTable.load(args.table)
    methods = args.methods.split(",")
    rows = []
    for nm in args.maps.split(","):
        for alpha in (float(a) for a in args.alphas.split(",")):
            for dist in args.distances.split(","):
                if args.scan:
                    row = scan_scene(table, nm, alpha, dist, spp=args.spp, ss_spp=args.ss_spp,
                                     flat_alphas=FLAT_ALPHAS if alpha >= 0.1 else None)
                    rows.append(row)
                    print(json.dumps(row), flush=True)
                    continue
                row = study_scene(table, nm, alpha, dist, spp=args.spp, ss_spp=args.ss_spp,
                                  ref_flicker_spp=args.ref_flicker_spp, methods=methods,
                                  cache=args.cache)
                rows.append(row)
                print(json.dumps(row), flush=True)
    if args.scan:
        print_scan(rows)
    else:
        print_tables(rows, methods)
    if args.out:
        from prefilter.fileio import save_json_atomic

        save_json_atomic(args.out, rows)


if __name__ == "__main__":
    main()
