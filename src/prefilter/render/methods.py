"""The registry of shading methods: name -> ``callable(scene, settings) -> (H, W, 3) image``.

Every built-in method is listed once, here, as a ``"module:attribute"`` string with its
description and variant settings: :mod:`prefilter.render` reaches the method packages only
through these strings, imported on first use.

A method receives the loaded :class:`~prefilter.render.scene.Scene` and a
:class:`RenderSettings` and returns linear radiance ``(H, W, 3)`` float32. Built-in methods are
registered lazily as ``"module:attribute"`` strings (importing a method's module only when it is
used); later methods register the same way::

    from prefilter.render.methods import register
    register("ltc-multiscale", "prefilter.multiscale.render:render_multiscale")

or with a decorator on the function itself (``@register("name")``), which needs the defining
module to be imported before use.
"""

from __future__ import annotations

import importlib
from dataclasses import dataclass, field
from typing import Callable

from prefilter.errors import PrefilterError


@dataclass(frozen=True)
class RenderSettings:
    """What every method is given besides the scene.

    Attributes
    ----------
    spp : int
        Samples per pixel (sub-pixel positions; the reference also uses them for Monte Carlo).
    seed : int
        Seed of every random choice (same settings -> same bytes).
    jitter : (float, float)
        Camera offset in pixels (for temporal-stability measurements); ``(0, 0)`` samples pixel
        centres (or strata of the whole pixel when ``spp > 1``).
    progress : bool
        Show a progress bar (tqdm) when the render takes more than about a second.
    chunk_samples : int
        Upper bound on shading samples processed at once (memory).
    table : str, Path, object or None
        The LTC table to use: a table file (loaded by the LTC methods), a table object, or
        ``None`` (the shipped :class:`prefilter.ltc.table.GGXTable`).
    params : dict of str to str
        The method's variant settings (``--param key=value``), checked against the choices the
        method registered (:func:`register`); a method reads them with :meth:`param`.
    rows : (int, int) or None
        Render only the image rows ``[r0, r1)`` (a band of a tiled render,
        :mod:`prefilter.render.tiles`); ``None``: the whole image. Honoured by the methods that
        run on :func:`prefilter.render.driver.render_positions`.
    """

    spp: int = 1
    seed: int = 0
    jitter: tuple[float, float] = (0.0, 0.0)
    progress: bool = False
    chunk_samples: int = 1 << 18
    table: object | None = None
    params: dict = field(default_factory=dict)
    rows: tuple[int, int] | None = None

    def param(self, key: str, default: str) -> str:
        """The value of variant setting ``key`` (``default`` when not given)."""
        return self.params.get(key, default)


Method = Callable[..., object]

