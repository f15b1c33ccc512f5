"""Issue #9's acceptance matrix: FLIP of ``glints`` vs ``glints-direct`` and frame wall times.

    python benchmarks/study_glints_scenes.py --lights point            # 2 shapes x 4 maps x 3 d
    python benchmarks/study_glints_scenes.py --lights quad --out m.jsonl   # appends, resumes
    python benchmarks/study_glints_scenes.py --lights quad,environment --floor  # + MC floor
    python benchmarks/study_glints_scenes.py --table m.jsonl           # only print the table
    python benchmarks/study_glints_scenes.py --reference --lights quad,environment \
        --shapes plane --distances mid --out ref.jsonl                 # against converged refs
    python benchmarks/study_glints_scenes.py --reference --table ref.jsonl

Scenes: the plane of :func:`prefilter.glints.render.measurement_scene` (camera and light scaled
with the distance, so only the footprint changes), and a sphere of radius ``0.25 d`` at the same
place under the same lights, textured at the plane's density (4 map repeats per unit length,
``uv_scale`` rounded to whole repeats so the ``phi`` seam is continuous). Maps: the four
procedural glint maps, 128^2 (baked once into the render cache, ~1 min each). One cell = one
frame per method at 64x48, 1 spp; FLIP (HDR, :func:`prefilter.render.metrics.flip`) with
``glints-direct`` as the reference: ``glints`` differs from it by its compression and by the
tabulated pyramid itself (resampling, NDF pixels; ``--lossless`` separates the two).
Wall times are single frames on a shared machine: indicative only. Quad and environment lights:
``glints-direct`` is a 1-spp Monte Carlo estimate (MIS, SG sampling) while ``glints`` mostly uses
noise-free range queries, so their FLIP includes the estimator's noise; ``--floor`` measures it
(FLIP of ``glints-direct`` seed 1 vs seed 0). Rows are appended to
``--out`` as JSON lines as they finish and cells already there are skipped.

``--reference`` (quad and environment lights) judges against deterministic references instead
(:mod:`prefilter.glints.reference`; no Monte Carlo noise): ``converged`` = the expectation of
``glints-direct`` (the light integral with the direct P-NDF by quadrature); for environments also
``matched`` = the expectation of ``glints``' prefiltered SG estimator with the direct P-NDF
(the same epsilon-support blur), for quads ``compressed`` = the light integral by the same
quadrature with ``glints``' compressed NDF (its point queries). ``glints`` is averaged over
``--seeds`` seeds (its SG and MIS estimators are noisy; range-path pixels are not) and FLIP is
reported after 1, 4 and all seeds, so a value that stops falling is error, not noise.
Compression error alone: quad ``compressed`` vs ``converged`` (both noise-free); environment
``glints`` (averaged) vs ``matched``. CPU times are process times (``time.process_time``).

``--bake '{"ndf_truncation": 4}'`` overrides entries of the render bake settings
(:data:`prefilter.glints.bake.BAKE_SETTINGS`; the cache is keyed by them, so other settings
bake into other files). ``--by-luminance`` adds the share of each cell's FLIP error sum by the
pixel's luminance relative to the frame maximum (:func:`error_by_luminance`): on a mostly black
frame HDR-FLIP's automatic exposure range reaches +24 stops and the tails count.

``--lossless``: also ``glints`` on the map stored without compression error
(:data:`LOSSLESS`: every group its exact non-negative CP, 16-bit codes; 0.1-0.8 GB per map) and
FLIP of ``glints`` against it (the compression error alone: the same pyramid, resampling and NDF
pixels) and of it against ``glints-direct`` (what the tabulated pyramid costs without any
compression); rows carry ``flip_lossless`` and ``flip_lossless_direct`` (frame, object pixels).

``--same-estimator`` (environment lights): ``glints`` shades with the unprefiltered SG estimator
(point NDF queries) instead of the epsilon-prefiltered one. Its light samples depend only on the
uniforms, not on the NDF, so with the same seed both methods evaluate their NDFs at the same half
vectors and the FLIP between the two frames is the NDF's error alone (compression and
pyramid, no Monte Carlo noise between them); rows carry ``same_estimator``.
"""

from __future__ import annotations

import argparse
import hashlib
import json
import time
from pathlib import Path

import numpy as np

