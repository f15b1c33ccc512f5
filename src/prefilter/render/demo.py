"""``prefilter demo``: the built-in showcase and its HTML report (``out/demo/index.html``).

The showcase is a normal-mapped GGX plane receding to the horizon under a quad area light, seen
from three distances (near: about one texel per pixel, far: many texels per pixel). Every
registered method renders it, ``reference`` gives ground truth, and the report shows the images
side by side with FLIP maps, a metrics table (RMSE, relative MSE, FLIP, flicker) and error against
distance. A first section checks the shipped LTC table against Monte Carlo.

The camera and the light scale together with the distance, so the lighting configuration (and the
solid angle of the light) is the same at every distance; only the number of texels under a pixel
changes. That isolates what prefiltering is about.
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from pathlib import Path

import click
import numpy as np

from prefilter.errors import PrefilterError


@dataclass(frozen=True)
class DemoSettings:
    """Sizes and sample counts of one demo run (``quick`` is the one-minute version)."""

    width: int = 256
    height: int = 160
    reference_spp: int = 64
    flicker_frames: int = 8
    table_configs: int = 400
    table_samples: int = 20_000
    distances: tuple[float, ...] = (1.0, 4.0, 16.0)

    @classmethod
    def quick(cls) -> "DemoSettings":
        return cls(width=128, height=80, reference_spp=16, flicker_frames=4, table_configs=100,
                   table_samples=10_000)


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


def _available_methods() -> list[str]:
    from prefilter.render.methods import available

    return [m for m in available() if m != "reference"]


def _table_section(report, settings: DemoSettings, seed: int, log) -> list[dict]:
    """Check the shipped isotropic LTC table against Monte Carlo and plot error vs angle."""
    from prefilter.ltc import GGXTable
    from prefilter.ltc.validate import format_statistics, run_acceptance

    t0 = time.perf_counter()
    table = GGXTable.load()
    result = run_acceptance(table, settings.table_configs, settings.table_samples, seed=seed)
    stats = result["stats"]
    log(f"LTC table check: {time.perf_counter() - t0:.1f} s")
    report.add_section(
        "Isotropic GGX LTC table vs Monte Carlo",
        f"{settings.table_configs} random configurations (view 0-85 deg, alpha 0.05-1, random "
        f"quads, some straddling the horizon), {settings.table_samples} MIS samples each. "
        "The full acceptance (2000 configurations, 1e5 samples) is `prefilter validate`.",
    )
    report.add_text("```\n" + format_statistics(stats) + "\n```")
    rows = []
    for b in stats["by_theta"]:
        rows.append([f"{b['lo']:.0f}-{b['hi']:.0f}", b["count"], b["median"], b["p90"]])
    report.add_table(["view angle (deg)", "count", "median rel. error", "p90 rel. error"], rows)
    return [stats]


def _render_all(settings: DemoSettings, methods: list[str], seed: int, log):
    from prefilter.render.metrics import flicker, jitter_offsets
    from prefilter.render.pipeline import render

    results = []
    jit = jitter_offsets(settings.flicker_frames)
    for d in settings.distances:
        scene = showcase_scene(d, settings.width, settings.height)
        t0 = time.perf_counter()
        ref = render(scene, "reference", spp=settings.reference_spp, seed=seed, progress=True)
        entry = {"distance": d, "reference": ref, "images": {}, "times": {}, "flicker": {},
                 "reference_time": time.perf_counter() - t0}
        log(f"distance {d:g}: reference {entry['reference_time']:.1f} s")
        for m in methods:
            try:
                t0 = time.perf_counter()
                img = render(scene, m, spp=1, seed=seed)
                entry["times"][m] = time.perf_counter() - t0
                frames = np.stack([render(scene, m, spp=1, seed=seed, jitter=tuple(j))
                                   for j in jit])
                entry["flicker"][m] = flicker(frames)
                entry["images"][m] = img
                log(f"distance {d:g}: {m} {entry['times'][m]:.2f} s")
            except PrefilterError as exc:
                log(f"distance {d:g}: {m} skipped ({exc})")
        results.append(entry)
    return results


def run_demo(out: str | Path = "out/demo", *, quick: bool = False, seed: int = 0,
             log=print) -> Path:
    """Render the showcase with every method, write the report; returns ``index.html``'s path."""
    from prefilter.render.report import Report, line_plot

    settings = DemoSettings.quick() if quick else DemoSettings()
    t_start = time.perf_counter()
    report = Report("prefilter demo")
    report.add_text(
        "A normal-mapped GGX plane (alpha 0.1, Gaussian bumps with rms slope 0.25) under a quad "
        "area light, from three camera distances (camera and light scale together, so only the "
        "number of texels per pixel changes). `reference`: supersampled full-resolution normals "
        f"and MIS Monte Carlo over the light ({settings.reference_spp} spp). Metrics against it: "
        "RMSE and relative MSE of linear radiance, mean HDR-FLIP, and flicker (mean per-pixel "
        f"standard deviation over {settings.flicker_frames} sub-pixel camera jitters)."
    )
    _table_section(report, settings, seed, log)

    methods = _available_methods()
    results = _render_all(settings, methods, seed, log)
    report.add_section("Showcase: methods vs reference at three distances")
    rows = []
    curves: dict[str, list[float]] = {m: [] for m in methods}
    for entry in results:
        if not entry["images"]:
            continue
        metrics = {r["method"]: r for r in report.add_comparison(
            f"distance x{entry['distance']:g}", entry["reference"], entry["images"], scale=2)}
        for m in methods:
            if m not in entry["images"]:
                curves[m].append(float("nan"))
                continue
            mm = metrics[m]
            rows.append([f"x{entry['distance']:g}", m, mm["rmse"], mm["relmse"], mm["flip"],
                         entry["flicker"][m], entry["times"][m]])
            curves[m].append(mm["flip"])
    report.add_table(["distance", "method", "RMSE", "relMSE", "FLIP", "flicker", "time (s)"],
                     rows, caption="Errors against the reference at each distance.")
    report.add_plot(line_plot(list(settings.distances), curves, xlabel="camera distance (x)",
                              ylabel="mean FLIP vs reference", logx=True),
                    caption="Error against distance.")
    report.add_text(f"Total demo time: {time.perf_counter() - t_start:.0f} s.")
    return report.write(out)


@click.command("demo")
@click.option("--out", type=click.Path(file_okay=False, path_type=Path), default=Path("out/demo"),
              show_default=True, help="Output folder for index.html and its images.")
@click.option("--quick", is_flag=True, help="A one-minute version (smaller images, fewer samples).")
@click.option("--seed", type=int, default=0, show_default=True)
def demo(out: Path, quick: bool, seed: int) -> None:
    """Render the built-in showcase with every method and write out/demo/index.html."""
    path = run_demo(out, quick=quick, seed=seed, log=lambda s: click.echo(s, err=True))
    click.echo(str(path))