_REGISTRY: dict[str, Method | str] = {
    "ltc": "prefilter.ltc.render:render_ltc",
    "reference": "prefilter.render.reference:render_reference",
    "path": "prefilter.render.pathtrace:render_path",
    "ltc-multiscale": "prefilter.multiscale.render:render_multiscale",
    "ltc-multiscale-aniso": "prefilter.multiscale.aniso:render_multiscale_aniso",
    "leadr-point": "prefilter.leadr.render:render_leadr_point",
    "leadr-env": "prefilter.leadr.render:render_leadr_env",
    "leadr-env-naive": "prefilter.leadr.render:render_leadr_env_naive",
    "leadr-irradiance": "prefilter.leadr.render:render_leadr_irradiance",
    "leadr-irradiance-naive": "prefilter.leadr.render:render_leadr_irradiance_naive",
    "ltc-aniso": "prefilter.ltc.aniso.render:render_ltc_aniso",
    "colormap-filtered": "prefilter.colormap.render:render_colormap_filtered",
    "colormap-naive": "prefilter.colormap.render:render_colormap_naive",
    "colormap-lit": "prefilter.colormap.lit:render_colormap_lit",
    "glints": "prefilter.glints.indirect:render_glints",
    "glints-direct": "prefilter.glints.indirect:render_glints_direct",
    "glints-reference": "prefilter.glints.render:render_glints_reference",
    "glints-wang": "prefilter.glints.wang_render:render_glints_wang",
    "glints-wave": "prefilter.glints.wave.render:render_glints_wave",
    "glints-wave-direct": "prefilter.glints.wave.render:render_glints_wave_direct",
}
_DESCRIPTIONS: dict[str, str] = {
    "ltc": "area lights by the isotropic LTC table, normal and colour from the footprint's mip "
           "level (the naive method)",
    "reference": "ground truth: stratified supersampling, full-resolution textures, MIS Monte "
                 "Carlo of the true GGX BRDF; control=ltc (default) subtracts the LTC fit and "
                 "adds its exact integral (unbiased, less noise), control=none plain MIS",
    "path": "path tracer: next-event estimation with MIS for quad, point, directional and "
            "environment lights, shadow rays, Russian roulette; bounces=N vertices per path "
            "(1: direct light)",
    "ltc-multiscale": "multi-scale LTC (Tao et al. 2021): roughness from the length of the "
                      "footprint's averaged normal; footprint=fit: exact eq. 4 inverse, refitted "
                      "eq. 7, biased LOD and anisotropic taps; paper: the paper's eqs. 5 and 7 "
                      "on the isotropic mip level; mrl: exact eq. 4 inverse and the product of "
                      "mean resultant lengths",
    "ltc-multiscale-aniso": "multi-scale LTC, anisotropic: LEAN slope moments of the normal map "
                            "plus micro roughness, anisotropic LTC table in the covariance's "
                            "principal frame",
    "leadr-point": "LEADR mapping under point and directional lights (closed form, Smith G2; "
                   "box-filtered moments, G2/G1 diffuse)",
    "leadr-env": "LEADR under environment (+ point/directional) light: Algorithm 1 specular "
                 "grid with self-shadowing (G2/G1), exact irradiance-map diffuse with shadowing; "
                 "algorithm=simplified: the supplemental's simplified algorithms (masking only, "
                 "order-2 SH irradiance)",
    "leadr-env-naive": "naive counterpart of leadr-env: mip-averaged normal, micro roughness only",
    "leadr-irradiance": "LEADR diffuse layer: exact irradiance map (FFT) of environment and "
                        "directional lights, with self-shadowing; algorithm=simplified: order-2 "
                        "SH irradiance, masking only",
    "leadr-irradiance-naive": "naive counterpart of leadr-irradiance",
    "ltc-aniso": "area lights by the anisotropic LTC table (alpha_x, alpha_y in the tangent "
                 "frame), textures at the footprint's mip level",
    "colormap-filtered": "colour-map filtering (Heitz et al. 2013): the filtered colour term of a "
                         "texture / noise / height colour map (scene extras.colormap), unlit",
    "colormap-naive": "naive counterpart of colormap-filtered: C(mean), times V_bar for heights",
    "colormap-lit": "colour-map filtering (Heitz et al. 2013) shaded under every light: the "
                    "colour of visible and lit microfacets (texture / noise / height / slope "
                    "drivers and section 6 combinations); filter=naive: C(mean); "
                    "filter=reference: 32 x 32 supersampling of eq. 1",
    "glints": "glints: compressed footprint P-NDF (point query); quad lights by range queries "
              "where valid, else MIS; environment maps by SG prefiltering; bounces=N > 1: "
              "path-traced, the pyramid queried with each vertex's enlarged footprint; "
              "level0=4: level 0 at 4 texels (frame time constant over distance, ~1.5x the bake)",
    "glints-direct": "glints: direct P-NDF of every footprint (Yan et al. 2016); quad and "
                     "environment lights by Monte Carlo (MIS, SG sampling); bounces=N > 1: "
                     "path-traced, the direct P-NDF at every vertex",
    "glints-reference": "glints ground truth: footprint supersampling, point P-NDF of the map; "
                        "quad and environment lights by Monte Carlo",
    "glints-wang": "glints on the implicit Wang tiling of the normal map (the exemplar): per-tile "
                   "CP-compressed footprint pyramids, constant storage; point, directional, "
                   "quad (range queries) and environment (SG prefiltering) lights; "
                   "estimator=samples: light samples with the point NDF (no range query or "
                   "prefilter); estimator=direct: also the direct P-NDF of the tiling (the "
                   "reference)",
    "glints-wave": "glints under wave optics: compressed RGB pyramid of the diffraction NDF of "
                   "the heightfield in extras.glints_wave (Yan et al. 2018, 8 wavelengths); "
                   "point/directional lights",
    "glints-wave-direct": "glints under wave optics, direct: uncompressed coherence-area images "
                          "with the footprint's exact weights; point/directional lights",
}


