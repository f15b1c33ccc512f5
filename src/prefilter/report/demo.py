"""``prefilter demo``: the built-in showcase and its HTML report (``out/demo/index.html``).

The showcase is a normal-mapped GGX plane receding to the horizon under a quad area light, seen
from three distances (near: about one texel per pixel, far: many texels per pixel). Every
registered area-light method renders it, ``reference`` gives ground truth, and the report shows
the images side by side with FLIP maps, a metrics table (RMSE, relative MSE, FLIP, flicker, time)
and error against distance. A first section checks the shipped LTC table against Monte Carlo.

Then one section per method package, each with its own scenes and numbers, built by calling the
package (never re-implementing it): anisotropic LTC (brushed plane and sphere), multi-scale LTC
(brushed and flakes normal maps, near and far), LEADR (point light; per-footprint errors against
the displaced-geometry reference), colour-map filtering (cases a-d, near and far) and glints part
1 (NDF images of footprints, direct against compressed), and the WebGL2 viewer (a screenshot of
each mode from :func:`prefilter.viewer.screenshots` and the browser-vs-Python pixel match measured
on the fly in headless Chromium; a note instead when Chromium is missing). A section that fails
leaves a note in the report instead of stopping the demo. ``docs/demo.md`` lists what each number
means.

The camera and the light scale together with the distance, so the lighting configuration (and the
solid angle of the light) is the same at every distance; only the number of texels under a pixel
changes. That isolates what prefiltering is about.
"""

from __future__ import annotations

import tempfile
import time
import traceback
from dataclasses import dataclass
from pathlib import Path

import click
import numpy as np

from prefilter.cliparams import SEED, OutputDir
from prefilter.errors import PrefilterError
from prefilter.report.colormap_lit import colormap_lit_section
from prefilter.report.glints_wave import glints_wave_section
from prefilter.report.pathtrace import pathtrace_section
from prefilter.report.roughness import roughness_section


#: (shape, view angle from the normal (deg), texels per world unit, label): near and far on a
#: grazing plane and on a sphere (a subset of ``prefilter.studies.colormap.CONFIGS``).
COLORMAP_CONFIGS = (("plane", 70.0, 40.0, "near"), ("plane", 70.0, 1500.0, "far"),
                    ("sphere", 0.0, 10.0, "near"), ("sphere", 0.0, 900.0, "far"))


@dataclass(frozen=True)
class DemoSettings:
    """Sizes and sample counts of one demo run (``quick`` is the one-minute version).

    ``width``/``height``/``reference_spp``/``flicker_frames``/``distances``: the showcase;
    ``table_*``: the LTC table check; ``section_*``: image size and reference samples of the
    method sections; ``colormap_*``: image side and reference grid (``n x n`` per pixel) of the
    colour-map scenes; ``leadr_*``: height-field size, footprint sizes (texels), shifts and rays
    per texel side of the per-footprint LEADR table; ``glints_*``: normal-map side, NDF image
    resolution and CP rank of the glints bake; ``glints_render_*``: normal-map side, frame size
    and camera distances of the rendered glints frames (the renderer's own bake settings,
    :data:`prefilter.glints.bake.BAKE_SETTINGS`); ``glints_wang``: the Wang-tile bake settings
    of the same frames' ``glints-wang`` renders (``(key, value)`` pairs of
    :data:`prefilter.glints.wang_render.WANG_SETTINGS`: the renderer's default bake takes
    minutes; NDF images of 256^2 pixels keep the FLIP against ``glints-direct`` near the
    default's, 128^2 in ``quick`` doubles it mid and far); ``viewer_*``: screenshot size,
    pixel-match image size, and whether the viewer section runs the browser at all.
    ``methods`` (showcase; ``None``: every registered method but :data:`SHOWCASE_EXCLUDE`),
    ``multiscale_maps`` and ``colormap_configs`` restrict the scenes (for tests: each HDR-FLIP
    evaluation costs most of a second whatever the image size).
    """

    width: int = 256
    height: int = 160
    reference_spp: int = 64
    flicker_frames: int = 8
    table_configs: int = 400
    table_samples: int = 20_000
    distances: tuple[float, ...] = (1.0, 4.0, 16.0)
    section_width: int = 192
    section_height: int = 120
    section_spp: int = 64
    colormap_size: int = 48
    colormap_nref: int = 32
    leadr_size: int = 128
    leadr_blocks: tuple[int, ...] = (16, 32)
    leadr_shifts: int = 3
    leadr_rays: int = 32
    glints_map: int = 64
    glints_ndf_res: int = 32
    glints_rank: int = 16
    glints_render_map: int = 128
    glints_render_size: tuple[int, int] = (64, 48)
    glints_render_distances: tuple[float, ...] = (0.5, 2.0, 8.0)
    glints_wang: tuple = (("ndf_res", 256), ("rank", 8), ("block", 16), ("n_iter_max", 30))
    viewer: bool = True
    viewer_size: tuple[int, int] = (384, 288)
    viewer_match_size: tuple[int, int] = (96, 72)
    methods: tuple[str, ...] | None = None
    multiscale_maps: tuple[str, ...] = ("brushed", "flakes")
    colormap_configs: tuple = COLORMAP_CONFIGS

    @classmethod
    def quick(cls) -> "DemoSettings":
        return cls(width=128, height=80, reference_spp=16, flicker_frames=4, table_configs=100,
                   table_samples=10_000, section_width=96, section_height=60, section_spp=16,
                   colormap_size=32, colormap_nref=12, leadr_size=64, leadr_blocks=(16,),
                   leadr_shifts=2, leadr_rays=16, glints_rank=8, glints_render_map=64,
                   glints_wang=(("ndf_res", 128), ("rank", 8), ("block", 16),
                                ("n_iter_max", 30)),
                   viewer_size=(256, 192),
                   viewer_match_size=(64, 48))


#: Texels of the normal map per world unit, and the distance (world units) at which one pixel
#: covers about one texel at the target point with the demo camera (fov 30 deg, 160 rows).
TEXELS_PER_UNIT = 256


