"""The ``glints-wang`` method on the glints measurement scene (docs/glints-wang.md, "Rendering").

Per distance (``prefilter.glints.render.measurement_scene(d, lights="point")``, flakes 128^2):

* frame times of ``glints-wang``, ``glints`` and ``glints-direct``, interleaved, ``--repeats``
  each (after one warm-up render of each: bakes and compilation outside the timing), wall and
  process CPU time (the machine is shared);
* FLIP (and mean ratio) of ``glints-wang`` on an explicit periodic 4 x 4 tile index map
  (``wang.periodic_index_map``: edges match across the wrap) against
  ``glints-direct`` on the assembled 128^2 map (same texel scale: tile 32), and of the hashed
  ``glints-wang`` against ``glints-direct`` on the exemplar (another surface: the look only);
* storage: ``TiledNDF.nbytes`` against the texel area the frame covers (bounding box of the hit
  samples' texel coordinates) and what an explicit map of that area would take (float32
  normals; the ``glints`` compressed pyramid at the exemplar's bytes per texel).

* ``--code-bits 0 8 16``: the cache file's factor codes (``WANG_SETTINGS["code_bits"]``, each
  its own cache file, baked once): per value the file size, the FLIP of the index-map frame
  against ``glints-direct`` on the assembled map and against the first value's frame, and the
  NDF image relative L2 (``wang_ndf.ndf_image``, hashed tiling) of ``--footprints`` footprints
  of the frame in the per-tile regime (at sigma_p quantiles), against the first value's and
  against the direct P-NDF (``wang.pndf_image_implicit`` at the bake's roughness).

* ``--lights quad environment`` (default ``point``, the rows above): the measurement scene with
  that light. Per distance: FLIP of ``glints-wang`` on the periodic index map against
  ``glints-direct`` on the assembled map **with the same seed** (the same uniforms: for the
  environment the same SG light samples, so the FLIP is the tiling and compression error
  without Monte Carlo noise; for the quad the first ``QUAD_MIS`` light samples are shared, the
  estimators differ: light sampling vs MIS), also with HDR-FLIP's top exposure capped at
  ``--stop-exposure`` stops (FLIP's own start exposure; default 12); the noise floor: FLIP of
  ``glints-wang`` seed 0 vs seed 1 (index map; ``--direct-floor``: also ``glints-direct``'s,
  assembled map); frame times of ``glints-wang`` (hashed) and
  ``glints`` on the exemplar scene (``--repeats``, interleaved) and of the one
  ``glints-direct`` render on the assembled map (its cost depends on the footprints, the same
  as on the exemplar). ``--mean-seeds K``: frame means over seeds ``0..K-1`` (``glints-direct``:
  ``1000..``, independent) (ratio,
  difference in standard errors, relative std of one frame's mean), and the FLIP of the two
  methods' images averaged over those seeds, with its floor: ``glints-direct``'s average over
  its even seeds against its odd ones.

* ``--exact-seeds K`` (with ``--lights quad environment``; instead of the rows above): against
  ``glints-wang``'s own ``direct=True`` mode (``wang_render.render_wang``: the direct P-NDF of
  the tiling at every footprint, light samples without range queries or lobe prefilter; under
  the environment pixel for pixel ``glints-direct`` on the assembled map, tested; under the quad
  light sampling where ``glints-direct`` uses MIS, the same expected image), which costs
  seconds where ``glints-direct`` takes minutes at far: FLIP of ``glints-wang``'s frames averaged
  over seeds ``0..K-1`` against the ``direct`` frames averaged over ``1000..`` (floor: the
  ``direct`` frames' even seeds against their odd ones) and the frame-mean ratio; the same
  estimator at seed 0 (``ranges=False``: the tiling and compression error alone, FLIP and mean
  ratio against ``direct`` at seed 0); and the range queries' / lobe prefilter's effect on the
  frame mean (``glints-wang`` over ``ranges=False`` at the same seeds, paired, K seeds).

Run: ``.venv/bin/python benchmarks/study_glints_wang_render.py [--repeats 3]
[--distances 0.5 2 8] [--set key=value ...] [--code-bits 0 8 16] [--no-times]
[--lights point quad environment] [--stop-exposure 12] [--direct-floor]
[--mean-seeds K] [--exact-seeds K]`` (``--set`` overrides
``WANG_SETTINGS``, values as JSON). One JSON line per (lights, distance) on stdout.
"""

