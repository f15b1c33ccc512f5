"""Lit colour maps (``colormap-lit``): scenes, far-field errors against the supersampled
reference, and the demo report's section.

The scenes are those of :mod:`prefilter.studies.colormap` (a plane seen at 0 / 70 degrees and a
sphere, texture density set so a pixel covers 30-50 texels), now carrying the colour map as a
diffuse albedo under a light rig: ``sun`` (a directional and a point light), ``quad`` (a quad
light above the object) or ``env`` (a procedural environment map). Each driver -- texture,
noise, height, slope, and the section-6 ``linear`` and ``product`` combinations -- is rendered by
``colormap-lit`` with ``filter=filtered``, ``naive`` and ``reference`` (32 x 32 jittered samples
per pixel of eq. 1); the error is the RMS CIE76 Delta E over valid pixels (every neighbour
covered, view and directional lights more than 3 degrees above the surface).
"""

from __future__ import annotations

import tempfile
import time
from pathlib import Path

import numpy as np

__all__ = ["DRIVERS", "FAR_CONFIGS", "RIGS", "driver_specs", "lit_scene", "measure",
           "colormap_lit_section", "format_rows", "valid_mask"]

#: Driver names, in table order.
DRIVERS = ("texture", "noise", "height", "slope", "linear", "product")
#: Light rigs (see :func:`lit_scene`).
RIGS = ("sun", "quad", "env")
#: (shape, view angle from the normal in degrees, texels per world unit, label): the far field.
FAR_CONFIGS = (("plane", 0.0, 3000.0, "far"), ("plane", 70.0, 1500.0, "far"),
               ("sphere", 0.0, 900.0, "far"))
#: The paper's targets: filtered error at most this fraction of the naive error, far away.
TARGETS = {"texture": 0.25, "noise": 0.25, "height": 0.5, "slope": 0.5, "linear": 0.5,
           "product": 0.5}


def driver_specs(size: int = 256) -> dict:
    """``extras.colormap`` of each driver of :data:`DRIVERS` on ``size^2`` textures."""
    from prefilter.studies.colormap import height_colormap, noise_colormap, slope_colormap

    noise = {"procedural": "noise", "size": size, "seed": 0, "corr_length": 3.0}
    surface = {"procedural": "gaussian", "size": size, "seed": 1, "rms_slope": 0.5,
               "corr_length": 4.0}
    c0 = {"texture": noise, "colors": noise_colormap(np.linspace(-4, 4, 64)).tolist(),
          "range": [-4, 4], "sigma_max": 1.5}
    height = {"driver": "height", "texture": surface, "range": [-4.5, 4.5], "sigma_max": 1.5,
              "colors": height_colormap(np.linspace(-4.5, 4.5, 64)).tolist()}
    x = -2.0 + (np.arange(32) + 0.5) * 4.0 / 32  # texel centres of [-2, 2]
    grid = np.stack(np.meshgrid(x, x), -1)  # row = s_y, column = s_x
    slope = {"driver": "slope", "texture": surface, "colors": slope_colormap(grid).tolist(),
             "extent": 2.0, "sigma_max": 1.0}
    return {"texture": {"driver": "texture", **c0}, "noise": {"driver": "noise", **c0},
            "height": height, "slope": slope,
            "linear": {"driver": "combine", "mode": "linear", "kappa": [0.5, 0.3, 0.2],
                       "c0": {"driver": "noise", **c0}, "height": height, "slope": slope},
            "product": {"driver": "combine", "mode": "product",
                        "c0": {"driver": "texture", **c0}, "height": height, "slope": slope}}


def _rig(rig: str, base: Path) -> list:
    if rig == "sun":
        return [{"type": "directional", "direction": [-0.4, -0.8, -0.45], "irradiance": 3.0},
                {"type": "point", "position": [1.5, 3.0, 2.0], "intensity": 6.0}]
    if rig == "quad":  # corners counter-clockwise seen from below: it emits downwards
        return [{"type": "quad", "vertices": [[-1.5, 3, -1], [0.5, 3, -1], [0.5, 3, 1],
                                              [-1.5, 3, 1]], "radiance": 6.0}]
    if rig == "env":
        from prefilter.leadr.envmap import procedural_env

        np.save(base / "colormap-lit-env.npy", procedural_env(32))
        return [{"type": "environment", "image": "colormap-lit-env.npy"}]
    raise ValueError(f"rig: expected one of {', '.join(RIGS)}, got {rig!r}")


def lit_scene(shape, view, density, size, spec: dict, rig: str, base: Path):
    """The loaded scene: :func:`prefilter.studies.colormap.scene_dict` with the light rig
    ``rig`` (files written to ``base``) and ``extras.colormap = spec``."""
    from prefilter.render.scene import load_scene
    from prefilter.studies.colormap import scene_dict

    sd = scene_dict(shape, view, density, size, size)
    sd["lights"] = _rig(rig, Path(base))
    sd["extras"] = {"colormap": spec}
    return load_scene(sd, base_dir=base)


