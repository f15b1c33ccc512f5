"""Path-traced scenes of the glint paper's set-ups, built procedurally (nothing downloaded), and
the demo report's path-tracing section.

* :func:`kettle_scene` (the paper's fig. 10): a kettle-like body of revolution in brushed metal
  (a brushed normal map running around it, as a lathe leaves it) on a glossy floor that reflects
  it, two small quad lights and a sky environment.
* :func:`panel_scene` (its car, direct light): a curved panel (a section of a cylinder) with a
  flakes normal map under the sky and a point light.
* :func:`room_scene` (its elevator): a box of brushed walls, open towards the camera, lit by
  three quad lights under the ceiling.

The meshes and the sky are written next to the scene (``kettle.ply``, ``panel.ply``,
``sky.npy``) by :func:`write_assets`.
"""

from __future__ import annotations

import os
import time
from pathlib import Path

import numpy as np


__all__ = ["KETTLE_PROFILE", "kettle_scene", "panel_scene", "pathtrace_section", "room_scene",
           "sky_image", "write_assets"]

#: Radius and height (metres) of the kettle's profile, bottom pole to the lid's knob.
KETTLE_PROFILE = [(0.0, 0.0), (0.085, 0.0), (0.1, 0.012), (0.112, 0.05), (0.113, 0.1),
                  (0.104, 0.15), (0.082, 0.19), (0.055, 0.205), (0.05, 0.215), (0.018, 0.22),
                  (0.014, 0.24), (0.0, 0.245)]


def sky_image(height: int = 32) -> np.ndarray:
    """A smooth equirectangular sky ``(H, 2H, 3)`` (``docs/scenes.md`` convention): bluish
    zenith 0.5, bright horizon 1.2, dark ground 0.08, and a soft warm sun-like lobe."""
    from prefilter.render.pathtrace import equirect_direction

    v = (np.arange(height) + 0.5) / height
    u = (np.arange(2 * height) + 0.5) / (2 * height)
    cos_t = np.cos(np.pi * v)[:, None]
    up = np.clip(cos_t, 0.0, 1.0)
    sky = np.stack([0.5 + 0.7 * (1 - up), 0.6 + 0.6 * (1 - up), 0.9 + 0.3 * (1 - up)], -1)
    ground = np.full(3, 0.08)
    img = np.where(cos_t[..., None] > 0, sky, ground) * np.ones((1, 2 * height, 1))
    d = equirect_direction(u[None, :], v[:, None])
    sun = np.array([0.5, 0.6, 0.62]) / np.linalg.norm([0.5, 0.6, 0.62])
    img += np.exp(40.0 * (d @ sun - 1.0))[..., None] * np.array([6.0, 5.0, 3.5])
    return img


def write_assets(directory) -> Path:
    """Write ``kettle.ply``, ``panel.ply`` and ``sky.npy`` into ``directory`` (the sky only when
    it changed); returns the directory."""
    from prefilter.render.lathe import lathe, smooth_profile
    from prefilter.render.mitsuba_export import write_ply

    d = Path(directory)
    d.mkdir(parents=True, exist_ok=True)
    prof = smooth_profile(KETTLE_PROFILE, 32)
    for name, (v, f, n, uv) in (("kettle", lathe(prof, segments=64, u_repeat=16.0,
                                                 v_repeat=4.0)), ("panel", _panel())):
        # PLY texture coordinates in the OBJ convention (v up the image), as the loader reads
        write_ply(d / f"{name}.ply", v, f, n, np.stack([uv[:, 0], 1.0 - uv[:, 1]], -1))
    sky = sky_image()
    p = d / "sky.npy"
    if not (p.exists() and np.array_equal(np.load(p), sky)):
        tmp = d / f"sky.{os.getpid()}.tmp.npy"
        np.save(tmp, sky)
        os.replace(tmp, p)
    return d


def _panel(n_u: int = 48, n_v: int = 8, radius: float = 1.2, angle: float = 0.9,
           length: float = 1.0):
    """A curved panel: the part ``|phi| < angle / 2`` of a cylinder of ``radius`` about the
    ``x`` axis (a car's bonnet, bulging up), ``length`` along ``x``, ``u`` along ``x`` (4 repeats
    per metre), ``v`` around (the flakes are isotropic)."""
    x = np.linspace(-length / 2, length / 2, n_v + 1)
    phi = np.linspace(-angle / 2, angle / 2, n_u + 1)
    X, P = np.meshgrid(x, phi, indexing="ij")
    verts = np.stack([X, radius * np.cos(P) - radius, -radius * np.sin(P)], -1).reshape(-1, 3)
    normals = np.stack([np.zeros_like(X), np.cos(P), -np.sin(P)], -1).reshape(-1, 3)
    uv = np.stack([(X + length / 2) * 4.0, (P + angle / 2) * radius * 4.0], -1).reshape(-1, 2)
    a = (np.arange(n_v)[:, None] * (n_u + 1) + np.arange(n_u)[None]).reshape(-1)
    b = a + n_u + 1
    f = np.concatenate([np.stack([a, a + 1, b + 1], -1), np.stack([a, b + 1, b], -1)])
    e = np.cross(verts[f[:, 1]] - verts[f[:, 0]], verts[f[:, 2]] - verts[f[:, 0]])
    flip = np.sum(e * normals[f].sum(1), -1) < 0
    f[flip] = f[flip][:, ::-1]
    return verts, f, normals, uv