from __future__ import annotations

import argparse
import json
import tempfile
import time
from pathlib import Path

import numpy as np


def _timed(fn):
    w, c = time.perf_counter(), time.process_time()
    out = fn()
    return out, time.perf_counter() - w, time.process_time() - c


def _repeat_times(sc, methods, repeats):
    """Wall and CPU seconds ``{method: [t, ...]}`` of ``repeats`` frames of each method,
    interleaved (one frame of each per round)."""
    from prefilter.render.driver import render

    wall = {m: [] for m in methods}
    cpu = {m: [] for m in methods}
    for _ in range(repeats):
        for m in methods:
            _, w, cp = _timed(lambda: render(sc, m))
            wall[m].append(round(w, 3))
            cpu[m].append(round(cp, 3))
    return wall, cpu


def main(argv=None):
    from prefilter.glints import wang_render

    ap = argparse.ArgumentParser()
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--distances", type=float, nargs="+", default=[0.5, 2.0, 8.0])
    ap.add_argument("--set", nargs="*", default=[], metavar="KEY=VALUE")
    ap.add_argument("--no-times", action="store_true")
    ap.add_argument("--code-bits", type=int, nargs="*", default=[])
    ap.add_argument("--footprints", type=int, default=6)
    ap.add_argument("--lights", nargs="+", default=["point"],
                    choices=["point", "quad", "environment"])
    ap.add_argument("--stop-exposure", type=float, default=12.0)
    ap.add_argument("--direct-floor", action="store_true")
    ap.add_argument("--mean-seeds", type=int, default=0)
    ap.add_argument("--exact-seeds", type=int, default=0)
    args = ap.parse_args(argv)
    wang = {k: json.loads(v) for k, v in (kv.split("=", 1) for kv in args.set)}
    if wang:
        wang_render.WANG_SETTINGS.update(wang)  # the registered method uses the module defaults
    tmp = Path(tempfile.mkdtemp())
    for kind in args.lights:
        for d in args.distances:
            if kind == "point":
                _point_row(args, wang, tmp, d)
            elif args.exact_seeds:
                _exact_row(args, tmp, d, kind)
            else:
                _lights_row(args, wang, tmp, d, kind)


def _assembled(d, kind, tmp):
    """The exemplar scene, its ``TiledNDF`` (and bake / load time), the periodic index map and
    the scene on the assembled map."""
    from prefilter.glints import wang_render
    from prefilter.glints.render import measurement_scene
    from prefilter.glints.wang import assemble, periodic_index_map
    from prefilter.render.scene import load_scene
    from prefilter.texture.normalmap import encode_normals

    sc = load_scene(measurement_scene(d, lights=kind))
    nm = sc.objects[0].material.normal_map.load()
    (wn, t_bake, _) = _timed(lambda: wang_render.baked_tiles(nm))
    ny = nm.shape[0] // wn.wang.size
    idx = periodic_index_map(ny, ny, rng=0)  # a valid tiling across the wrap
    np.save(tmp / "assembled.npy", encode_normals(assemble(wn.wang, idx)))
    spec = measurement_scene(d, lights=kind)
    spec["objects"][0]["material"]["normal_map"] = str(tmp / "assembled.npy")
    return sc, nm, wn, t_bake, idx, load_scene(spec)


def _flips(test, ref, stop):
    """HDR-FLIP, and with the top exposure capped at ``stop`` stops (FLIP's own start)."""
    from prefilter.render.metrics import flip

    fl = flip(test, ref)
    top = fl.settings["stop_exposure"]
    fc = flip(test, ref, start_exposure=fl.settings["start_exposure"],
              stop_exposure=min(stop, top))
    return float(fl.mean), float(fc.mean), float(top)