def showcase_scene(distance: float, width: int, height: int, *, normal_map: dict | None = None,
                   alpha: float = 0.1) -> dict:
    """The demo scene as a plain dict (see ``docs/scenes.md``), camera ``distance`` times the base.

    Base configuration: the camera looks down at 20 degrees onto the plane ``y = 0``; the quad
    light hangs above the far side so its reflection crosses the image. Camera and light scale
    with ``distance``; the plane and its texture do not. ``normal_map`` is a procedural texture
    spec (``docs/scenes.md``); the default is isotropic Gaussian bumps.
    """
    if normal_map is None:
        normal_map = {"procedural": "gaussian", "size": 256, "seed": 1, "rms_slope": 0.25,
                      "corr_length": 3}
    d = float(distance)
    elev = np.radians(20.0)
    base = 1.4  # world units from the camera to the target at distance 1
    eye = [0.0, base * d * np.sin(elev), base * d * np.cos(elev)]
    target = [0.0, 0.0, 0.0]
    # The light: a 1.2 x 0.6 quad (scaled), beyond the target, tilted to face the camera.
    lz = -2.0 * d
    ly0, ly1 = 0.35 * d, 0.95 * d
    hw = 0.6 * d
    size = 400.0
    return {
        "camera": {"origin": eye, "target": target, "up": [0, 1, 0], "fov": 30,
                   "width": int(width), "height": int(height)},
        "objects": [{
            "type": "plane", "center": [0, 0, -size / 2 + 20], "normal": [0, 1, 0],
            "tangent": [1, 0, 0], "size": [size, size],
            "uv_scale": [size * TEXELS_PER_UNIT / 256, size * TEXELS_PER_UNIT / 256],
            "material": {
                "alpha": alpha, "base_color": [0.02, 0.02, 0.02], "f0": [0.9, 0.9, 0.9],
                "normal_map": dict(normal_map),
            },
        }],
        "lights": [{
            "type": "quad",
            # Counter-clockwise seen from the plane below / the camera in front.
            "vertices": [[-hw, ly0, lz], [hw, ly0, lz], [hw, ly1, lz - 0.3 * d],
                         [-hw, ly1, lz - 0.3 * d]],
            "radiance": [6.0, 6.0, 6.0],
        }],
    }


# ------------------------------------------------------------------------------- shared parts

#: Normal maps of the multi-scale section (the built-in brushed and flakes textures, 256^2, with
#: the parameters of ``benchmarks/bench_multiscale.py``).
MULTISCALE_MAPS = {
    "brushed": {"procedural": "brushed", "size": 256, "seed": 1, "rms_slope": 0.25, "length": 64,
                "width": 1.5},
    "flakes": {"procedural": "flakes", "size": 256, "seed": 1, "rms_slope": 0.25,
               "flake_size": 4},
}
MULTISCALE_METHODS = ("ltc", "ltc-multiscale", "ltc-multiscale footprint=paper")


#: Registered methods the showcase leaves out: ground-truth evaluators (``reference``, the path
#: tracer ``path``, which has its own section), whose cost grows with the footprint
#: (``glints-direct`` ran for more than 10 minutes at distance x4 of the quick showcase; the
#: glints section compares them with ``glints``), and ``glints`` itself, whose pyramid bake for
#: the showcase's 256^2 normal map adds ~6 minutes to a fresh demo (the glint look is not what
#: the showcase's area-light comparison is about), and ``glints-wang`` (its default per-tile
#: bake takes ~3 minutes; the "Glints (part 3)" section renders it with a lighter bake).
SHOWCASE_EXCLUDE = ("reference", "path", "glints", "glints-direct", "glints-reference",
                    "glints-wang")


def _available_methods() -> list[str]:
    from prefilter.render.methods import available

    return [m for m in available() if m not in SHOWCASE_EXCLUDE]


def _note_failure(report, what: str, exc: BaseException, log) -> str:
    """Put a visible note in the report (and the log) instead of propagating ``exc``."""
    msg = f"{type(exc).__name__}: {exc}"
    log(f"{what} failed: {msg}")
    if not isinstance(exc, PrefilterError):
        log(traceback.format_exc(limit=4))
    report.add_text(f"**Not available: {what}** ({msg}).")
    return msg


def _section(report, status: list, title: str, intro: str, body, log) -> None:
    """Run ``body(report)`` under a heading; an exception becomes a note, never a crash."""
    report.add_section(title, intro)
    t0 = time.perf_counter()
    try:
        body(report)
        state = "ok"
    except Exception as exc:  # noqa: BLE001  (one broken package must not sink the demo)
        state = "failed: " + _note_failure(report, f"section '{title}'", exc, log)
    dt = time.perf_counter() - t0
    report.add_text(f"Section time: {dt:.1f} s.")
    log(f"{title}: {dt:.1f} s ({state})")
    status.append([title, state, dt])


def _compare(report, label: str, scene, methods, *, spp: int, seed: int, log,
             scale: int = 2) -> list[list]:
    """Render ``scene`` by ``reference`` and ``methods``; comparison rows + FLIP maps in the
    report; returns table rows ``[label, method, RMSE, relMSE, FLIP, time]`` (skips failures).
    A method is a registered name, optionally followed by ``key=value`` variant settings."""
    from prefilter.render.driver import render
    from prefilter.render.scene import load_scene

    # load once: textures and their mip chains are built on first use and then shared
    scene = load_scene(scene)
    t0 = time.perf_counter()
    ref = render(scene, "reference", spp=spp, seed=seed)
    t_ref = time.perf_counter() - t0
    images, times = {}, {}
    for m in methods:
        try:
            name, *params = m.split()
            images[m] = render(scene, name, spp=1, seed=seed, params=params or None)
            times[m] = _warm_time(lambda: render(scene, name, spp=1, seed=seed,
                                                 params=params or None))
        except Exception as exc:  # noqa: BLE001
            _note_failure(report, f"method {m} on {label}", exc, log)
    if not images:
        report.add_image_row(label, [("reference", ref)], scale=scale)
        return []
    rows = [[label, "reference", 0.0, 0.0, 0.0, t_ref]]
    for r in report.add_comparison(label, ref, images, scale=scale):
        rows.append([label, r["method"], r["rmse"], r["relmse"], r["flip"], times[r["method"]]])
    return rows


_COMPARE_HEADER = ["scene", "method", "RMSE", "relMSE", "FLIP", "time (s)"]