def _square_light(center, target, half: float, radiance) -> dict:
    """A square quad light of side ``2 half`` at ``center`` facing ``target``."""
    c = np.asarray(center, dtype=np.float64)
    n = np.asarray(target, dtype=np.float64) - c
    n /= np.linalg.norm(n)
    a = np.cross(n, [0.0, 1.0, 0.0])
    if np.linalg.norm(a) < 1e-6:
        a = np.array([1.0, 0.0, 0.0])
    a /= np.linalg.norm(a)
    b = np.cross(n, a)
    v = [c - half * a - half * b, c + half * a - half * b, c + half * a + half * b,
         c - half * a + half * b]
    if np.dot(np.cross(v[1] - v[0], v[2] - v[0]), n) < 0:
        v = v[::-1]
    return {"type": "quad", "vertices": [[round(float(x), 6) for x in p] for p in v],
            "radiance": [float(radiance)] * 3}


def kettle_scene(width: int = 96, height: int = 64, map_size: int = 64) -> dict:
    """The kettle (glints paper, fig. 10): brushed-metal body of revolution (normal map
    ``brushed`` of ``map_size`` texels, 16 repeats around, 4 along the profile) on a glossy floor
    (GGX alpha 0.08) reflecting it, two small quad lights and the sky (files of
    :func:`write_assets`, relative to the scene)."""
    return {
        "camera": {"origin": [0.0, 0.2, 0.8], "target": [0.0, 0.07, 0.0], "up": [0, 1, 0],
                   "fov": 28, "width": width, "height": height},
        "objects": [
            {"type": "mesh", "file": "kettle.ply",
             "material": {"alpha": 0.05, "base_color": 0.0, "f0": [0.95, 0.93, 0.88],
                          "normal_map": {"procedural": "brushed", "size": map_size, "seed": 1}}},
            {"type": "plane", "center": [0, 0, 0], "size": [4, 4], "uv_scale": [4, 4],
             "material": {"alpha": 0.08, "base_color": 0.04, "f0": 0.5}}],
        "lights": [_square_light([-0.35, 0.5, 0.4], [0, 0.12, 0], 0.04, 80.0),
                   _square_light([0.45, 0.4, 0.15], [0, 0.12, 0], 0.03, 80.0),
                   {"type": "environment", "image": "sky.npy", "scale": 0.5}]}


def panel_scene(width: int = 96, height: int = 64, map_size: int = 64) -> dict:
    """The car-like panel: a curved panel with a flakes normal map (``map_size`` texels) under
    the sky and a point light (direct light only in the paper)."""
    return {
        "camera": {"origin": [0.0, 0.55, 1.1], "target": [0.0, -0.05, -0.15], "up": [0, 1, 0],
                   "fov": 40, "width": width, "height": height},
        "objects": [
            {"type": "mesh", "file": "panel.ply",
             "material": {"alpha": 0.1, "base_color": [0.05, 0.01, 0.01], "f0": 0.9,
                          "normal_map": {"procedural": "flakes", "size": map_size, "seed": 1}}}],
        "lights": [{"type": "point", "position": [0.3, 1.2, 0.6], "intensity": 2.0},
                   {"type": "environment", "image": "sky.npy", "scale": 0.3}]}


