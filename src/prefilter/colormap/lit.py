"""Lit colour-map rendering: the ``colormap-lit`` render method (Heitz et al. 2013, eqs. 1, 6,
11, 19 and section 6).

The colour map is the diffuse albedo of a Gaussian microsurface shaded by the macro-surface
Lambert term under every light of the scene. With ``E_l`` the irradiance of light ``l`` at normal
incidence from direction ``wi_l`` (tangent frame) the pixel radiance is

    I = sum_l E_l max(0, wi_l,z) / pi * C_bar(wo, wi_l),

where ``C_bar`` is the colour of the *visible and lit* microfacets over the pixel footprint:

* texture / noise (eq. 6): ``C0_bar`` (eq. 7), the same for every light (a flat surface);
* height (eq. 14): ``Ch_bar = V_bar <Ch, D_h(wo, wi)>``, view- and light-dependent;
* slope (eq. 19): ``V_bar Cs_bar(wo)`` with eq. 20's view-dependent ``D_s`` and eq. 13's
  ``V_bar`` of the same surface;
* combinations (section 6): linear ``k0 C0_bar V_bar + k1 Ch_bar + k2 Cs_bar V_bar`` or product
  ``C0_bar Ch_bar Cs_bar`` (:mod:`prefilter.colormap.combine`).

``filter=naive`` replaces each filtered colour by the colour of the footprint's mean (``C(mean)``;
the shading terms ``V_bar`` stay). ``filter=reference`` is the ground truth of the same shading:
``k x k`` jittered samples per pixel (``k = 32``, or ``sqrt(spp)`` when ``spp > 1``) of eq. 1 with
the level-0 (bilinear) driving functions, the Smith visibility ``P_h(h)^Lambda`` (eq. 2) towards
view and light and the projected area ``max(0, wo_z - s . wo_xy)`` towards the view (eq. 19):
``I = sum_l E_l cos_l / pi sum_k C_k a_k b_kl / sum_k a_k``, ``a_k = P_h(h_k)^Lambda_o proj_k``,
``b_kl = P_h(h_k)^Lambda_i,l``.

Lights (the same for all three filters): point and directional lights as they are; a quad light
as ``QUAD_PATCHES^2`` small patches, each a point source ``L A_p max(0, cos_l) / d^2``; an
environment map as the ``ENV_ROWS x 2 ENV_ROWS`` texels of its solid-angle-weighted mip level,
each a directional light of irradiance ``L Omega``.

The driver (scene field ``extras.colormap``): the single drivers of
:mod:`prefilter.colormap.render` (``texture``, ``noise``, ``height``) plus ``slope``::

    {"driver": "slope", "texture": {"procedural": "gaussian", ...} | "heights.exr",
     "colors": [[[r, g, b], ...], ...] | "map.png",   # square: row = s_y, column = s_x
     "extent": 1.5,      # slopes [-extent, extent]^2; default 3 slope stds
     "sigma_max": 1.0,   # default 2 slope stds
     "size": 32}         # levels of the pre-blurred stack

and combinations, whose height and slope terms share one surface (same ``texture``)::

    {"driver": "combine", "mode": "linear" | "product", "kappa": [k0, k1, k2],  # linear only
     "c0": {texture or noise driver}, "height": {height driver}, "slope": {slope driver}}

Missing terms are left out (linear) or 1 (product).
"""

from __future__ import annotations

import functools
import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from scipy.special import log_ndtr

from prefilter.colormap.height import mean_visibility, smith_lambda_direction
from prefilter.colormap.kernels import shade_height, shade_noise, shade_texture
from prefilter.colormap.driver import (ColormapDriver, _driving_texture, colormap_driver,
                                       scene_colormap_spec)
from prefilter.colormap.slope import SlopeColormapTable, filter_slope, slope_prefilter_table
from prefilter.colormap.texture import footprint_stats
from prefilter.errors import PrefilterError
from prefilter.texture.mip import MipChain, moment_chain
from prefilter.validation import as_float_array