#: Variant settings each method accepts: name -> {key: (allowed values, first = default)}.
_PARAMS: dict[str, dict[str, tuple[str, ...]]] = {
    "reference": {"control": ("ltc", "none")},
    "path": {"bounces": ("4", "1", "2", "3", "5", "6", "8", "12", "16")},
    "glints": {"bounces": ("1", "2", "3", "4", "5", "6", "8"), "level0": ("8", "4")},
    "glints-direct": {"bounces": ("1", "2", "3", "4", "5", "6", "8")},
    "glints-wang": {"estimator": ("prefiltered", "samples", "direct")},
    "ltc-multiscale": {"footprint": ("fit", "paper", "mrl")},
    "leadr-env": {"algorithm": ("full", "simplified")},
    "leadr-env-naive": {"algorithm": ("full", "simplified")},
    "leadr-irradiance": {"algorithm": ("full", "simplified")},
    "leadr-irradiance-naive": {"algorithm": ("full", "simplified")},
    "colormap-lit": {"filter": ("filtered", "naive", "reference")},
}


def register(name: str, target: Method | str | None = None, *, description: str = "",
             params: dict[str, tuple[str, ...]] | None = None):
    """Register a method under ``name``: a callable, a ``"module:attr"`` string, or (no target)
    a decorator. ``params`` lists the variant settings it accepts, each with its allowed values
    (the first is the default). Re-registering a name replaces it."""
    if not isinstance(name, str) or not name:
        raise PrefilterError(f"method name: expected a non-empty string, got {name!r}")

    def _add(fn):
        if not (callable(fn) or (isinstance(fn, str) and fn.count(":") == 1)):
            raise PrefilterError(
                f"method {name!r}: expected a callable or a 'module:attr' string, got {fn!r}")
        _REGISTRY[name] = fn
        if description:
            _DESCRIPTIONS[name] = description
        if params is not None:
            _PARAMS[name] = {k: tuple(v) for k, v in params.items()}
        return fn

    return _add if target is None else _add(target)


def available() -> list[str]:
    """Names of all registered methods, sorted."""
    return sorted(_REGISTRY)


def describe(name: str) -> str:
    return _DESCRIPTIONS.get(name, "")


def method_params(name: str) -> dict[str, tuple[str, ...]]:
    """The variant settings of method ``name``: ``{key: allowed values}``, the first the default."""
    get_method(name)
    return dict(_PARAMS.get(name, {}))


def check_params(name: str, params) -> dict[str, str]:
    """``params`` (a dict, or ``"key=value"`` strings) checked against method ``name``'s settings;
    returns a dict of strings."""
    if params is None:
        return {}
    if not isinstance(params, dict):
        pairs = {}
        for item in params:
            key, sep, value = str(item).partition("=")
            if not sep or not key:
                raise PrefilterError(f"param: expected key=value, got {item!r}")
            pairs[key] = value
        params = pairs
    allowed = method_params(name)
    out = {}
    for key, value in params.items():
        if key not in allowed:
            known = ", ".join(sorted(allowed)) or "none"
            raise PrefilterError(
                f"param {key!r}: method {name!r} takes {known}, got {key}={value!r}")
        if str(value) not in allowed[key]:
            raise PrefilterError(
                f"param {key}: expected one of {', '.join(allowed[key])}, got {value!r}")
        out[key] = str(value)
    return out


#: What gives the isotropic GGX LTC table the ``reference`` method takes as its control variate,
#: named like the methods (``"module:attribute"``, imported on first use by :func:`resolve`).
GGX_TABLE = "prefilter.ltc.table:shipped_table"


def resolve(target: str):
    """The object a ``"module:attribute"`` string names (imported now)."""
    module, attr = target.split(":")
    return getattr(importlib.import_module(module), attr)


def get_method(name: str) -> Method:
    """The callable registered as ``name`` (imported on first use)."""
    if name not in _REGISTRY:
        raise PrefilterError(
            f"method: expected one of {', '.join(available())}, got {name!r}")
    fn = _REGISTRY[name]
    if isinstance(fn, str):
        try:
            fn = resolve(fn)
        except (ImportError, AttributeError) as exc:
            raise PrefilterError(f"method {name!r} is unavailable: {exc}") from exc
        _REGISTRY[name] = fn
    return fn