def room_scene(width: int = 96, height: int = 64, map_size: int = 64) -> dict:
    """The elevator-like room: a 2 x 2.4 x 2 box (floor, ceiling, three walls; open towards the
    camera) whose walls are brushed metal (normal map ``brushed``, vertical brushing) and whose
    floor is a glossy dark plane, lit by three quad lights under the ceiling."""
    wall = {"alpha": 0.1, "base_color": 0.02, "f0": [0.9, 0.88, 0.85],
            "normal_map": {"procedural": "brushed", "size": map_size, "seed": 2}}
    floor = {"alpha": 0.15, "base_color": 0.1, "f0": 0.3}
    ceiling = {"alpha": 0.6, "base_color": 0.6, "f0": 0.04}
    lights = [_square_light([x, 2.35, -1.0], [x, 0.0, -1.0], 0.12, 25.0)
              for x in (-0.6, 0.0, 0.6)]
    return {
        "camera": {"origin": [0.0, 1.3, 1.6], "target": [0.0, 1.0, -1.0], "up": [0, 1, 0],
                   "fov": 55, "width": width, "height": height},
        "objects": [
            {"type": "plane", "center": [0, 0, -1], "size": [2, 2], "uv_scale": [2, 2],
             "material": floor},
            {"type": "plane", "center": [0, 2.4, -1], "normal": [0, -1, 0], "size": [2, 2],
             "material": ceiling},
            {"type": "plane", "center": [0, 1.2, -2], "normal": [0, 0, 1], "tangent": [0, 1, 0],
             "size": [2.4, 2], "uv_scale": [24, 20], "material": wall},
            {"type": "plane", "center": [-1, 1.2, -1], "normal": [1, 0, 0], "tangent": [0, 1, 0],
             "size": [2.4, 2], "uv_scale": [24, 20], "material": wall},
            {"type": "plane", "center": [1, 1.2, -1], "normal": [-1, 0, 0], "tangent": [0, 1, 0],
             "size": [2.4, 2], "uv_scale": [24, 20], "material": wall}],
        "lights": lights}


def _example(name: str, width: int, height: int):
    """The shipped example ``name`` at ``width x height`` (its files next to it)."""
    from prefilter.examples import path
    from prefilter.render.scene import load_scene

    sc = load_scene(f"example:{name}").to_dict()
    sc["camera"].update(width=width, height=height)
    return load_scene(sc, base_dir=path(name).parent)


def pathtrace_section(report, settings, seed: int, log) -> None:
    """The demo report's section: the shipped kettle, flake-panel and brushed-room examples by
    ``path`` (direct light and 4 vertices), then the kettle's indirect glints by ``glints``
    against ``glints-direct`` on the same paths."""
    from prefilter.glints.indirect import render_glints_paths
    from prefilter.render.driver import render
    from prefilter.render.methods import RenderSettings
    from prefilter.render.pathtrace import PathOptions, PathStats

    w, h, spp = settings.section_width, settings.section_height, settings.section_spp
    rows = []
    for name in ("kettle", "flake-panel", "brushed-room"):
        scene = _example(name, w, h)
        items = []
        for bounces in ("1", "4"):
            t0 = time.perf_counter()
            img = render(scene, "path", spp=spp, seed=seed, params={"bounces": bounces})
            dt = time.perf_counter() - t0
            items.append((f"path bounces={bounces}", img))
            rows.append([name, bounces, spp, dt, float(img.mean())])
            log(f"pathtrace: {name} bounces={bounces}: {dt:.1f} s")
        report.add_image_row(f"example:{name}", items, scale=2)
    report.add_table(["example", "bounces", "spp", "time (s)", "mean radiance"], rows,
                     caption="`path`: next-event estimation with MIS, shadow rays, Russian "
                     "roulette after 3 vertices; bounces=1 is the direct light. Wall clock on "
                     "this machine, measured now.")
    # indirect glints: light that reached the camera after 2 vertices (camera -> floor ->
    # kettle -> light), the kettle's glint lobe queried with the enlarged footprint
    scene = _example("kettle", w // 2, h // 2)
    st = RenderSettings(spp=4, seed=seed)
    images, stats, times = {}, {}, {}
    for mode, name in (("compressed", "glints"), ("direct", "glints-direct")):
        stats[name] = PathStats()
        t0 = time.perf_counter()
        images[name] = render_glints_paths(scene, st, mode, name, options=PathOptions(bounces=2),
                                           stats=stats[name], min_depth=1)
        times[name] = time.perf_counter() - t0
    cmp = report.add_comparison("kettle, indirect light only", images["glints-direct"],
                                {"glints": images["glints"]}, scale=4,
                                reference_name="glints-direct")[0]
    glint = {n: sum(d.get("FootprintGlintLobe", 0.0) for d in stats[n].by_lobe[1:])
             for n in images}
    report.add_table(
        ["method", "glint lobe at vertex 2 (s)", "render (s)", "FLIP vs glints-direct"],
        [["glints", glint["glints"], times["glints"], cmp["flip"]],
         ["glints-direct", glint["glints-direct"], times["glints-direct"], 0.0]],
        caption=f"{w // 2} x {h // 2}, 4 spp, 2 vertices. Speed-up of the indirect glints: "
                f"{glint['glints-direct'] / max(glint['glints'], 1e-9):.1f}x (the paper: 14x). "
                "`benchmarks/bench_indirect_glints.py` measures it at 96 x 64, 16 spp.")