__all__ = ["ENV_ROWS", "FILTERS", "QUAD_PATCHES", "REFERENCE_GRID", "LitColormap", "Sources",
           "lit_colormap", "render_colormap_lit", "scene_sources", "shade_lit"]

#: Values of the method's ``filter`` setting (the first is the default).
FILTERS = ("filtered", "naive", "reference")
#: Jittered samples per pixel side of ``filter=reference`` (the paper's 32 x 32).
REFERENCE_GRID = 32
#: A quad light is shaded as ``QUAD_PATCHES x QUAD_PATCHES`` point-like patches.
QUAD_PATCHES = 4
#: An environment map is shaded as the ``ENV_ROWS x 2 ENV_ROWS`` texels of one mip level.
ENV_ROWS = 8
#: Views and lights closer to the horizon are clamped to this cosine for ``Lambda`` (eq. 3).
Z_MIN = 1e-3

_SLOPE_KEYS = ("driver", "texture", "colors", "extent", "sigma_max", "size")
_COMBINE_KEYS = ("driver", "mode", "kappa", "c0", "height", "slope")


@dataclass(frozen=True)
class Surface:
    """The Gaussian microsurface of the height / slope terms: normalised heights ``(H, W)``,
    slopes ``(H, W, 2)``, their level-0 chains, the slope moments chain and covariance."""

    height: MipChain
    slopes: MipChain
    slope_moments: MipChain
    slope_cov: np.ndarray


@dataclass(frozen=True)
class LitColormap:
    """A lit colour map: ``mode`` (a driver name, ``linear`` or ``product``), its terms
    (``None`` where absent), the weights ``kappa`` and the surface of the height / slope terms.
    ``c0_level0``: the unfiltered driving texture of ``c0`` (reference)."""

    mode: str
    c0: ColormapDriver | None = None
    height: ColormapDriver | None = None
    slope: SlopeColormapTable | None = None
    kappa: tuple = (1.0, 1.0, 1.0)
    surface: Surface | None = None
    c0_level0: MipChain | None = None


def _err(key, what, got):
    return PrefilterError(f"extras.colormap.{key}: expected {what}, got {got!r}")


def _surface(spec, base: Path) -> Surface:
    h, s, _ = _driving_texture(spec, "height", base)
    h = (h - h.mean()) / max(float(h.std()), 1e-12)
    cov = np.cov(s.reshape(-1, 2).T, bias=True)
    return Surface(MipChain(h), MipChain(s), moment_chain(s), cov)


def _slope_table(spec: dict, surface: Surface, base: Path, key: str) -> SlopeColormapTable:
    unknown = [k for k in spec if k not in _SLOPE_KEYS]
    if unknown:
        raise _err(f"{key}{unknown[0]}", f"one of the fields {', '.join(_SLOPE_KEYS)}",
                   "an unknown field")
    std = float(np.sqrt(max(np.trace(surface.slope_cov) / 2.0, 1e-12)))
    c = spec["colors"]
    if isinstance(c, str):
        from prefilter.texture import read_image

        c = read_image((base / c).resolve())[..., :3]
    c = as_float_array(c, f"extras.colormap.{key}colors")
    if c.ndim != 3 or c.shape[0] != c.shape[1] or c.shape[0] < 2 or np.any(c < 0):
        raise _err(f"{key}colors", "a square (n, n, 3) grid of non-negative colours (row = s_y, "
                   "column = s_x) or a square image", np.shape(c))
    extent = spec.get("extent", 3.0 * std)
    sigma_max = spec.get("sigma_max", 2.0 * std)
    for name, v in (("extent", extent), ("sigma_max", sigma_max)):
        if isinstance(v, bool) or not isinstance(v, (int, float)) or not 0 < v < 1e6:
            raise _err(f"{key}{name}", "a positive number", v)
    size = spec.get("size", 32)
    if isinstance(size, bool) or not isinstance(size, int) or not 2 <= size <= 256:
        raise _err(f"{key}size", "an integer in [2, 256]", size)
    return slope_prefilter_table(c, float(extent), float(sigma_max), size)


