"""A scene -> the viewer's static folder: page, GLSL, tables, texture atlas and ``viewer.json``.

The folder layout and the binary formats are documented in ``docs/viewer.md``. Everything the
page draws comes from here: the isotropic table as :func:`prefilter.ltc.glsl.export_all` writes
it, the anisotropic table as ``prefilter bake ltc-aniso --export`` writes it
(:func:`prefilter.ltc.aniso.export.export_all`), the multi-scale roughness from
:func:`prefilter.multiscale.glsl.export_all`, and the scene's normal maps as the box-filtered mip
chains the Python renderer reads (:class:`prefilter.texture.MipChain`; for
``ltc-multiscale-aniso`` the slope-moment chains of
:func:`prefilter.multiscale.aniso.slope_moments_chain`; for ``leadr-point`` the height maps'
moment chains, also in float16), and LEADR's shading from :func:`prefilter.leadr.glsl.export_all`.
"""

from __future__ import annotations

import re
import shutil
from pathlib import Path

import numpy as np

from prefilter.fileio import atomic_path, save_json_atomic, write_text_atomic
from prefilter.errors import PrefilterError

__all__ = ["BUILTIN_MAPS", "MAX_OBJECTS", "MAX_QUADS", "METHODS", "default_scene",
           "export_scene", "viewer_scene"]

#: Render methods the page implements (GLSL names in ``static/shaders/viewer.frag.glsl``).
METHODS = ("ltc", "ltc-multiscale", "ltc-aniso", "ltc-multiscale-aniso", "leadr-point",
           "colormap-filtered", "colormap-naive", "leadr-env", "leadr-irradiance",
           "colormap-lit")
MAX_OBJECTS = 4
MAX_QUADS = 4
#: Texels per row of the texture atlas.
ATLAS_WIDTH = 2048
#: The page's normal-map choices besides the scene's own: the procedural built-ins at 256^2.
BUILTIN_MAPS = {
    "gaussian": {"procedural": "gaussian", "size": 256, "seed": 1, "rms_slope": 0.25,
                 "corr_length": 3},
    "anisotropic": {"procedural": "anisotropic", "size": 256, "seed": 1},
    "brushed": {"procedural": "brushed", "size": 256, "seed": 1, "rms_slope": 0.25,
                "length": 64, "width": 1.5},
    "scratches": {"procedural": "scratches", "size": 256, "seed": 1},
    "flakes": {"procedural": "flakes", "size": 256, "seed": 1, "rms_slope": 0.25,
               "flake_size": 4},
}

STATIC_DIR = Path(__file__).resolve().parent / "static"


def default_scene(width: int = 512, height: int = 384) -> dict:
    """The page's default scene: a Gaussian-bump plane and a flakes sphere under one quad light."""
    return {
        "camera": {"origin": [0.0, 1.3, 3.6], "target": [0.0, 0.2, 0.0], "up": [0, 1, 0],
                   "fov": 40, "width": int(width), "height": int(height)},
        "objects": [
            {"type": "plane", "center": [0, 0, 0], "normal": [0, 1, 0], "tangent": [1, 0, 0],
             "size": [8, 8], "uv_scale": [8, 8],
             "material": {"alpha": 0.15, "base_color": 0.02, "f0": 0.9,
                          "normal_map": dict(BUILTIN_MAPS["gaussian"])}},
            {"type": "sphere", "center": [1.4, 0.5, -1.5], "radius": 0.5, "uv_scale": [4, 2],
             "material": {"alpha_x": 0.3, "alpha_y": 0.1, "base_color": [0.2, 0.3, 0.6],
                          "f0": 0.04}},
        ],
        "lights": [{"type": "quad", "vertices": [[-1, 0.4, -2], [1, 0.4, -2], [1, 1.6, -2.3],
                                                 [-1, 1.6, -2.3]], "radiance": 5.0}],
    }


