"""Scenes as data: JSON or TOML (or a dict) -> frozen dataclasses, validated field by field.

The format is documented in ``docs/scenes.md``. Every error is a
:class:`~prefilter.errors.PrefilterError` naming the field path and what was expected, e.g.
``objects[1].material.alpha_x: expected a number in [0.001, 1], got "a"``; unknown fields are
rejected. Textures are referenced by file path (relative to the scene file) or by a procedural
spec, and are loaded lazily (first use) and cached.
"""

from __future__ import annotations

import functools
import json
import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from prefilter.errors import PrefilterError
from prefilter.examples import resolve as resolve_example
from prefilter.render.camera import Camera

__all__ = ["DirectionalLightSpec", "EnvironmentLight", "Material", "Plane", "PointLightSpec",
           "QuadLightSpec", "Scene", "Sphere", "TextureRef", "load_scene"]


# -- field validation ------------------------------------------------------------------------------


#: The domain of scene magnitudes (docs/scenes.md, "Ranges"), checked when a scene is loaded so
#: that every kernel works well inside the float range: coordinates of points (camera, centres,
#: vertices, light positions) and lengths (sizes, radii) at most :data:`EXTENT_MAX` in magnitude,
#: texture repeats ``uv_scale`` at most :data:`UV_SCALE_MAX`, light values (radiance,
#: intensity, irradiance, environment scale) at most :data:`LIGHT_MAX`, reflectances
#: (``base_color``, ``f0``) at most :data:`REFLECTANCE_MAX`, height-map scales at most
#: :data:`HEIGHT_SCALE_MAX`.
EXTENT_MAX = 1e6
UV_SCALE_MAX = 1e6
LIGHT_MAX = 1e12
REFLECTANCE_MAX = 1e3
HEIGHT_SCALE_MAX = 1e4


def _got(v: Any) -> str:
    if isinstance(v, int) and not isinstance(v, bool) and abs(v) >= 10**30:
        return f"an integer of {len(str(abs(v)))} digits"
    if isinstance(v, list) and any(isinstance(x, int) and abs(x) >= 10**30 for x in v
                                   if not isinstance(x, bool)):
        return "[" + ", ".join(map(_got, v)) + "]"
    try:
        return json.dumps(v)
    except (TypeError, ValueError):
        return repr(v)


def _is_number(v) -> bool:
    """A JSON number that is a finite float (integers beyond the float range are not)."""
    if isinstance(v, bool) or not isinstance(v, (int, float)):
        return False
    try:
        return bool(np.isfinite(float(v)))
    except OverflowError:  # a JSON integer such as 10**400
        return False


def _beyond(at: str, limit: float, given) -> PrefilterError:
    """The error of a value outside the scene domain (docs/scenes.md, "Ranges")."""
    return PrefilterError(f"{at}: expected magnitudes <= {limit:g} (the scene domain), got "
                          f"{_got(given)}")