def _seed_means(fa, fb, stop):
    """Frames ``fa`` of ``glints-wang`` against independent reference frames ``fb`` (one per
    seed): FLIP and capped FLIP of the two seed averages (what is left without most of the two
    estimators' noise), those of the reference's even-seed average against its odd-seed one (the
    floor: half as many frames each), the frame-mean ratio and its difference in standard
    errors."""
    ma, mb = [float(x.mean()) for x in fa], [float(x.mean()) for x in fb]
    se = np.sqrt(np.var(ma, ddof=1) / len(ma) + np.var(mb, ddof=1) / len(mb))
    fm, fmc, _ = _flips(np.mean(fa, axis=0), np.mean(fb, axis=0), stop)
    hf, hfc, _ = _flips(np.mean(fb[0::2], axis=0), np.mean(fb[1::2], axis=0), stop)
    return (fm, fmc, hf, hfc, float(np.mean(ma) / np.mean(mb)),
            float((np.mean(ma) - np.mean(mb)) / se))


def _lights_row(args, wang, tmp, d, kind):
    """One ``--lights quad|environment`` row (module docstring)."""
    from prefilter.glints import wang_render
    from prefilter.render.methods import RenderSettings
    from prefilter.render.driver import render

    sc, nm, wn, t_bake, idx, sa = _assembled(d, kind, tmp)
    row = dict(lights=kind, distance=d, tile=wn.wang.size,
               settings=wang_render.wang_settings(wang), bake_or_load_s=round(t_bake, 2))
    a0 = wang_render.render_wang(sc, RenderSettings(seed=0), index=idx)
    a1 = wang_render.render_wang(sc, RenderSettings(seed=1), index=idx)
    b0, t_direct, c_direct = _timed(lambda: render(sa, "glints-direct", seed=0))
    f, fc, top = _flips(a0, b0, args.stop_exposure)
    nf, nfc, _ = _flips(a1, a0, args.stop_exposure)
    row.update(flip_wang_index_vs_direct_assembled=f, flip_capped=fc, stop_exposure_auto=top,
               mean_ratio_index=float(a0.mean() / b0.mean()),
               flip_wang_seed1_vs_seed0=nf, flip_capped_seed1_vs_seed0=nfc,
               black_fraction=float(np.mean(b0.max(-1) < 1e-3 * b0.max())),
               direct_assembled_s=round(t_direct, 3), direct_assembled_cpu_s=round(c_direct, 3))
    if args.direct_floor:
        b1 = render(sa, "glints-direct", seed=1)
        row.update(zip(("flip_direct_seed1_vs_seed0", "flip_capped_direct_seed1_vs_seed0"),
                       _flips(b1, b0, args.stop_exposure)[:2]))
    if args.mean_seeds:
        # frame means over seeds of both: the estimators' agreement beyond one frame. Seeds
        # 1000.. for glints-direct: independent of glints-wang's (shared light samples would
        # correlate them and the standard error below assumes independence)
        fa = [wang_render.render_wang(sc, RenderSettings(seed=k), index=idx)
              for k in range(args.mean_seeds)]
        fb = [render(sa, "glints-direct", seed=1000 + k) for k in range(args.mean_seeds)]
        fm, fmc, hf, hfc, ratio, z = _seed_means(fa, fb, args.stop_exposure)
        row.update(flip_seed_mean_wang_vs_direct=fm, flip_capped_seed_mean_wang_vs_direct=fmc,
                   flip_seed_mean_direct_even_vs_odd=hf,
                   flip_capped_seed_mean_direct_even_vs_odd=hfc)
        ma = [float(x.mean()) for x in fa]
        mb = [float(x.mean()) for x in fb]
        row.update(mean_seeds=args.mean_seeds, mean_ratio_seeds=ratio, mean_diff_over_se=z,
                   frame_mean_rel_std_wang=float(np.std(ma, ddof=1) / np.mean(ma)),
                   frame_mean_rel_std_direct=float(np.std(mb, ddof=1) / np.mean(mb)))
    if not args.no_times:
        render(sc, "glints-wang")  # warm-up (compilation)
        render(sc, "glints")
        wall, cpu = _repeat_times(sc, ("glints-wang", "glints"), args.repeats)
        row.update(wall_s=wall, cpu_s=cpu,
                   direct_over_wang=t_direct / min(wall["glints-wang"]),
                   glints_over_wang=min(wall["glints"]) / min(wall["glints-wang"]))
    print(json.dumps(row), flush=True)