#: What the time columns measure (one caption sentence for every table that has them).
TIME_NOTE = ("Times: one frame at 1 spp after a first, untimed call of the same method (so "
             "Numba compilation and texture set-up are not counted); the reference rows time "
             "its one call, compilation included.")


def _warm_time(frame) -> float:
    """Wall time of ``frame()``, called after the caller's own first (compiling) call."""
    t0 = time.perf_counter()
    frame()
    return time.perf_counter() - t0


# -------------------------------------------------------------------------------- sections


def _table_section(report, settings: DemoSettings, seed: int, log) -> list[dict]:
    """Check the shipped isotropic LTC table against Monte Carlo and plot error vs angle."""
    from prefilter.ltc import GGXTable
    from prefilter.ltc.validate import format_statistics, run_acceptance

    t0 = time.perf_counter()
    table = GGXTable.load()
    result = run_acceptance(table, settings.table_configs, settings.table_samples, seed=seed)
    stats = result["stats"]
    log(f"LTC table check: {time.perf_counter() - t0:.1f} s")
    report.add_text(
        f"{settings.table_configs} random configurations (view 0-85 deg, alpha 0.05-1, random "
        f"quads, some straddling the horizon), {settings.table_samples} MIS samples each. "
        "Numbers: relative error of the LTC integral against the Monte Carlo estimate. "
        "The full acceptance (2000 configurations, 1e5 samples) is `prefilter validate`.",
    )
    report.add_text("```\n" + format_statistics(stats) + "\n```")
    def pct(x):
        return "-" if x is None else f"{100 * x:.2f}"

    rows = [[f"{b['lo']:.0f}-{b['hi']:.0f}", b["count"], pct(b["median"]), pct(b["p90"])]
            for b in stats["by_theta"]]
    report.add_table(["view angle (deg)", "count", "median rel. error (%)", "p90 rel. error (%)"],
                     rows)
    return [stats]


def _render_all(settings: DemoSettings, methods: list[str], seed: int, log):
    from prefilter.render.metrics import flicker, jitter_offsets
    from prefilter.render.driver import render
    from prefilter.render.scene import load_scene

    results = []
    jit = jitter_offsets(settings.flicker_frames)
    for d in settings.distances:
        # load once: a scene dict would rebuild the normal map and its mips on every render
        scene = load_scene(showcase_scene(d, settings.width, settings.height))
        t0 = time.perf_counter()
        ref = render(scene, "reference", spp=settings.reference_spp, seed=seed, progress=True)
        entry = {"distance": d, "reference": ref, "images": {}, "times": {}, "flicker": {},
                 "skipped": {}, "failed": {}, "reference_time": time.perf_counter() - t0}
        log(f"distance {d:g}: reference {entry['reference_time']:.1f} s")
        for m in methods:
            try:
                img = render(scene, m, spp=1, seed=seed)  # first call: compiles, not timed
                frames, times = [], []
                for j in jit:  # warm frames: their median time is the method's time
                    t0 = time.perf_counter()
                    frames.append(render(scene, m, spp=1, seed=seed, jitter=tuple(j)))
                    times.append(time.perf_counter() - t0)
                entry["times"][m] = float(np.median(times))
                entry["flicker"][m] = flicker(np.stack(frames))
                entry["images"][m] = img
                log(f"distance {d:g}: {m} {entry['times'][m]:.2f} s")
            except PrefilterError as exc:  # the method rejects the scene (e.g. point lights only)
                entry["skipped"][m] = str(exc)
                log(f"distance {d:g}: {m}: skipped: {exc}")
            except Exception as exc:  # noqa: BLE001  (one broken method must not sink the demo)
                entry["failed"][m] = f"{type(exc).__name__}: {exc}"
                log(f"distance {d:g}: {m} failed ({exc})")
        results.append(entry)
    return results


def _showcase_section(report, settings: DemoSettings, seed: int, log) -> None:
    methods = _available_methods() if settings.methods is None else list(settings.methods)
    results = _render_all(settings, methods, seed, log)
    skipped = {m: why for e in results for m, why in e["skipped"].items()}
    failed = {m: why for e in results for m, why in e["failed"].items()}
    if skipped:
        report.add_text(_not_applicable(skipped))
    if failed:
        report.add_text("**Failed on this scene:**\n\n" + "\n".join(
            f"- `{m}`: {why}" for m, why in sorted(failed.items())))
    rows = []
    curves: dict[str, list[float]] = {m: [] for m in methods
                                      if m not in skipped and m not in failed}
    for entry in results:
        if not entry["images"]:
            continue
        metrics = {r["method"]: r for r in report.add_comparison(
            f"distance x{entry['distance']:g}", entry["reference"], entry["images"], scale=2)}
        rows.append([f"x{entry['distance']:g}", "reference", 0.0, 0.0, 0.0, 0.0,
                     entry["reference_time"]])
        for m in curves:
            if m not in entry["images"]:
                curves[m].append(float("nan"))
                continue
            mm = metrics[m]
            rows.append([f"x{entry['distance']:g}", m, mm["rmse"], mm["relmse"], mm["flip"],
                         entry["flicker"][m], entry["times"][m]])
            curves[m].append(mm["flip"])
    report.add_table(["distance", "method", "RMSE", "relMSE", "FLIP", "flicker", "time (s)"],
                     rows, caption="Errors against the reference at each distance. Times: median "
                     "of the jittered 1-spp frames, each after the method's first (compiling) "
                     "call; the reference rows time its one call, compilation included at x"
                     f"{settings.distances[0]:g}.")
    if curves:
        report.add_plot(_distance_plot(list(settings.distances), curves), caption="Error "
                        "against distance.")


def _not_applicable(skipped: dict[str, str]) -> str:
    """One sentence naming the methods that reject the showcase scene, grouped by family."""
    families: dict[str, list[str]] = {}
    for m in sorted(skipped):
        families.setdefault(m.split("-")[0], []).append(m)
    names = ", ".join(f"`{ms[0]}`" if len(ms) == 1 else f"`{f}-*` ({len(ms)} methods)"
                      for f, ms in families.items())
    return (f"Not shown here: {names}. They reject this scene (they shade point, directional or "
            "environment lights, or need a colour-map driver); the LEADR and colour-map sections "
            "below show those methods on their own scenes.")


def _distance_plot(x, curves):
    from prefilter.report.report import line_plot

    return line_plot(x, curves, xlabel="camera distance (x)", ylabel="mean FLIP vs reference",
                     logx=True)