class _Obj:
    """A JSON object under validation at ``path``: typed getters that raise path-named errors."""

    def __init__(self, value, path: str, allowed: tuple[str, ...]):
        if not isinstance(value, dict):
            raise PrefilterError(f"{path or 'scene'}: expected an object, got {_got(value)}")
        self.d, self.path = value, path
        unknown = [k for k in value if k not in allowed]
        if unknown:
            raise PrefilterError(
                f"{self.at(unknown[0])}: unknown field; expected one of {', '.join(allowed)}")

    def at(self, key) -> str:
        return f"{self.path}.{key}" if self.path else str(key)

    def raw(self, key, default=...):
        if key not in self.d:
            if default is ...:
                raise PrefilterError(f"{self.at(key)}: required field is missing")
            return default
        return self.d[key]

    def number(self, key, default=..., lo=-np.inf, hi=np.inf, lo_open=False,
               limit=np.inf) -> float:
        """A finite number in ``[lo, hi]`` (``(lo, hi]`` if ``lo_open``) of magnitude at most
        ``limit`` (the scene domain, reported on its own)."""
        v = self.raw(key, default)
        ok = _is_number(v) and (lo < v if lo_open else lo <= v) and v <= hi
        if not ok:
            rng = "" if (lo, hi) == (-np.inf, np.inf) else (
                f" in {'(' if lo_open else '['}{lo:g}, {hi:g}]" if hi < np.inf else
                f" {'>' if lo_open else '>='} {lo:g}")
            raise PrefilterError(f"{self.at(key)}: expected a number{rng}, got {_got(v)}")
        if abs(v) > limit:
            raise _beyond(self.at(key), limit, v)
        return float(v)

    def integer(self, key, default=..., lo=1, hi=1 << 16) -> int:
        v = self.raw(key, default)
        if isinstance(v, bool) or not isinstance(v, int) or not lo <= v <= hi:
            raise PrefilterError(
                f"{self.at(key)}: expected an integer in [{lo}, {hi}], got {_got(v)}")
        return v

    def vector(self, key, n, default=..., lo=-np.inf, scalar_ok=False,
               limit=np.inf) -> np.ndarray:
        """A list of ``n`` finite numbers ``>= lo`` of magnitude at most ``limit`` (the scene
        domain, reported on its own); with ``scalar_ok`` one number stands for all ``n``."""
        v = given = self.raw(key, default)
        if scalar_ok and isinstance(v, (int, float)) and not isinstance(v, bool):
            v = [v] * n
        ok = (isinstance(v, (list, tuple)) and len(v) == n
              and all(_is_number(x) and x >= lo for x in v))
        if not ok:
            what = f"a list of {n} numbers" + (f" >= {lo:g}" if lo > -np.inf else "")
            if scalar_ok:
                what += " (or one number)"
            raise PrefilterError(f"{self.at(key)}: expected {what}, got {_got(given)}")
        if any(abs(x) > limit for x in v):
            raise _beyond(self.at(key), limit, given)
        return np.array(v, dtype=np.float64)

    def unit(self, key, default=...) -> np.ndarray:
        """A direction (any finite length >= 1e-12), normalised (components so large that the
        squared length overflows are scaled by the largest one first)."""
        v = self.vector(key, 3, default)
        with np.errstate(over="ignore"):
            n = np.linalg.norm(v)
        if not np.isfinite(n):  # |v|^2 overflowed
            v = v / np.max(np.abs(v))
            n = np.linalg.norm(v)
        if n < 1e-12:
            raise PrefilterError(
                f"{self.at(key)}: expected a non-zero vector, got {_got(v.tolist())}")
        return v / n

    def point(self, key, default=...) -> np.ndarray:
        """A position: 3 numbers of magnitude at most :data:`EXTENT_MAX`."""
        return self.vector(key, 3, default, limit=EXTENT_MAX)

    def choice(self, key, options, default=...) -> str:
        v = self.raw(key, default)
        if v not in options:
            raise PrefilterError(
                f"{self.at(key)}: expected one of {', '.join(map(_got, options))}, got {_got(v)}")
        return v


def _list(value, path: str) -> list:
    if not isinstance(value, list):
        raise PrefilterError(f"{path}: expected a list, got {_got(value)}")
    return value


# -- textures -------------------------------------------------------------------------------------

TEXTURE_ROLES = ("normal_map", "height_map", "color_map", "light_texture", "environment")


@dataclass(frozen=True)
class TextureRef:
    """A texture by file path or procedural spec; :meth:`load` reads/generates it once (cached).

    ``spec``: the procedural spec or the file entry as written; ``where``: its field path (for
    errors); ``path``: the resolved file (``None`` for procedural textures). Procedural parameters
    (names and values) are checked when the scene is loaded.
    """

    role: str
    spec: Any
    where: str = ""
    path: Path | None = None
    convention: str = "opengl"
    srgb: bool = False
    scale: float = 1.0

    def cache_key(self) -> tuple:
        """What identifies the texture's data (spec or file and its mtime, decoding options):
        the arguments of :func:`load_texture`, a key for caches of data derived from it."""
        key = json.dumps(self.spec, sort_keys=True) if self.path is None else None
        mtime = self.path.stat().st_mtime_ns if self.path is not None and self.path.exists() else 0
        return (self.role, key, str(self.path) if self.path else None, mtime, self.convention,
                self.srgb, self.scale)

    def load(self):
        """The texture data (generated or read on first use, then cached).

        ``normal_map``: unit tangent-space normals ``(H, W, 3)``; ``height_map``: a
        :class:`prefilter.texture.HeightMap` (height ``(H, W)`` and slopes ``(H, W, 2)`` in texel
        units, scaled by ``scale``); other roles: linear values ``(H, W, C)``.
        """
        try:
            return load_texture(*self.cache_key())
        except PrefilterError as exc:
            raise PrefilterError(f"{self.where}: {exc}") from None

    def mip(self):
        """A cached :class:`prefilter.texture.MipChain` of :meth:`load` (normal maps:
        unnormalised averages; height maps: the moments chain of the slopes)."""
        try:
            return _load_mip(*self.cache_key())
        except PrefilterError as exc:
            raise PrefilterError(f"{self.where}: {exc}") from None