KINDS = ("gaussian", "brushed", "flakes", "scratches")
DISTANCES = {"near": 0.5, "mid": 2.0, "far": 8.0}
TARGET = 0.05
#: render bake settings that store the pyramid without compression error (``--lossless``): no
#: group fitted, every one its exact non-negative CP; 16-bit ``c`` codes (8-bit ones round the
#: NDF tails)
LOSSLESS = {"exact_from_level": 0, "c_bits": 16, "exact_cell": None}
#: map repeats per unit length of the measurement plane (``uv_scale / size = 160 d / 40 d``)
DENSITY = 4.0


def scene(shape: str, distance: float, kind: str, lights: str) -> dict:
    """The measurement plane, or a sphere at its place with the same camera and lights."""
    from prefilter.glints.render import measurement_scene

    sc = measurement_scene(distance, kind, lights=lights)
    if shape == "sphere":
        plane = sc["objects"][0]
        r = 0.25 * distance
        uv = [max(1.0, round(2 * np.pi * r * DENSITY)), max(1.0, round(np.pi * r * DENSITY))]
        sc["objects"] = [{"type": "sphere", "center": [0.0, 0.0, 0.0], "radius": r,
                          "uv_scale": uv, "material": plane["material"]}]
    return sc


def coverage(sc, size: int = 128):
    """Median footprint std (texels) over the hit pixels (the render's own footprint) and the
    ``(H, W)`` mask of pixels whose centre hits the object."""
    from prefilter.glints.render import pixel_footprints

    _, sp, hit = pixel_footprints(sc, (size, size))
    return float(np.median(sp)), hit


#: relative-luminance bin edges of :func:`error_by_luminance`
LUMINANCE_BINS = (0.0, 1e-12, 1e-9, 1e-6, 1e-4, 1e-2, np.inf)


def error_by_luminance(error_map, test, reference) -> dict:
    """Share of the FLIP error sum ``error_map (H, W)`` in pixels whose luminance
    ``max(test, reference)`` relative to the reference's maximum falls in each
    :data:`LUMINANCE_BINS` interval (and the pixel fraction there), keyed ``"[lo,hi)"``."""
    w = np.array([0.2126, 0.7152, 0.0722])
    yr, yt = reference @ w, test @ w
    top = float(yr.max())
    rel = np.maximum(yr, yt) / top if top > 0 else np.zeros_like(yr)
    tot = float(error_map.sum())
    out = {}
    for lo, hi in zip(LUMINANCE_BINS[:-1], LUMINANCE_BINS[1:]):
        m = (rel >= lo) & (rel < hi)
        out[f"[{lo:g},{hi:g})"] = dict(error_share=float(error_map[m].sum()) / tot if tot else 0.0,
                                       pixels=float(m.mean()))
    return out


def _direct_frame(sc_dict: dict, sc, cache: Path | None) -> tuple[np.ndarray, float]:
    """``glints-direct`` frame of a scene and its wall seconds; with ``cache`` (``--direct-cache``)
    kept there under the SHA-1 of the scene (the frame does not depend on the bake: re-runs of
    the matrix with other bake settings skip it; delete the folder when glints-direct
    changes)."""
    from prefilter.render.driver import render

    f = None
    if cache is not None:
        key = hashlib.sha1(json.dumps(sc_dict, sort_keys=True).encode()).hexdigest()[:16]
        f = cache / f"direct-{key}.npz"
        if f.exists():
            with np.load(f) as d:
                return d["img"], float(d["t"])
    t0 = time.perf_counter()
    img = render(sc, "glints-direct")
    t = time.perf_counter() - t0
    if f is not None:
        cache.mkdir(parents=True, exist_ok=True)
        tmp = f.with_suffix(".tmp.npz")
        np.savez(tmp, img=img, t=t)
        tmp.replace(f)
    return img, t


