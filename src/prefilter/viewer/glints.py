"""The viewer's ``glints`` mode checked and timed: the measurement scenes
(:func:`glints_scene`), pages sharing one copy of the glint maps (:func:`glint_pages`), the
pixel match against ``prefilter.render`` (:func:`glints_pixel_match`), frame times
(:func:`glints_frame_times`) and the split-view screenshot (:func:`glints_screenshot`). The maps
themselves: :mod:`prefilter.viewer.glint_maps`.
"""

from __future__ import annotations

import json
import math
import tempfile
from contextlib import contextmanager
from pathlib import Path

from prefilter.errors import PrefilterError
from prefilter.viewer.glint_maps import (GLINT_MAPS, export_glints, glint_normal_map,  # noqa: F401
                                         glint_surface)


#: Distances of the pixel-match scenes (:func:`glints_scene`): the footprint grows with them
#: (64^2 maps: below the finest level near, resampled levels mid, the top levels far).
DISTANCES = {"near": 0.5, "mid": 2.0, "far": 8.0}


def _distance(distance) -> float:
    if isinstance(distance, str):
        if distance not in DISTANCES:
            raise PrefilterError(f"distance: expected one of {sorted(DISTANCES)} or a number, "
                                 f"got {distance!r}")
        return DISTANCES[distance]
    try:
        d = float(distance)
    except (TypeError, ValueError):
        d = math.nan
    if not (math.isfinite(d) and d > 0):
        raise PrefilterError(f"distance: expected a positive number, got {distance!r}")
    return d


def glints_scene(kind: str, distance: str = "mid", lights: str = "point", width: int = 96,
                 height: int = 72, shape: str = "plane") -> dict:
    """The glints measurement plane (:func:`prefilter.glints.render.measurement_scene`) with
    built-in map ``kind`` (:data:`GLINT_MAPS`) seen from ``distance`` (a name of
    :data:`DISTANCES` or a positive number).

    ``lights``: ``"point"``, ``"quad"`` (as ``measurement_scene``) or ``"directional"`` (from the
    point light's direction, irradiance 5); ``shape``: ``"plane"`` or ``"sphere"`` (radius
    ``0.25 d`` at the origin, about as many texels per unit length as the plane)."""
    from prefilter.glints.render import measurement_scene

    d = _distance(distance)
    if shape not in ("plane", "sphere"):
        raise PrefilterError(f"shape: expected 'plane' or 'sphere', got {shape!r}")
    glint_normal_map(kind)  # validates the kind
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
    from prefilter.viewer.export import export_scene
    from prefilter.viewer.match import browse_pages

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
        with browse_pages(root, driver) as pages:
            yield pages


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


def glints_paths(kind: str, distance, width: int, height: int) -> dict:
    """Fractions of the hit pixels of :func:`glints_scene` whose footprint the ``glints`` method
    (and the page) shades by the direct P-NDF (below the finest level), by a resampled pyramid
    level (:func:`prefilter.glints.pyramid.resample_weights`) or by the trilinear blend of the
    top levels, and the median footprint std in texels."""
    import numpy as np

    from prefilter.glints.pyramid import resample_weights
    from prefilter.glints.render import pixel_footprints
    from prefilter.render.scene import load_scene

    surf = glint_surface(kind)
    c, sp, _ = pixel_footprints(load_scene(glints_scene(kind, distance, "point", width,
                                                        height)), surf.shape)
    direct = sp < surf.sigma_min
    _, _, ok = resample_weights(surf.gm.pyramid, c, sp)
    n = max(len(sp), 1)
    return {"direct": float(direct.sum() / n), "resampled": float((ok & ~direct).sum() / n),
            "trilinear": float((~ok & ~direct).sum() / n), "median_sigma": float(np.median(sp))}


def glints_frame_times(kind: str = "flakes", distances=tuple(DISTANCES), *, width: int = 512,
                       height: int = 512, frames: int = 3, rounds: int = 3, codes: str = "f32",
                       driver=None) -> dict:
    """Frame time in ms of the ``glints`` mode per distance (names of :data:`DISTANCES` or
    numbers; best of ``rounds`` rounds of ``frames`` synchronised frames, the distances
    interleaved in each round) at ``width x height``."""
    scenes = {f"d-{d}": glints_scene(kind, d, "point", width, height) for d in distances}
    best = {d: math.inf for d in distances}
    with glint_pages(scenes, (kind,), (codes,), driver) as (drv, url_of):
        # a SwiftShader frame of the compressed path at 512 x 512 can exceed the client's
        # default 120 s per command
        drv.command_executor.client_config.timeout = max(
            drv.command_executor.client_config.timeout or 0, 1800)
        for _ in range(rounds):
            for d in distances:
                open_viewer_glints(drv, url_of(f"d-{d}"), kind, codes)
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