def _exact_row(args, tmp, d, kind):
    """One ``--exact-seeds`` row (module docstring)."""
    from prefilter.glints import wang_render
    from prefilter.render.methods import RenderSettings

    sc, _, wn, _, idx, _ = _assembled(d, kind, tmp)
    K = args.exact_seeds

    def frame(seed, **kw):
        t0 = time.perf_counter()
        img = wang_render.render_wang(sc, RenderSettings(seed=seed), index=idx, **kw)
        return img, time.perf_counter() - t0

    fa = [frame(k) for k in range(K)]
    fn = [frame(k, ranges=False)[0] for k in range(K)]
    fe = [frame(1000 + k, direct=True) for k in range(K)]
    e0 = frame(0, direct=True)[0]
    wang_s = float(np.median([t for _, t in fa]))
    direct_s = float(np.median([t for _, t in fe]))
    fa, fe = [x for x, _ in fa], [x for x, _ in fe]
    paired = [float(a.mean()) / float(n.mean()) for a, n in zip(fa, fn)]
    fm, fmc, hf, hfc, ratio, z = _seed_means(fa, fe, args.stop_exposure)
    sf, sfc, _ = _flips(fn[0], e0, args.stop_exposure)
    print(json.dumps(dict(
        lights=kind, distance=d, tile=wn.wang.size, exact_seeds=K,
        flip_seed_mean_wang_vs_exact=fm, flip_capped_seed_mean_wang_vs_exact=fmc,
        flip_seed_mean_exact_even_vs_odd=hf, flip_capped_seed_mean_exact_even_vs_odd=hfc,
        mean_ratio_wang_over_exact=ratio, mean_diff_over_se=z,
        flip_same_estimator_vs_exact=sf, flip_capped_same_estimator_vs_exact=sfc,
        mean_ratio_same_estimator=float(fn[0].mean() / e0.mean()),
        mean_ratio_ranges_over_same_estimator=float(np.mean(paired)),
        mean_ratio_ranges_over_same_estimator_se=float(np.std(paired, ddof=1) / np.sqrt(K)),
        wang_frame_s=round(wang_s, 3), exact_frame_s=round(direct_s, 3))), flush=True)