def _term(spec, key: str, drivers: tuple):
    if not isinstance(spec, dict) or spec.get("driver") not in drivers:
        raise _err(f"{key}driver", f"one of {', '.join(drivers)}",
                   spec.get("driver") if isinstance(spec, dict) else spec)
    if "texture" not in spec or "colors" not in spec:
        raise _err(f"{key}{'texture' if 'texture' not in spec else 'colors'}", "a value", None)
    return spec


@functools.lru_cache(maxsize=8)
def _build(key: str, base: str) -> LitColormap:
    spec, base_dir = json.loads(key), Path(base)
    if not isinstance(spec, dict):
        raise PrefilterError(f"extras.colormap: expected an object, got {spec!r}")
    driver = spec.get("driver")
    if driver in ("texture", "noise", "height"):
        d = colormap_driver(spec, base_dir=base_dir)
        if driver == "height":
            return LitColormap("height", height=d, surface=_surface(spec["texture"], base_dir))
        return LitColormap(driver, c0=d, c0_level0=_level0(spec, base_dir))
    if driver == "slope":
        _term(spec, "", ("slope",))
        surface = _surface(spec["texture"], base_dir)
        return LitColormap("slope", slope=_slope_table(spec, surface, base_dir, ""),
                           surface=surface)
    if driver != "combine":
        raise _err("driver", "one of texture, noise, height, slope, combine", driver)
    unknown = [k for k in spec if k not in _COMBINE_KEYS]
    if unknown:
        raise _err(unknown[0], f"one of the fields {', '.join(_COMBINE_KEYS)}",
                   "an unknown field")
    mode = spec.get("mode")
    if mode not in ("linear", "product"):
        raise _err("mode", "linear or product", mode)
    kappa = spec.get("kappa", [1.0, 1.0, 1.0])
    k = as_float_array(kappa, "extras.colormap.kappa")
    if k.shape != (3,):
        raise _err("kappa", "three weights [k0, k1, k2]", kappa)
    terms = {t: spec[t] for t in ("c0", "height", "slope") if t in spec}
    if not terms:
        raise _err("c0", "at least one term among c0, height, slope", None)
    c0 = h = s = surface = lvl0 = None
    if "c0" in terms:
        c0 = colormap_driver(_term(terms["c0"], "c0.", ("texture", "noise")),
                             base_dir=base_dir)
        lvl0 = _level0(terms["c0"], base_dir)
    if "height" in terms and "slope" in terms and (
            terms["height"].get("texture") != terms["slope"].get("texture")):
        raise _err("slope.texture", "the height term's surface (height and slope terms "
                   "colour one microsurface)", terms["slope"].get("texture"))
    if "height" in terms:
        h = colormap_driver(_term(terms["height"], "height.", ("height",)),
                            base_dir=base_dir)
        surface = _surface(terms["height"]["texture"], base_dir)
    if "slope" in terms:
        _term(terms["slope"], "slope.", ("slope",))
        surface = surface or _surface(terms["slope"]["texture"], base_dir)
        s = _slope_table(terms["slope"], surface, base_dir, "slope.")
    return LitColormap(mode, c0=c0, height=h, slope=s, kappa=tuple(float(x) for x in k),
                       surface=surface, c0_level0=lvl0)


def _level0(spec: dict, base: Path) -> MipChain:
    f, _, _ = _driving_texture(spec["texture"], spec["driver"], base)
    return MipChain(f)


def lit_colormap(spec: dict, *, base_dir=".") -> LitColormap:
    """Build (and cache) the lit colour map described by ``spec`` (module docstring); file
    paths are relative to ``base_dir``."""
    try:
        key = json.dumps(spec, sort_keys=True)
    except (TypeError, ValueError):
        raise PrefilterError(f"extras.colormap: expected JSON data, got {spec!r}") from None
    return _build(key, str(Path(base_dir).resolve()))


# -- lights ------------------------------------------------------------------------------------


