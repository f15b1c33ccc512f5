"""LEADR render methods: ``leadr-point`` (point and directional lights), ``leadr-env``
(environment + point/directional lights), ``leadr-irradiance`` (the diffuse layer), and the naive
counterparts ``leadr-env-naive`` / ``leadr-irradiance-naive``.

Per G-buffer sample: the slope moments of the material's height map over the pixel footprint
(:func:`footprint_moments`: a box filter of the renderer's moment mip chain) give the mean slope
and covariance (:func:`prefilter.leadr.maps.shading_stats`); the micro roughness adds the
Beckmann slope variance ``alpha^2 / 2`` per axis (GGX alpha taken as the Beckmann alpha).
Shading is in the *geometric* frame: the mesonormal is carried by the mean slope.

Self-shadowing (the displaced reference has it, docs/leadr.md): specular under
point/directional lights by the closed form of supplemental 3.3 with ``G2``; under the
environment by Algorithm 1 with ``G2 / G1`` per grid sample
(:func:`prefilter.leadr.shading.env_specular` with ``shadowing``); diffuse by Algorithm 3 with
``E(m) = <m, wl> G2 / G1`` per delta light and, for the environment, the exact irradiance
(:class:`prefilter.leadr.envmap.IrradianceMap`, looked up per grid normal) plus
:func:`prefilter.leadr.shading.diffuse_shadowing`. The ``algorithm=simplified`` setting
(:data:`ALGORITHMS`) selects the supplemental's Simplified Algorithms 1-3 instead (masking only,
order-2 SH irradiance). Schlick Fresnel per grid sample is linear in ``f0``, so rgb ``f0`` costs
two scalar passes (``f0 = 1`` and ``f0 = 0``) blended per channel. ``leadr-irradiance`` renders
the diffuse layer only (``base_color``). The environment orientation is
:data:`prefilter.leadr.envmap.ENV_FROM_WORLD` (``docs/leadr.md``).

The ``-naive`` methods are naive mip-mapped normal mapping under the same integrators (and the
same irradiance map): the mean slope of the footprint (the mip-averaged height-map normal) with
the micro roughness only, i.e. without the meso-scale slope covariance.
"""

from __future__ import annotations


import numpy as np

from prefilter.errors import PrefilterError
from prefilter.leadr.envmap import (ENV_FROM_WORLD, IrradianceMap, env_from_image,
                                    latlong_resample, sh9_project)
from prefilter.leadr.maps import shading_stats
from prefilter.leadr.shading import (diffuse_directional, diffuse_irradiance, diffuse_sh,
                                     diffuse_shadowing, env_specular, largest_slope_variance,
                                     point_light)
from prefilter.microfacet.fresnel import schlick
from prefilter.render.shading import point_incoming, shading_frames

DIFFUSE_GRID = 5
#: Specular grid of ``leadr-env``: 9 x 9 is within ~3% of the N = 128 grid for isotropic lobes
#: (docs/leadr.md convergence table), 5 x 5 within 7-14%.
ENV_GRID = 9
#: Footprints whose largest slope std (meso + micro) is at least :data:`ROUGH_SIGMA` use a
#: ``ENV_GRID_ROUGH`` grid: against the N = 128 grid 9 x 9 is 5.5% off at std 0.5 and 16% for an
#: anisotropic (0.5, 0.1) lobe, 17 x 17 1.3% / 3.7% (docs/leadr.md convergence table; the
#: supplemental: specular needs more samples above 0.25).
ENV_GRID_ROUGH = 17
ROUGH_SIGMA = 0.35
#: Moment lookups box-filter the pixel footprint: up to ``FOOTPRINT_TAPS^2`` trilinear taps
#: spread over the footprint parallelogram (one per ~2 x 2 texels), each at the LOD of its share.
#: Moments are linear, so this is a box filter over the pixel's own texels; a single trilinear
#: tap blends a square of the major axis' size aligned to the mip grid, whose statistics flicker
#: as the camera moves (docs/leadr.md, point-light image rows). 1: one isotropic trilinear tap.
FOOTPRINT_TAPS = 8
#: ``leadr-point``'s moment filter (the WebGL viewer's ``footprintBox()`` and the exported
#: ``leadr.glsl`` reproduce it).
POINT_FOOTPRINT_TAPS = FOOTPRINT_TAPS
#: ``leadr-point``'s diffuse is Algorithm 3 for one light with ``G2 / G1`` (self-shadowing).
POINT_SHADOWING = True