def _point_row(args, wang, tmp, d):
    """One point-light row (module docstring)."""
    from prefilter.glints import wang_render
    from prefilter.glints.render import baked_surface, pixel_footprints
    from prefilter.render.methods import RenderSettings
    from prefilter.render.metrics import flip
    from prefilter.render.driver import render

    sc, nm, wn, t_bake, idx, sa = _assembled(d, "point", tmp)
    size, T = nm.shape[0], wn.wang.size
    row = dict(lights="point", distance=d, tile=T, settings=wang_render.wang_settings(wang),
               bake_or_load_s=round(t_bake, 2), nbytes_mb=wn.nbytes / 1e6,
               cp_error=list(wn.cp_error))
    c, sp, _ = pixel_footprints(sc, (size, size))
    ext = c.max(0) - c.min(0)
    # the glints pyramid of the exemplar, per texel: what an explicit map of the frame's
    # area would take in that format
    gm_mb = baked_surface(nm).gm.compressed_bytes / 1e6
    row.update(sigma_p_median=float(np.median(sp)),
               frame_texels=float(np.prod(ext)), frame_tiles=float(np.prod(ext) / T**2),
               explicit_normals_mb=float(np.prod(ext)) * 3 * 4 / 1e6,
               glints_map_mb=gm_mb,
               explicit_glints_map_mb=gm_mb * float(np.prod(ext)) / size**2)
    # FLIP on the assembled map (same surface) and the hashed tiling (another surface)
    a_idx = wang_render.render_wang(sc, RenderSettings(), index=idx)
    img = {"wang": render(sc, "glints-wang"), "glints": render(sc, "glints"),
           "direct": render(sc, "glints-direct")}
    b_idx = render(sa, "glints-direct")
    row.update(flip_wang_index_vs_direct_assembled=float(flip(a_idx, b_idx).mean),
               mean_ratio_index=float(a_idx.mean() / b_idx.mean()),
               flip_wang_hashed_vs_direct_exemplar=float(flip(img["wang"],
                                                               img["direct"]).mean),
               mean_ratio_hashed=float(img["wang"].mean() / img["direct"].mean()),
               flip_glints_vs_direct=float(flip(img["glints"], img["direct"]).mean))
    if args.code_bits:
        row["codes"] = _codes_study(sc, nm, idx, b_idx, c, sp, args.code_bits, args.footprints)
    if not args.no_times:
        wall, cpu = _repeat_times(sc, ("glints-wang", "glints", "glints-direct"), args.repeats)
        row.update(wall_s=wall, cpu_s=cpu,
                   min_wall_ratio_direct_over_wang=min(wall["glints-direct"])
                   / min(wall["glints-wang"]),
                   min_wall_ratio_glints_over_wang=min(wall["glints"])
                   / min(wall["glints-wang"]))
    print(json.dumps(row), flush=True)


def _codes_study(sc, nm, idx, b_idx, c, sp, code_bits, n_fp):
    """The ``--code-bits`` comparison of one frame (module docstring); ``c``, ``sp``: the
    frame's pixel footprints."""
    from prefilter.glints import wang_render
    from prefilter.glints.wang import pndf_image_implicit
    from prefilter.glints.wang_ndf import ndf_image
    from prefilter.render.methods import RenderSettings
    from prefilter.render.metrics import flip

    out, ref, direct = {}, None, {}
    for b in code_bits:
        over = {"code_bits": b}
        t0 = time.perf_counter()
        wn = wang_render.baked_tiles(nm, over)
        t_load = time.perf_counter() - t0
        st = wang_render.wang_settings(over)
        st["tile"] = wang_render.tile_size(st["tile"], nm.shape[:2])
        frame = wang_render.render_wang(sc, RenderSettings(), index=idx, wang=over)
        inside = np.flatnonzero((sp >= wn.min_sigma) & (sp < wn.wide_sigma))
        q = np.linspace(0.05, 0.95, n_fp)
        pick = inside[np.argsort(sp[inside])][(q * (inside.size - 1)).astype(int)] \
            if inside.size else np.zeros(0, int)
        imgs = [ndf_image(wn, c[k], sp[k]) for k in pick]
        for k in pick:
            if k not in direct:  # the same footprints for every b (same regimes)
                direct[k] = pndf_image_implicit(wn.wang, c[k], sp[k], wn.resolution, wn.support,
                                                wn.intrinsic_roughness)
        r = dict(file_mb=wang_render.cache_path(nm, st).stat().st_size / 1e6,
                 bake_or_load_s=round(t_load, 2),
                 flip_vs_direct_assembled=float(flip(frame, b_idx).mean),
                 sigma_p=[round(float(sp[k]), 2) for k in pick],
                 ndf_rel_l2_vs_direct=[_rel(i, direct[k]) for i, k in zip(imgs, pick)])
        if ref is None:
            ref = dict(frame=frame, imgs=imgs)
        else:
            r["flip_vs_first"] = float(flip(frame, ref["frame"]).mean)
            r["ndf_rel_l2_vs_first"] = [_rel(i, j) for i, j in zip(imgs, ref["imgs"])]
        out[str(b)] = r
    return out


def _rel(a, b):
    return float(np.linalg.norm(a - b) / max(np.linalg.norm(b), 1e-300))


if __name__ == "__main__":
    main()