@dataclass(frozen=True)
class Sources:
    """Every light as points ``(P, 3)`` with intensities ``(P, 3)`` and emission normals
    ``(P, 3)`` (zero: isotropic), and directions *towards* distant lights ``(D, 3)`` with their
    irradiance ``(D, 3)``."""

    positions: np.ndarray
    intensities: np.ndarray
    normals: np.ndarray
    directions: np.ndarray
    irradiances: np.ndarray


def _quad_patches(vertices, radiance, n: int):
    """Centres, ``L A_p`` and the normal of ``n x n`` bilinear patches of a planar quad."""
    v = np.asarray(vertices, dtype=np.float64)
    t = (np.arange(n) + 0.5) / n
    u, w = np.meshgrid(t, t, indexing="ij")
    u, w = u.reshape(-1, 1), w.reshape(-1, 1)
    p = (1 - u) * (1 - w) * v[0] + u * (1 - w) * v[1] + u * w * v[2] + (1 - u) * w * v[3]
    du = (1 - w) * (v[1] - v[0]) + w * (v[2] - v[3])
    dv = (1 - u) * (v[3] - v[0]) + u * (v[2] - v[1])
    a = np.cross(du, dv) / (n * n)  # area vector of each patch (exact for parallelograms)
    area = np.linalg.norm(a, axis=-1, keepdims=True)
    return p, area * np.asarray(radiance, dtype=np.float64), a / area


def scene_sources(scene, method: str = "colormap-lit") -> Sources:
    """The scene's lights as :class:`Sources` (module docstring); textured quads are refused."""
    from prefilter.leadr.envmap import ENV_FROM_WORLD, env_from_image, texel_directions

    pos, inten, nrm, dirs, irr = [], [], [], [], []
    for i, light in enumerate(scene.lights):
        if light.type == "point":
            pos.append(light.position[None])
            inten.append(np.asarray(light.intensity, np.float64)[None])
            nrm.append(np.zeros((1, 3)))
        elif light.type == "directional":
            d = -np.asarray(light.direction, np.float64)  # stored: the direction of travel
            dirs.append(d[None] / np.linalg.norm(d))
            irr.append(np.asarray(light.irradiance, np.float64)[None])
        elif light.type == "quad":
            if getattr(light, "texture", None) is not None:
                raise PrefilterError(f"lights[{i}]: textured quad lights are not supported by "
                                     f"method {method!r}; expected an untextured quad")
            p, li, n = _quad_patches(light.vertices, light.radiance, QUAD_PATCHES)
            pos.append(p)
            inten.append(li)
            nrm.append(n)
        elif light.type == "environment":
            env = env_from_image(light.image.load(), light.scale)
            level = next((k for k, a in enumerate(env.levels) if a.shape[0] <= ENV_ROWS), 0)
            rad = env.levels[level]
            w, omega = texel_directions(*rad.shape[:2])
            dirs.append(w.reshape(-1, 3) @ ENV_FROM_WORLD)  # map -> world: d = E^T w
            irr.append((rad * omega[..., None]).reshape(-1, 3))
    cat = (lambda a: np.concatenate(a) if a else np.zeros((0, 3)))  # noqa: E731
    return Sources(cat(pos), cat(inten), cat(nrm), cat(dirs), cat(irr))


def incoming(sources: Sources, position):
    """``(w, E)`` per light: unit world directions towards it ``(N, 3)`` and the irradiance at
    normal incidence ``(N, 3)`` at points ``position (N, 3)``."""
    out = []
    for p, i, n in zip(sources.positions, sources.intensities, sources.normals):
        d = p - position
        d2 = np.maximum(np.sum(d * d, -1), 1e-300)
        w = d / np.sqrt(d2)[:, None]
        cos_l = np.maximum(-(w @ n), 0.0) if np.any(n) else np.ones(len(w))
        out.append((w, i * (cos_l / d2)[:, None]))
    for w, e in zip(sources.directions, sources.irradiances):
        out.append((np.broadcast_to(w, position.shape), np.broadcast_to(e, position.shape)))
    return out


# -- shading ------------------------------------------------------------------------------------