def cell(shape: str, dist_name: str, kind: str, lights: str, floor: bool = False,
         converged: int = 0, stop_exposure: float | None = None,
         by_luminance: bool = False, direct_cache: Path | None = None,
         lossless: bool = False) -> dict:
    """One matrix cell. ``floor``: also ``glints-direct`` with another seed, and FLIP between
    its two images: the Monte Carlo noise floor of a comparison against a 1-spp MIS / SG-sampled
    ``glints-direct`` (quad and environment lights; 0 for point lights). ``converged``: also
    FLIP between the means of ``converged`` seeds of each method (the Monte Carlo noise of both
    averaged down, the compression error stays). ``stop_exposure``: also HDR-FLIP with FLIP's own
    start exposure but the top exposure capped at this many stops (``flip_capped``): on nearly
    black frames FLIP's automatic top (+24 stops) compares tails far below the peak."""
    from prefilter.render.metrics import flip
    from prefilter.render.driver import render
    from prefilter.render.scene import load_scene

    sd = scene(shape, DISTANCES[dist_name], kind, lights)
    sc = load_scene(sd)
    render(sc, "glints")  # bake (disk cache) and compile outside the timing
    img, t = {}, {}
    t0 = time.perf_counter()
    img["glints"] = render(sc, "glints")
    t["glints"] = time.perf_counter() - t0
    img["glints-direct"], t["glints-direct"] = _direct_frame(sd, sc, direct_cache)
    mean_d = float(img["glints-direct"].mean())
    sp, hit = coverage(sc)
    extra = {}
    if floor:
        fl2 = flip(render(sc, "glints-direct", seed=1), img["glints-direct"])
        extra = dict(floor=float(fl2.mean), floor_object=float(fl2.error_map[hit].mean()))
    if converged > 1:
        avg = {m: np.mean([img[m]] + [render(sc, m, seed=k) for k in range(1, converged)], 0)
               for m in img}
        fl3 = flip(avg["glints"], avg["glints-direct"])
        extra.update(converged=converged, flip_converged=float(fl3.mean),
                     flip_converged_object=float(fl3.error_map[hit].mean()))
    fl = flip(img["glints"], img["glints-direct"])
    if stop_exposure is not None:
        fc = flip(img["glints"], img["glints-direct"],
                  start_exposure=fl.settings["start_exposure"],
                  stop_exposure=min(stop_exposure, fl.settings["stop_exposure"]))
        extra.update(stop_exposure=stop_exposure, flip_capped=float(fc.mean),
                     flip_capped_object=float(fc.error_map[hit].mean()))
    if lossless:
        from prefilter.glints.bake import BAKE_SETTINGS

        saved = dict(BAKE_SETTINGS)
        BAKE_SETTINGS.update(LOSSLESS)
        if BAKE_SETTINGS["exact_cell"] is None:
            del BAKE_SETTINGS["exact_cell"]
        try:
            ll = render(sc, "glints")
        finally:
            BAKE_SETTINGS.clear()
            BAKE_SETTINGS.update(saved)
        extra.update(flip_lossless=_flip_pair(img["glints"], ll, hit),
                     flip_lossless_direct=_flip_pair(ll, img["glints-direct"], hit))
    if by_luminance:
        extra.update(stop_exposure_auto=fl.settings["stop_exposure"],
                     by_luminance=error_by_luminance(fl.error_map, img["glints"],
                                                     img["glints-direct"]))
    # the sphere leaves black background pixels (zero error): also the mean over the object
    return dict(lights=lights, shape=shape, distance=dist_name, map=kind, sigma_p_median=sp,
                flip=float(fl.mean), flip_object=float(fl.error_map[hit].mean()),
                object_pixels=float(hit.mean()),
                t_glints=t["glints"], t_direct=t["glints-direct"],
                mean_ratio=float(img["glints"].mean()) / mean_d if mean_d > 0 else float("nan"),
                **extra)


def _flip_pair(a, b, hit):
    from prefilter.render.metrics import flip

    f = flip(a, b)
    return float(f.mean), float(f.error_map[hit].mean())


