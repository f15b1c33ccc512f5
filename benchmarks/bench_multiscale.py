"""Multi-scale LTC: cost against ``ltc`` and (``--acceptance``) error against ``reference``.

Default (``make bench``): the shading time of ``ltc-multiscale`` divided by that of ``ltc`` on the
same normal-mapped view, both measured in this run (best of 9, interleaved, after a warm-up; wall
and process CPU time). The shading time is the whole method minus nothing: G-buffer, mip lookups,
roughness, table lookups, polygon integrals; ``ltc`` and the isotropic multi-scale methods run the
same fused kernel, the multi-scale roughness adds one norm, one table interpolation and one
square root per sample.

``--acceptance [--quick]``: the issue's scenes (the demo plane with three built-in normal maps,
micro roughness 0.03 and 0.3, camera at three distances: ~1, ~4 and ~16 texels per pixel, one quad
light). For each: RMSE and mean FLIP of ``ltc``, ``ltc-multiscale`` and ``ltc-multiscale-paper``
against ``reference``, and flicker over K = 8 jitters. The reference is two independent half-spp
renders: their difference estimates the reference's own noise, which is reported next to the
errors (``noise / error`` must stay below 0.1 for the numbers to count) and removed from the
squared RMSE (``RMSE_debiased^2 = RMSE^2 - noise^2``). ``--table PATH`` selects an LTC table.

``--study [--maps brushed,gaussian] [--variants ltc,ms,...]``: the issue-5 follow-up at the far /
mid / near distances: ``ltc``, ``ltc-multiscale`` (registered default and the paper's footprint,
``ms``), ``ltc-multiscale-aniso`` and both multi-scale methods with the anisotropic (multi-tap)
footprint, a LOD bias of one level, or a bias ramping in above 4 texels per pixel (:data:`STUDY`);
RMSE (debiased), FLIP and flicker per method, and the flicker of ``ltc`` on the same plane
*without* the normal map (the geometric floor: what a 1-spp shader flickers from the light's and
the plane's edges alone).
"""

from __future__ import annotations

import argparse
import json
import time

import numpy as np

import prefilter.multiscale  # noqa: F401  (registers the ltc-multiscale methods)
from prefilter.ltc.table import GGXTable
from prefilter.report.demo import showcase_scene
from prefilter.render.metrics import flicker, flip, jitter_offsets, rmse
from prefilter.render.driver import render

METHODS = ("ltc", "ltc-multiscale", "ltc-multiscale-paper")
#: Labels of method variants: label -> (registered method, its params).
VARIANTS = {"ltc-multiscale-paper": ("ltc-multiscale", {"footprint": "paper"})}


def render_method(sc, label: str, **kw) -> np.ndarray:
    """:func:`render` of a method name or a :data:`VARIANTS` label."""
    name, params = VARIANTS.get(label, (label, None))
    return render(sc, name, params=params, **kw)

#: The three built-in normal maps: isotropic Gaussian bumps, brushed, a structured (flakes) one.
MAPS = {
    "gaussian": {"rms_slope": 0.25, "corr_length": 3},
    "brushed": {"rms_slope": 0.25, "length": 64, "width": 1.5},
    "flakes": {"rms_slope": 0.25, "flake_size": 4},
}


def scene(distance: float, width: int, height: int, alpha: float, normal_map: str) -> dict:
    """The demo showcase with one of :data:`MAPS` (256^2 texels, seed 1)."""
    sc = showcase_scene(distance, width, height, alpha=alpha)
    sc["objects"][0]["material"]["normal_map"] = {"procedural": normal_map, "size": 256,
                                                  "seed": 1, **MAPS[normal_map]}
    return sc


def best_of(fn, repeats: int = 5) -> float:
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return min(times)


