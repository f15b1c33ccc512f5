"""Colour-map drivers: what drives a colour map (a texture, procedural noise or microsurface
heights; Heitz et al. 2013, sections 3-4) and its prefiltered table, built from the
``extras.colormap`` dict of a scene (the format is in :mod:`prefilter.colormap.render`) and
cached by its JSON. Shared by the unlit methods (:mod:`prefilter.colormap.render`), the lit one
(:mod:`prefilter.colormap.lit`) and the viewer's export.
"""

from __future__ import annotations

import functools
import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from prefilter.validation import as_float_array
from prefilter.colormap.kernels import PackedChain
from prefilter.colormap.table import EDGES, ColormapTable, prefilter_table
from prefilter.colormap.texture import NoiseStd
from prefilter.errors import PrefilterError

__all__ = ["DRIVERS", "ColormapDriver", "colormap_driver", "scene_colormap_spec"]

DRIVERS = ("texture", "noise", "height")
_KEYS = ("driver", "texture", "colors", "range", "sigma_max", "edge", "size", "light")


@dataclass(frozen=True)
class ColormapDriver:
    """A colour map and what drives it, ready for the kernels.

    ``mean_chain``: one-channel mean mip (naive method, noise); ``moments_chain``: ``E[f],
    E[f^2]`` mip (filtered texture and height); ``light``: world direction towards the light
    (height) or ``None``."""

    driver: str
    table: ColormapTable
    mean_chain: PackedChain
    moments_chain: PackedChain | None = None
    noise_std: NoiseStd | None = None
    slope_cov: np.ndarray | None = None
    light: np.ndarray | None = None


def _err(key, what, got):
    return PrefilterError(f"extras.colormap.{key}: expected {what}, got {got!r}")


def _driving_texture(spec, driver, base: Path):
    """``(values (H, W), slopes (H, W, 2) or None, noise params or None)``."""
    from prefilter.texture import height_map, noise, read_image
    from prefilter.texture.procedural import PARAMS

    if isinstance(spec, str):
        if driver == "noise":
            raise _err("texture", "a procedural noise spec for the noise driver (its std per "
                       "LOD comes from the generator)", spec)
        img = read_image((base / spec).resolve())[..., 0]
        if driver != "height":
            return img, None, None
        sx = (np.roll(img, -1, 1) - np.roll(img, 1, 1)) / 2.0  # periodic central differences
        sy = (np.roll(img, -1, 0) - np.roll(img, 1, 0)) / 2.0
        return img, np.stack([sx, sy], -1), None
    if not isinstance(spec, dict) or "procedural" not in spec:
        raise _err("texture", "a file path or a {\"procedural\": ...} spec", spec)
    p = dict(spec)
    kind = p.pop("procedural")
    kinds = ("gaussian", "anisotropic") if driver == "height" else ("noise",)
    if kind not in kinds:
        raise _err("texture.procedural", f"one of {', '.join(kinds)} for the {driver} driver",
                   kind)
    unknown = set(p) - {"size", "seed"} - set(PARAMS[kind])
    if unknown:
        raise _err("texture", f"parameters among size, seed, {', '.join(PARAMS[kind])}",
                   sorted(unknown))
    size, seed = p.pop("size", 256), p.pop("seed", 0)
    if driver == "height":
        hm = height_map(kind, size, seed, **p)
        return hm.height, hm.slopes, None
    return noise(size, seed, **p), None, (size, p.get("corr_length", 4.0), p.get("sigma", 1.0))


def _colors(spec, base: Path) -> np.ndarray:
    if isinstance(spec, str):
        from prefilter.colormap.commands import load_colormap_image

        return load_colormap_image((base / spec).resolve())
    c = as_float_array(spec, "extras.colormap.colors")
    if c.ndim != 2 or c.shape[0] < 2:
        raise _err("colors", "a list of at least 2 colours [r, g, b] or an image path",
                   np.shape(spec))
    if np.any(c < 0):
        raise _err("colors", "non-negative (linear) colours", float(c.min()))
    return c


@functools.lru_cache(maxsize=8)
def _build(key: str, base: str) -> ColormapDriver:
    from prefilter.colormap.texture import moments_mip
    from prefilter.texture.mip import MipChain

    spec, base_dir = json.loads(key), Path(base)
    if not isinstance(spec, dict):
        raise PrefilterError(f"extras.colormap: expected an object, got {spec!r}")
    unknown = [k for k in spec if k not in _KEYS]
    if unknown:
        raise _err(unknown[0], f"one of the fields {', '.join(_KEYS)}", "an unknown field")
    driver = spec.get("driver")
    if driver not in DRIVERS:
        raise _err("driver", f"one of {', '.join(DRIVERS)}", driver)
    if "texture" not in spec or "colors" not in spec:
        raise _err("texture" if "texture" not in spec else "colors", "a value", None)
    f, slopes, noise_params = _driving_texture(spec["texture"], driver, base_dir)
    cov = None
    if driver == "height":
        f = (f - f.mean()) / max(float(f.std()), 1e-12)
        cov = np.cov(slopes.reshape(-1, 2).T, bias=True)
    mean, std = float(f.mean()), float(f.std())
    value_range = spec.get("range", (mean - 4 * std, mean + 4 * std))
    if (not isinstance(value_range, (list, tuple)) or len(value_range) != 2
            or not all(isinstance(v, (int, float)) and not isinstance(v, bool)
                       for v in value_range)):
        raise _err("range", "two numbers [lo, hi]", value_range)
    lo, hi = value_range
    edge = spec.get("edge", "clamp")
    if edge not in EDGES:
        raise _err("edge", f"one of {', '.join(EDGES)}", edge)
    table = prefilter_table(_colors(spec["colors"], base_dir), (lo, hi),
                            spec.get("sigma_max", 1.5 * max(std, 1e-6)),
                            size=spec.get("size", 256), edge=edge)
    light = spec.get("light")
    if light is not None:
        light = as_float_array(light, "extras.colormap.light", last_dim=3)
        if light.shape != (3,) or not np.linalg.norm(light) > 0:
            raise _err("light", "a non-zero direction [x, y, z]", spec["light"])
        light = light / np.linalg.norm(light)
    return ColormapDriver(
        driver, table, PackedChain(MipChain(f)),
        moments_chain=None if driver == "noise" else PackedChain(moments_mip(f)),
        noise_std=NoiseStd.from_procedural(*noise_params) if driver == "noise" else None,
        slope_cov=cov, light=light)


def colormap_driver(spec: dict, *, base_dir=".") -> ColormapDriver:
    """Build (and cache) the driver described by ``spec`` (module docstring); file paths are
    relative to ``base_dir``."""
    try:
        key = json.dumps(spec, sort_keys=True)
    except (TypeError, ValueError):
        raise PrefilterError(f"extras.colormap: expected JSON data, got {spec!r}") from None
    return _build(key, str(Path(base_dir).resolve()))


def scene_colormap_spec(scene, driver):
    """``driver`` if given, else the scene's ``extras.colormap`` (a PrefilterError where neither
    is): the colour-map specification every colour-map method reads."""
    if driver is None:
        extras = getattr(scene, "extras", None) or {}
        driver = extras.get("colormap") if isinstance(extras, dict) else None
        if driver is None:
            raise PrefilterError("extras.colormap: the colour-map methods need a driver (scene "
                                 "field extras.colormap, or the driver argument)")
    return driver
