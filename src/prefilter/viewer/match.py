"""End-to-end checks of the viewer: the same scene by the Python renderer and by WebGL2 in
headless Chromium (pixel match), screenshots per mode, and the frame time.

``python -m prefilter.viewer.match`` prints the pixel-match table and the frame time.
"""

from __future__ import annotations

import contextlib
import math
import tempfile
from pathlib import Path

import numpy as np

from prefilter.errors import PrefilterError
from prefilter.viewer.export import BUILTIN_MAPS, METHODS, default_scene, export_scene

__all__ = ["SCENES", "applies", "frame_time", "pixel_match", "scene", "screenshots"]


def _quad(z=-2.0, y0=0.4, y1=1.6, hw=1.0, tilt=0.3, radiance=5.0):
    return {"type": "quad", "radiance": radiance,
            "vertices": [[-hw, y0, z], [hw, y0, z], [hw, y1, z - tilt], [-hw, y1, z - tilt]]}


def _plane(material, size=8.0, uv=8.0):
    return {"type": "plane", "center": [0, 0, 0], "normal": [0, 1, 0], "tangent": [1, 0, 0],
            "size": [size, size], "uv_scale": [uv, uv], "material": material}


def _camera(width, height):
    return {"origin": [0.0, 1.3, 3.6], "target": [0.0, 0.2, 0.0], "up": [0, 1, 0], "fov": 40,
            "width": width, "height": height}


#: The pixel-match scenes: a flat anisotropic plane, the default scene (Gaussian-bump plane and
#: an anisotropic sphere), a brushed plane (anisotropic normal distribution) and a light that
#: crosses the plane seen by a close sphere (horizon clipping everywhere), the default scene with
#: a point and a directional light added, a height-mapped plane and a sphere with colour maps,
#: and height-mapped objects under point and directional lights only (``leadr-point``; in
#: ``leadr-grazing`` low lights on a mostly diffuse material, where self-shadowing shows), a
#: texture-driven colour map (``colormap-*``), and a bump-mapped plane seen from just above it
#: (``near-grazing``: near, elongated footprints, where ``ltc-multiscale`` reads anisotropic taps),
#: then the environment scene of ``leadr-env`` / ``leadr-irradiance`` and the colour map driven by
#: noise, heights and slopes (``colormap-env``: the slope driver under an environment, for
#: ``colormap-lit``).
SCENES = ("flat", "bumps-sphere", "brushed", "horizon", "delta", "textured", "leadr",
          "leadr-grazing", "colormap", "near-grazing", "leadr-env", "colormap-noise",
          "colormap-height", "colormap-slope", "colormap-env")


def applies(sc, method: str) -> bool:
    """Whether the Python renderer draws scene ``sc`` (dict or :class:`Scene`) with ``method``:
    ``leadr-point`` takes point and directional lights only (quad lights raise)."""
    if method.startswith("colormap-"):
        extras = sc.get("extras", {}) if isinstance(sc, dict) else sc.extras
        return (extras or {}).get("colormap", {}).get("driver") in (
            "texture", "noise", "height", "slope")
    lights = sc["lights"] if isinstance(sc, dict) else [{"type": x.type} for x in sc.lights]
    kinds = {x["type"] for x in lights}
    if method in ("leadr-env", "leadr-irradiance"):
        return bool(kinds) and kinds <= {"environment", "point", "directional"}
    if method != "leadr-point":
        return "environment" not in kinds
    return bool(kinds) and kinds <= {"point", "directional"}