def _aniso_section(report, settings: DemoSettings, seed: int, log) -> None:
    from prefilter.ltc.aniso.demo import demo_scene

    scene = demo_scene(settings.section_width, settings.section_height)
    rows = _compare(report, "brushed plane + sphere", scene, ("ltc-aniso", "ltc"),
                    spp=settings.section_spp, seed=seed, log=log)
    report.add_table(_COMPARE_HEADER, rows, caption="ltc-aniso should be closer to the "
                     "reference than the isotropic ltc (which shades with sqrt(alpha_x alpha_y)). "
                     + TIME_NOTE)


def _multiscale_section(report, settings: DemoSettings, seed: int, log) -> None:
    # texels per pixel of the showcase camera ~ distance * 160 / height
    k = 160.0 / settings.section_height
    rows = []
    for name in settings.multiscale_maps:
        spec = MULTISCALE_MAPS[name]
        for label, tpp in (("near", 1.0), ("far", 16.0)):
            scene = showcase_scene(tpp / k, settings.section_width, settings.section_height,
                                   normal_map=spec, alpha=0.03)
            rows += _compare(report, f"{name} map, {label} (~{tpp:g} texels/pixel)", scene,
                             MULTISCALE_METHODS, spp=settings.section_spp, seed=seed, log=log)
    report.add_table(_COMPARE_HEADER, rows, caption="Far away the mip-averaged normal of ltc "
                     "loses the meso-scale roughness (too sharp a highlight); the multi-scale "
                     "variants widen the lobe by the length of the averaged normal. Compare the "
                     "far rows; near, the reference resolves single texels that no "
                     "one-lobe-per-pixel method reproduces. " + TIME_NOTE)
    if "brushed" in settings.multiscale_maps:
        report.add_text(
            "On the brushed map far away `ltc-multiscale` can have a lower RMSE but a higher FLIP "
            "than `ltc`: it widens the lobe equally in every direction while the brushed slopes "
            "vary along one axis only, so its highlight bleeds sideways into surroundings that "
            "are dark in the reference (where its FLIP map is brightest), whereas the error of "
            "`ltc` is a too-bright highlight, which weighs more in RMSE; "
            "`ltc-multiscale-aniso` widens the lobe along the brushing only and does better on "
            "both (`prefilter render example:multiscale-brushed --method ltc-multiscale-aniso`).")


def leadr_scene(width: int, height: int) -> dict:
    """A height-mapped sphere on a height-mapped plane under one point light (LEADR section).

    Gaussian height fields (rms slope 0.35, 128^2 texels) tiled densely, so a pixel covers
    several texels: the regime where averaging normals (naive) loses the roughness."""
    def material(seed):
        return {"alpha": 0.1, "base_color": [0.05, 0.05, 0.05], "f0": [0.9, 0.8, 0.6],
                "height_map": {"procedural": "gaussian", "size": 128, "seed": seed,
                               "rms_slope": 0.35, "corr_length": 3}}

    return {
        "camera": {"origin": [0.0, 1.6, 4.2], "target": [0.0, 0.45, 0.0], "up": [0, 1, 0],
                   "fov": 45, "width": int(width), "height": int(height)},
        "objects": [
            {"type": "plane", "center": [0, 0, 0], "normal": [0, 1, 0], "tangent": [1, 0, 0],
             "size": [12, 12], "uv_scale": [24, 24], "material": material(1)},
            {"type": "sphere", "center": [0, 0.7, 0], "radius": 0.7, "pole": [0, 1, 0],
             "uv_scale": [12, 6], "material": material(2)},
        ],
        "lights": [{"type": "point", "position": [-1.2, 2.6, -2.5], "intensity": [12, 12, 12]}],
    }


def _leadr_section(report, settings: DemoSettings, seed: int, log) -> None:
    from prefilter.studies import leadr as acceptance

    scene = leadr_scene(settings.section_width, settings.section_height)
    try:
        rows = _compare(report, "point light: sphere + plane", scene, ("leadr-point", "ltc"),
                        spp=settings.section_spp, seed=seed, log=log)
        report.add_table(_COMPARE_HEADER, rows, caption="Image level: the reference is the "
                         "normal-mapped surface supersampled at full resolution (the renderer "
                         "has no displaced geometry); ltc = naive mip-mapped normals. "
                         + TIME_NOTE)
    except Exception as exc:  # noqa: BLE001  (the per-footprint table below still runs)
        _note_failure(report, "LEADR image comparison", exc, log)
    rows = acceptance.run(size=settings.leadr_size, blocks=settings.leadr_blocks,
                          shifts=settings.leadr_shifts, k=settings.leadr_rays, seed=seed,
                          log=lambda r: None)
    table = [[r["surface"], r["shading"], r["block"], r["err leadr"], r["err normal-mapped"],
              r["err naive"], r["flicker leadr"], r["flicker naive"]] for r in rows]
    report.add_text(
        "Per footprint against the **displaced reference** (a ray-marched height field with "
        "masking and shadowing, `prefilter.leadr.displaced`): mean relative error "
        "|method - ref| / ref over four view/light pairs, and flicker = std of (method - ref) "
        f"over {settings.leadr_shifts} footprints shifted by 3 texels, relative to the mean. "
        f"Height fields {settings.leadr_size}^2, {settings.leadr_rays}^2 rays per footprint.")
    report.add_table(["surface", "shading", "texels/pixel", "err LEADR", "err normal-mapped",
                      "err naive", "flicker LEADR", "flicker naive"], table,
                     caption="Relative errors (fractions, not percent).")


def _srgb8(img) -> np.ndarray:
    from prefilter.render.metrics import linear_to_srgb

    return np.round(linear_to_srgb(np.clip(img, 0.0, 1.0)) * 255.0).astype(np.uint8)


_CASE_NAMES = {"tabulated": "(a) tabulated noise", "procedural": "(b) procedural noise",
               "height": "(c) microsurface heights", "slope": "(d) microsurface slopes"}