def reference_cell(shape: str, dist_name: str, kind: str, lights: str, seeds: int = 16,
                   direct: bool = True) -> dict:
    """One cell against the deterministic references (see the module docstring); FLIP values are
    pairs (frame, object pixels)."""
    from prefilter.glints.reference import render_converged
    from prefilter.render.driver import render
    from prefilter.render.scene import load_scene

    sc = load_scene(scene(shape, DISTANCES[dist_name], kind, lights))
    render(sc, "glints")  # bake (disk cache) and compile outside the timing
    sp, hit = coverage(sc)
    t0 = time.process_time()
    imgs = [render(sc, "glints", seed=k) for k in range(seeds)]
    t_glints = (time.process_time() - t0) / seeds
    t0 = time.process_time()
    conv = render_converged(sc)
    t_conv = time.process_time() - t0
    row = dict(mode="reference", lights=lights, shape=shape, distance=dist_name, map=kind,
               sigma_p_median=sp, object_pixels=float(hit.mean()), seeds=seeds,
               cpu_glints=t_glints, cpu_converged=t_conv)
    if lights == "environment":
        t0 = time.process_time()
        other = render_converged(sc, matched=True)
        row.update(cpu_matched=time.process_time() - t0, other="matched")
    else:
        t0 = time.process_time()
        other = render_converged(sc, ndf="compressed")
        row.update(cpu_compressed=time.process_time() - t0, other="compressed")
        row["flip_compressed_converged"] = _flip_pair(other, conv, hit)
        row["mean_compressed_converged"] = float(other.mean() / conv.mean())
    for n in sorted({1, min(4, seeds), seeds}):
        g = np.mean(imgs[:n], 0)
        row[f"flip_glints{n}_converged"] = _flip_pair(g, conv, hit)
        row[f"flip_glints{n}_{row['other']}"] = _flip_pair(g, other, hit)
    row["mean_glints_converged"] = float(np.mean(imgs) / conv.mean())
    row["mean_glints_other"] = float(np.mean(imgs) / other.mean())
    if direct:
        t0 = time.process_time()
        d = render(sc, "glints-direct")
        row.update(cpu_direct=time.process_time() - t0,
                   flip_direct_converged=_flip_pair(d, conv, hit),
                   flip_glints1_direct=_flip_pair(imgs[0], d, hit),
                   mean_direct_converged=float(d.mean() / conv.mean()))
    return row


def _pair(p, obj: bool) -> str:
    if p is None:
        return "-"
    txt = f"{p[0]:.3f}" + (f" ({p[1]:.3f})" if obj else "")
    return f"**{txt}**" if max(p) > TARGET else txt


def table_reference(rows: list[dict]) -> str:
    """Markdown: one row per (lights, shape, map, distance) of ``--reference`` cells."""
    out = ["| lights | shape | map | d | compression only | glints vs converged, 1 / 4 / S seeds "
           "| glints(S) vs matched or compressed | glints-direct (1 spp) vs converged | "
           "glints vs glints-direct (1 spp) | mean glints(S) / converged | CPU s: glints frame / "
           "converged / direct |",
           "|---|---|---|---|---|---|---|---|---|---|---|"]
    rows = [r for r in rows if r.get("mode") == "reference"]
    order = {d: i for i, d in enumerate(DISTANCES)}
    rows.sort(key=lambda r: (r["lights"] != "quad", r["shape"] != "plane", KINDS.index(r["map"]),
                             order[r["distance"]]))
    for r in rows:
        obj = r["object_pixels"] < 0.999
        S = r["seeds"]
        ns = sorted({1, min(4, S), S})
        if r["other"] == "compressed":
            comp = _pair(r["flip_compressed_converged"], obj)
        else:
            comp = _pair(r[f"flip_glints{S}_matched"], obj) + f" (S={S})"
        conv = " / ".join(_pair(r[f"flip_glints{n}_converged"], obj) for n in ns)
        oth = _pair(r[f"flip_glints{S}_{r['other']}"], obj)
        cpu = (f"{r['cpu_glints']:.2f} / {r['cpu_converged']:.0f} / "
               + (f"{r['cpu_direct']:.0f}" if "cpu_direct" in r else "-"))
        out.append(f"| {r['lights']} | {r['shape']} | {r['map']} | {r['distance']} | {comp} | "
                   f"{conv} | {oth} | {_pair(r.get('flip_direct_converged'), obj)} | "
                   f"{_pair(r.get('flip_glints1_direct'), obj)} | "
                   f"{r['mean_glints_converged']:.3f} | {cpu} |")
    return "\n".join(out)


def worst(r: dict) -> float:
    """The FLIP a cell is judged by: over the frame and over the object's pixels."""
    return max(r["flip"], r.get("flip_object", r["flip"]))


def _flip_cell(r: dict) -> str:
    txt = f"{r['flip']:.3f}"
    if r.get("object_pixels", 1.0) < 0.999:
        txt += f" ({r['flip_object']:.3f})"
    return f"**{txt}**" if worst(r) > TARGET else txt