def scene(name: str, width: int = 160, height: int = 120) -> dict:
    """The pixel-match scene ``name`` (one of :data:`SCENES`) as a dict."""
    if name == "flat":
        return {"camera": _camera(width, height), "lights": [_quad()],
                "objects": [_plane({"alpha_x": 0.25, "alpha_y": 0.08, "base_color": 0.05,
                                    "f0": [0.9, 0.7, 0.5]})]}
    if name == "bumps-sphere":
        return default_scene(width, height)
    if name == "brushed":
        return {"camera": _camera(width, height), "lights": [_quad()],
                "objects": [_plane({"alpha": 0.1, "base_color": 0.02, "f0": 0.9,
                                    "normal_map": dict(BUILTIN_MAPS["brushed"])})]}
    if name == "horizon":
        return {"camera": {**_camera(width, height), "origin": [0.0, 0.9, 2.2]},
                "lights": [_quad(z=-1.2, y0=-0.6, y1=0.9, hw=0.8, tilt=0.2, radiance=3.0)],
                "objects": [_plane({"alpha": 0.3, "base_color": 0.3, "f0": 0.5}),
                            {"type": "sphere", "center": [0.55, 0.35, -0.3], "radius": 0.35,
                             "uv_scale": [4, 2], "material": {"alpha": 0.2, "base_color": 0.2,
                                                              "f0": 0.9}}]}
    if name == "delta":
        sc = default_scene(width, height)
        sc["lights"] += [{"type": "point", "position": [-1.0, 1.2, 0.5], "intensity": 1.5},
                         {"type": "directional", "direction": [0.3, -1.0, -0.4],
                          "irradiance": [0.4, 0.3, 0.2]}]
        return sc
    if name == "textured":
        noise = {"procedural": "noise", "size": 64, "seed": 3, "corr_length": 3, "sigma": 1.0}
        sc = default_scene(width, height)
        plane, sphere = sc["objects"]
        del plane["material"]["normal_map"]
        plane["material"].update(height_map={"procedural": "gaussian", "size": 128, "seed": 2,
                                             "rms_slope": 0.3, "corr_length": 4},
                                 base_color=0.3, color_map=dict(noise))
        sphere["material"].update(normal_map=dict(BUILTIN_MAPS["flakes"]),
                                  color_map=dict(noise, seed=4))
        return sc
    if name == "leadr":
        hmap = {"procedural": "gaussian", "size": 128, "seed": 2, "rms_slope": 0.3,
                "corr_length": 4}
        return {"camera": _camera(width, height),
                "lights": [{"type": "point", "position": [-1.0, 1.2, 0.5], "intensity": 2.0},
                           {"type": "point", "position": [1.0, 0.9, -2.2],
                            "intensity": [1.5, 1.2, 0.8]},
                           # low sun: the footprint's self-shadowing (G2 / G1) shows
                           {"type": "directional", "direction": [0.8, -0.25, -0.4],
                            "irradiance": [1.0, 0.8, 0.6]}],
                "objects": [_plane({"alpha_x": 0.15, "alpha_y": 0.06, "base_color": 0.2,
                                    "f0": [0.9, 0.7, 0.5], "height_map": hmap}),
                            {"type": "sphere", "center": [1.0, 0.5, -1.2], "radius": 0.5,
                             "uv_scale": [4, 2],
                             "material": {"alpha": 0.2, "base_color": [0.2, 0.3, 0.6],
                                          "f0": 0.04, "height_map": dict(
                                              hmap, size=64, seed=5, rms_slope=0.4,
                                              corr_length=2)}}]}
    if name == "leadr-grazing":
        # the leadr scene, mostly diffuse, under low lights: the footprint's self-shadowing
        # (G2 / G1) changes the image by far more than the pixel-match tolerance
        sc = scene("leadr", width, height)
        sc["lights"] = [{"type": "point", "position": [-2.5, 0.3, -0.5], "intensity": 6.0},
                        {"type": "directional", "direction": [0.9, -0.12, -0.4],
                         "irradiance": [1.0, 0.8, 0.6]}]
        for o in sc["objects"]:
            o["material"].update(f0=0.02, base_color=0.5)
        return sc
    if name == "colormap":
        # a colour-mapped noise texture on a plane and a sphere (prefilter.colormap.render)
        colors = [[0.05, 0.1, 0.4], [0.9, 0.9, 0.85], [0.1, 0.45, 0.15], [0.95, 0.55, 0.1],
                  [0.5, 0.05, 0.05]] * 3
        return {"camera": _camera(width, height), "lights": [_quad()],
                "objects": [_plane({"alpha": 0.2, "base_color": 0.2, "f0": 0.04}, uv=4.0),
                            {"type": "sphere", "center": [1.0, 0.5, -1.2], "radius": 0.5,
                             "uv_scale": [2, 1], "material": {"alpha": 0.2}}],
                "extras": {"colormap": {"driver": "texture", "colors": colors,
                                        "texture": {"procedural": "noise", "size": 64,
                                                    "seed": 3, "corr_length": 1.5},
                                        "range": [-4, 4], "sigma_max": 1.5}}}
    if name == "near-grazing":
        # the camera 0.4 above the Gaussian-bump plane (1/4 of the default texel density): over
        # half of the covered pixels have footprints < 4 texels long, 2-6x longer than wide
        return {"camera": {**_camera(width, height), "origin": [0.0, 0.4, 2.0],
                           "target": [0.0, 0.0, -1.0]},
                "lights": [_quad(y0=0.2, y1=1.0)],
                "objects": [_plane({"alpha": 0.1, "base_color": 0.02, "f0": 0.9,
                                    "normal_map": dict(BUILTIN_MAPS["gaussian"])}, uv=2.0)]}
    if name == "colormap-noise":
        # the colormap scene driven by procedural noise (its std per LOD from the generator)
        sc = scene("colormap", width, height)
        sc["extras"]["colormap"].update(driver="noise", texture={
            "procedural": "noise", "size": 64, "seed": 3, "corr_length": 1.5})
        return sc
    if name == "colormap-height":
        # heights driving the colour map, lit by a low sun (the scene's first directional
        # light): V_bar and the height filtering depend on the view and the light
        sc = scene("colormap", width, height)
        sc["extras"]["colormap"].update(driver="height", range=[-4.5, 4.5], texture={
            "procedural": "gaussian", "size": 64, "seed": 1, "rms_slope": 0.5,
            "corr_length": 3.0})
        sc["lights"].append({"type": "directional", "direction": [-0.95, -0.15, -0.2],
                             "irradiance": 1.0})
        return sc
    if name == "colormap-slope":
        # slopes driving a 2D colour map (row = s_y, column = s_x), lit by the colormap-height
        # scene's low sun: the slope distribution depends on the view, V_bar on view and light;
        # a point light added for colormap-lit (the unlit modes read the sun only)
        sc = scene("colormap-height", width, height)
        sc["lights"].append({"type": "point", "position": [-1.0, 1.2, 0.5],
                             "intensity": [1.5, 1.2, 0.8]})
        g = np.linspace(0.0, 1.0, 8)
        colors = np.stack([np.broadcast_to(g, (8, 8)), np.broadcast_to(g[:, None], (8, 8)),
                           0.5 + 0.45 * np.cos(6.0 * np.add.outer(g, g))], -1)
        sc["extras"]["colormap"] = {
            "driver": "slope", "colors": colors.round(4).tolist(), "extent": 1.5,
            "sigma_max": 1.0, "size": 16,
            "texture": {"procedural": "gaussian", "size": 64, "seed": 1, "rms_slope": 0.5,
                        "corr_length": 3.0}}
        return sc
    if name == "colormap-env":
        # the colormap-slope scene under the leadr-env scene's procedural sky and a point light
        # (colormap-lit: the environment as the texels of its 8 x 16 level)
        sc = scene("colormap-slope", width, height)
        sc["lights"] = [{"type": "environment", "image": str(_procedural_env_file())},
                        {"type": "point", "position": [-1.0, 1.2, 0.5], "intensity": 1.0}]
        return sc
    if name == "leadr-env":
        # the leadr objects under prefilter.leadr.envmap.procedural_env (sharp sun and window
        # stripes: the per-sample LOD matters) and a point light (leadr-env, leadr-irradiance)
        sc = scene("leadr", width, height)
        sc["lights"] = [{"type": "environment", "image": str(_procedural_env_file())},
                        {"type": "point", "position": [-1.0, 1.2, 0.5], "intensity": 1.0}]
        return sc
    raise PrefilterError(f"scene: expected one of {', '.join(SCENES)}, got {name!r}")