@functools.lru_cache(maxsize=64)
def load_texture(role, key, path, mtime, convention, srgb, scale):
    """The data of the texture whose :meth:`TextureRef.cache_key` is the arguments (cached; see
    :meth:`TextureRef.load`)."""
    from prefilter import texture as tx
    from prefilter.texture.procedural import noise_texture

    if path is None:
        spec = dict(json.loads(key))
        kind = spec.pop("procedural")
        size = spec.pop("size", 512)
        seed = spec.pop("seed", 0)
        if role == "normal_map":
            return tx.normal_map(kind, size, seed, **spec)
        if role == "height_map":
            h = tx.height_map(kind, size, seed, **spec)
            return tx.HeightMap(h.height * scale, h.slopes * scale)
        # colours and radiance multiply light: the noise mapped to [0, 1] (noise_texture)
        return noise_texture(size, seed, **spec)[..., None]
    img = tx.read_image(path, srgb=srgb)
    if role == "normal_map":
        return tx.decode_normals(img, convention)
    if role == "height_map":
        h = img[..., 0] * scale
        sx = (np.roll(h, -1, 1) - np.roll(h, 1, 1)) / 2.0  # periodic central differences
        sy = (np.roll(h, -1, 0) - np.roll(h, 1, 0)) / 2.0
        return tx.HeightMap(h, np.stack([sx, sy], -1))
    return _radiometric(img, role)


def _radiometric(a, role: str):
    """``a`` if it holds finite values >= 0: colours and radiance multiply light, so a negative
    texel of a file would make negative pixels (and NaN spreads through the mip chain)."""
    finite = np.isfinite(a)
    if not finite.all() or np.any(a < 0):
        got = "NaN or inf" if not finite.all() else f"min {float(a.min()):.4g}"
        raise PrefilterError(f"{role.replace('_', ' ')}: expected finite values >= 0, got {got}")
    return a


@functools.lru_cache(maxsize=64)
def _load_mip(*key):
    from prefilter.texture import MipChain, moment_chain

    data = load_texture(*key)
    return moment_chain(data.slopes) if key[0] == "height_map" else MipChain(data)


def _texture(value, path: str, role: str, base: Path) -> TextureRef:
    from prefilter.texture import HEIGHT_KINDS, NORMAL_KINDS
    from prefilter.texture.io import IMAGE_SUFFIXES
    from prefilter.texture.procedural import PARAMS, check_params

    if isinstance(value, str):
        value = {"path": value}
    if isinstance(value, dict) and "procedural" in value:
        kinds = {"normal_map": NORMAL_KINDS, "height_map": HEIGHT_KINDS}.get(role, ("noise",))
        kind = _Obj(value, path, tuple(value)).choice("procedural", kinds)
        allowed = ("procedural", "size", "seed") + PARAMS[kind] + (
            ("scale",) if role == "height_map" else ())
        o = _Obj(value, path, allowed)
        size = o.integer("size", 512, lo=4, hi=8192)
        o.integer("seed", 0, lo=0, hi=2**63 - 1)
        try:  # the values too, before any render (the generators check them the same way)
            check_params(kind, size, **{k: v for k, v in value.items()
                                        if k not in ("procedural", "size", "seed", "scale")})
        except PrefilterError as exc:
            raise PrefilterError(f"{path}.{exc}") from None
        scale = (o.number("scale", 1.0, lo=0.0, limit=HEIGHT_SCALE_MAX) if role == "height_map"
                 else 1.0)
        spec = {k: v for k, v in value.items() if k != "scale"}
        return TextureRef(role, spec, path, None, scale=scale)
    o = _Obj(value, path, ("path", "convention", "srgb", "scale"))
    p = o.raw("path")
    if not isinstance(p, str) or not p:
        raise PrefilterError(f"{o.at('path')}: expected a file path string, got {_got(p)}")
    full = (base / p).resolve()
    if full.suffix.lower() not in IMAGE_SUFFIXES:
        raise PrefilterError(
            f"{o.at('path')}: expected a {'/'.join(IMAGE_SUFFIXES)} file, got {_got(p)}")
    if not full.is_file():
        raise PrefilterError(f"{o.at('path')}: file not found: {full}")
    conv = o.choice("convention", ("opengl", "directx"), "opengl")
    srgb = o.raw("srgb", role in ("color_map", "light_texture") and full.suffix.lower() == ".png")
    if not isinstance(srgb, bool):
        raise PrefilterError(f"{o.at('srgb')}: expected true or false, got {_got(srgb)}")
    scale = o.number("scale", 1.0, lo=0.0,
                     limit=HEIGHT_SCALE_MAX if role == "height_map" else LIGHT_MAX)
    return TextureRef(role, value, path, full, conv, srgb, scale)