def _check_supported(scene) -> None:
    if len(scene.objects) > MAX_OBJECTS:
        raise PrefilterError(f"objects: the viewer draws at most {MAX_OBJECTS} objects, got "
                             f"{len(scene.objects)}")
    count = {"quad": 0, "point": 0, "directional": 0}
    for i, light in enumerate(scene.lights):
        if light.type == "environment":  # leadr-env / leadr-irradiance / colormap-lit read them
            continue
        if getattr(light, "texture", None) is not None:
            raise PrefilterError(f"lights[{i}]: the viewer supports untextured quad, point, "
                                 "directional and environment lights, got a textured quad light")
        count[light.type] += 1
    for kind, n in count.items():
        if n > MAX_QUADS:
            raise PrefilterError(f"lights: the viewer draws at most {MAX_QUADS} {kind} lights, "
                                 f"got {n}")


def viewer_scene(scene, map_index=None, color_chain=None, height_chain=None) -> dict:
    """The flat scene the page reads (``viewer.json`` field ``scene``; ``docs/viewer.md``).

    ``map_index``: object index -> index into the manifest's ``maps`` (``-1``: no map);
    ``color_chain``: object index -> ``[first level, levels, channels]`` of its colour map;
    ``height_chain``: object index -> ``[first level, levels]`` of its height map's slope
    moments (what ``leadr-point`` reads, whether or not a normal map takes precedence).
    """
    c = scene.camera
    objs = []
    for i, o in enumerate(scene.objects):
        if o.type not in ("plane", "sphere"):  # the page ray-casts analytic planes and spheres
            raise PrefilterError(f"objects[{i}].type: the viewer shows planes and spheres only, "
                                 f"got {o.type!r} (render it with `prefilter render`)")
        m = o.material
        row = {"type": 0 if o.type == "plane" else 1, "center": o.center.tolist(),
               "uv_scale": o.uv_scale.tolist(),
               "material": {"alpha_x": m.alpha_x, "alpha_y": m.alpha_y,
                            "base_color": m.base_color.tolist(), "f0": m.f0.tolist(),
                            "map": -1 if map_index is None else map_index.get(i, -1),
                            "color": (color_chain or {}).get(i, [-1, 0, 0]),
                            "height": (height_chain or {}).get(i, [-1, 0])}}
        if o.type == "plane":
            row.update(n=o.normal.tolist(), t=o.tangent.tolist(),
                       b=np.cross(o.normal, o.tangent).tolist(), size=o.size.tolist(), radius=0.0)
        else:
            row.update(n=o.pole.tolist(), t=o.axis_x.tolist(),
                       b=np.cross(o.axis_x, o.pole).tolist(), size=[0.0, 0.0], radius=o.radius)
        objs.append(row)
    ls = scene.light_set()
    quads = [{"vertices": q.vertices.tolist(), "normal": q.normal.tolist(),
              "radiance": q.radiance.tolist()} for q in ls.quads]
    points = [{"position": np.asarray(p.position, float).tolist(),
               "intensity": np.asarray(p.intensity, float).tolist()} for p in ls.points]
    dirs = [{"direction": np.asarray(d.direction, float).tolist(),
             "irradiance": np.asarray(d.irradiance, float).tolist()} for d in ls.directionals]
    return {"camera": {"origin": c.origin.tolist(), "target": c.target.tolist(),
                       "up": c.up.tolist(), "fov": c.fov, "width": c.width, "height": c.height},
            "objects": objs, "lights": quads, "points": points, "directionals": dirs}