def footprint_moments(chain, uv, dudv, max_taps: int | None = None) -> np.ndarray:
    """Box-filtered moments ``(N, C)`` of a mip chain over pixel footprints ``uv (N, 2)``,
    ``dudv (N, 2, 2)``: ``T x T`` taps, ``T = clip(ceil(major / 2), 1, max_taps)`` with
    ``major`` the footprint's major axis in texels (:data:`FOOTPRINT_TAPS`), compiled
    (:func:`prefilter.leadr.kernels.box_moments_kernel`); objects other than a
    :class:`~prefilter.texture.MipChain` (precomputed moments) answer ``lookup_footprint``
    themselves."""
    from prefilter.leadr.kernels import box_moments_kernel
    from prefilter.texture.mip import footprint_axes

    max_taps = FOOTPRINT_TAPS if max_taps is None else int(max_taps)
    if max_taps <= 1 or not hasattr(chain, "packed"):
        return chain.lookup_footprint(uv, dudv)
    flat, offsets, heights, widths = chain.packed
    uv = np.ascontiguousarray(uv, dtype=np.float64)
    dudv = np.ascontiguousarray(dudv, dtype=np.float64)
    major = np.ascontiguousarray(footprint_axes(dudv, chain.shape[:2])[0], dtype=np.float64)
    out = np.empty((len(uv), flat.shape[1]))
    return box_moments_kernel(flat, offsets, heights, widths, uv, dudv, major, max_taps, out)


def _local(w, t, b, n):
    return np.stack([np.sum(w * t, -1), np.sum(w * b, -1), np.sum(w * n, -1)], -1)


def leadr_stats(scene, g, *, meso: bool = True, mips=None, taps: int | None = None):
    """Mean slope ``(N, 2)`` and covariance ``(N, 2, 2)`` per hit sample, plus materials.

    ``meso=False`` keeps the mean slope and drops the footprint's slope covariance (naive
    mip-mapped normal mapping: the micro roughness only). ``mips``: optional
    ``{object index: MipChain of the 5 moments}`` (or any object with the same
    ``lookup_footprint``) replacing the materials' height-map chains (the acceptance feeds the
    exact moments of the bilinear surface it ray traces). ``taps``: :func:`footprint_moments`'
    ``max_taps`` (``None``: :data:`FOOTPRINT_TAPS`)."""
    n = g.hit.size
    mean = np.zeros((n, 2))
    cov = np.zeros((n, 2, 2))
    base = np.zeros((n, 3))
    f0 = np.zeros((n, 3))
    for k in np.unique(g.object_id):
        m = g.object_id == k
        mat = scene.objects[int(k)].material
        if mips is not None and int(k) in mips:
            mom = footprint_moments(mips[int(k)], g.uv[m], g.dudv[m], taps)
        elif mat.height_map is not None:
            mom = footprint_moments(mat.height_map.mip(), g.uv[m], g.dudv[m], taps)
        else:
            mom = np.zeros((int(m.sum()), 5))
        mu, c = shading_stats(mom, 0.0)
        if not meso:
            c = np.zeros_like(c)
        c[:, 0, 0] += 0.5 * mat.alpha_x**2
        c[:, 1, 1] += 0.5 * mat.alpha_y**2
        mean[m], cov[m] = mu, c
        base[m] = mat.base_color
        f0[m] = mat.f0
    return mean, cov, base, f0