# -- materials, objects, lights --------------------------------------------------------------------


@dataclass(frozen=True)
class Material:
    """GGX + Lambert material (see ``prefilter.render.shading``).

    ``alpha_x``/``alpha_y``: GGX roughness along the tangent (+u) and bitangent (+v);
    ``base_color``: diffuse albedo (linear rgb); ``f0``: Schlick reflectance at normal incidence;
    optional ``normal_map``, ``height_map``, ``color_map`` textures (``color_map`` multiplies
    ``base_color``).
    """

    alpha_x: float = 0.3
    alpha_y: float = 0.3
    base_color: np.ndarray = field(default_factory=lambda: np.zeros(3))
    f0: np.ndarray = field(default_factory=lambda: np.ones(3))
    normal_map: TextureRef | None = None
    height_map: TextureRef | None = None
    color_map: TextureRef | None = None


@dataclass(frozen=True)
class Plane:
    """A finite rectangle: ``center``, unit ``normal``, unit ``tangent`` (+u direction, made
    orthogonal to the normal), ``size`` (extent along tangent and bitangent = normal x tangent),
    ``uv_scale`` (texture repeats across the plane)."""

    center: np.ndarray
    normal: np.ndarray
    tangent: np.ndarray
    size: np.ndarray
    uv_scale: np.ndarray
    material: Material
    type: str = "plane"


@dataclass(frozen=True)
class Sphere:
    """A sphere: ``center``, ``radius``, ``pole`` (theta = 0 axis), ``axis_x`` (phi = 0 direction),
    ``uv_scale``; uv = (phi / 2pi, theta / pi) * uv_scale."""

    center: np.ndarray
    radius: float
    pole: np.ndarray
    axis_x: np.ndarray
    uv_scale: np.ndarray
    material: Material
    type: str = "sphere"


@dataclass(frozen=True)
class QuadLightSpec:
    """A one-sided quad light: corners ``(4, 3)`` (counter-clockwise seen from the lit side),
    ``radiance`` rgb, optional ``texture`` (multiplies the radiance)."""

    vertices: np.ndarray
    radiance: np.ndarray
    texture: TextureRef | None = None
    type: str = "quad"


@dataclass(frozen=True)
class PointLightSpec:
    position: np.ndarray
    intensity: np.ndarray
    type: str = "point"


@dataclass(frozen=True)
class DirectionalLightSpec:
    direction: np.ndarray
    irradiance: np.ndarray
    type: str = "directional"


@dataclass(frozen=True)
class EnvironmentLight:
    """An equirectangular environment map (``image``), radiance multiplied by ``scale``."""

    image: TextureRef
    scale: float = 1.0
    type: str = "environment"


#: Optional features under the scene field ``extras`` and the modules that validate their content.
EXTRAS = ("colormap",  # prefilter.colormap.render: the colour-map methods' driver
          "glints_wave")  # prefilter.glints.wave.render: the heightfield of the wave glints