def bench_cost(table, width: int = 384, height: int = 240) -> None:
    from prefilter.multiscale.render import render_multiscale
    from prefilter.render.methods import RenderSettings
    from prefilter.render.scene import load_scene

    sc = scene(4.0, width, height, 0.03, "gaussian")
    loaded = load_scene(sc)
    runs = {m: (lambda m=m: render_method(loaded, m, table=table))
            for m in ("ltc", "ltc-multiscale", "ltc-multiscale-paper", "ltc-multiscale-aniso")}
    # ltc-multiscale without its anisotropic taps (the footprint before they became the default)
    runs["ms-notaps"] = lambda: render_multiscale(loaded, RenderSettings(table=table), taps=0)
    names = tuple(runs)
    for m in names:
        runs[m]()  # warm-up: textures, mips, Numba
    # interleave so load changes on the shared machine hit all alike; the process CPU time (all
    # threads) is reported too: it is less sensitive to other jobs than the wall time
    t = {m: [] for m in names}
    c = {m: [] for m in names}
    for _ in range(9):
        for m in names:
            c0, t0 = time.process_time(), time.perf_counter()
            runs[m]()
            t[m].append(time.perf_counter() - t0)
            c[m].append(time.process_time() - c0)
    best = {m: min(v) for m, v in t.items()}
    cpu = {m: min(v) for m, v in c.items()}
    print(f"showcase x4 {width}x{height}, alpha 0.03 (best of 9 each): "
          + ", ".join(f"{m} {best[m] * 1e3:.1f} ms (cpu {cpu[m] * 1e3:.1f})" for m in names))
    for m in names[1:]:
        pairs = np.median(np.array(t[m]) / np.array(t["ltc"]))
        print(f"  {m} / ltc: ratio of bests {best[m] / best['ltc']:.3f}, median ratio of "
              f"back-to-back pairs {pairs:.3f}, ratio of best CPU times "
              f"{cpu[m] / cpu['ltc']:.3f}")


