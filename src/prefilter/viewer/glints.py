"""The viewer's glint maps: built-in normal maps baked as the ``glints`` method bakes them
(:func:`prefilter.glints.render.baked_surface`, the render cache) and written for the page by
:func:`prefilter.glints.gpu.write_gpu` in every code variant.

The built-ins are small (:data:`GLINT_MAPS`, 64^2): a bake at the render's settings
(:data:`prefilter.glints.bake.BAKE_SETTINGS`, 512^2 NDF images, rank budget 48) takes minutes
per map on a loaded machine, once; later exports load it from the cache.
"""

from __future__ import annotations

import json
import math
import tempfile
from contextlib import contextmanager
from pathlib import Path

from prefilter.errors import PrefilterError

#: The glint mode's built-in maps (``prefilter.texture.normal_map`` kinds and parameters).
GLINT_MAPS = {kind: {"procedural": kind, "size": 64, "seed": 1}
              for kind in ("gaussian", "brushed", "flakes", "scratches")}


def glint_normal_map(kind: str):
    """The ``(H, W, 3)`` normal map of built-in ``kind`` (:data:`GLINT_MAPS`)."""
    from prefilter.texture import normal_map

    if kind not in GLINT_MAPS:
        raise PrefilterError(f"glint map: expected one of {sorted(GLINT_MAPS)}, got {kind!r}")
    spec = dict(GLINT_MAPS[kind])
    return normal_map(spec.pop("procedural"), **spec)


def glint_surface(kind: str, *, progress: bool = False):
    """The ``glints`` method's surface of built-in ``kind``: baked on first use (render cache,
    ``$PREFILTER_GLINTS_CACHE``), then loaded."""
    from prefilter.glints.render import baked_surface

    return baked_surface(glint_normal_map(kind), progress=progress)


def export_glints(out_dir, kinds=tuple(GLINT_MAPS), codes=("f32", "f16", "u8"), *,
                  limits: dict | None = None, progress: bool = False) -> dict:
    """Write the glint maps ``kinds`` in the code variants ``codes`` into ``out_dir`` (files
    ``glints_<kind>_<codes>_<texture>.bin``) and the glints GLSL (``glints.glsl``); returns the
    manifest entry ``{"glsl": "glints.glsl", "maps": {kind: {codes: write_gpu entry}}}``."""
    from prefilter.glints.gpu import export_surface, glsl_source, write_gpu

    d = Path(out_dir)
    d.mkdir(parents=True, exist_ok=True)
    (d / "glints.glsl").write_text(glsl_source())
    maps = {}
    for kind in kinds:
        surf = glint_surface(kind, progress=progress)
        maps[kind] = {c: write_gpu(export_surface(surf, codes=c, limits=limits), d,
                                   prefix=f"glints_{kind}_{c}") for c in codes}
    return {"glsl": "glints.glsl", "maps": maps}


#: Distances of the pixel-match scenes (:func:`glints_scene`): the footprint grows with them
#: (64^2 maps: below the finest level near, resampled levels mid, the top levels far).
DISTANCES = {"near": 0.5, "mid": 2.0, "far": 8.0}


def glints_scene(kind: str, distance: str = "mid", lights: str = "point", width: int = 96,
                 height: int = 72, shape: str = "plane") -> dict:
    """The glints measurement plane (:func:`prefilter.glints.render.measurement_scene`) with
    built-in map ``kind`` (:data:`GLINT_MAPS`) seen from ``distance`` (:data:`DISTANCES`).

    ``lights``: ``"point"``, ``"quad"`` (as ``measurement_scene``) or ``"directional"`` (from the
    point light's direction, irradiance 5); ``shape``: ``"plane"`` or ``"sphere"`` (radius
    ``0.25 d`` at the origin, about as many texels per unit length as the plane)."""
    from prefilter.glints.render import measurement_scene

    if distance not in DISTANCES:
        raise PrefilterError(f"distance: expected one of {sorted(DISTANCES)}, got {distance!r}")
    if shape not in ("plane", "sphere"):
        raise PrefilterError(f"shape: expected 'plane' or 'sphere', got {shape!r}")
    glint_normal_map(kind)  # validates the kind
    d = DISTANCES[distance]
    sc = measurement_scene(d, kind, size=GLINT_MAPS[kind]["size"], width=width, height=height,
                           lights="point" if lights == "directional" else lights)
    if lights == "directional":
        p = sc["lights"][0]["position"]
        sc["lights"] = [{"type": "directional", "direction": [-x for x in p],
                         "irradiance": [5.0] * 3}]
    obj = sc["objects"][0]
    obj["material"]["normal_map"] = dict(GLINT_MAPS[kind])
    if shape == "sphere":
        r = 0.25 * d
        sc["objects"] = [{"type": "sphere", "center": [0, 0, 0], "radius": r,
                          "uv_scale": [8 * math.pi * r, 4 * math.pi * r],
                          "material": obj["material"]}]
    return sc