@dataclass(frozen=True)
class Scene:
    """A loaded scene. ``extras``: optional feature data (keys of :data:`EXTRAS`, validated by
    the methods that read them); ``base_dir``: the directory relative paths are resolved in."""

    camera: Camera
    objects: tuple
    lights: tuple
    source: Any = None
    extras: dict = field(default_factory=dict)
    base_dir: str = "."

    def light_set(self):
        """The quad, point and directional lights as a :class:`prefilter.render.lights.LightSet`
        (textured quads and environment maps are not part of it)."""
        from prefilter.render.lights import DirectionalLight, LightSet, PointLight, QuadLight

        return LightSet(
            quads=tuple(QuadLight(q.vertices, q.radiance) for q in self.lights
                        if q.type == "quad"),
            points=tuple(PointLight(p.position, p.intensity) for p in self.lights
                         if p.type == "point"),
            directionals=tuple(DirectionalLight(d.direction, d.irradiance) for d in self.lights
                               if d.type == "directional"))

    def to_dict(self) -> dict:
        """The JSON-friendly dict this scene was loaded from (a copy)."""
        return json.loads(json.dumps(self.source))


# -- parsing ---------------------------------------------------------------------------------------


def _camera(v, path) -> Camera:
    o = _Obj(v, path, ("origin", "target", "up", "fov", "width", "height"))
    origin, target = o.point("origin"), o.point("target")
    up = o.unit("up", [0.0, 1.0, 0.0])
    if np.linalg.norm(target - origin) < 1e-9:
        raise PrefilterError(f"{o.at('target')}: expected a point different from the origin")
    f = (target - origin) / np.linalg.norm(target - origin)
    if np.linalg.norm(np.cross(f, up)) < 1e-6:
        raise PrefilterError(f"{o.at('up')}: expected a vector not parallel to the view direction")
    return Camera(origin, target, up, o.number("fov", lo=0.0, hi=179.0, lo_open=True),
                  o.integer("width", lo=1, hi=16384), o.integer("height", lo=1, hi=16384))


def _material(v, path, base) -> Material:
    o = _Obj(v, path, ("alpha_x", "alpha_y", "alpha", "base_color", "f0", "normal_map",
                       "height_map", "color_map"))
    if "alpha" in o.d and ("alpha_x" in o.d or "alpha_y" in o.d):
        raise PrefilterError(f"{o.at('alpha')}: expected either alpha or alpha_x/alpha_y, not both")
    a = o.number("alpha", 0.3, lo=0.001, hi=1.0)
    ax = o.number("alpha_x", a, lo=0.001, hi=1.0)
    ay = o.number("alpha_y", ax if "alpha_x" in o.d else a, lo=0.001, hi=1.0)
    tex = {k: _texture(o.d[k], o.at(k), k, base) if o.d.get(k) is not None else None
           for k in ("normal_map", "height_map", "color_map")}
    return Material(ax, ay, o.vector("base_color", 3, [0.0] * 3, lo=0.0, scalar_ok=True,
                                     limit=REFLECTANCE_MAX),
                    o.vector("f0", 3, [1.0] * 3, lo=0.0, scalar_ok=True, limit=REFLECTANCE_MAX),
                    **tex)


def _object(v, path, base):
    kind = _Obj(v, path, tuple(v) if isinstance(v, dict) else ()).choice(
        "type", ("plane", "sphere", "mesh"))
    if kind == "mesh":
        return _mesh_object(v, path, base)
    if kind == "plane":
        o = _Obj(v, path, ("type", "center", "normal", "tangent", "size", "uv_scale", "material"))
        n = o.unit("normal", [0.0, 1.0, 0.0])
        t = o.unit("tangent", [1.0, 0.0, 0.0])
        t = t - (t @ n) * n
        if np.linalg.norm(t) < 1e-6:
            raise PrefilterError(f"{o.at('tangent')}: expected a vector not parallel to the normal")
        size = o.vector("size", 2, [1.0, 1.0], scalar_ok=True, limit=EXTENT_MAX)
        if np.any(size <= 0):
            raise PrefilterError(
                f"{o.at('size')}: expected positive sizes, got {_got(size.tolist())}")
        return Plane(o.point("center", [0.0] * 3), n, t / np.linalg.norm(t), size,
                     o.vector("uv_scale", 2, [1.0, 1.0], scalar_ok=True, limit=UV_SCALE_MAX),
                     _material(o.raw("material", {}), o.at("material"), base))
    o = _Obj(v, path, ("type", "center", "radius", "pole", "axis_x", "uv_scale", "material"))
    pole = o.unit("pole", [0.0, 1.0, 0.0])
    ax = o.unit("axis_x", [1.0, 0.0, 0.0])
    ax = ax - (ax @ pole) * pole
    if np.linalg.norm(ax) < 1e-6:
        raise PrefilterError(f"{o.at('axis_x')}: expected a vector not parallel to the pole")
    return Sphere(o.point("center", [0.0] * 3),
                  o.number("radius", lo=0.0, lo_open=True, limit=EXTENT_MAX),
                  pole, ax / np.linalg.norm(ax),
                  o.vector("uv_scale", 2, [1.0, 1.0], scalar_ok=True, limit=UV_SCALE_MAX),
                  _material(o.raw("material", {}), o.at("material"), base))