def _procedural_env_file(size: int = 64) -> Path:
    """:func:`prefilter.leadr.envmap.procedural_env` as a ``.npy`` file in the temporary
    directory (scenes reference environment images by path)."""
    from prefilter.fileio import atomic_path
    from prefilter.leadr.envmap import procedural_env

    path = Path(tempfile.gettempdir()) / f"prefilter-procedural-env-{size}.npy"
    if not path.exists():
        with atomic_path(path, suffix=".npy") as tmp:
            np.save(tmp, procedural_env(size))
    return path


@contextlib.contextmanager
def browse_pages(root: Path, driver=None):
    """Serve folder ``root`` (pages in its subfolders) and yield ``(driver, url_of)``:
    ``driver`` as given, else a headless Chromium started here and quit on exit; ``url_of(name)``
    the URL of ``root/name/index.html``."""
    from prefilter.viewer.browser import chromium
    from prefilter.viewer.server import serve

    server, url = serve(root)
    own = driver is None
    try:
        drv = chromium(root / "profile") if own else driver
        try:
            yield drv, (lambda name: f"{url}{name}/index.html")
        finally:
            if own:
                drv.quit()
    finally:
        server.shutdown()
        server.server_close()


@contextlib.contextmanager
def _served_pages(scenes: dict, driver=None, builtin_maps=False):
    """Export ``scenes`` (name -> dict) under one served folder; yields ``(driver, url_of)``."""
    with tempfile.TemporaryDirectory(prefix="prefilter-viewer-") as tmp:
        root = Path(tmp)
        for name, sc in scenes.items():
            export_scene(sc, root / name, builtin_maps=builtin_maps)
        (root / "index.html").write_text("prefilter viewer pages\n")
        with browse_pages(root, driver) as pages:
            yield pages