def _frame(g):
    from prefilter.render.driver import two_sided_frame

    t, b, n = two_sided_frame(g)
    return t, b, n


def _local(w, t, b, n):
    return np.stack([np.sum(w * t, -1), np.sum(w * b, -1), np.sum(w * n, -1)], -1)


def _upper(w):
    w = w.copy()
    w[..., 2] = np.maximum(w[..., 2], Z_MIN)
    return w / np.linalg.norm(w, axis=-1, keepdims=True)


def _combine(lit: LitColormap, c0, ch, cs, vbar):
    """Section 6: the filtered colour of one light from its terms (``None``: absent)."""
    if lit.mode in ("texture", "noise"):
        return c0
    if lit.mode == "height":
        return ch
    if lit.mode == "slope":
        return cs * vbar[:, None]
    if lit.mode == "linear":
        k0, k1, k2 = lit.kappa
        out = 0.0
        if c0 is not None:
            out = out + k0 * c0 * vbar[:, None]
        if ch is not None:
            out = out + k1 * ch
        if cs is not None:
            out = out + k2 * cs * vbar[:, None]
        return out
    out = 1.0
    for c in (c0, ch, cs):
        if c is not None:
            out = out * c
    if ch is None:  # the product's only visibility is the one inside Ch_bar (eq. 14)
        out = out * vbar[:, None]
    return out


def _c0(d: ColormapDriver, uv, dudv, filtered: bool):
    if d.driver == "noise":
        return shade_noise(d.table, d.mean_chain, d.noise_std, uv, dudv, filtered=filtered)
    chain = d.moments_chain if filtered else d.mean_chain
    return shade_texture(d.table, chain, uv, dudv, filtered=filtered)


def shade_lit(lit: LitColormap, g, sources: Sources, *, filtered: bool = True) -> np.ndarray:
    """Radiance ``(N, 3)`` of hit samples ``g`` (a flat G-buffer selection): the filtered
    (or naive) colour of the visible and lit microfacets times the Lambert term of every light
    (module docstring)."""
    t, b, n = _frame(g)
    wo = _upper(_local(g.view, t, b, n))
    c0 = None if lit.c0 is None else _c0(lit.c0, g.uv, g.dudv, filtered)
    cs = None
    if lit.slope is not None:
        mean, cov = footprint_stats(lit.surface.slope_moments, g.uv, g.dudv, anisotropic=True)
        cs = filter_slope(lit.slope, wo, mean, cov) if filtered else lit.slope.naive(mean)
    lam_o = None if lit.surface is None else smith_lambda_direction(wo, lit.surface.slope_cov)
    out = np.zeros((len(wo), 3))
    for w, e in incoming(sources, g.position):
        wi = _local(w, t, b, n)
        cos = np.maximum(wi[:, 2], 0.0)
        if not np.any(cos > 0):
            continue
        wi = _upper(wi)
        vbar = np.ones(len(wo))
        if lit.surface is not None:
            vbar = mean_visibility(lam_o, smith_lambda_direction(wi, lit.surface.slope_cov))
        ch = None
        if lit.height is not None:
            d = lit.height
            ch = shade_height(d.table, d.moments_chain if filtered else d.mean_chain, g.uv,
                              g.dudv, wo, wi, d.slope_cov, filtered=filtered)
        out += e * (cos / np.pi)[:, None] * _combine(lit, c0, ch, cs, vbar)
    return out