def _transform(v, path) -> np.ndarray:
    """A mesh transform: a 4 x 4 row-major matrix (last row ``[0, 0, 0, 1]``) or
    ``{"translate": [x, y, z], "rotate": [rx, ry, rz] degrees, "scale": s or [sx, sy, sz]}``."""
    from prefilter.render.mesh import transform_matrix

    if isinstance(v, list):
        if len(v) != 4:
            raise PrefilterError(f"{path}: expected a 4 x 4 matrix (4 rows of 4 numbers) or an "
                                 f"object with translate, rotate, scale, got {_got(v)}")
        rows = _Obj({str(i): r for i, r in enumerate(v)}, path, tuple("0123"))
        m = np.stack([rows.vector(str(i), 4) for i in range(4)])
        if not np.allclose(m[3], [0.0, 0.0, 0.0, 1.0]):
            raise PrefilterError(f"{path}[3]: expected [0, 0, 0, 1] (an affine transform), got "
                                 f"{_got(m[3].tolist())}")
    else:
        o = _Obj(v, path, ("translate", "rotate", "scale"))
        scale = o.vector("scale", 3, [1.0, 1.0, 1.0], scalar_ok=True)
        m = transform_matrix(o.vector("translate", 3, [0.0] * 3),
                             o.vector("rotate", 3, [0.0] * 3), scale)
    if abs(np.linalg.det(m[:3, :3])) < 1e-12:
        raise PrefilterError(f"{path}: expected an invertible transform, got a singular one")
    return m


def _mesh_object(v, path, base):
    """``{"type": "mesh", "file", "transform", "material"}``: a triangle mesh read from an
    OBJ, PLY or glTF 2.0 file relative to the scene (:mod:`prefilter.render.mesh`)."""
    from prefilter.render.mesh import Mesh, load_mesh

    o = _Obj(v, path, ("type", "file", "transform", "material"))
    f = o.raw("file")
    if not isinstance(f, str) or not f:
        raise PrefilterError(f"{o.at('file')}: expected a file path string, got {_got(f)}")
    m = _transform(o.raw("transform", {}), o.at("transform"))
    mat = _material(o.raw("material", {}), o.at("material"), base)
    full = (base / f).resolve()
    return Mesh(full, m, mat, load_mesh(full, m, mat, where=o.at("file")))


def _light(v, path, base):
    kind = _Obj(v, path, tuple(v) if isinstance(v, dict) else ()).choice(
        "type", ("quad", "point", "directional", "environment"))
    if kind == "quad":
        o = _Obj(v, path, ("type", "vertices", "radiance", "texture"))
        verts = o.raw("vertices")
        if not isinstance(verts, list) or len(verts) != 4:
            raise PrefilterError(f"{o.at('vertices')}: expected a list of 4 corners [x, y, z], "
                                 f"got {_got(verts)}")
        vo = _Obj({str(i): c for i, c in enumerate(verts)}, o.at("vertices"), tuple("0123"))
        vs = np.stack([vo.point(str(i)) for i in range(4)])
        tex = o.raw("texture", None)
        spec = QuadLightSpec(vs, o.vector("radiance", 3, lo=0.0, scalar_ok=True, limit=LIGHT_MAX),
                             None if tex is None else
                             _texture(tex, o.at("texture"), "light_texture", base))
        try:  # planarity / convexity checks live with the shading light type
            from prefilter.render.lights import QuadLight

            QuadLight(spec.vertices, spec.radiance)
        except PrefilterError as exc:
            raise PrefilterError(f"{o.at('vertices')}: {exc}") from None
        return spec
    if kind == "point":
        o = _Obj(v, path, ("type", "position", "intensity"))
        return PointLightSpec(o.point("position"),
                              o.vector("intensity", 3, lo=0.0, scalar_ok=True, limit=LIGHT_MAX))
    if kind == "directional":
        o = _Obj(v, path, ("type", "direction", "irradiance"))
        return DirectionalLightSpec(o.unit("direction"),
                                    o.vector("irradiance", 3, lo=0.0, scalar_ok=True,
                                             limit=LIGHT_MAX))
    o = _Obj(v, path, ("type", "image", "scale"))
    return EnvironmentLight(_texture(o.raw("image"), o.at("image"), "environment", base),
                            o.number("scale", 1.0, lo=0.0, limit=LIGHT_MAX))