class _Atlas:
    """Mip chains packed as RGBA float32 texels (``stride`` texels per texel of the chain)."""

    def __init__(self):
        self.parts, self.levels, self.size = [], [], 0

    def add(self, chain) -> list[int]:
        first = len(self.levels)
        c = chain.shape[2]
        stride = -(-c // 4)
        for lv in chain.levels:
            h, w = lv.shape[:2]
            x = np.zeros((h, w, 4 * stride), np.float32)
            x[..., :c] = lv
            self.parts.append(x.reshape(-1))
            self.levels.append([self.size, h, w, stride])
            self.size += h * w * stride
        return [first, len(chain.levels)]

    def data(self) -> np.ndarray:
        rows = max(1, -(-self.size // ATLAS_WIDTH))
        out = np.zeros(rows * ATLAS_WIDTH * 4, np.float32)
        if self.parts:
            flat = np.concatenate(self.parts)
            out[:flat.size] = flat
        return out


class _Levels:
    """The levels of a :class:`prefilter.colormap.kernels.PackedChain` as ``_Atlas.add`` reads a
    mip chain."""

    def __init__(self, packed):
        c = packed.channels
        self.levels = [packed.data[o:o + h * w].reshape(h, w, c) for o, h, w in
                       zip(packed.offsets, packed.heights, packed.widths)]
        self.shape = self.levels[0].shape


#: ``viewer.json`` ``colormap.driver_code`` (``uColormapDriver`` in ``viewer.frag.glsl``).
COLORMAP_DRIVERS = {"texture": 0, "noise": 1, "height": 2, "slope": 3}


def _colormap_light(scene, driver) -> list[float]:
    """The height driver's light as ``prefilter.colormap.render`` picks it: the driver's own,
    else the scene's first directional light; ``[x, y, z, 1]`` (world, towards the light) or
    ``[0, 0, 1, 0]`` without (lit everywhere)."""
    if driver.light is not None:
        return [*np.asarray(driver.light, float).tolist(), 1.0]
    for light in scene.lights:
        if light.type == "directional":
            return [*(-np.asarray(light.direction, float)).tolist(), 1.0]
    return [0.0, 0.0, 1.0, 0.0]


def _colormap(scene, atlas: "_Atlas", data: Path) -> dict:
    """The scene's colour-map driver (``extras.colormap``: texture, noise, height or slope) for
    the ``colormap-*`` modes: the exported snippet (table lookup and the drivers' GLSL), the
    table and the slope stack (``glsl_drivers.slope_texture``), and the driving chain in the
    atlas (noise: its mean chain; slope: the slope moments ``E[sx], E[sy], E[sx^2], E[sy^2],
    E[sx sy]``; else ``(E[f], E[f^2])``)."""
    from types import SimpleNamespace

    from prefilter.colormap.glsl import GLSL_WRAP, glsl_snippet
    from prefilter.colormap.glsl_drivers import driver_glsl, slope_texture
    from prefilter.colormap.lit import lit_colormap
    from prefilter.colormap.driver import colormap_driver
    from prefilter.colormap.table import ColormapTable

    spec = (getattr(scene, "extras", None) or {}).get("colormap")
    driver, light, slope = None, [0.0, 0.0, 1.0, 0.0], None
    kind = spec.get("driver") if isinstance(spec, dict) else None
    if kind == "slope":
        lit = lit_colormap(spec, base_dir=getattr(scene, "base_dir", "."))
        slope = lit.slope
        # the driver's GLSL reads the surface's slope covariance (Smith Lambda, V_bar)
        driver = SimpleNamespace(driver="slope", slope_cov=lit.surface.slope_cov)
        table = ColormapTable(np.zeros((2, 2, 3)), (0.0, 1.0), 1.0)
        chain = atlas.add(lit.surface.slope_moments)
        light = _colormap_light(scene, SimpleNamespace(light=None))
    elif kind in COLORMAP_DRIVERS:
        driver = colormap_driver(spec, base_dir=getattr(scene, "base_dir", "."))
        packed = driver.mean_chain if driver.driver == "noise" else driver.moments_chain
        table, chain = driver.table, atlas.add(_Levels(packed))
        if driver.driver == "height":
            light = _colormap_light(scene, driver)
    else:  # no colour map the page draws: a placeholder table, the modes draw black
        table = ColormapTable(np.zeros((2, 2, 3)), (0.0, 1.0), 1.0)
        chain = [-1, 0]
    img = np.concatenate([table.table, np.ones(table.table.shape[:2] + (1,))], -1)
    _write(data / "colormap_f32.bin", img.astype("<f4").tobytes())
    # glsl_snippet writes an integer-valued sigma_max as an int literal ("= 2;"), which GLSL ES
    # does not convert to float: add the ".0" (reported to the colormap package)
    src = re.sub(r"(const float kSigmaMax\s*=\s*)(-?\d+);", r"\1\2.0;",
                 glsl_snippet(table.metadata())) + driver_glsl(driver, slope)
    stack = slope_texture(slope)
    _write(data / "colormap_slope_f32.bin", stack.astype("<f4").tobytes())
    write_text_atomic(data / "colormap.glsl", src)
    return {"glsl": "colormap.glsl", "f32": "colormap_f32.bin", "width": table.n_mean,
            "height": table.n_sigma, "wrap_s": GLSL_WRAP[table.edge].removeprefix("GL_"),
            "chain": chain, "driver": None if driver is None else driver.driver,
            "driver_code": -1 if driver is None else COLORMAP_DRIVERS[driver.driver],
            "light": light, "slope": {"f32": "colormap_slope_f32.bin",
                                      "width": int(stack.shape[1]),
                                      "height": int(stack.shape[0])}}


def _leadr_env(scene, data: Path) -> dict:
    """The scene's environment lights (summed, :func:`prefilter.leadr.render.scene_environment`)
    for the ``leadr-env`` / ``leadr-irradiance`` modes: the exported ``leadr_env.glsl``, the
    radiance mip levels in ``env_f32.bin`` (RGBA float32, level after level) and the irradiance
    map's nodes in ``irradiance_f32.bin``."""
    from prefilter.leadr import glsl_env
    from prefilter.leadr.render import scene_environment

    glsl_env.export_all(data)
    tex = glsl_env.env_textures(scene_environment(scene))
    levels, offset = [], 0
    for a in tex["levels"]:
        levels.append({"width": a.shape[1], "height": a.shape[0], "offset": offset})
        offset += a.size
    _write(data / "env_f32.bin", np.concatenate([a.reshape(-1) for a in tex["levels"]])
           .astype("<f4").tobytes())
    irr = tex["irradiance"]
    _write(data / "irradiance_f32.bin", irr.astype("<f4").tobytes())
    return {"glsl": "leadr_env.glsl", "env": "env_f32.bin", "levels": levels,
            "present": tex["present"], "texel": tex["texel"], "irradiance": "irradiance_f32.bin",
            "irradiance_width": irr.shape[1], "irradiance_height": irr.shape[0]}


def _write(path: Path, data: bytes) -> None:
    with atomic_path(path, suffix=path.suffix) as tmp:
        tmp.write_bytes(data)


def export_scene(scene=None, out_dir="viewer", *, builtin_maps: bool = True,
                 iso_table=None, aniso_table=None, glints=()) -> Path:
    """Write the viewer's static folder for ``scene`` (a :class:`Scene`, a JSON path, a dict or
    ``None`` for :func:`default_scene`) to ``out_dir``; returns ``out_dir``.

    ``builtin_maps``: also pack the :data:`BUILTIN_MAPS` for the page's normal-map choice.
    ``iso_table`` / ``aniso_table``: the tables (default: the shipped ones).
    ``glints``: glint maps for the ``glints`` mode, kinds of
    :data:`prefilter.viewer.glint_maps.GLINT_MAPS` (baked on first use: minutes each).
    """
    from prefilter.leadr import glsl as leadr_glsl
    from prefilter.ltc import glsl as iso_glsl
    from prefilter.ltc.aniso import export as aniso_export
    from prefilter.ltc.aniso.table import AnisoGGXTable
    from prefilter.ltc.table import GGXTable
    from prefilter.multiscale import glsl as ms_glsl
    from prefilter.multiscale.aniso import slope_moments_chain
    from prefilter.render.scene import Scene, TextureRef, load_scene
    from prefilter.texture import MipChain

    if scene is None:
        scene = default_scene()
    if not isinstance(scene, Scene):
        scene = load_scene(scene)
    _check_supported(scene)
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    shutil.copytree(STATIC_DIR, out, dirs_exist_ok=True,
                    ignore=shutil.ignore_patterns("__pycache__"))
    data = out / "data"
    iso = iso_table if iso_table is not None else GGXTable.load()
    aniso = aniso_table if aniso_table is not None else AnisoGGXTable.load()
    iso_glsl.export_all(iso, data)
    aniso_export.export_all(aniso, data)
    ms_glsl.export_all(data)
    leadr_glsl.export_all(data)

    atlas, maps, map_index, seen, colors, heights = _Atlas(), [], {}, {}, {}, {}

    def add_map(name: str, ref: TextureRef) -> int:
        key = ref.cache_key()
        if key in seen:
            maps[seen[key]]["names"].append(name)
            return seen[key]
        if ref.role == "height_map":
            # slope moments, as the renderer's height-map mip chain; no normal chain
            chain = ref.mip()
            maps.append({"name": name, "names": [name], "normals": [-1, 0],
                         "slopes": atlas.add(chain), "size": list(chain.shape[:2])})
        else:
            normals = ref.load()
            maps.append({"name": name, "names": [name], "normals": atlas.add(MipChain(normals)),
                         "slopes": atlas.add(slope_moments_chain(normals)),
                         "size": list(normals.shape[:2])})
        seen[key] = len(maps) - 1
        return seen[key]

    for i, o in enumerate(scene.objects):
        m = o.material
        if m.normal_map is not None:  # normal maps take precedence over height maps
            map_index[i] = add_map(f"scene: objects[{i}]", m.normal_map)
        elif m.height_map is not None:
            map_index[i] = add_map(f"scene: objects[{i}] (height)", m.height_map)
        if m.height_map is not None:
            key = m.height_map.cache_key()
            j = seen[key] if key in seen else add_map(f"scene: objects[{i}] (height)",
                                                      m.height_map)
            heights[i] = maps[j]["slopes"]
        if m.color_map is not None:
            chain = m.color_map.mip()
            colors[i] = atlas.add(chain) + [int(chain.shape[2])]
    if builtin_maps:
        for name, spec in BUILTIN_MAPS.items():
            add_map(name, TextureRef("normal_map", spec, f"builtin {name}"))
    colormap = _colormap(scene, atlas, data)
    packed = atlas.data()
    _write(data / "atlas_f32.bin", packed.astype("<f4").tobytes())
    # LEADR's moment maps as a real-time renderer would store them (the page's f16 option)
    _write(data / "atlas_f16.bin", packed.astype("<f2").tobytes())
    _write(data / "levels_i32.bin", np.asarray(atlas.levels or [[0, 1, 1, 1]],
                                               "<i4").reshape(-1).tobytes())
    at = iso_glsl.texture_params(iso)
    an = aniso_export.texture_params(aniso)
    manifest = {
        "version": 1,
        "methods": list(METHODS),
        "ltc_iso": {"f32": "ggx_iso_f32.bin", "f16": "ggx_iso_f16.bin", "glsl": "ltc_iso.glsl",
                    "width": at["T"], "height": at["R"], "layers": 3},
        "ltc_aniso": {"f32": "ggx_aniso_f32.bin", "f16": "ggx_aniso_f16.bin",
                      "glsl": "ltc_aniso.glsl", "width": an["T"], "height": an["F"],
                      "depth": an["A"] * an["R"], "layers": 3},
        "alpha_meso": {"f32": "alpha_meso_f32.bin", "glsl": "multiscale.glsl",
                       "width": ms_glsl.ALPHA_MESO_WIDTH,
                       "height": int(ms_glsl.alpha_meso_nodes().shape[0])},
        "leadr": {"glsl": "leadr.glsl"},
        "colormap": colormap,
        "leadr_env": _leadr_env(scene, data),
        "atlas": {"f32": "atlas_f32.bin", "f16": "atlas_f16.bin", "width": ATLAS_WIDTH,
                  "height": max(1, -(-atlas.size // ATLAS_WIDTH)),
                  "levels": "levels_i32.bin", "n_levels": max(1, len(atlas.levels))},
        "maps": maps,
        "scene": viewer_scene(scene, map_index, colors, heights),
    }
    if glints:
        from prefilter.viewer.glint_maps import export_glints

        manifest["glints"] = export_glints(data, tuple(glints))
    save_json_atomic(data / "viewer.json", manifest)
    return out