def shade_leadr_delta(scene, g, lights, *, meso: bool = True, shadowing: bool = True,
                      mips=None, taps: int | None = None) -> np.ndarray:
    """Radiance ``(N, 3)`` of the hit samples ``g`` under point and directional lights:
    closed-form specular (supplemental 3.3, with G2) + the diffuse grid (Algorithm 3 for one
    light; ``shadowing`` multiplies it by ``G2 / G1``, :func:`shading.shadowing_ratio`)."""
    t, b, n, wo = shading_frames(g)
    mean, cov, base, f0 = leadr_stats(scene, g, meso=meso, mips=mips, taps=taps)
    out = np.zeros((len(wo), 3))
    for w, e in point_incoming(lights, g.position):
        wi = _local(w, t, b, n)
        wi /= np.linalg.norm(wi, axis=-1, keepdims=True)
        h = wo + wi
        h /= np.maximum(np.linalg.norm(h, axis=-1, keepdims=True), 1e-12)
        spec = point_light(wo, wi, mean, cov)[:, None] * schlick(f0, np.sum(h * wi, -1)[:, None])
        diff = base * diffuse_directional(wo, wi, mean, cov, DIFFUSE_GRID,
                                          shadowing=shadowing)[:, None]
        out += (spec + diff) * e
    return out


def scene_environment(scene):
    """The sum of the scene's environment lights as a :class:`prefilter.leadr.envmap.EnvMap`
    (``None`` without any); several maps are resampled to the largest one's size."""
    imgs = []
    for light in scene.lights:
        if light.type == "environment":
            env = env_from_image(light.image.load(), light.scale)
            imgs.append(env.levels[0])
    if not imgs:
        return None
    rows = max(a.shape[0] for a in imgs)
    return env_from_image(sum(a if a.shape[0] == rows else latlong_resample(a, rows)
                              for a in imgs))


def _env_rotation(t, b, n) -> np.ndarray:
    """Local shading frame -> environment-map coordinates, ``(N, 3, 3)``."""
    return np.einsum("ij,njk->nik", ENV_FROM_WORLD, np.stack([t, b, n], -1))


def shade_leadr_env(scene, g, env, sh, lights, *, meso: bool = True, n_grid: int = ENV_GRID,
                    diffuse_grid: int = DIFFUSE_GRID, shadowing: bool = True,
                    mips=None, irradiance=None) -> np.ndarray:
    """Radiance ``(N, 3)`` of hits ``g``: environment specular (Algorithm 1 with self-shadowing,
    compiled; ``shadowing=False``: Simplified Algorithm 1; ``n_grid`` x ``n_grid`` or
    :data:`ENV_GRID_ROUGH` for rough footprints, :func:`env_specular_adaptive`) + diffuse
    (Algorithm 3's grid on the irradiance map ``irradiance``, or on the SH irradiance ``sh`` if
    it is ``None``, plus
    :func:`~prefilter.leadr.shading.diffuse_shadowing` if ``shadowing``) + point/directional
    lights (:func:`shade_leadr_delta`)."""
    t, b, n, wo = shading_frames(g)
    mean, cov, base, f0 = leadr_stats(scene, g, meso=meso, mips=mips)
    rot = _env_rotation(t, b, n)
    out = np.zeros((len(wo), 3))
    if env is not None:
        spec = lambda f: env_specular_adaptive(env, wo, mean, cov, f0=f,  # noqa: E731
                                               to_world=rot, shadowing=shadowing,
                                               n_grid=n_grid)
        if np.all(f0 == f0[:, :1]):
            out += spec(f0[:, 0])
        elif np.any(f0 != 0.0):
            # Schlick is linear in f0: F = f0 * 1 + (1 - f0) * (1 - c)^5.
            out += f0 * spec(1.0)
            if np.any(f0 != 1.0):
                out += (1.0 - f0) * spec(0.0)
        if np.any(base != 0.0):
            diff = _diffuse_env(sh, irradiance, wo, mean, cov, diffuse_grid, rot)
            if shadowing:
                diff = np.maximum(diff + diffuse_shadowing(env, wo, mean, cov, diffuse_grid,
                                                           to_world=rot), 0.0)
            out += base * diff
    if lights.points or lights.directionals:
        out += shade_leadr_delta(scene, g, lights, meso=meso, shadowing=shadowing, mips=mips)
    return out