def _colormap_section(report, settings: DemoSettings, seed: int, log) -> None:
    from prefilter.studies import colormap as cm
    from prefilter.render.metrics import flip
    from prefilter.render.scene import load_scene

    data = cm.build_data(seed=seed)
    n = settings.colormap_size
    scale = max(1, 192 // n)
    rows = []
    for shape, view, density, label in settings.colormap_configs:
        scene = load_scene(cm.scene_dict(shape, view, density, n, n))
        imgs, mask, fp = cm.render_case(scene, data, n_ref=settings.colormap_nref, seed=seed)
        for case in cm.CASES:
            ref, hidden = _visible_reference(imgs[case])
            valid = mask & ~hidden
            row_imgs = [("reference", _srgb8(ref))]
            row = [f"{shape} {view:.0f} deg", label, fp, _CASE_NAMES[case]]
            for m in ("filtered", "naive"):
                row_imgs.append((m, _srgb8(imgs[case][m])))
                f = flip(_srgb8(imgs[case][m]) / 255.0, _srgb8(ref) / 255.0, hdr=False)
                row += [cm.lab_rmse(imgs[case][m], ref, valid),
                        float(np.mean(np.asarray(f.error_map)[valid]))]
            report.add_image_row(f"{shape}, {label} ({fp:.1f} texels/pixel): "
                                 f"{_CASE_NAMES[case]}", row_imgs, scale=scale)
            rows.append(row + [int(hidden.sum())])
    report.add_table(["scene", "distance", "texels/pixel", "case", "dE filtered", "FLIP filtered",
                      "dE naive", "FLIP naive", "hidden pixels"], rows,
                     caption="dE: RMS CIE76 colour difference to the reference over valid pixels "
                     "(view and light above the surface); FLIP: mean LDR-FLIP over the same "
                     "pixels. Far away, naive C(mean) collapses towards the colour of the mean "
                     "input while the filtered colour stays close to the reference's average. "
                     "Hidden pixels: every reference sample of the pixel has zero weight (in case "
                     "(d) all microfacets under a pixel face away from the camera, so the pixel "
                     "has no visible colour at the texture's resolution); the reference shows "
                     "them in magenta and they are left out of dE and FLIP.")


#: Display colour of reference pixels without a visible sample (linear RGB, a colour the four
#: colour maps do not use).
HIDDEN_COLOUR = (0.8, 0.0, 0.8)


def _visible_reference(images: dict) -> tuple[np.ndarray, np.ndarray]:
    """The colour-map reference with its hidden pixels marked, and their mask ``(H, W)``.

    A covered pixel (the filtered or naive image is not black there) whose reference is exactly
    zero had zero total weight: no reference sample is visible (``0 / 0`` reads as black)."""
    ref = images["reference"]
    covered = np.any(images["filtered"] != 0, -1) | np.any(images["naive"] != 0, -1)
    hidden = covered & np.all(ref == 0, -1)
    return np.where(hidden[..., None], HIDDEN_COLOUR, ref), hidden


def _glints_section(report, settings: DemoSettings, seed: int, log) -> None:
    from prefilter.glints import load, pndf_image, point
    from prefilter.glints.bake import bake
    from prefilter.render.metrics import flip_heatmap
    from prefilter.texture.procedural import normal_map

    size = settings.glints_map
    nm = normal_map("flakes", size=size, seed=seed + 1, rms_slope=0.25, flake_size=6)
    res = settings.glints_ndf_res
    cell = min(32, size)
    with tempfile.TemporaryDirectory(prefix="prefilter-demo-glints-") as tmp:
        summary = bake(nm, Path(tmp) / "glints.npz", rank=settings.glints_rank, ndf_res=res,
                       block=8 if res % 8 == 0 else res, cell=cell, n_iter_max=30, seed=seed,
                       progress=True)
        gm = load(Path(tmp) / "glints.npz")
    report.add_text(
        f"A {size}^2 flakes normal map (flake size 6 texels) baked on the fly: NDF images "
        f"{res}^2 over |s| <= {gm.support:g}, footprint pyramid from stride 4, CP rank "
        f"{settings.glints_rank} per group. Bake: {summary['seconds']:.1f} s, compressed "
        f"{summary['compressed_bytes'] / 1024:.0f} KiB = {100 * summary['ratio']:.1f} % of the "
        f"raw pyramid, relative L2 compression error {100 * summary['rel_l2_error']:.1f} % "
        "over all stored images.")
    centers = np.array([[0.3, 0.4], [0.7, 0.25], [0.5, 0.75]]) * size
    sigmas = np.array([4.0, 8.0, 16.0])
    c = np.repeat(centers, len(sigmas), axis=0)
    sp = np.tile(sigmas, len(centers))
    direct = pndf_image(nm, c, sp, res, gm.support)
    h = 2.0 * gm.support / res
    x = -gm.support + (np.arange(res) + 0.5) * h
    s = np.stack(np.meshgrid(x, x), -1)  # rows along s_y, columns along s_x
    comp = point(gm, c[:, None, None, :], sp[:, None, None], s[None])
    rows = []
    scale = max(1, 128 // res)
    for i in range(len(c)):
        top = max(float(direct[i].max()), 1e-300)
        err = float(np.linalg.norm(comp[i] - direct[i]) / max(np.linalg.norm(direct[i]), 1e-300))
        label = f"footprint at ({c[i, 0]:.0f}, {c[i, 1]:.0f}), sigma {sp[i]:g} texels"
        report.add_image_row(label, [
            ("direct P-NDF", flip_heatmap(np.clip(direct[i] / top, 0, 1))),
            ("compressed query", flip_heatmap(np.clip(comp[i] / top, 0, 1))),
            ("|difference|", flip_heatmap(np.clip(np.abs(comp[i] - direct[i]) / top, 0, 1))),
        ], scale=scale)
        rows.append([f"({c[i, 0]:.0f}, {c[i, 1]:.0f})", sp[i], err,
                     float(direct[i].sum() * h * h)])
    report.add_table(["centre (texels)", "sigma_p (texels)", "rel. L2 error", "mass in support"],
                     rows, caption="Direct: exact pixel averages of the Gaussian-footprint P-NDF "
                     "(Yan et al. 2016). Compressed: `glints.point` at the pixel centres "
                     "(trilinear over the pyramid, CP factors). The error combines pyramid "
                     "interpolation and compression. Images share the direct image's maximum.")


def _timed(frames: dict) -> tuple[dict, dict]:
    """Each ``name -> callable`` called once, in order: its images and wall times (s)."""
    images, times = {}, {}
    for name, fn in frames.items():
        t0 = time.perf_counter()
        images[name] = fn()
        times[name] = time.perf_counter() - t0
    return images, times


def _glints_render_section(report, settings: DemoSettings, seed: int, log) -> None:
    from prefilter.glints.render import cache_dir, measurement_scene, pixel_footprints
    from prefilter.render.driver import render
    from prefilter.render.scene import load_scene

    size = settings.glints_render_map
    w, h = settings.glints_render_size
    rows = []
    for d in settings.glints_render_distances:
        sc = load_scene(measurement_scene(d, "flakes", size, width=w, height=h))
        t0 = time.perf_counter()
        render(sc, "glints", seed=seed, progress=True)  # the bake (disk cache), compilation
        t_first = time.perf_counter() - t0
        if t_first > 5.0:
            log(f"glints: first frame (bake or cache load, compilation) {t_first:.1f} s; "
                f"pyramids cached in {cache_dir()}")
        if d == settings.glints_render_distances[0]:
            render(sc, "glints-direct", seed=seed)  # compilation, not timed below
        images, times = _timed({m: (lambda m=m: render(sc, m, seed=seed))
                                for m in ("glints", "glints-direct")})
        cmp = report.add_comparison(f"distance {d:g}", images["glints-direct"],
                                    {"glints": images["glints"]}, scale=4,
                                    reference_name="glints-direct")[0]
        _, sp, _ = pixel_footprints(sc, (size, size))
        rows.append([f"{d:g}", float(np.median(sp)), times["glints"], times["glints-direct"],
                     times["glints-direct"] / times["glints"], cmp["flip"],
                     float(images["glints"].mean() / max(images["glints-direct"].mean(),
                                                         1e-300))])
    report.add_table(
        ["distance", "median footprint std (texels)", "glints (s)", "glints-direct (s)",
         "speed-up", "FLIP glints vs direct", "mean radiance ratio"], rows,
        caption="One frame each at 1 spp, measured now (wall clock, this machine, after an "
        "untimed first call of each method). `glints` "
        "queries the CP-compressed footprint pyramid (constant cost per pixel); `glints-direct` "
        "sums every texel under the footprint, so its cost grows with the footprint's area. "
        "The full acceptance matrix (plane and sphere, four maps, point, quad and environment "
        "lights) is `benchmarks/study_glints_scenes.py` (docs/glints-part2.md).")


def _glints_wang_section(report, settings: DemoSettings, seed: int, log) -> None:
    from prefilter.glints import wang_render
    from prefilter.glints.render import measurement_scene, pixel_footprints
    from prefilter.glints.wang import assemble, periodic_index_map
    from prefilter.render.driver import render
    from prefilter.render.methods import RenderSettings
    from prefilter.render.scene import load_scene
    from prefilter.texture.normalmap import encode_normals

    size = settings.glints_render_map
    w, h = settings.glints_render_size
    over = dict(settings.glints_wang)
    rows = []
    with tempfile.TemporaryDirectory(prefix="prefilter-demo-wang-") as tmp:
        for k, d in enumerate(settings.glints_render_distances):
            spec = measurement_scene(d, "flakes", size, width=w, height=h)
            sc = load_scene(spec)
            nm = sc.objects[0].material.normal_map.load()
            t0 = time.perf_counter()
            wn = wang_render.baked_tiles(nm, over, progress=True)
            if k == 0:
                log(f"glints-wang: tiles baked or loaded in {time.perf_counter() - t0:.1f} s")
            # a valid periodic tiling of the exemplar's size, and the same surface assembled as
            # an ordinary normal map for glints-direct
            n_t = max(1, nm.shape[0] // wn.wang.size)
            idx = periodic_index_map(n_t, n_t, rng=seed)
            path = Path(tmp) / f"assembled-{k}.npy"
            np.save(path, encode_normals(assemble(wn.wang, idx)))
            spec["objects"][0]["material"]["normal_map"] = str(path)
            sd = load_scene(spec)
            rs = RenderSettings(seed=seed)
            if k == 0:  # compilation, not timed below
                wang_render.render_wang(sc, rs, index=idx, wang=over)
                render(sc, "glints", seed=seed)
                render(sd, "glints-direct", seed=seed)
            images, times = _timed({
                "glints-wang": lambda: wang_render.render_wang(sc, rs, index=idx, wang=over),
                "glints": lambda: render(sc, "glints", seed=seed),
                "glints-direct": lambda: render(sd, "glints-direct", seed=seed)})
            cmp = report.add_comparison(f"distance {d:g}", images["glints-direct"],
                                        {"glints-wang": images["glints-wang"]}, scale=4,
                                        reference_name="glints-direct (assembled tiling)")[0]
            _, sp, _ = pixel_footprints(sc, (size, size))
            rows.append([f"{d:g}", float(np.median(sp)), times["glints-wang"], times["glints"],
                         times["glints-wang"] / times["glints"], times["glints-direct"],
                         cmp["flip"]])
    report.add_table(
        ["distance", "median footprint std (texels)", "glints-wang (s)", "glints (s)",
         "wang / glints", "glints-direct (s)", "FLIP wang vs direct"], rows,
        caption="One frame each at 1 spp, measured now (wall clock, this machine, after an "
        "untimed first call of each method). `glints-wang` queries the 16 tiles' compressed "
        "footprint pyramids (the bake settings of this section: "
        + ", ".join(f"{k} {v}" for k, v in settings.glints_wang) + ") over a valid periodic "
        "tiling; `glints-direct` renders the same tiling assembled as one normal map; `glints` "
        "renders the exemplar itself (another surface: its time is the reference cost). The "
        "default bake and the full measurements (point, quad and environment lights): "
        "`benchmarks/bench_glints_wang.py`, docs/glints-wang.md.")


def _viewer_section(report, settings: DemoSettings, seed: int, log) -> None:
    import os

    from prefilter.viewer import METHODS, pixel_match, screenshots
    from prefilter.viewer.browser import CHROMEDRIVER, CHROMIUM, chromium
    from prefilter.viewer.glints import glints_screenshot

    if not settings.viewer:
        report.add_text("Skipped (demo settings: `viewer=False`).")
        return
    missing = [p for p in (CHROMIUM, CHROMEDRIVER) if not os.access(p, os.X_OK)]
    if missing:
        report.add_text(f"Headless Chromium is missing ({', '.join(missing)}): no screenshots or "
                        "pixel match here. Install Debian's `chromium` and `chromium-driver` and "
                        "run `prefilter view` / `python -m prefilter.viewer.match`.")
        log(f"viewer section: skipped: {', '.join(missing)} missing")
        return
    w, h = settings.viewer_size
    mw, mh = settings.viewer_match_size
    ltc = tuple(m for m in METHODS if m.startswith("ltc"))
    cmap = tuple(m for m in METHODS if m.startswith("colormap-"))
    with tempfile.TemporaryDirectory(prefix="prefilter-demo-viewer-") as tmp:
        driver = chromium(Path(tmp) / "profile")
        try:
            t0 = time.perf_counter()
            shots = screenshots(Path(tmp) / "shots", width=w, height=h, driver=driver)
            glint_shot = glints_screenshot(Path(tmp) / "glints.png", width=w, height=h,
                                           driver=driver)
            t_shots = time.perf_counter() - t0
            t0 = time.perf_counter()
            rows = (pixel_match(scenes=("bumps-sphere",), methods=ltc, width=mw, height=mh,
                                driver=driver)
                    + pixel_match(scenes=("leadr",), methods=("leadr-point",), width=mw,
                                  height=mh, driver=driver)
                    + pixel_match(scenes=("colormap",), methods=cmap, precisions=("f32",),
                                  width=mw, height=mh, driver=driver)
                    + pixel_match(scenes=("leadr-env",), methods=("leadr-env", "leadr-irradiance"),
                                  width=mw, height=mh, driver=driver))
            t_match = time.perf_counter() - t0
        finally:
            driver.quit()
        names = [p.stem.removeprefix("viewer_") for p in shots]
        half = (len(shots) + 1) // 2
        report.add_image_row("viewer modes", list(zip(names[:half], map(str, shots[:half]))))
        report.add_image_row("viewer modes 2", list(zip(names[half:], map(str, shots[half:]))))
        report.add_image_row("viewer glints", [("glints | smooth lobe", str(glint_shot))])
    report.add_text(
        f"Canvas screenshots ({w} x {h}, sRGB, exposure 1/2) of the default scene (Gaussian-bump "
        "plane, anisotropic sphere, one quad light) per method, `split` = ltc-multiscale | ltc; "
        "`leadr-point` on the pixel-match `leadr` scene (height-mapped plane and sphere, two "
        "point lights and a directional light), the `colormap-*` modes on its `colormap` "
        "scene (a colour-mapped noise texture), `leadr-env` / `leadr-irradiance` on its "
        "`leadr-env` scene (the leadr objects under a procedural sky with a sun and a point "
        "light, at most 256 x 192); `glints | smooth lobe`: the `glints` mode on the "
        "64^2 flakes map (`prefilter.viewer.glints.glints_scene`, mid distance, point light) "
        f"against a Gaussian lobe of the same slope moments. Taken in {t_shots:.1f} s.")
    report.add_table(
        ["scene", "method", "tables / maps", "relative RMSE", "max abs error",
         "max error / max radiance"],
        [[r["scene"], r["method"], r["precision"], f"{r['rel_rmse']:.2e}", f"{r['max_abs']:.2e}",
          f"{r['max_rel']:.2e}"] for r in rows],
        caption="WebGL2 (headless Chromium, SwiftShader) against `prefilter.render.render`, "
                f"{mw} x {mh} pixels, linear float read-back; relative RMSE = |browser - python|_2"
                " / |python|_2 over covered pixels (the tests require <= 1 %). f16: float16 LTC "
                "tables, or for leadr-point float16 moment maps (the colour-map table is "
                f"float32 only). Measured in {t_match:.1f} s.")


# ---------------------------------------------------------------------------------- driver


def run_demo(out: str | Path = "out/demo", *, quick: bool = False, seed: int = 0,
             log=print, settings: DemoSettings | None = None) -> Path:
    """Render the showcase and every method section, write the report; returns ``index.html``.

    ``settings`` overrides the sizes (default: :class:`DemoSettings`, or ``.quick()`` with
    ``quick``). Sections that fail leave a note in the report; the demo itself does not fail.
    """
    from prefilter.report.report import Report

    if settings is None:
        settings = DemoSettings.quick() if quick else DemoSettings()
    t_start = time.perf_counter()
    report = Report("prefilter demo")
    report.add_text(
        "Each section compares a prefiltering method with a ground truth rendered without "
        "prefiltering and states what its numbers mean. Images: linear radiance tone mapped "
        "(ACES) for display, each pixel shown as a block so aliasing stays visible. FLIP maps: "
        "per-pixel HDR-FLIP error (magma, 0 to 1). RMSE and relative MSE are on linear radiance "
        "(relMSE = mean of (x - ref)^2 / (ref^2 + 0.01)).")
    status: list[list] = []
    _section(report, status, "Isotropic GGX LTC table vs Monte Carlo", "",
             lambda r: _table_section(r, settings, seed, log), log)
    _section(
        report, status, "Showcase: area-light methods vs reference at three distances",
        "A normal-mapped GGX plane (alpha 0.1, Gaussian bumps with rms slope 0.25) under a quad "
        "area light, from three camera distances (camera and light scale together, so only the "
        "number of texels per pixel changes). `reference`: supersampled full-resolution normals "
        f"and MIS Monte Carlo over the light ({settings.reference_spp} spp). Flicker: mean "
        f"per-pixel standard deviation over {settings.flicker_frames} sub-pixel camera jitters "
        "(lower is steadier). Time: one warm frame at 1 spp on this machine (compilation "
        "excluded).",
        lambda r: _showcase_section(r, settings, seed, log), log)
    _section(
        report, status, "Anisotropic LTC: brushed metal",
        "The `prefilter.ltc.aniso.demo` scene: a plane brushed along x (alpha 0.08 x 0.45) and a "
        "sphere brushed along its latitudes, one quad light. `ltc-aniso` uses the anisotropic "
        "table in the tangent frame; `ltc` the isotropic table at sqrt(alpha_x alpha_y). "
        f"Reference: {settings.section_spp} spp Monte Carlo of the anisotropic GGX BRDF.",
        lambda r: _aniso_section(r, settings, seed, log), log)
    _section(
        report, status, "Multi-scale LTC: normal maps near and far",
        "The showcase plane with the built-in brushed and flakes normal maps, micro roughness "
        "0.03, camera at ~1 and ~16 texels per pixel. `ltc`: mip-averaged normal, micro "
        "roughness only; `ltc-multiscale`: roughness from the length of the averaged normal "
        "(exact eq. 4 inverse, refitted eq. 7); `footprint=paper`: the paper's eqs. 5 and 7. "
        f"Reference: {settings.section_spp} spp, full-resolution normals.",
        lambda r: _multiscale_section(r, settings, seed, log), log)
    _section(
        report, status, "LEADR: point light on height-mapped surfaces",
        "Two views of LEADR mapping. Images: `leadr-point` (mean and covariance of slopes from "
        "the moments mip, closed-form specular) against the supersampled normal-mapped "
        "reference and naive normal mapping (`ltc` with mip-averaged normals). Table: the "
        "per-footprint acceptance against displaced geometry.",
        lambda r: _leadr_section(r, settings, seed, log), log)
    _section(
        report, status, "Colour-map filtering: cases a-d",
        "The colour term of each case on a grazing plane and a sphere, near and far (texture "
        "density changed, geometry fixed): `filtered` (pre-filtered tables), `naive` (colour map "
        "of the mip-mapped input, C(mean)) and `reference` "
        f"({settings.colormap_nref} x {settings.colormap_nref} jittered samples per pixel of the "
        "unfiltered function). Displayed as sRGB without tone mapping.",
        lambda r: _colormap_section(r, settings, seed, log), log)
    _section(
        report, status, "Glints (part 1): NDF images of footprints",
        "Position-normal NDFs of Gaussian pixel footprints on a small built-in normal map: the "
        "direct evaluation against the compressed pyramid's constant-time query.",
        lambda r: _glints_section(r, settings, seed, log), log)
    _section(
        report, status, "Glints (part 2): rendered frames, compressed vs direct",
        f"The glints measurement plane (a {settings.glints_render_map}^2 flakes normal map, "
        "metallic, one point light) from three distances, camera and light scaled together so "
        "only the footprint changes: `glints` (the compressed P-NDF of each pixel footprint, "
        "paper eq. 1) against `glints-direct` (the exact P-NDF summed over the footprint's "
        "texels). Their FLIP difference is the compression error alone.",
        lambda r: _glints_render_section(r, settings, seed, log), log)
    _section(
        report, status, "Glints (part 3): Wang tiles",
        f"The same plane and light on an unbounded surface of 16 Wang tiles synthesised from the "
        f"{settings.glints_render_map}^2 flakes map (glints paper sec. 5.5): `glints-wang` (per-"
        "tile compressed pyramids, constant storage whatever the area) against `glints-direct` "
        "on the same tiling assembled.",
        lambda r: _glints_wang_section(r, settings, seed, log), log)
    _section(
        report, status, "Roughness mip chains from a normal map",
        "`prefilter bake roughness`: the GGX roughness per mip level that keeps a normal map's "
        "highlights when the level's averaged normal is shaded (Toksvig, LEAN variance, "
        "multi-scale LTC `alpha_total`; docs/roughness.md). Images: the baked levels of the "
        "built-in flakes map; table: the far-field error of each choice on the built-in maps.",
        lambda r: roughness_section(r, 64 if quick else 256, seed, log), log)
    _section(
        report, status, "Colour-map filtering under lights (colormap-lit)",
        "The colour map as the diffuse albedo of a Gaussian microsurface on the grazing plane, "
        "far away, under a directional and a point light (every driver and the section-6 "
        "combinations), a quad light and an environment map (heights): `filtered` (the colour "
        "of the visible and lit microfacets), `naive` (C(mean)) and `reference` "
        f"({settings.colormap_nref} x {settings.colormap_nref} jittered samples per pixel of eq. "
        "1, the same lit shading). Displayed as sRGB without tone mapping (`docs/colormap.md`).",
        lambda r: colormap_lit_section(r, settings, seed, log), log)
    _section(
        report, status, "Glints under wave optics",
        "A flat panel of isotropic height noise under a small point light: the compressed RGB "
        "diffraction NDF (`glints-wave`), the same model uncompressed (`glints-wave-direct`) and "
        "the geometric glints of the same surface (`glints-direct`), measured now "
        "(`docs/glints-wave.md`).",
        lambda r: glints_wave_section(r, settings, seed, log), log)
    _section(
        report, status, "Path tracing: the glint paper's scenes and indirect glints",
        "The shipped `kettle`, `flake-panel` and `brushed-room` examples by the `path` method "
        "(docs/pathtracing.md), direct light and 4 vertices per path; then the kettle's glints "
        "seen in the glossy floor, whose footprints the floor's bounce enlarges: `glints` "
        "(compressed pyramid) against `glints-direct` (exact P-NDF) on the same paths.",
        lambda r: pathtrace_section(r, settings, seed, log), log)
    _section(
        report, status, "Real-time viewer: WebGL2 against Python",
        "The `prefilter view` page (WebGL2, the exported tables and GLSL snippets) in headless "
        "Chromium: a screenshot per mode and the pixel match against the Python renderer, "
        "measured now (`docs/viewer.md`).",
        lambda r: _viewer_section(r, settings, seed, log), log)
    total = time.perf_counter() - t_start
    report.add_section("Summary")
    report.add_table(["section", "status", "time (s)"], status,
                     caption=f"Total demo time: {total:.0f} s "
                     f"({'quick' if quick else 'default'} settings).")
    log(f"demo total: {total:.1f} s")
    return report.write(out)


@click.command("demo")
@click.option("--out", type=OutputDir(path_type=Path), default=Path("out/demo"),
              show_default=True, help="Output folder for index.html and its images.")
@click.option("--quick", is_flag=True, help="A one-minute version (smaller images, fewer samples).")
@click.option("--seed", type=SEED, default=0, show_default=True)
def demo(out: Path, quick: bool, seed: int) -> None:
    """Render the showcase and every method's section; write out/demo/index.html."""
    path = run_demo(out, quick=quick, seed=seed, log=lambda s: click.echo(s, err=True))
    click.echo(str(path))