def _floor(rs) -> str:
    def one(r):
        if r is None or "floor" not in r:
            return "-"
        if r.get("object_pixels", 1.0) < 0.999:
            return f"{r['floor']:.3f} ({r['floor_object']:.3f})"
        return f"{r['floor']:.3f}"

    return " / ".join(one(r) for r in rs)


def table(rows: list[dict]) -> str:
    """Markdown: one row per (lights, shape, map), FLIP near / mid / far (frame, and in brackets
    over the object's pixels where the background shows; bold over the target), wall times and
    the Monte Carlo floor (``--floor``)."""
    out = ["| lights | shape | map | FLIP near | mid | far | glints s (n/m/f) | "
           "glints-direct s (n/m/f) | mean glints/direct (n/m/f) | MC floor (n/m/f) |",
           "|---|---|---|---|---|---|---|---|---|---|"]
    by = {(r["lights"], r["shape"], r["map"], r["distance"]): r for r in rows
          if r.get("mode") != "reference"}
    for lights in ("point", "quad", "environment"):
        for shape in ("plane", "sphere"):
            for kind in KINDS:
                rs = [by.get((lights, shape, kind, d)) for d in DISTANCES]
                if not any(rs):
                    continue

                def f(key, fmt, rs=rs):
                    return " / ".join("-" if r is None else format(r[key], fmt) for r in rs)

                fl = ["-" if r is None else _flip_cell(r) for r in rs]
                out.append(f"| {lights} | {shape} | {kind} | {' | '.join(fl)} | "
                           f"{f('t_glints', '.2f')} | {f('t_direct', '.2f')} | "
                           f"{f('mean_ratio', '.3f')} | {_floor(rs)} |")
    return "\n".join(out)


def table_lossless(rows: list[dict]) -> str:
    """Markdown: per cell with ``--lossless`` data, FLIP (object pixels in brackets where the
    background shows) of ``glints`` vs ``glints-direct``, vs the lossless map, and of the
    lossless map vs ``glints-direct``."""
    rs = [r for r in rows if r.get("mode") != "reference" and "flip_lossless" in r]
    if not rs:
        return ""

    def pair(r, key):
        v = r[key]
        return f"{v[0]:.3f} ({v[1]:.3f})" if r["object_pixels"] < 0.999 else f"{v[0]:.3f}"

    out = ["| lights | shape | map | d | glints vs direct | glints vs lossless (compression) | "
           "lossless vs direct |", "|---|---|---|---|---|---|---|"]
    for r in rs:
        fl = (f"{r['flip']:.3f} ({r['flip_object']:.3f})" if r["object_pixels"] < 0.999
              else f"{r['flip']:.3f}")
        out.append(f"| {r['lights']} | {r['shape']} | {r['map']} | {r['distance']} | {fl} | "
                   f"{pair(r, 'flip_lossless')} | {pair(r, 'flip_lossless_direct')} |")
    return "\n".join(out)


def table_exposure(rows: list[dict]) -> str:
    """Markdown: per cell with ``--stop-exposure`` / ``--by-luminance`` data, FLIP at FLIP's own
    exposure range, capped, and the error share by relative luminance."""
    rs = [r for r in rows if r.get("mode") != "reference"
          and ("flip_capped" in r or "by_luminance" in r)]
    if not rs:
        return ""
    bins = [f"[{lo:g},{hi:g})" for lo, hi in zip(LUMINANCE_BINS[:-1], LUMINANCE_BINS[1:])]
    out = ["| lights | shape | map | d | FLIP (top stop) | capped | error share by luminance / "
           "frame max: " + " / ".join(bins) + " |", "|---|---|---|---|---|---|---|"]
    for r in rs:
        top = f" (+{r['stop_exposure_auto']:.1f})" if "stop_exposure_auto" in r else ""
        cap = (f"{r['flip_capped']:.3f} (+{r['stop_exposure']:g})" if "flip_capped" in r
               else "-")
        lum = r.get("by_luminance")
        share = " / ".join(f"{lum[b]['error_share']:.2f}" for b in bins) if lum else "-"
        out.append(f"| {r['lights']} | {r['shape']} | {r['map']} | {r['distance']} | "
                   f"{r['flip']:.3f}{top} | {cap} | {share} |")
    return "\n".join(out)