def _json_int(text: str) -> int:
    """A JSON integer of a scene file; every scene number is used as a float, so one beyond the
    float range is refused while parsing (Python would read it exactly, then fail to convert)."""
    digits = len(text.lstrip("-"))  # JSON has no leading zeros; 2**1024 has 309 digits
    if digits > 309 or abs(int(text)) >= 2**1024:
        raise OverflowError(f"expected numbers within the float range (|x| < 1.8e308), got an "
                            f"integer of {digits} digits")
    return int(text)


def _read_scene_file(p: Path):
    """The parsed JSON (or, for ``.toml``, TOML) document of a scene file."""
    if not p.is_file():
        raise PrefilterError(f"{p}: scene file not found")
    try:
        text = p.read_bytes().decode("utf-8")
    except UnicodeDecodeError as exc:
        raise PrefilterError(f"{p}: expected UTF-8 text, got an invalid byte at offset "
                             f"{exc.start}") from None
    except OSError as exc:
        raise PrefilterError(f"{p}: unreadable scene file ({exc})") from None
    if p.suffix.lower() == ".toml":
        try:
            import tomllib
        except ImportError:  # Python 3.10
            raise PrefilterError(f"{p}: TOML scenes need Python >= 3.11 (tomllib)") from None
        try:
            return tomllib.loads(text)
        except tomllib.TOMLDecodeError as exc:
            raise PrefilterError(f"{p}: invalid TOML: {exc}") from None
    try:
        return json.loads(text, parse_int=_json_int)
    except json.JSONDecodeError as exc:
        raise PrefilterError(f"{p}: invalid JSON at line {exc.lineno}, column {exc.colno}: "
                             f"{exc.msg}") from None
    except RecursionError:
        raise PrefilterError(f"{p}: invalid JSON: nested too deeply") from None
    except OverflowError as exc:  # from _json_int
        raise PrefilterError(f"{p}: invalid JSON number: {exc}") from None


def _parse(data, base: Path) -> Scene:
    o = _Obj(data, "", ("camera", "objects", "lights", "extras"))
    camera = _camera(o.raw("camera"), "camera")
    objects = tuple(_object(v, f"objects[{i}]", base)
                    for i, v in enumerate(_list(o.raw("objects"), "objects")))
    lights = tuple(_light(v, f"lights[{i}]", base)
                   for i, v in enumerate(_list(o.raw("lights", []), "lights")))
    extras = _Obj(o.raw("extras", {}), "extras", EXTRAS).d
    try:  # the content is the reading method's to check, but it must be JSON data
        extras = json.loads(json.dumps(extras, allow_nan=False))
    except (TypeError, ValueError):
        raise PrefilterError(f"extras: expected JSON data (no NaN or infinity), got "
                             f"{_got(extras)}") from None
    return Scene(camera, objects, lights, source=data, extras=extras, base_dir=str(base))


def load_scene(path_or_dict, *, base_dir: str | os.PathLike | None = None) -> Scene:
    """Load and validate a scene from a JSON (or ``.toml``) file path or a parsed dict.

    Texture paths are relative to the scene file's directory (``base_dir`` for dicts, default the
    current directory). Raises :class:`PrefilterError` naming the offending field (prefixed with
    the file for scene files).
    ``example:NAME`` names a shipped example scene (:mod:`prefilter.examples`).
    """
    if isinstance(path_or_dict, dict):
        return _parse(path_or_dict, Path(base_dir or "."))
    if not isinstance(path_or_dict, (str, os.PathLike)):
        raise PrefilterError(
            f"scene: expected a JSON file path or a dict, got {type(path_or_dict).__name__}")
    p = Path(resolve_example(path_or_dict))
    data = _read_scene_file(p)
    base = Path(base_dir) if base_dir is not None else p.parent
    try:
        return _parse(data, base)
    except PrefilterError as exc:
        raise PrefilterError(f"{p}: {exc}") from None
