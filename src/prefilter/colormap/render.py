"""Colour-map filtering as render methods: ``colormap-filtered`` and ``colormap-naive``.

A scene carries its colour-map driver under ``extras.colormap`` (a scene field the scene format
adds for optional features; see ``docs/colormap.md``), or the functions take it as an argument.
The image is the colour term of Heitz et al. 2013 at each sample (unlit, like the acceptance
images): ``C0_bar`` (eq. 7) for a tabulated texture or procedural noise, ``Ch_bar`` (eq. 14, with
the Smith visibility towards a directional light) for microsurface heights, ``V_bar Cs_bar(wo)``
(eq. 19, the slope driver of :mod:`prefilter.colormap.lit` with eq. 13's ``V_bar`` towards the
same light) for slopes; the naive method shades ``C(mean)`` (times eq. 13's ``V_bar`` for heights
and slopes). Texture, noise and height use the compiled kernels of
:mod:`prefilter.colormap.kernels`, slopes :func:`prefilter.colormap.slope.filter_slope` on the
footprint's slope moments (:func:`prefilter.colormap.texture.footprint_stats`); every object of
the scene, at ``settings.spp`` sub-pixel samples per pixel (pixel centres for 1), with the
pixel's footprint.

The driver (a dict, as in a scene file)::

    {"driver": "texture" | "noise" | "height",
     "texture": {"procedural": "noise", "size": 256, "seed": 0, "corr_length": 3.0}
                | {"procedural": "gaussian", "size": 256, "rms_slope": 0.5, ...} (height)
                | "file.exr" (texture, height: first channel),
     "colors": [[r, g, b], ...] | "map.png",     # the colour map, left to right
     "range": [lo, hi],         # default: the driving values' mean -+ 4 std
     "sigma_max": 1.5,          # default: 1.5 std of the driving values
     "edge": "clamp",           # clamp | mirror | periodic
     "size": 256,               # table columns and rows
     "light": [x, y, z]}        # height: direction towards the light; default: the scene's first
                                # directional light, else the surface normal (V_bar = 1)

Heights are normalised to zero mean and unit std before the colour map reads them (``range`` is
in units of the height std); their slopes give the Smith ``Lambda`` (eq. 3). The slope driver
(``"driver": "slope"``) has the fields of :mod:`prefilter.colormap.lit` and takes its light as the
height driver without its own: the scene's first directional light, else the surface normal.
"""

from __future__ import annotations

import numpy as np

from prefilter.colormap.driver import ColormapDriver, colormap_driver, scene_colormap_spec
from prefilter.colormap.kernels import shade_height, shade_noise, shade_texture

__all__ = ["render_colormap_filtered", "render_colormap_naive"]


def _scene_driver(scene, driver) -> ColormapDriver:
    if isinstance(driver, ColormapDriver):
        return driver
    return colormap_driver(scene_colormap_spec(scene, driver),
                           base_dir=getattr(scene, "base_dir", "."))


def _light(scene, d: ColormapDriver):
    if d.light is not None:
        return d.light
    for light in scene.lights:
        if light.type == "directional":
            return -np.asarray(light.direction, dtype=np.float64)  # stored: direction of travel
    return None


def _slope_shader(scene, spec, filtered: bool):
    """The slope driver's per-sample colour ``V_bar Cs_bar(wo)`` (filtered) or ``V_bar C(mean)``
    (naive), ``(N, 3)`` (Heitz et al. 2013, eqs. 13, 19, 20)."""
    from prefilter.colormap.height import mean_visibility, smith_lambda_direction
    from prefilter.colormap.lit import _frame, _local, _upper, lit_colormap
    from prefilter.colormap.slope import filter_slope
    from prefilter.colormap.texture import footprint_stats

    lit = spec if not isinstance(spec, dict) else lit_colormap(
        spec, base_dir=getattr(scene, "base_dir", "."))
    light = next((-np.asarray(x.direction, np.float64) for x in scene.lights
                  if x.type == "directional"), None)
    surf = lit.surface

    def shade(g, _u):
        t, b, n = _frame(g)
        wo = _upper(_local(g.view, t, b, n))
        mean, cov = footprint_stats(surf.slope_moments, g.uv, g.dudv, anisotropic=True)
        cs = filter_slope(lit.slope, wo, mean, cov) if filtered else lit.slope.naive(mean)
        wi = (np.broadcast_to([0.0, 0.0, 1.0], wo.shape) if light is None
              else _upper(_local(np.broadcast_to(light, g.view.shape), t, b, n)))
        vbar = mean_visibility(smith_lambda_direction(wo, surf.slope_cov),
                               smith_lambda_direction(wi, surf.slope_cov))
        return cs * vbar[:, None]

    return shade


def _shade(scene, settings, driver, filtered: bool) -> np.ndarray:
    from prefilter.render.driver import render_samples

    desc = "colormap-filtered" if filtered else "colormap-naive"
    if not isinstance(driver, ColormapDriver):
        spec = scene_colormap_spec(scene, driver)
        if getattr(spec, "mode", None) == "slope" or (
                isinstance(spec, dict) and spec.get("driver") == "slope"):
            return render_samples(scene, settings, _slope_shader(scene, spec, filtered),
                                  stratified=False, desc=desc)
    d = _scene_driver(scene, driver)
    light = _light(scene, d)

    def shade(g, _u):
        if d.driver == "texture":
            chain = d.moments_chain if filtered else d.mean_chain
            return shade_texture(d.table, chain, g.uv, g.dudv, filtered=filtered)
        if d.driver == "noise":
            return shade_noise(d.table, d.mean_chain, d.noise_std, g.uv, g.dudv,
                               filtered=filtered)
        # two-sided surfaces: seen from behind, the frame flips (n, b -> -n, -b)
        s = np.where(np.sum(g.view * g.normal, -1) < 0, -1.0, 1.0)[..., None]
        t, b, n = g.tangent, g.bitangent * s, g.normal * s

        def local(w):
            w = np.stack([np.sum(w * t, -1), np.sum(w * b, -1), np.sum(w * n, -1)], -1)
            # grazing and back-facing directions: just above the horizon (V_bar -> 0, Lambda
            # finite), as the acceptance scenes do
            w[..., 2] = np.maximum(w[..., 2], 1e-3)
            return w / np.linalg.norm(w, axis=-1, keepdims=True)

        wo = local(g.view)
        if light is None:  # no light given: lit everywhere (Lambda_i = 0, V_bar = 1)
            wi = np.broadcast_to([0.0, 0.0, 1.0], wo.shape)
        else:
            wi = local(np.broadcast_to(light, g.view.shape))
        chain = d.moments_chain if filtered else d.mean_chain
        return shade_height(d.table, chain, g.uv, g.dudv, wo, wi, d.slope_cov,
                            filtered=filtered)

    return render_samples(scene, settings, shade, stratified=False, desc=desc)


def render_colormap_filtered(scene, settings, driver=None) -> np.ndarray:
    """Filtered colour-mapped texture / noise / heights / slopes (Heitz et al. 2013, eqs. 7, 10,
    14, 19), ``(H, W, 3)``. ``driver``: a :class:`ColormapDriver`, a slope
    :class:`~prefilter.colormap.lit.LitColormap` or their dict; default the scene's
    ``extras.colormap``."""
    return _shade(scene, settings, driver, True)


def render_colormap_naive(scene, settings, driver=None) -> np.ndarray:
    """The naive counterpart: ``C(mean)`` (times eq. 13's ``V_bar`` for heights and slopes),
    ``(H, W, 3)``."""
    return _shade(scene, settings, driver, False)