@contextmanager
def glint_pages(scenes: dict, kinds, codes=("f32",), driver=None):
    """Export ``scenes`` (name -> dict) as viewer pages sharing one copy of the glint maps
    ``kinds`` in ``codes``; yields ``(driver, url_of)`` (``url_of(name)``: the page's URL)."""
    from prefilter.fileio import save_json_atomic
    from prefilter.viewer.browser import chromium
    from prefilter.viewer.export import export_scene
    from prefilter.viewer.server import serve

    with tempfile.TemporaryDirectory(prefix="prefilter-glints-") as tmp:
        root = Path(tmp)
        shared = root / "glints-data"
        entry = export_glints(shared, tuple(kinds), tuple(codes))
        for name, sc in scenes.items():
            page = export_scene(sc, root / name, builtin_maps=False)
            for f in shared.iterdir():
                (page / "data" / f.name).symlink_to(f)
            man = json.loads((page / "data" / "viewer.json").read_text())
            man["glints"] = entry
            save_json_atomic(page / "data" / "viewer.json", man)
        (root / "index.html").write_text("prefilter glints pages\n")
        server, url = serve(root)
        own = driver is None
        drv = chromium(root / "profile") if own else driver
        try:
            yield drv, (lambda name: f"{url}{name}/index.html")
        finally:
            if own:
                drv.quit()
            server.shutdown()
            server.server_close()


def select_glints(driver, kind: str, codes: str = "f32") -> None:
    """Make the open page's glints mode use map ``kind`` with ``codes`` (loads its textures)."""
    driver.set_script_timeout(600)
    msg = driver.execute_async_script(
        "const done = arguments[arguments.length - 1];"
        "window.prefilterViewer.selectGlints(arguments[0], arguments[1])"
        ".then(() => done(''), e => done(String(e && e.message || e)));", kind, codes)
    if msg:
        raise PrefilterError(f"glints map {kind} ({codes}): {msg}")


def glints_pixel_match(kinds=tuple(GLINT_MAPS), distances=tuple(DISTANCES), codes=("f32",), *,
                       lights: str = "point", shape: str = "plane", width: int = 96,
                       height: int = 72, driver=None) -> list[dict]:
    """The page's ``glints`` mode against ``prefilter.render.render(scene, "glints")`` on
    :func:`glints_scene` for every map, distance and code variant: rows ``{map, distance,
    codes, rel_rmse, max_abs, max_rel, covered}`` (as :func:`prefilter.viewer.pixel_match`)."""
    from prefilter.render.driver import render
    from prefilter.viewer.browser import open_viewer, render_linear
    from prefilter.viewer.match import _errors

    scenes = {f"{k}-{d}": glints_scene(k, d, lights, width, height, shape)
              for k in kinds for d in distances}
    rows = []
    with glint_pages(scenes, kinds, codes, driver) as (drv, url_of):
        for k in kinds:
            for d in distances:
                sc = scenes[f"{k}-{d}"]
                ref = render(sc, "glints")
                open_viewer(drv, url_of(f"{k}-{d}"))
                for c in codes:
                    select_glints(drv, k, c)
                    img, covered = render_linear(drv, "glints")
                    rows.append({"map": k, "distance": d, "codes": c, "lights": lights,
                                 "shape": shape,
                                 **_errors(img, ref, covered)})
    return rows


def glints_frame_times(kind: str = "flakes", distances=tuple(DISTANCES), *, width: int = 512,
                       height: int = 512, frames: int = 3, rounds: int = 3, codes: str = "f32",
                       driver=None) -> dict:
    """Frame time in ms of the ``glints`` mode per distance (best of ``rounds`` rounds of
    ``frames`` synchronised frames, the distances interleaved in each round) at
    ``width x height``."""
    scenes = {d: glints_scene(kind, d, "point", width, height) for d in distances}
    best = {d: math.inf for d in distances}
    with glint_pages(scenes, (kind,), (codes,), driver) as (drv, url_of):
        for _ in range(rounds):
            for d in distances:
                open_viewer_glints(drv, url_of(d), kind, codes)
                ms = float(drv.execute_script(
                    "return window.prefilterViewer.frameTime(arguments[0]);", frames))
                if not math.isfinite(ms):
                    raise PrefilterError(f"frame time: expected a finite number, got {ms}")
                best[d] = min(best[d], ms)
    return best


def open_viewer_glints(driver, url: str, kind: str, codes: str = "f32") -> None:
    """Open the page at ``url`` in the ``glints`` mode with map ``kind`` (whole canvas)."""
    from prefilter.viewer.browser import open_viewer

    open_viewer(driver, url, timeout=600.0)
    select_glints(driver, kind, codes)
    driver.execute_script("const v = window.prefilterViewer.viewer;"
                          "Object.assign(v.params, {methodLeft: 'glints', "
                          "methodRight: 'glints', split: -1});")


def glints_screenshot(path, kind: str = "flakes", distance: str = "mid", *, width: int = 512,
                      height: int = 384, driver=None) -> Path:
    """A PNG of the page's canvas in split view: ``glints`` (left) | ``glints-smooth`` (the
    smooth lobe of the same moments, right) on :func:`glints_scene` (exposure 1/16, sRGB)."""
    from prefilter.viewer.browser import screenshot

    with glint_pages({"shot": glints_scene(kind, distance, "point", width, height)}, (kind,),
                     driver=driver) as (drv, url_of):
        open_viewer_glints(drv, url_of("shot"), kind)
        drv.execute_script("Object.assign(window.prefilterViewer.viewer.params, "
                           "{methodRight: 'glints-smooth', split: 0.5, exposure: 0.0625});")
        return screenshot(drv, path)