def _errors(img, ref, covered) -> dict:
    e = (img - ref)[covered]
    r = ref[covered]
    return {"rel_rmse": float(np.sqrt(np.mean(e * e)) / max(np.sqrt(np.mean(r * r)), 1e-30)),
            "max_abs": float(np.max(np.abs(e))) if e.size else 0.0,
            "max_rel": float(np.max(np.abs(e)) / max(float(np.max(np.abs(r))), 1e-30))
            if e.size else 0.0,
            "covered": int(covered.sum())}


def pixel_match(scenes=SCENES, methods=METHODS, precisions=("f32", "f16"), *, width=160,
                height=120, driver=None) -> list[dict]:
    """Render each scene x method x table precision in the browser and with
    :func:`prefilter.render.render`; compare linear radiance over the covered pixels.

    Combinations the Python renderer refuses (:func:`applies`) are left out. ``precision``
    selects the LTC tables (float32 / float16 textures) and, for ``leadr-point``, the moment maps.

    Returns rows ``{scene, method, precision, rel_rmse, max_abs, max_rel, covered}``:
    ``rel_rmse = |browser - python|_2 / |python|_2`` over covered pixels and channels,
    ``max_abs`` the largest absolute difference, ``max_rel`` it over the largest radiance.
    ``driver``: a WebDriver to reuse (default: a fresh headless Chromium).
    """
    from prefilter.render.driver import render
    from prefilter.viewer.browser import open_viewer, render_linear

    dicts = {s: scene(s, width, height) for s in scenes}
    rows = []
    with _served_pages(dicts, driver) as (drv, url_of):
        for s, sc in dicts.items():
            open_viewer(drv, url_of(s))
            for m in methods:
                if not applies(sc, m):
                    continue
                ref = render(sc, m)
                for p in precisions:
                    img, covered = render_linear(drv, m, p)
                    rows.append({"scene": s, "method": m, "precision": p,
                                 **_errors(img, ref, covered)})
    return rows