def shade_leadr_irradiance(scene, g, sh, lights, *, meso: bool = True,
                           diffuse_grid: int = DIFFUSE_GRID, shadowing: bool = True,
                           env=None, mips=None, taps: int | None = None,
                           irradiance=None) -> np.ndarray:
    """Diffuse radiance ``(N, 3)`` of hits ``g``: the environment's irradiance map
    ``irradiance`` (or, if ``None``, its SH irradiance ``sh (9, 3)``; map coordinates) by
    Algorithm 3's grid (plus the environment ``env``'s
    :func:`~prefilter.leadr.shading.diffuse_shadowing` if ``shadowing``); point and directional
    lights one by one (Algorithm 3 for one light, times ``G2 / G1`` if ``shadowing``)."""
    t, b, n, wo = shading_frames(g)
    mean, cov, base, _ = leadr_stats(scene, g, meso=meso, mips=mips, taps=taps)
    rot = _env_rotation(t, b, n)
    out = _diffuse_env(sh, irradiance, wo, mean, cov, diffuse_grid, rot)
    if shadowing and env is not None:
        out = np.maximum(out + diffuse_shadowing(env, wo, mean, cov, diffuse_grid, to_world=rot),
                         0.0)
    for w, e in point_incoming(lights, g.position):
        wl = _local(w, t, b, n)
        wl /= np.linalg.norm(wl, axis=-1, keepdims=True)
        out += diffuse_directional(wo, wl, mean, cov, diffuse_grid,
                                   shadowing=shadowing)[:, None] * e
    return base * out


def specular_grid_size(cov, n_grid: int = ENV_GRID, n_rough: int = ENV_GRID_ROUGH) -> np.ndarray:
    """Grid size per footprint ``(...)`` of slope covariances ``cov (..., 2, 2)``: ``n_rough``
    where the largest slope std is at least :data:`ROUGH_SIGMA`, else ``n_grid``."""
    return np.where(largest_slope_variance(cov) >= ROUGH_SIGMA ** 2, n_rough, n_grid)


def env_specular_adaptive(env, wo, mean, cov, *, f0=None, to_world=None, shadowing: bool = True,
                          n_grid: int = ENV_GRID, n_rough: int = ENV_GRID_ROUGH) -> np.ndarray:
    """:func:`~prefilter.leadr.shading.env_specular` of points ``wo (P, 3)``, ``mean (P, 2)``,
    ``cov (P, 2, 2)`` (``f0`` scalar or ``(P,)``, ``to_world (P, 3, 3)`` or ``None``) with the
    grid size of :func:`specular_grid_size` per point; ``(P, C)``."""
    wo = np.asarray(wo, np.float64).reshape(-1, 3)
    p = len(wo)
    mean = np.broadcast_to(np.asarray(mean, np.float64).reshape(-1, 2), (p, 2))
    cov = np.broadcast_to(np.asarray(cov, np.float64).reshape(-1, 2, 2), (p, 2, 2))
    sizes = specular_grid_size(cov, n_grid, n_rough)
    f = None if f0 is None else np.broadcast_to(np.asarray(f0, np.float64), (p,))
    out = None
    for n in np.unique(sizes):
        sel = sizes == n
        part = env_specular(env, wo[sel], mean[sel], cov[sel], int(n),
                            f0=None if f is None else f[sel],
                            to_world=None if to_world is None else to_world[sel],
                            shadowing=shadowing)
        if out is None:
            out = np.empty((p, part.shape[1]))
        out[sel] = part
    if out is None:  # no points
        out = env_specular(env, wo, mean, cov, n_grid, shadowing=shadowing)
    return out


def _diffuse_env(sh, irradiance, wo, mean, cov, n, rot):
    if irradiance is None:
        return diffuse_sh(sh, wo, mean, cov, n, to_world=rot)
    return diffuse_irradiance(irradiance, wo, mean, cov, n, to_world=rot)


def _environment_inputs(scene, method, irradiance_map: bool):
    """Point/directional lights (quads rejected), the summed environment (or ``None``), its SH
    coefficients and, if ``irradiance_map``, its :class:`IrradianceMap`."""
    if any(light.type == "quad" for light in scene.lights):
        raise PrefilterError(f"method {method!r}: quad lights are not supported; expected "
                             "environment, point and directional lights")
    env = scene_environment(scene)
    sh = sh9_project(env) if env is not None else np.zeros((9, 3))
    irr = IrradianceMap(env) if env is not None and irradiance_map else None
    return scene.light_set(), env, sh, irr