def _unprefiltered_environment():
    """``glints`` shades environments with the unprefiltered SG estimator (``--same-estimator``)."""
    import prefilter.glints.render as R

    shade = R.environment_radiance

    def unprefiltered(*args, **kw):
        kw["prefilter"] = False
        return shade(*args, **kw)

    R.environment_radiance = unprefiltered


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--lights", default="point", help="comma list: point, quad, environment")
    ap.add_argument("--shapes", default="plane,sphere")
    ap.add_argument("--kinds", default=",".join(KINDS))
    ap.add_argument("--distances", default="near,mid,far")
    ap.add_argument("--out", default="glints_scenes.jsonl")
    ap.add_argument("--floor", action="store_true",
                    help="also FLIP of glints-direct seed 1 vs seed 0 (MC noise floor)")
    ap.add_argument("--converged", type=int, default=0,
                    help="also FLIP between the means of this many seeds of each method")
    ap.add_argument("--stop-exposure", type=float, default=None,
                    help="also FLIP with the top exposure capped at this many stops")
    ap.add_argument("--table", default=None, help="only print the table of this .jsonl")
    ap.add_argument("--bake", default=None,
                    help="JSON object overriding entries of the render bake settings")
    ap.add_argument("--by-luminance", action="store_true",
                    help="also the FLIP error share by relative pixel luminance")
    ap.add_argument("--reference", action="store_true",
                    help="judge against the deterministic references (quad, environment)")
    ap.add_argument("--seeds", type=int, default=16, help="--reference: glints seeds averaged")
    ap.add_argument("--same-estimator", action="store_true",
                    help="environment: glints with the unprefiltered SG estimator (same light "
                         "samples as glints-direct: FLIP = the NDF's error alone)")
    ap.add_argument("--no-direct", action="store_true",
                    help="--reference: skip the 1-spp glints-direct frame (costly far away)")
    ap.add_argument("--lossless", action="store_true",
                    help="also glints on the map stored exactly: FLIP of glints against it "
                         "(compression alone) and of it against glints-direct")
    ap.add_argument("--direct-cache", default=None,
                    help="folder keeping the glints-direct frames between runs (they do not "
                         "depend on the bake settings)")
    a = ap.parse_args()
    if a.bake:
        from prefilter.glints.bake import BAKE_SETTINGS

        BAKE_SETTINGS.update(json.loads(a.bake))
    if a.same_estimator:
        if a.reference:
            ap.error("--same-estimator compares glints with glints-direct, not the references")
        _unprefiltered_environment()
    fmt = table_reference if a.reference else table
    if a.table:
        rows = [json.loads(x) for x in Path(a.table).read_text().splitlines() if x]
        print(fmt(rows))
        if not a.reference:
            for extra in (table_exposure(rows), table_lossless(rows)):
                if extra:
                    print(extra)
        return
    out = Path(a.out)
    done = set()
    if out.exists():
        for x in out.read_text().splitlines():
            if x:
                r = json.loads(x)
                if (r.get("mode") == "reference") == a.reference:
                    done.add((r["lights"], r["shape"], r["map"], r["distance"]))
    for lights in a.lights.split(","):
        for kind in a.kinds.split(","):  # map-major: one bake, then all its cells
            for shape in a.shapes.split(","):
                for dn in a.distances.split(","):
                    if (lights, shape, kind, dn) in done:
                        continue
                    if a.reference:
                        r = reference_cell(shape, dn, kind, lights, a.seeds, not a.no_direct)
                    else:
                        r = cell(shape, dn, kind, lights, a.floor, a.converged,
                                 a.stop_exposure, a.by_luminance,
                                 Path(a.direct_cache) if a.direct_cache else None,
                                 a.lossless)
                        if a.bake:
                            r["bake"] = json.loads(a.bake)
                        if a.same_estimator:
                            r["same_estimator"] = True
                    print(json.dumps(r), flush=True)
                    with out.open("a") as fh:
                        fh.write(json.dumps(r) + "\n")
    rows = [json.loads(x) for x in out.read_text().splitlines() if x]
    print(fmt(rows))
    if a.reference:
        return
    rows = [r for r in rows if r.get("mode") != "reference"]
    for extra in (table_exposure(rows), table_lossless(rows)):
        if extra:
            print(extra)
    bad = [r for r in rows if worst(r) > TARGET]
    print(f"cells over FLIP {TARGET}: {len(bad)} of {len(rows)}")


if __name__ == "__main__":
    main()