def valid_mask(scene) -> np.ndarray:
    """Pixels ``(H, W)`` whose 3 x 3 neighbourhood is covered, seen and lit by every directional
    light more than ~3 degrees above the surface (silhouettes and terminators left out)."""
    from prefilter.render.camera import gbuffer

    g = gbuffer(scene)
    pad = np.pad(g.hit, 1)
    m = np.ones_like(g.hit)
    h, w = g.hit.shape
    for dy in range(3):
        for dx in range(3):
            m &= pad[dy:dy + h, dx:dx + w]
    m &= np.abs(np.sum(g.view * g.normal, -1)) > 0.05
    for light in scene.lights:
        if light.type == "directional":
            m &= np.sum(-np.asarray(light.direction) * g.normal, -1) > 0.05
    return m


def measure(configs=FAR_CONFIGS, drivers=DRIVERS, rigs=("sun",), *, size: int = 32,
            n_ref: int = 32, tex_size: int = 256, seed: int = 0, log=None, images=None):
    """Rows ``{shape, view_deg, rig, driver, dE_filtered, dE_naive, ratio, target, pixels,
    seconds_filtered, seconds_naive}``; ``images``: a dict filled with
    ``{(shape, view, rig, driver): {filter: (H, W, 3)}}`` when given."""
    from prefilter.render.driver import render
    from prefilter.studies.colormap import lab_rmse

    specs = driver_specs(tex_size)
    rows = []
    with tempfile.TemporaryDirectory(prefix="prefilter-colormap-lit-") as tmp:
        for shape, view, density, _label in configs:
            for rig in rigs:
                for name in drivers:
                    scene = lit_scene(shape, view, density, size, specs[name], rig, Path(tmp))
                    mask = valid_mask(scene)
                    out, secs = {}, {}
                    for f in ("filtered", "naive", "reference"):
                        t0 = time.perf_counter()
                        out[f] = render(scene, "colormap-lit", spp=n_ref * n_ref if f ==
                                        "reference" else 1, seed=seed, params={"filter": f})
                        secs[f] = time.perf_counter() - t0
                    ef = lab_rmse(out["filtered"], out["reference"], mask)
                    en = lab_rmse(out["naive"], out["reference"], mask)
                    row = {"shape": shape, "view_deg": view, "rig": rig, "driver": name,
                           "dE_filtered": ef, "dE_naive": en, "ratio": ef / max(en, 1e-12),
                           "target": TARGETS[name], "pixels": int(mask.sum()),
                           "seconds_filtered": secs["filtered"],
                           "seconds_naive": secs["naive"]}
                    rows.append(row)
                    if images is not None:
                        images[shape, view, rig, name] = out
                    if log:
                        log(row)
    return rows


def format_rows(rows) -> str:
    """A Markdown table of :func:`measure`'s rows."""
    head = ("| scene | light | driver | dE filtered | dE naive | ratio | target | pass |\n"
            "|---|---|---|---|---|---|---|---|")
    lines = [head]
    for r in rows:
        lines.append(f"| {r['shape']} {r['view_deg']:.0f} deg | {r['rig']} | {r['driver']} | "
                     f"{r['dE_filtered']:.2f} | {r['dE_naive']:.2f} | {r['ratio']:.3f} | "
                     f"<= {r['target']} | {'yes' if r['ratio'] <= r['target'] else 'NO'} |")
    return "\n".join(lines)


def _srgb8(img) -> np.ndarray:
    from prefilter.render.metrics import linear_to_srgb

    return np.round(linear_to_srgb(np.clip(img, 0.0, 1.0)) * 255.0).astype(np.uint8)


def colormap_lit_section(report, settings, seed: int, log) -> None:
    """The demo report's section: lit colour maps of every driver on the grazing plane under
    the ``sun`` rig, and one driver under the quad and environment rigs, with their errors."""
    n = settings.colormap_size
    images: dict = {}
    plane = (("plane", 70.0, 1500.0, "far"),)
    rows = measure(plane, DRIVERS, ("sun",), size=n, n_ref=settings.colormap_nref, seed=seed,
                   log=lambda r: log(f"colormap-lit {r['driver']} {r['rig']}: "
                                     f"ratio {r['ratio']:.3f}"), images=images)
    rows += measure(plane, ("height",), ("quad", "env"), size=n, n_ref=settings.colormap_nref,
                    seed=seed, images=images)
    scale = max(1, 192 // n)
    for (shape, view, rig, name), out in images.items():
        report.add_image_row(f"{shape} {view:.0f} deg, {rig}: {name}",
                             [(f, _srgb8(out[f])) for f in ("reference", "filtered", "naive")],
                             scale=scale)
    report.add_table(["scene", "light", "driver", "dE filtered", "dE naive", "ratio", "target"],
                     [[f"{r['shape']} {r['view_deg']:.0f} deg", r["rig"], r["driver"],
                       r["dE_filtered"], r["dE_naive"], r["ratio"], r["target"]] for r in rows],
                     caption="RMS CIE76 Delta E against the reference over valid pixels "
                     "(covered neighbourhood, view and directional lights above 3 degrees); "
                     "ratio = filtered / naive, target the paper's far-field bound.")
