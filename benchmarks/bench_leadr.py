"""LEADR: convergence of the N x N Gaussian grid against N = 128, and shading throughput.

Convergence (``python benchmarks/bench_leadr.py``): 1000 random shading configurations (views
with wo_z in [0.15, 1], mean slopes N(0, 0.15^2 I)) under the procedural environment of
``prefilter.leadr.envmap.procedural_env(128)``. Specular (Simplified Algorithm 1, Schlick f0 = 1,
LOD bias 0) at isotropic slope std 0.1 / 0.25 / 0.5 and anisotropic (0.5, 0.1, correlation 0.5);
diffuse (Simplified Algorithm 3) with order-2 SH irradiance at std 0.5 and with one directional
light. Error: relative RMSE of the luminance over the configurations vs the N = 128 grid; time:
wall time per shading point (NumPy path, best of 3). ``paper5`` is the supplemental's 5 x 5 grid
(spacing 0.9); other rows use the derived spacing of ``gaussian_grid``.

The same table with more cases (diffuse at every sigma) and per-N timings of the compiled
specular kernel: ``--convergence`` (:func:`prefilter.studies.leadr.convergence`).

Acceptance (``--acceptance``): :mod:`prefilter.studies.leadr` (LEADR, normal-mapped reference
and naive mip-mapped normal mapping vs the displaced height field, 16 to 64 texels per pixel);
``--acceptance-env`` the same under the procedural environment (add ``--no-shadowing`` for a
reference without self-shadowing, the model of the simplified algorithms; ``--surfaces``,
``--shadings``, ``--blocks`` select rows, ``--k`` / ``--spp`` set the reference's view rays per
side and MIS samples per hit, e.g. ``--surfaces 'iso 0.1' --shadings diffuse --k 64 --spp 64``
for a 16x reference); the diffuse rows are also printed against naive shading with the same
irradiance representation (``acceptance.env_diffuse_table``).

Point-light images (``--image-point``, ~30-50 min): :func:`prefilter.studies.leadr.image_point`,
planes and spheres, iso / anisotropic height fields, specular and diffuse, 4 and 16 texels per
pixel, RMSE / FLIP / flicker of LEADR, the normal-mapped reference and naive normal mapping vs the
ray-traced displaced surface (``--quick``: one surface, the plane only). ``--flicker-floor``
(~15 min): the far rows' flickers with the reference's own sampling-error floor
(:func:`prefilter.studies.leadr.flicker_table`). ``--flicker-source 'iso 0.25, sphere; ...'
--tpp 16``: flicker against the displaced and the normal-mapped references
(:func:`prefilter.studies.leadr.flicker_source_table`).

Specular diagnosis (``--spec-diagnosis --blocks 16,32``, ~15 min per block on a loaded machine):
:func:`prefilter.studies.leadr.specular_diagnosis`, why sigma 0.5 specular misses 0.5x naive
(reference noise, grid N, LOD bias, parallax, the footprint's non-Gaussian slope histogram).

Render methods (``--render``): wall time of ``leadr-env`` (and ``algorithm=simplified``),
``leadr-irradiance`` and the naive methods on a 160 x 90 plane + sphere scene with a Gaussian
height map under ``procedural_env(128)``.

Throughput (``--throughput``): shading points per second per light type and grid size on 2^16
points. No assertions.
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from prefilter.leadr import (EnvMap, IrradianceMap, diffuse_directional, diffuse_irradiance,
                             diffuse_sh, diffuse_shadowing, env_specular, point_light,
                             procedural_env, sh9_project)

LUM = np.array([0.2126, 0.7152, 0.0722])


def configs(p: int, seed: int = 0):
    rng = np.random.default_rng(seed)
    cz = rng.uniform(0.15, 1.0, p)
    phi = rng.uniform(0, 2 * np.pi, p)
    sz = np.sqrt(1 - cz**2)
    wo = np.stack([sz * np.cos(phi), sz * np.sin(phi), cz], -1)
    mu = rng.normal(scale=0.15, size=(p, 2))
    return wo, mu


def cov_of(sx, sy, r=0.0):
    return np.array([[sx * sx, r * sx * sy], [r * sx * sy, sy * sy]])


def _timed(fn, reps=3):
    best, out = np.inf, None
    for _ in range(reps):
        t = time.perf_counter()
        out = fn()
        best = min(best, time.perf_counter() - t)
    return out, best


def convergence(p: int = 1000) -> None:
    env = EnvMap(procedural_env(128))
    sh = sh9_project(env)
    wo, mu = configs(p)
    wl = np.array([0.3, 0.2, 0.93]) / np.linalg.norm([0.3, 0.2, 0.93])
    cases = {
        "spec s=0.10": ("spec", cov_of(0.1, 0.1)),
        "spec s=0.25": ("spec", cov_of(0.25, 0.25)),
        "spec s=0.50": ("spec", cov_of(0.5, 0.5)),
        "spec aniso (0.5,0.1,r=.5)": ("spec", cov_of(0.5, 0.1, 0.5)),
        "diffuse SH s=0.50": ("sh", cov_of(0.5, 0.5)),
        "diffuse dir s=0.50": ("dir", cov_of(0.5, 0.5)),
    }
    grids = [("3", 3, None), ("5", 5, None), ("paper5", 5, 0.9), ("9", 9, None),
             ("17", 17, None), ("33", 33, None)]
    print("| case | ref N=128 mean | " + " | ".join(f"N={g[0]} err / us" for g in grids) + " |")
    print("|---|---|" + "---|" * len(grids))
    for name, (kind, cov) in cases.items():
        def run(n, spacing, reps=1):
            if kind == "spec":
                f = lambda: env_specular(env, wo, mu, cov, n, spacing=spacing) @ LUM
            elif kind == "sh":
                f = lambda: diffuse_sh(sh, wo, mu, cov, n, spacing=spacing) @ LUM
            else:
                f = lambda: diffuse_directional(wo, wl, mu, cov, n, spacing=spacing)
            return _timed(f, reps)

        ref, _ = run(128, None)
        cells = []
        for _, n, spacing in grids:
            val, t = run(n, spacing, 3)
            err = np.sqrt(np.mean((val - ref) ** 2)) / np.mean(ref)
            cells.append(f"{100 * err:.2f}% / {1e6 * t / p:.1f}")
        print(f"| {name} | {ref.mean():.4f} | " + " | ".join(cells) + " |", flush=True)


def throughput(p: int = 1 << 16) -> None:
    env = EnvMap(procedural_env(128))
    sh = sh9_project(env)
    wo, mu = configs(p, 1)
    cov = cov_of(0.25, 0.2, 0.3)
    wl = np.array([0.3, 0.2, 0.93]) / np.linalg.norm([0.3, 0.2, 0.93])
    runs = {"point light (closed form)": lambda: point_light(wo, wl, mu, cov, f0=0.04)}
    for n in (3, 5, 9, 17):
        runs[f"env specular {n}x{n}"] = lambda n=n: env_specular(env, wo, mu, cov, n, f0=0.04)
    runs["env specular 9x9 + shadowing"] = lambda: env_specular(env, wo, mu, cov, 9, f0=0.04,
                                                               shadowing=True)
    runs["diffuse shadowing 5x5 (16 x 32 directions)"] = lambda: diffuse_shadowing(
        env, wo, mu, cov, 5, rows=16)
    runs["diffuse shadowing 5x5 (32 x 64 directions)"] = lambda: diffuse_shadowing(
        env, wo, mu, cov, 5, rows=32)
    irr = IrradianceMap(env)
    runs["diffuse irradiance map 5x5"] = lambda: diffuse_irradiance(irr, wo, mu, cov, 5)
    for n in (5, 9):
        runs[f"diffuse SH {n}x{n}"] = lambda n=n: diffuse_sh(sh, wo, mu, cov, n)
        runs[f"diffuse directional {n}x{n}"] = lambda n=n: diffuse_directional(wo, wl, mu, cov, n)
    print("| light type | shading points / s |\n|---|---|")
    for name, fn in runs.items():
        _, t = _timed(fn)
        print(f"| {name} | {p / t:,.0f} |", flush=True)
    _, t = _timed(lambda: IrradianceMap(env))
    print(f"\nIrradianceMap build (once per environment, 128 rows): {1e3 * t:.0f} ms")


#: (label, method, variant settings)
METHODS = (("leadr-env", "leadr-env", None),
           ("leadr-env algorithm=simplified", "leadr-env", {"algorithm": "simplified"}),
           ("leadr-env-naive", "leadr-env-naive", None),
           ("leadr-irradiance", "leadr-irradiance", None),
           ("leadr-irradiance-naive", "leadr-irradiance-naive", None))


def render_times(width: int = 160, height: int = 90) -> None:
    import tempfile
    from pathlib import Path

    from prefilter.render import load_scene
    from prefilter.render.driver import render
    tmp = Path(tempfile.mkdtemp())
    np.save(tmp / "sky.npy", procedural_env(128))
    mat = {"alpha": 0.1, "f0": 0.04, "base_color": [0.3, 0.25, 0.2],
           "height_map": {"procedural": "gaussian", "size": 256, "rms_slope": 0.4, "scale": 1.0}}
    scene = load_scene({
        "camera": {"origin": [0, 1.2, 4], "target": [0, 0.3, 0], "fov": 40, "width": width,
                   "height": height},
        "objects": [{"type": "plane", "size": [20, 20], "uv_scale": [40, 40], "material": mat},
                    {"type": "sphere", "center": [0, 0.6, 0], "radius": 0.6,
                     "uv_scale": [8, 4], "material": mat}],
        "lights": [{"type": "environment", "image": "sky.npy"}]}, base_dir=tmp)
    print("| method | ms per frame | Mpixel / s |\n|---|---|---|")
    for label, method, params in METHODS:
        _, t = _timed(lambda: render(scene, method, params=params), reps=2)
        print(f"| {label} | {1e3 * t:.0f} | {width * height / t / 1e6:.3f} |", flush=True)


if __name__ == "__main__":
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--throughput", action="store_true")
    ap.add_argument("--acceptance", action="store_true",
                    help="far-field LEADR / normal-mapped / naive vs displaced reference table")
    ap.add_argument("--acceptance-env", action="store_true",
                    help="the far-field table under environment light")
    ap.add_argument("--no-shadowing", action="store_true")
    ap.add_argument("--convergence", action="store_true",
                    help="N x N vs N = 128 (prefilter.studies.leadr.convergence)")
    ap.add_argument("--render", action="store_true", help="render-method frame times")
    ap.add_argument("--image-point", action="store_true",
                    help="point-light image rows, planes and spheres (acceptance.image_point)")
    ap.add_argument("--quick", action="store_true", help="with --image-point: iso 0.25, plane")
    ap.add_argument("--flicker-floor", action="store_true",
                    help="far (16 texels/pixel) flicker rows with the reference's own flicker "
                         "floor (acceptance.image_point(noise_floor=True)), ~15 min")
    ap.add_argument("--flicker-source", default=None, metavar="'SURFACE, SHAPE; ...'",
                    help="far flicker against the displaced and the normal-mapped references "
                         "(acceptance.flicker_source_table), e.g. 'iso 0.25, sphere; flat, "
                         "plane' (surfaces of acceptance.POINT_SURFACES, or flat: rms slope "
                         "1e-3); ~3 min per row at --tpp 16")
    ap.add_argument("--tpp", type=float, default=16.0,
                    help="with --flicker-source: texels per pixel")
    ap.add_argument("--points", type=int, default=None)
    ap.add_argument("--spec-diagnosis", action="store_true",
                    help="why specular sigma 0.5 misses 0.5x naive at 16 / 32 texels "
                         "(acceptance.specular_diagnosis; --blocks, --surfaces: one surface)")
    ap.add_argument("--surfaces", default=None,
                    help="with --acceptance-env: ';'-separated subset of acceptance.SURFACES "
                         "(e.g. 'iso 0.5;aniso (0.45, 0.15)')")
    ap.add_argument("--shadings", default="specular,diffuse",
                    help="with --acceptance-env: specular, diffuse or both")
    ap.add_argument("--blocks", default="16,32,64", help="with --acceptance-env: texels/pixel")
    ap.add_argument("--k", type=int, default=32,
                    help="with --acceptance-env: reference view rays per footprint side")
    ap.add_argument("--spp", type=int, default=16,
                    help="with --acceptance-env: MIS samples per reference hit")
    a = ap.parse_args()
    if a.spec_diagnosis:
        from prefilter.studies.leadr import diagnosis_table, specular_diagnosis

        print(diagnosis_table(specular_diagnosis(
            a.surfaces or "iso 0.5", blocks=tuple(int(b) for b in a.blocks.split(",")),
            log=lambda row: None)))
    elif a.flicker_source:
        from prefilter.studies.leadr import POINT_SURFACES, flicker_source_table, image_point

        # 'flat': a nearly flat height map, every method's flicker is then macro geometry only
        known = dict(POINT_SURFACES, flat=dict(procedural="gaussian", rms_slope=1e-3))
        rows = []
        for spec in a.flicker_source.split(";"):
            surf, shape = (x.strip() for x in spec.rsplit(",", 1))
            rows += image_point(surfaces={surf: known[surf]}, shapes=(shape,),
                                texels_per_pixel=(a.tpp,), log=lambda row: None)
        print(flicker_source_table(rows))
    elif a.flicker_floor:
        from prefilter.studies.leadr import flicker_table, image_point

        print(flicker_table(image_point(texels_per_pixel=(16.0,), noise_floor=True,
                                        log=lambda row: None)))
    elif a.image_point:
        from prefilter.studies.leadr import POINT_SURFACES, image_point, point_table

        kw = dict(surfaces={"iso 0.25": POINT_SURFACES["iso 0.25"]},
                  shapes=("plane",)) if a.quick else {}
        print(point_table(image_point(log=lambda row: None, **kw)))
    elif a.render:
        render_times()
    elif a.acceptance_env:
        from prefilter.studies.leadr import SURFACES, env_diffuse_table, env_table, run_env

        surf = None if a.surfaces is None else {
            k.strip(): SURFACES[k.strip()] for k in a.surfaces.split(";")}
        rows = run_env(shadowing=not a.no_shadowing, surfaces=surf, k=a.k, spp=a.spp,
                       shadings=tuple(x.strip() for x in a.shadings.split(",")),
                       blocks=tuple(int(b) for b in a.blocks.split(",")), log=lambda row: None)
        print(env_table(rows))
        if any(r["shading"] == "diffuse" for r in rows):
            print()
            print(env_diffuse_table(rows))
    elif a.convergence:
        from prefilter.studies.leadr import convergence as conv, convergence_table

        print(convergence_table(conv(points=a.points or 1000, log=lambda row: None)))
    elif a.acceptance:
        from prefilter.studies.leadr import run, table

        print(table(run(log=lambda row: None)))
    elif a.throughput:
        throughput(a.points or 1 << 16)
    else:
        convergence(a.points or 1000)