def reference_sums(lit: LitColormap, g, sources: Sources):
    """Per-sample terms of eq. 1 for ``filter=reference``: numerator ``(N, 3)`` and weight
    ``(N,)`` (module docstring), from the level-0 (bilinear) driving functions."""
    t, b, n = _frame(g)
    wo = _upper(_local(g.view, t, b, n))
    c0 = ch_col = cs = None
    if lit.c0 is not None:
        c0 = lit.c0.table.naive(lit.c0_level0.lookup(g.uv, 0.0)[:, 0])
    a = np.ones(len(wo))
    log_p = None
    if lit.surface is not None:
        log_p = log_ndtr(lit.surface.height.lookup(g.uv, 0.0)[:, 0])  # log P_h(h), eq. 2
        lam_o = smith_lambda_direction(wo, lit.surface.slope_cov)
        a = np.exp(lam_o * log_p)
        s = lit.surface.slopes.lookup(g.uv, 0.0)
        a = a * np.maximum(0.0, wo[:, 2] - np.sum(s * wo[:, :2], -1))  # projected area
        if lit.slope is not None:
            cs = lit.slope.naive(s)
    if lit.height is not None:
        ch_col = lit.height.table.naive(lit.surface.height.lookup(g.uv, 0.0)[:, 0])
    if lit.mode == "linear":
        k0, k1, k2 = lit.kappa
        col = sum(k * c for k, c in ((k0, c0), (k1, ch_col), (k2, cs)) if c is not None)
    else:
        col = 1.0
        for c in (c0, ch_col, cs):
            if c is not None:
                col = col * c
    num = np.zeros((len(wo), 3))
    for w, e in incoming(sources, g.position):
        wi = _local(w, t, b, n)
        cos = np.maximum(wi[:, 2], 0.0)
        if not np.any(cos > 0):
            continue
        bl = np.ones(len(wo))
        if log_p is not None:
            bl = np.exp(smith_lambda_direction(_upper(wi), lit.surface.slope_cov) * log_p)
        num += e * (cos / np.pi * bl)[:, None]
    return num * (col * a[:, None]), a


def _render_reference(scene, settings, lit: LitColormap, sources: Sources) -> np.ndarray:
    from dataclasses import replace

    from prefilter.render.camera import gbuffer_at
    from prefilter.render.driver import render_positions

    k = REFERENCE_GRID if settings.spp <= 1 else max(1, int(round(np.sqrt(settings.spp))))
    s = k * k
    st = replace(settings, spp=s)

    def sums(xy, _u):
        gs = gbuffer_at(scene, xy)
        num = np.zeros((gs.hit.size, 3))
        den = np.zeros(gs.hit.size)
        if np.any(gs.hit):
            num[gs.hit], den[gs.hit] = reference_sums(lit, gs.select(gs.hit), sources)
        num, den = num.reshape(-1, s, 3), den.reshape(-1, s)
        # eq. 1 per pixel (ratio of sums), times the pixel's covered fraction
        cover = gs.hit.reshape(-1, s).mean(-1)
        pix = num.sum(1) / np.maximum(den.sum(1), 1e-300)[:, None] * cover[:, None]
        return np.repeat(pix, s, axis=0)

    return render_positions(scene, st, sums, stratified=True, desc="colormap-lit reference")


def _scene_lit(scene, driver) -> LitColormap:
    if isinstance(driver, LitColormap):
        return driver
    return lit_colormap(scene_colormap_spec(scene, driver),
                        base_dir=getattr(scene, "base_dir", "."))


def render_colormap_lit(scene, settings, driver=None) -> np.ndarray:
    """The ``colormap-lit`` method: the colour map as the diffuse albedo of a microsurface under
    the scene's point, directional, quad and environment lights, ``(H, W, 3)``; the setting
    ``filter`` (:data:`FILTERS`) chooses the filtered colour (Heitz et al. 2013, eqs. 6, 11, 19,
    section 6), the naive ``C(mean)`` or the supersampled reference of eq. 1. ``driver``: a
    :class:`LitColormap` or its dict; default the scene's ``extras.colormap``."""
    from prefilter.render.driver import render_samples

    mode = settings.param("filter", FILTERS[0])
    if mode not in FILTERS:
        raise PrefilterError(f"param filter: expected one of {', '.join(FILTERS)}, got {mode!r}")
    lit = _scene_lit(scene, driver)
    sources = scene_sources(scene)
    if mode == "reference":
        return _render_reference(scene, settings, lit, sources)
    return render_samples(scene, settings,
                          lambda g, _u: shade_lit(lit, g, sources, filtered=mode == "filtered"),
                          stratified=False, desc=f"colormap-lit {mode}")