def acceptance(table, quick: bool, seed: int = 0) -> list[dict]:
    # texels per pixel ~ distance * 160 / height for the demo camera
    width, height, spp = (64, 40, 64) if quick else (96, 60, 1024)
    k = 160.0 / height
    distances = {"near": 1.0 / k, "mid": 4.0 / k, "far": 16.0 / k}
    rows = []
    for nm in MAPS:
        for alpha in (0.03, 0.3):
            for name, d in distances.items():
                sc = scene(d, width, height, alpha, nm)
                t0 = time.perf_counter()
                r1 = render(sc, "reference", spp=spp // 2, seed=seed)
                r2 = render(sc, "reference", spp=spp // 2, seed=seed + 1)
                ref = 0.5 * (r1 + r2)
                noise = rmse(r1, r2) / 2.0  # std of the mean of two independent renders
                t_ref = time.perf_counter() - t0
                row = {"map": nm, "alpha": alpha, "distance": name, "noise": noise,
                       "t_ref": t_ref}
                jit = jitter_offsets(8)
                for m in METHODS:
                    img = render_method(sc, m, table=table)
                    e = rmse(img, ref)
                    frames = np.stack([render_method(sc, m, table=table, jitter=tuple(j))
                                       for j in jit])
                    row[m] = {"rmse": e, "rmse_debiased": float(np.sqrt(max(e * e - noise**2,
                                                                               0.0))),
                              "flip": flip(ref, img).mean, "flicker": flicker(frames)}
                rows.append(row)
                print(json.dumps(row), flush=True)
    return rows


def _variant(name: str, **kw):
    """A render function ``(scene_dict, jitter) -> image`` for a method variant."""
    from prefilter.render.methods import RenderSettings
    from prefilter.render.scene import load_scene

    def run(sc, table, jitter=(0.0, 0.0)):
        if not kw:
            return render_method(sc, name, table=table, jitter=jitter)
        mod = __import__("prefilter.multiscale." + ("aniso" if "aniso" in name else "render"),
                         fromlist=["x"])
        fn = mod.render_multiscale_aniso if "aniso" in name else mod.render_multiscale
        st = RenderSettings(table=table, jitter=tuple(float(x) for x in jitter))
        return np.asarray(fn(load_scene(sc), st, **kw), np.float32)
    return run


STUDY = {
    "ltc": _variant("ltc"),
    # the registered ltc-multiscale (its default footprint: "ms+taps" below, the ramped bias
    # "ramp2" plus anisotropic taps below 4 texels)
    "ms-default": _variant("ltc-multiscale"),
    # the paper's footprint: one isotropic mip level, no bias
    "ms": _variant("ltc-multiscale", lod_bias=0.0, lod_bias_start=None, taps=0),
    "ms-aniso": _variant("ltc-multiscale-aniso"),
    "ms+ewa": _variant("ltc-multiscale", anisotropic_footprint=True, lod_bias=0.0, taps=0,
                       lod_bias_start=None),
    "ms-aniso+ewa": _variant("ltc-multiscale-aniso", anisotropic_footprint=True),
    "ms+bias1": _variant("ltc-multiscale", lod_bias=1.0, lod_bias_start=None, taps=0),
    "ms-aniso+bias1": _variant("ltc-multiscale-aniso", lod_bias=1.0),
    # the bias ramps in above 4 texels per pixel: clip(lod - 2, 0, 1 or 2) levels
    "ms+ramp1": _variant("ltc-multiscale", lod_bias=1.0, lod_bias_start=2.0, taps=0),
    "ms+ramp2": _variant("ltc-multiscale", lod_bias=2.0, lod_bias_start=2.0, taps=0),
    # the registered footprint: ramp2 plus compiled anisotropic taps below 4 texels
    "ms+taps": _variant("ltc-multiscale", taps=4),
}


def study(table, maps, spp: int = 1024, seed: int = 0, width: int = 96, height: int = 60,
          variants=None):
    runs = {m: STUDY[m] for m in (variants or STUDY)}
    k = 160.0 / height
    jit = jitter_offsets(8)
    rows = []
    for nm in maps:
        for alpha in (0.03, 0.3):
            for name, d in {"near": 1.0 / k, "mid": 4.0 / k, "far": 16.0 / k}.items():
                sc = scene(d, width, height, alpha, nm)
                r1 = render(sc, "reference", spp=spp // 2, seed=seed)
                r2 = render(sc, "reference", spp=spp // 2, seed=seed + 1)
                ref, noise = 0.5 * (r1 + r2), rmse(r1, r2) / 2.0
                flat = scene(d, width, height, alpha, nm)
                del flat["objects"][0]["material"]["normal_map"]
                row = {"map": nm, "alpha": alpha, "distance": name, "noise": noise,
                       "flicker_flat_ltc": flicker(np.stack([render(flat, "ltc", table=table,
                                                                    jitter=tuple(j))
                                                             for j in jit]))}
                for label, run in runs.items():
                    img = run(sc, table)
                    e = rmse(img, ref)
                    row[label] = {"rmse": float(np.sqrt(max(e * e - noise**2, 0.0))),
                                  "flip": flip(ref, img).mean,
                                  "flicker": flicker(np.stack([run(sc, table, tuple(j))
                                                               for j in jit]))}
                rows.append(row)
                print(json.dumps(row), flush=True)
    print("\nmap alpha dist noise | RMSE " + " ".join(runs) + " | FLIP | flicker (+ flat ltc)")
    for r in rows:
        print(f"{r['map']} {r['alpha']} {r['distance']} {r['noise']:.4f} | "
              + " ".join(f"{r[m]['rmse']:.4f}" for m in runs) + " | "
              + " ".join(f"{r[m]['flip']:.3f}" for m in runs) + " | "
              + " ".join(f"{r[m]['flicker']:.4f}" for m in runs)
              + f" {r['flicker_flat_ltc']:.4f}")
    return rows


def summary(rows: list[dict]) -> None:
    print("\nmap        alpha dist | noise/err | RMSE ltc  ms   ratio | FLIP ltc  ms   ratio"
          " | flicker ltc  ms  ratio | paper RMSE FLIP")
    for r in rows:
        a, b, p = r["ltc"], r["ltc-multiscale"], r["ltc-multiscale-paper"]
        ne = r["noise"] / max(min(a["rmse_debiased"], b["rmse_debiased"]), 1e-12)
        print(f"{r['map']:10s} {r['alpha']:.2f} {r['distance']:4s} | {ne:9.3f} | "
              f"{a['rmse_debiased']:.4f} {b['rmse_debiased']:.4f} "
              f"{b['rmse_debiased'] / a['rmse_debiased']:.2f} | {a['flip']:.3f} {b['flip']:.3f} "
              f"{b['flip'] / a['flip']:.2f} | {a['flicker']:.4f} {b['flicker']:.4f} "
              f"{b['flicker'] / max(a['flicker'], 1e-12):.2f} | {p['rmse_debiased']:.4f} "
              f"{p['flip']:.3f}")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--acceptance", action="store_true")
    ap.add_argument("--quick", action="store_true")
    ap.add_argument("--table", default=None)
    ap.add_argument("--out", default=None, help="write the acceptance rows as JSON")
    ap.add_argument("--study", action="store_true", help="aniso / footprint study (no timing)")
    ap.add_argument("--maps", default="brushed,gaussian")
    ap.add_argument("--spp", type=int, default=1024)
    ap.add_argument("--variants", default=None,
                    help="comma-separated study variants (default: all of STUDY)")
    args = ap.parse_args()
    try:
        table = GGXTable.load(args.table)
    except Exception as exc:  # noqa: BLE001  (no table shipped yet: say so, do not crash make)
        print(f"skipped: no LTC table ({exc})")
        return
    if args.study:
        rows = study(table, args.maps.split(","), spp=args.spp,
                     variants=args.variants.split(",") if args.variants else None)
        if args.out:
            from prefilter.fileio import save_json_atomic

            save_json_atomic(args.out, rows)
        return
    bench_cost(table)
    if args.acceptance:
        rows = acceptance(table, args.quick)
        summary(rows)
        if args.out:
            from prefilter.fileio import save_json_atomic

            save_json_atomic(args.out, rows)


if __name__ == "__main__":
    main()