def screenshots(out_dir, scene=None, *, width=512, height=384, driver=None) -> list[Path]:
    """A PNG of the page's canvas per method and one split view (method | naive) in
    ``out_dir`` (``viewer_<method>.png``, ``viewer_split.png``); returns the paths.
    ``scene`` defaults to :func:`default_scene` at ``width x height``; ``leadr-point`` (point and
    directional lights only) is shot on the ``leadr`` scene of :func:`scene` at the same size
    when ``scene`` has no point or directional light (or has quad lights), the ``colormap-*``
    modes on the ``colormap`` scene when ``scene`` has no texture-driven ``extras.colormap``,
    ``leadr-env`` / ``leadr-irradiance`` on the ``leadr-env`` scene (at most 256 x 192) when
    ``scene`` has no environment light (or has quad lights)."""
    from prefilter.render.scene import Scene, load_scene
    from prefilter.viewer.browser import open_viewer, screenshot
    from prefilter.viewer.match import scene as named_scene  # shadowed by the argument

    out = Path(out_dir)
    sc = scene if scene is not None else default_scene(width, height)
    loaded = sc if isinstance(sc, Scene) else load_scene(sc)
    c = loaded.camera
    pages = {"shots": sc}
    # modes the scene cannot show are shot on the pixel-match scene made for them
    where = {m: "shots" for m in METHODS}
    for m, name in (("leadr-point", "leadr"), ("colormap-filtered", "colormap"),
                    ("colormap-naive", "colormap"), ("colormap-lit", "colormap"),
                    ("leadr-env", "leadr-env"),
                    ("leadr-irradiance", "leadr-env")):
        if not applies(loaded, m) or (m == "leadr-point" and not any(
                x.type in ("point", "directional") for x in loaded.lights)) or (
                m.startswith("leadr-") and m != "leadr-point"
                and not any(x.type == "environment" for x in loaded.lights)):
            # the environment modes cost ~0.35 ms per pixel on SwiftShader: at most 256 x 192
            w, h = (min(c.width, 256), min(c.height, 192)) if name == "leadr-env" else (
                c.width, c.height)
            pages[name] = named_scene(name, w, h)
            where[m] = name
    paths = []
    show = ("const v = window.prefilterViewer.viewer;"
            "Object.assign(v.params, {methodLeft: arguments[0], methodRight: arguments[0], "
            "split: -1});")
    with _served_pages(pages, driver) as (drv, url_of):
        current = None
        for m in METHODS:
            if where[m] != current:
                current = where[m]
                open_viewer(drv, url_of(current))
            drv.execute_script(show, m)
            paths.append(screenshot(drv, out / f"viewer_{m}.png"))
        if current != "shots":
            open_viewer(drv, url_of("shots"))
        drv.execute_script("const v = window.prefilterViewer.viewer;"
                           "Object.assign(v.params, {methodLeft: 'ltc-multiscale', "
                           "methodRight: 'ltc', split: 0.5});")
        paths.append(screenshot(drv, out / "viewer_split.png"))
    return paths


def frame_time(width: int = 512, height: int = 512, method: str = "ltc", frames: int = 10, *,
               driver=None) -> float:
    """Mean frame time in ms of the default scene at ``width x height`` drawn by ``method``
    (synchronised by a one-pixel read-back per frame); ``leadr-point`` draws the ``leadr`` scene
    (the default one has no point or directional light), ``leadr-env`` and ``leadr-irradiance``
    the ``leadr-env`` scene."""
    from prefilter.viewer.browser import open_viewer

    own = {"leadr-point": "leadr", "leadr-env": "leadr-env", "leadr-irradiance": "leadr-env"}
    sc = scene(own[method], width, height) if method in own else default_scene(width, height)
    with _served_pages({"timing": sc}, driver) as (drv, url_of):
        open_viewer(drv, url_of("timing"))
        drv.execute_script("const v = window.prefilterViewer.viewer;"
                           "Object.assign(v.params, {methodLeft: arguments[0], "
                           "methodRight: arguments[0], split: -1});", method)
        ms = float(drv.execute_script("return window.prefilterViewer.frameTime(arguments[0]);",
                                      frames))
    if not math.isfinite(ms):
        raise PrefilterError(f"frame time: expected a finite number, got {ms}")
    return ms


def _main() -> None:
    rows = pixel_match()
    print("| scene | method | tables | relative RMSE | max abs error | max error / max radiance |")
    print("|---|---|---|---|---|---|")
    for r in rows:
        print(f"| {r['scene']} | {r['method']} | {r['precision']} | {r['rel_rmse']:.2e} | "
              f"{r['max_abs']:.2e} | {r['max_rel']:.2e} |")
    for m in METHODS:
        if m in ("leadr-env", "leadr-irradiance"):  # ~20 s a frame at 256 x 256 on SwiftShader
            print(f"frame time 256x256 {m}: {frame_time(256, 256, m, frames=1):.1f} ms")
        else:
            print(f"frame time 512x512 {m}: {frame_time(method=m):.1f} ms")


if __name__ == "__main__":
    _main()