def _render_env(scene, settings, meso: bool, name: str, shadowing: bool = True,
                irradiance_map: bool = True) -> np.ndarray:
    from prefilter.render.driver import render_samples

    lights, env, sh, irr = _environment_inputs(scene, name, irradiance_map)
    return render_samples(scene, settings,
                          lambda g, _u: shade_leadr_env(scene, g, env, sh, lights, meso=meso,
                                                        shadowing=shadowing, irradiance=irr),
                          stratified=settings.spp > 1, desc=name)


def _render_irradiance(scene, settings, meso: bool, name: str,
                       shadowing: bool = True, irradiance_map: bool = True) -> np.ndarray:
    from prefilter.render.driver import render_samples

    lights, env, sh, irr = _environment_inputs(scene, name, irradiance_map)
    return render_samples(scene, settings,
                          lambda g, _u: shade_leadr_irradiance(scene, g, sh, lights, meso=meso,
                                                               env=env, shadowing=shadowing,
                                                               irradiance=irr),
                          stratified=settings.spp > 1, desc=name)


#: The ``algorithm`` setting of the environment methods: ``full``, the paper's Algorithms 1-3
#: (self-shadowing ``G2 / G1`` in every layer, exact irradiance map); ``simplified``, the
#: supplemental's Simplified Algorithms 1-3 (masking only, order-2 SH irradiance).
ALGORITHMS = {"full": {"shadowing": True, "irradiance_map": True},
              "simplified": {"shadowing": False, "irradiance_map": False}}


def _algorithm(settings) -> dict:
    return ALGORITHMS[settings.param("algorithm", "full")]


def render_leadr_env(scene, settings) -> np.ndarray:
    """The ``leadr-env`` method (environment, point and directional lights): Algorithms 1-3 of
    the paper, or with ``algorithm=simplified`` the supplemental's simplified ones
    (:data:`ALGORITHMS`)."""
    return _render_env(scene, settings, True, "leadr-env", **_algorithm(settings))


def render_leadr_env_naive(scene, settings) -> np.ndarray:
    """``leadr-env-naive``: as ``leadr-env`` with the mip-averaged normal and micro roughness."""
    return _render_env(scene, settings, False, "leadr-env-naive", **_algorithm(settings))


def render_leadr_irradiance(scene, settings) -> np.ndarray:
    """The ``leadr-irradiance`` method (diffuse layer; environment by its irradiance map,
    point, directional lights; with self-shadowing; ``algorithm=simplified``: SH irradiance, no
    self-shadowing)."""
    return _render_irradiance(scene, settings, True, "leadr-irradiance", **_algorithm(settings))


def render_leadr_irradiance_naive(scene, settings) -> np.ndarray:
    """``leadr-irradiance-naive``: ``leadr-irradiance`` with the mip-averaged normal only."""
    return _render_irradiance(scene, settings, False, "leadr-irradiance-naive",
                              **_algorithm(settings))


def render_leadr_point(scene, settings) -> np.ndarray:
    """The ``leadr-point`` method (point and directional lights only): closed-form specular with
    ``G2`` (supplemental 3.3), Algorithm 3 diffuse with ``G2 / G1`` per light, moments
    box-filtered over the pixel footprint (:data:`POINT_FOOTPRINT_TAPS`); the WebGL viewer
    renders the same (``leadr.glsl``)."""
    from prefilter.render.driver import render_samples

    if any(light.type in ("quad", "environment") for light in scene.lights):
        raise PrefilterError("method 'leadr-point': expected only point and directional lights")
    lights = scene.light_set()
    return render_samples(scene, settings,
                          lambda g, _u: shade_leadr_delta(scene, g, lights,
                                                          shadowing=POINT_SHADOWING,
                                                          taps=POINT_FOOTPRINT_TAPS),
                          stratified=settings.spp > 1, desc="leadr-point")
