"""Render methods for glinty materials: ``glints``, ``glints-direct``, ``glints-reference``.

A material's ``normal_map`` is the microstructure; its NDF over each pixel footprint replaces the
GGX lobe (``alpha_x``/``alpha_y`` are ignored; the intrinsic roughness is the bake's). Shading is
in the *geometric* frame (``x`` = tangent = ``+u``, ``y`` = ``+v``): the normal map enters only
through the NDF. Diffuse: Lambert with ``base_color``.

Lights: point and directional (the BRDF at the light direction); untextured quads (``glints``:
range queries over the light's half-vector footprint where it is small and well filled,
:func:`quad_range`; elsewhere, and always for ``glints-direct`` / ``glints-reference``, multiple
importance sampling of light and NDF samples, :func:`quad_mis`; diffuse by Lambert's polygon
formula); environment maps (fitted by spherical Gaussians, :func:`environment_sgs`, sampled lobe
by lobe; ``glints`` blurs the NDF over each lobe's compact epsilon-support by a range query,
sec. 5.4). Equirectangular convention: that of ``docs/scenes.md``
(:func:`prefilter.glints.envlight.equirect_directions`). Textured quads are rejected.

Footprints: the pixel is a Gaussian of std ``PIXEL_SIGMA`` pixels; through the texel-space
Jacobian ``J = diag(W, H) dudv`` it becomes an ellipse, approximated by the isotropic Gaussian of
the same area, ``sigma_p = PIXEL_SIGMA sqrt(|det J|)`` texels, centred at ``(u W, v H)``; with
``spp > 1`` stratified sub-pixel samples each gets ``sigma_p / sqrt(spp)`` (the paper's "pixel
footprint divided by the sample count").

* ``glints``: the compressed NDF (:func:`prefilter.glints.brdf.glint_ndf`: point query, trilinear
  over the pyramid, direct P-NDF below the finest level). The normal map is baked on first use
  with :data:`prefilter.glints.bake.BAKE_SETTINGS` (what ``prefilter bake glints`` makes) and
  cached on disk (``$PREFILTER_GLINTS_CACHE`` or ``~/.cache/prefilter/glints``) under the SHA-1
  of the normals, the settings, the CP fit's version (:data:`prefilter.glints.cp.FIT_VERSION`)
  and the bake's budget rule
  (:data:`prefilter.glints.bake.EXACT_BUDGET_RULE`, settings with exact levels).
* ``glints-direct``: the direct P-NDF of Yan et al. 2016 for every footprint (cost ~ its area).
* ``glints-reference``: supersampling of the footprint with the full-resolution normal map and the
  intrinsic roughness: ``spp`` sub-pixel positions drawn from the same pixel Gaussian, each shaded
  with the P-NDF of a point (``sigma_p = 0``: Yan's partition of unity of per-texel linearised
  normals, each blurred by the intrinsic roughness). Its mean converges to the Gaussian-footprint
  integral with the view and light directions of each sub-pixel position; ``glints-direct``
  evaluates that integral in closed form up to the isotropic approximation of the footprint, the
  linearisation of ``uv`` across the pixel and the half vector taken at the pixel centre (it moves
  by about the intrinsic roughness per half pixel).
"""

from __future__ import annotations

import json
import os
from pathlib import Path

import numpy as np
from tqdm import tqdm

from prefilter.errors import PrefilterError
from prefilter.validation import as_directions, as_float_array
from prefilter.glints.bake import (BAKE_SETTINGS, bake_if_missing, bake_settings, cache_dir,
                                  cache_path)
from prefilter.glints.brdf import (FALLBACK_TRUNCATION, brdf_cos_from_ndf, direct_ndf_k,
                                   glint_brdf_cos, half)
from prefilter.glints.envlight import equirect_directions, fit_sg, shade_sg
from prefilter.glints.pndf import TRUNCATION, as_normal_map, map_digest, pndf
from prefilter.glints.query import point, point_flat, range_multi, weights
from prefilter.glints.sample import (direct_mis_fits, direct_mis_k, half_from_s, n_uniforms,
                                     sample_s_direct_k, sample_s_k)
from prefilter.glints.store import load
from prefilter.glints.surface import GlintSurface, surface
from prefilter.render.shading import point_incoming, shading_frames
from prefilter.sphere.sampling import to_local, to_world

PIXEL_SIGMA = 0.5
#: How ``glints`` evaluates compressed footprints (:func:`prefilter.glints.surface.surface`):
#: Gaussian resampling of a finer pyramid level with bilinear NDF lookup. The paper's trilinear
#: blend with the pixel's value (``"trilinear"``, ``False``) moves sparse glints between pyramid
#: samples: FLIP vs glints-direct 0.065 / 0.212 / 0.090 instead of 0.039 / 0.103 / 0.059 on the
#: measurement scene (near / mid / far).
INTERP = "resample"
BILINEAR = True
_SURFACES: dict = {}
_BY_ID: dict = {}


def baked_surface(normal_map, *, direct: bool = False, settings: dict | None = None,
                  progress: bool = False) -> GlintSurface:
    """The :class:`GlintSurface` of a normal map: baked once (disk cache,
    :func:`prefilter.glints.bake.cache_path`, where ``prefilter bake glints`` writes by default),
    then kept in memory. ``settings`` override :data:`prefilter.glints.bake.BAKE_SETTINGS`.

    ``direct=True`` returns a surface without the compressed map (``glints-direct``).
    ``progress``: a bake reports what it bakes, where and how far it is on stderr
    (:func:`prefilter.glints.bake.bake`); a map found in the cache is loaded silently.
    """
    # the renderer passes the same (cached) texture array every frame: skip validating and
    # hashing it again (~20 ms per frame for a 128^2 map)
    model = dict(BAKE_SETTINGS, **(settings or {}))
    ident = (id(normal_map), direct, json.dumps(model, sort_keys=True), str(cache_dir()), INTERP,
             BILINEAR)
    hit = _BY_ID.get(ident)
    if hit is not None and hit[0] is normal_map:
        return hit[1]
    nm = as_normal_map(normal_map)
    sr = model["intrinsic_roughness"]  # the model's: direct P-NDF, fallback and reference
    digest = map_digest(nm)
    if direct:
        # the direct surface is the normal map and the model's roughness (no bake): key it by both
        mem = (digest, f"direct-{sr!r}", INTERP, BILINEAR)
        if mem not in _SURFACES:
            _SURFACES[mem] = surface(None, nm, intrinsic_roughness=sr)
    else:
        st = bake_settings(nm.shape, settings, bilinear=BILINEAR)
        path = cache_path(nm, st)
        mem = (digest, str(path), INTERP, BILINEAR)  # another cache folder bakes (or loads) anew
        if mem not in _SURFACES:
            # several renderers (pytest workers, CLI runs) may share the cache: the first bakes
            # under the lock, the others wait for it and load its file
            path.parent.mkdir(parents=True, exist_ok=True)
            bake_if_missing(nm, path, progress=progress, **st)
            _SURFACES[mem] = surface(load(path), nm, check=False, interp=INTERP,
                                     bilinear=BILINEAR, intrinsic_roughness=sr)
    if isinstance(normal_map, np.ndarray):
        _BY_ID[ident] = (normal_map, _SURFACES[mem])
    return _SURFACES[mem]


def footprints(g, shape, spp: int = 1):
    """Footprint centres ``(N, 2)`` and stds ``(N,)`` in texels of flat G-buffer samples ``g``
    on a ``shape = (H, W)`` map (see the module docstring)."""
    H, W = shape
    center = g.uv * np.array([W, H], dtype=np.float64)
    J = g.dudv * np.array([W, H], dtype=np.float64)[:, None]
    det = np.abs(J[:, 0, 0] * J[:, 1, 1] - J[:, 0, 1] * J[:, 1, 0])
    return center, PIXEL_SIGMA * np.sqrt(det / spp)


def pixel_footprints(scene, shape):
    """Footprints (:func:`footprints`: centres ``(n, 2)``, stds ``(n,)`` in texels of a ``shape``
    map) of the ``n`` pixel centres of ``scene``'s camera that hit an object, and the ``(H, W)``
    hit mask; ``scene``: a loaded :class:`prefilter.render.scene.Scene`."""
    from prefilter.render.camera import gbuffer_at

    cam = scene.camera
    xy = np.stack(np.meshgrid(np.arange(cam.width) + 0.5, np.arange(cam.height) + 0.5), -1)
    g = gbuffer_at(scene, xy).reshape(-1)
    c, sp = footprints(g.select(g.hit), shape)
    return c, sp, g.hit.reshape(cam.height, cam.width)


#: Quad lights: each MIS estimate takes ``QUAD_MIS`` light samples and as many BRDF samples per
#: shading sample; uniforms per pair: 2 (light) + up to 9 (hierarchical NDF sampler, blocks up
#: to 64; 7 for the default 16).
QUAD_MIS = 4
U_PAIR = 11
#: Range-query path of quad lights: the light is split into ``QUAD_SUB^2`` patches (then
#: ``(2 QUAD_SUB)^2`` where those are too large); each patch's
#: half-vector region must have a bounding box narrower than ``RANGE_MAX`` in ``s`` (the BRDF's
#: smooth factors are taken at the patch centre) and fill at least ``FILL_MIN`` of it (the range
#: mean is over a rectangle of the patch's area, :data:`QUAD_RECT`; the guard is against
#: degenerate patches: 0.3 keeps the plane's mid pixels with patches filled 0.3-0.5 on the range
#: path, at FLIP 0.028 vs the reference on the range pixels).
QUAD_SUB = 2
RANGE_MAX = 0.08
#: Pyramid weights of the quad lights' range queries: Gaussian resampling, the point queries'
#: footprint (:data:`INTERP`). The trilinear blend (8 images of the wrong sizes and places) is
#: a systematic error of the range path: plane flakes mid, range pixels vs the deterministic
#: reference FLIP 0.143 trilinear, 0.042 resampled (both with bounding boxes). The weights are
#: computed once per pixel and shared by its patches.
QUAD_INTERP = "resample"
#: The rectangle of each patch's range query: ``"equal-area"`` (:func:`_equal_area_rects`) or
#: ``"box"`` (the bounding box of its half-vector polygon, the mean scaled by the polygon's area).
QUAD_RECT = "equal-area"
FILL_MIN = 0.3
_HORIZON = 1e-3


def _brdf_terms(wo, wi, f0):
    """``F G / (4 wo_z)`` (..., C) and the half vector: everything of ``f cos`` but ``D``."""
    h = half(wo, wi)
    return brdf_cos_from_ndf(wo, wi, h, 1.0, f0), h


def _equal_area_rects(x, y, area, lo, hi):
    """Rectangles ``(lo, hi)`` (..., 2) of area ``area`` (...) centred on the centroids of the
    polygons ``x, y`` (..., V), with their bounding boxes' ``lo, hi`` aspect ratio.

    The range mean is over an axis-aligned rectangle: the bounding box spreads a skewed patch's
    weight over up to twice its area (fill >= ``FILL_MIN``), the equal-area rectangle keeps it
    where the patch is (plane flakes mid, range pixels vs the reference: FLIP 0.042 -> 0.027)."""
    xs, ys = np.roll(x, -1, -1), np.roll(y, -1, -1)
    cr = x * ys - xs * y
    a2 = np.sum(cr, -1)
    a2 = np.where(np.abs(a2) > 1e-300, a2, 1e-300)
    ctr = (np.stack([np.sum((x + xs) * cr, -1), np.sum((y + ys) * cr, -1)], -1)
           / (3.0 * a2[..., None]))
    ext = hi - lo
    f = np.sqrt(area / np.maximum(np.prod(ext, -1), 1e-300))[..., None]
    return ctr - 0.5 * f * ext, ctr + 0.5 * f * ext


def quad_range(surf: GlintSurface, center, sigma_p, wo, corners, radiance, f0, *,
               n_sub: int | None = None):
    """Specular radiance of a quad light by range queries over its half-vector footprint.

    ``int_quad f cos L dwi = int_S D(s) F G L (wi.h) / (wo_z h_z) ds`` (``dwi = 4 (wi.h) dw_h``,
    ``dw_h = ds / h_z``) over the light's half-vector region ``S``: per patch of an
    ``n_sub x n_sub`` split of the quad (default :data:`QUAD_SUB`), the smooth factor at the patch
    centre times the patch's ``s``-polygon area times the range mean of the footprint NDF (pyramid
    weights :data:`QUAD_INTERP`) over a rectangle of the same area at the polygon's centroid
    (:data:`QUAD_RECT`; glints paper, sec. 3 and eq. 7: the angularly prefiltered NDF).

    Parameters
    ----------
    surf : GlintSurface with a compressed map; center (N, 2), sigma_p (N,): footprints.
    wo : (N, 3) local view directions; corners : (N, 4, 3) quad corners relative to the shading
        point in the local frame (counter-clockwise seen from the lit side).
    radiance : (3,); f0 : (3,) or scalar.

    Returns
    -------
    value (N, 3) and valid (N,): where the approximation holds (front face, light above the
    horizon, every patch's box narrower than ``RANGE_MAX`` and filled >= ``FILL_MIN``, footprint
    at or above the finest level); ``value`` is 0 elsewhere (use :func:`quad_mis` there).
    """
    N = corners.shape[0]
    n_sub = QUAD_SUB if n_sub is None else int(n_sub)
    f0 = np.atleast_1d(np.asarray(f0, dtype=np.float64))
    sp = np.broadcast_to(np.asarray(sigma_p, dtype=np.float64), (N,))
    cand = sp >= surf.sigma_min if surf.gm is not None else np.zeros(N, bool)
    if not np.all(cand):
        # footprints below the finest level are never valid: the patch geometry only for the
        # others (near the camera 9 in 10 pixels, all to quad_mis)
        out = np.zeros((N, len(np.broadcast_to(f0, (3,)))))
        valid = np.zeros(N, bool)
        if np.any(cand):
            out[cand], valid[cand] = quad_range(surf, np.asarray(center)[cand], sp[cand],
                                                wo[cand], corners[cand], radiance, f0,
                                                n_sub=n_sub)
        return out, valid
    ok, lo_v, hi_v, fac = quad_patches(wo, corners, f0, n_sub)
    valid = ok & (np.asarray(sigma_p) >= surf.sigma_min) & (surf.gm is not None)
    out = np.zeros((N, len(np.broadcast_to(f0, (3,)))))
    if not np.any(valid):
        return out, valid
    sel = valid[ok]
    # one footprint per pixel: its (up to ~170) resampling weights serve all its patches, whose
    # rectangles share the walk over the taps (range_multi)
    idx, w, _ = weights(surf.gm, np.asarray(center)[valid], np.asarray(sigma_p)[valid],
                        interp=QUAD_INTERP)
    mean = range_multi(surf.gm, idx, w, lo_v[sel], hi_v[sel])
    k, ja = fac
    val = k[sel] * (ja[sel] * mean)[..., None]
    out[valid] = val.sum(axis=1) * np.asarray(radiance, dtype=np.float64)
    return out, valid


def quad_patches(wo, corners, f0, n_sub: int | None = None):
    """The half-vector geometry of :func:`quad_range` (no NDF query): per shading sample, an
    ``n_sub x n_sub`` split of the quad, each patch's range rectangle (:data:`QUAD_RECT`) in
    ``s`` and its factors at the patch centre, ``k = F G / (4 wo_z)`` and ``ja = 4 (wi.h) /
    h_z`` times the patch's ``s``-polygon area: the specular radiance is ``radiance
    sum_patches k (ja mean)`` with ``mean`` the footprint NDF's mean over the rectangle.

    Parameters: ``wo (N, 3)``, ``corners (N, 4, 3)``, ``f0`` as :func:`quad_range`.

    Returns
    -------
    ok (N,): front face, light above the horizon, every patch's box narrower than
    ``RANGE_MAX`` and filled >= ``FILL_MIN``; for the ``n`` samples where ``ok``: ``lo``, ``hi``
    ``(n, n_sub^2, 2)`` (``hi > lo``) and ``factor = (k (n, n_sub^2, C), ja (n, n_sub^2))``.
    """
    N = corners.shape[0]
    n_sub = QUAD_SUB if n_sub is None else int(n_sub)
    f0 = np.atleast_1d(np.asarray(f0, dtype=np.float64))
    g = (np.arange(n_sub + 1) / n_sub)
    A, B = np.meshgrid(g, g, indexing="ij")
    a, b = A.ravel()[None, :, None], B.ravel()[None, :, None]
    v0, v1, v2, v3 = (corners[:, k][:, None, :] for k in range(4))
    P = (1 - a) * (1 - b) * v0 + a * (1 - b) * v1 + a * b * v2 + (1 - a) * b * v3  # (N, G, 3)
    d = P / np.linalg.norm(P, axis=-1, keepdims=True)
    h = d + wo[:, None, :]
    h /= np.maximum(np.linalg.norm(h, axis=-1, keepdims=True), 1e-300)
    S = h[..., :2].reshape(N, n_sub + 1, n_sub + 1, 2)
    # patch corners (N, n, n, 4, 2), counter-clockwise in the patch's (a, b) parameters
    q = np.stack([S[:, :-1, :-1], S[:, 1:, :-1], S[:, 1:, 1:], S[:, :-1, 1:]], axis=3)
    x, y = q[..., 0], q[..., 1]
    area = 0.5 * np.abs(np.sum(x * np.roll(y, -1, -1) - np.roll(x, -1, -1) * y, axis=-1))
    lo, hi = q.min(axis=3), q.max(axis=3)
    box = np.prod(hi - lo, axis=-1)
    normal = np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0])
    front = np.sum(normal * corners[:, 0], -1) < 0.0  # the point is on the emitting side
    valid = (front & np.all(d[..., 2] > _HORIZON, axis=1) & np.all(h[..., 2] > 0, axis=1)
             & (wo[:, 2] > 0) & np.all(hi - lo < RANGE_MAX, axis=(1, 2, 3))
             & np.all(area >= FILL_MIN * box, axis=(1, 2)))
    nv = int(valid.sum())
    m = n_sub * n_sub
    C = len(np.broadcast_to(f0, (3,)))
    if not nv:
        return valid, np.zeros((0, m, 2)), np.ones((0, m, 2)), (np.zeros((0, m, C)),
                                                                np.zeros((0, m)))
    eps = 1e-9
    if QUAD_RECT == "equal-area":
        lo, hi = _equal_area_rects(x, y, area, lo, hi)
    lo_v, hi_v = lo[valid].reshape(nv, m, 2), hi[valid].reshape(nv, m, 2) + eps
    # smooth factor at each patch centre direction
    ac = ((np.arange(n_sub) + 0.5) / n_sub)
    Ac, Bc = np.meshgrid(ac, ac, indexing="ij")
    a, b = Ac.ravel()[None, :, None], Bc.ravel()[None, :, None]
    cv = corners[valid]
    Pc = ((1 - a) * (1 - b) * cv[:, None, 0] + a * (1 - b) * cv[:, None, 1]
          + a * b * cv[:, None, 2] + (1 - a) * b * cv[:, None, 3])
    wi = Pc / np.linalg.norm(Pc, axis=-1, keepdims=True)
    wov = np.broadcast_to(wo[valid][:, None, :], wi.shape)
    k, hc = _brdf_terms(wov, wi, f0)
    # k = F G / (4 wo_z): f cos dwi = k D dwi, and dwi = 4 (wi.h) / h_z ds
    jac = 4.0 * np.sum(wi * hc, -1) / np.maximum(hc[..., 2], 1e-300)
    return valid, lo_v, hi_v, (k, jac * area[valid].reshape(nv, m))


def quad_mis(surf: GlintSurface, center, sigma_p, wo, position, frame, light, f0, u, *,
             fallback_truncation: float | None = None):
    """Specular radiance of ``light`` by multiple importance sampling (balance heuristic): per
    shading sample ``n`` light samples (uniform on the quad's area) and ``n`` BRDF samples
    (:func:`prefilter.glints.sample.sample_wi`: the hierarchical NDF sampler, or the direct
    P-NDF sampler below the finest level / without a compressed map).

    Parameters
    ----------
    position : (N, 3) world shading points; frame : (t, b, n) each (N, 3) (world);
    light : QuadLight; u : (N, n * 11) uniforms in ``[0, 1)``; fallback_truncation: see
    :func:`prefilter.glints.brdf.glint_ndf` (the BRDF's direct P-NDF below the finest level).

    Returns
    -------
    (N, 3) the unbiased estimate of ``int_quad f cos L dwi``: the balance heuristic of
    ``glint_brdf_cos``, ``pdf_wi`` and ``sample_wi`` per pair, evaluated per footprint instead of
    per direction (the tests check it against that per-direction form). Below the finest level (with
    the 4-std fallback) one walk over its texels gives the NDF at the light samples' half
    vectors (also their density), the draws, their densities and the NDF at them
    (:func:`prefilter.glints.sample.direct_mis_k`); elsewhere the draws are taken together with
    the block masses computed once (:func:`prefilter.glints.sample.sample_s_k`), then the NDF at
    all ``2 n`` half vectors together (:func:`prefilter.glints.brdf.direct_ndf_k`). The
    per-direction version walked a near footprint's texels ~16 times (the NDF for the BRDF and
    again for the density, the sampler twice and the exact P-NDF for the draw's density).
    """
    from prefilter.render.lights import quad_light_pdf, quad_light_sample

    N = len(wo)
    P = u.shape[1] // U_PAIR
    L = np.asarray(light.radiance, dtype=np.float64)
    if P == 0:
        return np.zeros((N, 3)) * L
    f0 = np.atleast_1d(as_float_array(f0, "f0"))
    wo = as_directions(wo, "wo")
    c = np.asarray(center, dtype=np.float64)
    sp = np.broadcast_to(np.asarray(sigma_p, dtype=np.float64), (N,))
    # the P pairs of every shading sample at once: rows pair-major (P N), element-wise the
    # operations of glint_brdf_cos, pdf_wi and sample_wi per pair
    t, b, n = (np.tile(x, (P, 1)) for x in frame)
    pos = np.tile(position, (P, 1))
    woP = np.tile(wo, (P, 1))
    uu = u[:, :P * U_PAIR].reshape(N, P, U_PAIR)
    # light samples and their half vectors
    w, pl = quad_light_sample(light, pos, uu[:, :, :2].transpose(1, 0, 2).reshape(P * N, 2))
    wl = as_directions(to_local(w, t, b, n), "wi")
    hl = half(woP, wl)
    Hl = hl.reshape(P, N, 3).transpose(1, 0, 2)
    # BRDF samples: sample_wi's draws, then its reflection and density; glint_brdf_cos's wi.
    # Footprints below the finest level (4-std fallback): draws, densities and the NDF at the
    # light samples' and the draws' half vectors in one walk (direct_mis_k); the others: draws
    # together (_mis_draws), then the NDF at all half vectors together (_mis_ndf)
    U = np.ascontiguousarray(uu[:, :, 2:])
    one = np.zeros(N, bool)
    if fallback_truncation == TRUNCATION and surf.normal_map is not None:
        one = (sp < surf.sigma0) & (sp < surf.sigma_min) & direct_mis_fits(surf, sp)
    rest = ~one
    s, ps, D = np.zeros((N, P, 2)), np.zeros((N, P)), np.zeros((N, 2 * P))
    M = np.full(N, np.nan)
    if np.any(one):
        D[one, :P], s[one], ps[one], D[one, P:] = direct_mis_k(
            surf, c[one], sp[one], Hl[one][..., :2], U[one][..., :3])
    if np.any(rest):
        s[rest], ps[rest], M[rest] = _mis_draws(surf, c[rest], sp[rest], U[rest])
    s = s.transpose(1, 0, 2).reshape(P * N, 2)
    ps = ps.T.reshape(P * N)
    m = half_from_s(s)
    wom = np.sum(woP * m, axis=-1)
    ok = (ps > 0) & (np.sum(s * s, axis=-1) < 1.0) & (wom > 0)
    w = 2.0 * wom[..., None] * m - woP
    pb2 = np.where(ok, ps * m[..., 2] / (4.0 * np.where(ok, wom, 1.0)), 0.0)
    ok = pb2 > 0
    w = np.where(ok[:, None], w, np.array([0.0, 0.0, 1.0]))
    pl2 = quad_light_pdf(light, pos, to_world(w, t, b, n))
    wb = as_directions(w, "wi")
    hb = half(woP, wb)
    if np.any(rest):
        Hb = hb.reshape(P, N, 3).transpose(1, 0, 2)
        D[rest] = _mis_ndf(surf, c[rest], sp[rest],
                           np.concatenate([Hl[rest, :, :2], Hb[rest, :, :2]], 1),
                           fallback_truncation)
    pb = _mis_light_pdf(surf, c, sp, wo, Hl, D[:, :P], M, fallback_truncation).T.reshape(P * N)
    fl = brdf_cos_from_ndf(woP, wl, hl, D[:, :P].T.reshape(P * N), f0).reshape(P, N, -1)
    wgt = np.where(pl > 0, 1.0 / np.where(pl > 0, pl + pb, 1.0), 0.0).reshape(P, N)
    fb = brdf_cos_from_ndf(woP, wb, hb, D[:, P:].T.reshape(P * N), f0).reshape(P, N, -1)
    wgt2 = np.where(ok & (pl2 > 0), 1.0 / np.where(ok, pb2 + pl2, 1.0), 0.0).reshape(P, N)
    out = np.zeros((N, 3))
    for j in range(P):  # the pairs' order of summation
        out += fl[j] * wgt[j][:, None]
        out += fb[j] * wgt2[j][:, None]
    return out * L / P


def _mis_small(surf, sp):
    """Footprints that :func:`prefilter.glints.sample.sample_wi` and ``pdf_wi`` give to the
    direct P-NDF (below the finest level, with the normal map)."""
    return sp < surf.sigma0 if surf.normal_map is not None else np.zeros(sp.shape, bool)


def _mis_draws(surf, c, sp, u):
    """``sample_wi``'s projected half vectors ``s (N, K, 2)`` and densities ``(N, K)`` for the
    uniforms ``u (N, K, 9)``, and the compressed footprints' NDF masses ``M (N,)`` (NaN for the
    direct ones)."""
    N, K = u.shape[:2]
    s = np.zeros((N, K, 2))
    ps = np.zeros((N, K))
    M = np.full(N, np.nan)
    small = _mis_small(surf, sp)
    if np.any(small):
        s[small], ps[small] = sample_s_direct_k(surf, c[small], sp[small], u[small][:, :, :3])
    if not np.all(small):
        if surf.gm is None:
            raise PrefilterError("gm: footprints at or above sigma0 need a compressed map")
        k = ~small
        s[k], ps[k], M[k] = sample_s_k(surf.gm, c[k], sp[k], u[k][:, :, :n_uniforms(surf.gm)])
    return s, ps, M


def _mis_ndf(surf, c, sp, q, fallback_truncation):
    """``glint_ndf`` at ``q (N, K, 2)`` -> ``(N, K)``, the ``K`` points of a footprint together."""
    N, K = q.shape[:2]
    out = np.zeros((N, K))
    direct = sp < surf.sigma_min if surf.normal_map is not None else np.zeros(sp.shape, bool)
    if np.any(direct) and fallback_truncation is not None:
        out[direct] = direct_ndf_k(surf, c[direct], sp[direct], q[direct],
                                   truncation=fallback_truncation)
    elif np.any(direct):
        n = int(direct.sum())
        out[direct] = pndf(surf.normal_map, np.repeat(c[direct], K, 0),
                           np.repeat(sp[direct], K), q[direct].reshape(n * K, 2),
                           surf.intrinsic_roughness, elements_=surf.elements_).reshape(n, K)
    if surf.gm is not None and not np.all(direct):
        k = ~direct
        n = int(k.sum())
        out[k] = point_flat(surf.gm, np.repeat(c[k], K, 0), np.repeat(sp[k], K),
                            q[k].reshape(n * K, 2), interp=surf.interp,
                            bilinear=surf.bilinear).reshape(n, K)
    return out


def _mis_light_pdf(surf, c, sp, wo, h, D, M, fallback_truncation):
    """``pdf_wi`` of light samples with half vectors ``h (N, K, 3)``: the direct P-NDF at 4 stds
    below the finest level (``D``, the BRDF's values, when it was evaluated so), else the
    compressed NDF over its mass ``M``."""
    N, K = h.shape[:2]
    ps = np.zeros((N, K))
    small = _mis_small(surf, sp)
    if np.any(small):
        if fallback_truncation == TRUNCATION and np.all(sp[small] < surf.sigma_min):
            ps[small] = D[small]
        else:
            ps[small] = direct_ndf_k(surf, c[small], sp[small], h[small][..., :2],
                                     truncation=TRUNCATION)
    k = ~small
    if np.any(k):
        n = int(k.sum())
        v = point(surf.gm, np.repeat(c[k], K, 0), np.repeat(sp[k], K),
                  h[k][..., :2].reshape(n * K, 2)).reshape(n, K)
        Mk = M[k][:, None]
        ps[k] = np.where(Mk > 0, v / np.where(Mk > 0, Mk, 1.0), 0.0)
    woh = np.sum(wo[:, None] * h, -1)
    ok = (h[..., 2] > 0) & (woh > 0) & (wo[:, None, 2] > 0)
    return np.where(ok, ps * h[..., 2] / (4.0 * np.where(ok, woh, 1.0)), 0.0)


def shade_glints(scene, g, *, mode: str, spp: int = 1, sigma=None, u=None,
                 use_range: bool | None = None, progress: bool = False,
                 bake: dict | None = None) -> np.ndarray:
    """Radiance ``(N, 3)`` of hit samples ``g`` under the scene's lights.

    ``mode``: ``"compressed"`` or ``"direct"``; ``sigma`` overrides the footprint stds (the
    reference passes zeros). Point and directional lights: the BRDF at the light direction
    (point query). Quad lights: :func:`quad_range` where valid (``use_range``, default for the
    compressed mode), else :func:`quad_mis` with the uniforms ``u (N, n_quads * QUAD_MIS * 11)``;
    the diffuse term by Lambert's polygon formula. Environment lights: see
    :func:`environment_radiance` (uniforms after the quads'). ``progress``: a map baked on
    first use reports its bake on stderr (:func:`baked_surface`); ``bake``: settings overriding
    :data:`BAKE_SETTINGS` (:func:`bake_overrides`)."""
    from prefilter.ltc import clamped_cosine_integral

    lights = scene.light_set()
    env = [lt for lt in scene.lights if lt.type == "environment"]
    if use_range is None:
        use_range = mode == "compressed"
    t, b, n, wo = shading_frames(g)
    incoming = point_incoming(lights, g.position)
    out = np.zeros((len(wo), 3))
    nq = len(lights.quads)
    for k in np.unique(g.object_id):
        m = g.object_id == k
        mat = scene.objects[int(k)].material
        if mat.normal_map is None:
            raise PrefilterError(f"objects[{int(k)}].material.normal_map: the glints methods "
                                 "expected a normal map (the microstructure), got none")
        surf = baked_surface(mat.normal_map.load(), direct=(mode == "direct"), settings=bake,
                             progress=progress)
        c, sp = footprints(g.select(m), surf.shape, spp)
        if sigma is not None:
            sp = np.broadcast_to(sigma, m.shape)[m]
        base = np.asarray(mat.base_color, dtype=np.float64)
        f0 = np.asarray(mat.f0, dtype=np.float64)
        # glints: the fast truncated fallback below the finest level; the direct method and the
        # reference keep the exact P-NDF
        trunc = FALLBACK_TRUNCATION if mode == "compressed" else None
        for w, e in incoming:
            wi = to_local(w[m], t[m], b[m], n[m])
            wi /= np.linalg.norm(wi, axis=-1, keepdims=True)
            spec = glint_brdf_cos(surf, c, sp, wo[m], wi, f0, fallback_truncation=trunc)
            diff = base / np.pi * np.maximum(wi[:, 2], 0.0)[:, None]
            out[m] += (spec + diff) * e[m]
        frame = (t[m], b[m], n[m])
        for qi, ql in enumerate(lights.quads):
            corners = np.stack([to_local(v - g.position[m], *frame) for v in ql.vertices], 1)
            if np.any(base > 0):
                out[m] += base * ql.radiance * clamped_cosine_integral(corners)[:, None]
            val = np.zeros((int(m.sum()), 3))
            done = np.zeros(int(m.sum()), bool)
            if use_range and surf.gm is not None:
                val, done = quad_range(surf, c, sp, wo[m], corners, ql.radiance, f0)
                # lights too large for 2x2 patches: 4x4 (16 range queries) before MIS
                r = np.flatnonzero(~done & (sp >= surf.sigma_min))
                if r.size:
                    v4, d4 = quad_range(surf, c[r], sp[r], wo[m][r], corners[r], ql.radiance,
                                        f0, n_sub=2 * QUAD_SUB)
                    val[r[d4]] = v4[d4]
                    done[r[d4]] = True
            rest = ~done
            if np.any(rest):
                uq = u[m][:, uniform_columns(nq, "quad", qi)]
                val[rest] = quad_mis(surf, c[rest], sp[rest], wo[m][rest],
                                     g.position[m][rest], tuple(f[rest] for f in frame), ql,
                                     f0, uq[rest], fallback_truncation=trunc)
            out[m] += val
        if env:
            out[m] += environment_radiance(env, surf, c, sp, wo[m], frame, f0, base,
                                           None if u is None else u[m],
                                           prefilter=(mode == "compressed"),
                                           fallback_truncation=trunc, n_quads=nq)
    return out


#: Environment lights: SG samples per shading sample, lobes of the fit (:func:`fit_sg`) and the
#: epsilon of the compact support that sets the NDF blur (relative to the lobe's peak). The blur
#: trades noise for bias: on the measurement scene (flakes, sigma_p 6 / 20, 8 samples) eps 0.1
#: cuts the noise 10x / 3.5x but the mean is 25 % low; 0.5: 6x / 2.6x, 9 % low; 0.9: 3.4x / 2x,
#: 2 % low (docs/glints-part2.md).
ENV_SAMPLES = 8
ENV_LOBES = 32
ENV_EPS = 0.9
_SG_FITS: dict = {}


def environment_sgs(light):
    """The spherical-Gaussian fit ``(mu, lam, p)`` (world axes) of an environment light, times
    its ``scale`` (:func:`prefilter.glints.envlight.fit_sg`; cached per image)."""
    key = light.image.cache_key()
    if key not in _SG_FITS:
        _SG_FITS[key] = fit_sg(light.image.load(), ENV_LOBES)
    mu, lam, p = _SG_FITS[key]
    return mu * light.scale, lam, p


def environment_lobes(light, frame):
    """The SG fit of an environment light (:func:`environment_sgs`): sharpnesses ``mu (K,)``,
    amplitudes ``lam (K, 3)`` and lobe axes in each sample's local frame ``(N, K, 3)`` for the
    world frames ``frame = (t, b, n)``, each ``(N, 3)``."""
    try:
        mu, lam, p = environment_sgs(light)
    except PrefilterError as exc:
        raise PrefilterError(f"{light.image.where}: {exc}") from None
    t, b, n = frame
    return mu, lam, np.stack([p @ t.T, p @ b.T, p @ n.T], -1).transpose(1, 0, 2)


def environment_radiance(env, surf, center, sigma_p, wo, frame, f0, base, u, *,
                         prefilter: bool, fallback_truncation: float | None = None,
                         n_quads: int = 0) -> np.ndarray:
    """Radiance ``(N, 3)`` (specular and Lambert) from environment lights by SG sampling
    (:func:`prefilter.glints.envlight.shade_sg`, ``ENV_SAMPLES`` per shading sample); the NDF is
    range-prefiltered over the lobe's compact epsilon-support when ``prefilter`` (sec. 5.4).
    ``u``: the shading samples' uniforms (:func:`uniform_columns` with ``n_quads`` quad lights;
    None or too few columns: drawn from a fixed seed)."""
    out = np.zeros((len(wo), 3))
    for j, light in enumerate(env):
        mu, lam, pl = environment_lobes(light, frame)
        uj = None if u is None else u[:, uniform_columns(n_quads, "environment", j)]
        if uj is not None and uj.shape[1] < 3 * ENV_SAMPLES:
            uj = None
        out += shade_sg(surf, center, sigma_p, wo, mu, lam, pl, f0, n_samples=ENV_SAMPLES,
                        rng=0, prefilter=prefilter and surf.gm is not None, eps=ENV_EPS, u=uj,
                        base_color=base, fallback_truncation=fallback_truncation)
    return out


def random_dims(scene) -> int:
    """Uniforms per shading sample the glints methods need (quad MIS, environment samples): the
    columns of :func:`uniform_columns` for every light."""
    n_env = sum(lt.type == "environment" for lt in scene.lights)
    return uniform_columns(len(scene.light_set().quads), "environment", n_env).start


def uniform_columns(n_quads: int, kind: str, i: int) -> slice:
    """The columns of light ``i`` of ``kind`` (``"quad"`` or ``"environment"``) in the uniforms
    of one shading sample (the layout :func:`random_dims` counts, shared by ``glints``,
    ``glints-direct`` and ``glints-wang`` so that one seed gives them the same light samples):
    ``QUAD_MIS`` pairs of ``U_PAIR`` per quad light, then ``3 ENV_SAMPLES`` per environment
    light; ``n_quads``: the scene's quad lights."""
    quads = n_quads * QUAD_MIS * U_PAIR
    if kind == "quad":
        return slice(i * QUAD_MIS * U_PAIR, (i + 1) * QUAD_MIS * U_PAIR)
    if kind == "environment":
        return slice(quads + i * 3 * ENV_SAMPLES, quads + (i + 1) * 3 * ENV_SAMPLES)
    raise PrefilterError(f"kind: expected 'quad' or 'environment', got {kind!r}")


def check_lights(scene, name):
    """Untextured quad, point, directional and environment lights: a textured quad is a
    :class:`PrefilterError` naming the method ``name`` (the glints methods and ``glints-wang``)."""
    for i, light in enumerate(scene.lights):
        if getattr(light, "texture", None) is not None:
            raise PrefilterError(f"lights[{i}]: method {name!r} expected untextured quad, point, "
                                 "directional or environment lights, got a textured quad")


def bake_overrides(settings) -> dict | None:
    """The bake settings a render's ``settings`` (:class:`prefilter.render.methods.
    RenderSettings`) override: ``stride0`` from the ``glints`` method's ``level0`` variant, or
    ``None``. Level 0 at 8 texels (the default, :data:`BAKE_SETTINGS`) bakes fast and leaves
    footprints below ~10 texels to the direct P-NDF, whose cost grows with their area; at 4 the
    frame time stays about constant over distance for a longer bake (docs/glints-part2.md)."""
    level0 = settings.param("level0", str(BAKE_SETTINGS["stride0"]))
    return None if int(level0) == BAKE_SETTINGS["stride0"] else {"stride0": int(level0)}


def bake_maps(scene, *, progress: bool = False, settings: dict | None = None) -> None:
    """Bake the normal maps of ``scene``'s objects that the render cache lacks, all of them
    before any is loaded (:func:`baked_surface`): a bake's memory then never adds to that of the
    maps a render holds (~3 times a map's stored bytes each). ``settings`` override
    :data:`BAKE_SETTINGS`."""
    for obj in scene.objects:
        nmap = getattr(obj.material, "normal_map", None)
        if nmap is None:
            continue
        nm = as_normal_map(nmap.load())
        st = bake_settings(nm.shape, settings, bilinear=BILINEAR)
        path = cache_path(nm, st)
        path.parent.mkdir(parents=True, exist_ok=True)
        bake_if_missing(nm, path, progress=progress, **st)


def _render(scene, settings, mode, name):
    from prefilter.render.driver import render_samples

    check_lights(scene, name)
    bake = bake_overrides(settings) if mode == "compressed" else None
    if mode == "compressed":
        bake_maps(scene, progress=settings.progress, settings=bake)
    spp = settings.spp
    k = random_dims(scene)
    return render_samples(scene, settings,
                          lambda g, u: shade_glints(scene, g, mode=mode, spp=spp, u=u,
                                                    progress=settings.progress, bake=bake),
                          random_dims=k, stratified=spp > 1, desc=name)


def render_glints(scene, settings) -> np.ndarray:
    """The ``glints`` method: compressed footprint NDF (point query; range queries for quad
    lights where valid, else MIS; SG-prefiltered environment)."""
    return _render(scene, settings, "compressed", "glints")


def render_glints_direct(scene, settings) -> np.ndarray:
    """The ``glints-direct`` method: direct P-NDF of every footprint (Yan et al. 2016); quad and
    environment lights by Monte Carlo (MIS / SG sampling)."""
    return _render(scene, settings, "direct", "glints-direct")


def render_glints_reference(scene, settings) -> np.ndarray:
    """The ``glints-reference`` method: ``spp`` sub-pixel samples from the pixel Gaussian, each
    shaded with the point P-NDF of the full-resolution normal map (``sigma_p = 0``); quad and
    environment lights by Monte Carlo as in ``glints-direct``."""
    from prefilter.render.camera import gbuffer_at
    from prefilter.render.driver import row_rng

    check_lights(scene, "glints-reference")
    cam = scene.camera
    h, w, s = cam.height, cam.width, settings.spp
    k = random_dims(scene)
    rows_per_chunk = max(1, settings.chunk_samples // (w * s))
    image = np.zeros((h, w, 3))
    with tqdm(total=h, desc="glints-reference", unit="row", delay=1.0, leave=False,
              disable=not settings.progress) as bar:
        for r0 in range(0, h, rows_per_chunk):
            rows = range(r0, min(h, r0 + rows_per_chunk))
            gens = [row_rng(settings.seed, y) for y in rows]
            offs = np.stack([gen.normal(0.0, PIXEL_SIGMA, (w, s, 2)) for gen in gens])
            us = np.concatenate([gen.random((w * s, k)) for gen in gens])
            xy = offs + 0.5 + np.asarray(settings.jitter, dtype=np.float64)
            xy[..., 0] += np.arange(w)[None, :, None]
            xy[..., 1] += np.asarray(rows, dtype=np.float64)[:, None, None]
            g = gbuffer_at(scene, xy).reshape(-1)
            rad = np.zeros((g.hit.size, 3))
            if np.any(g.hit):
                rad[g.hit] = shade_glints(scene, g.select(g.hit), mode="direct", sigma=0.0,
                                          u=us[g.hit])
            image[r0:r0 + len(rows)] = rad.reshape(len(rows), w, s, 3).mean(axis=2)
            bar.update(len(rows))
    return image.astype(np.float32)


# ------------------------------------------------------------------------------- measurements


def measurement_environment() -> Path:
    """An equirectangular ``.npy`` environment (64 x 128, written once to the cache directory):
    a dim sky (0.3), a dark ground (0.05) and a bright window (20) of +-12 degrees around the
    direction that the measurement scenes' plane mirrors towards the camera (59 degrees from
    ``+y``, towards ``-z``: near the image centre in the convention of ``docs/scenes.md``)."""
    path = cache_dir() / "measurement-environment-v2.npy"
    if not path.exists():
        d = equirect_directions(64, 128)
        img = np.where(d[..., 1:2] > 0, 0.3, 0.05) * np.ones(3)
        w = np.array([0.0, 0.6, -1.0]) / np.linalg.norm([0.0, 0.6, -1.0])
        img[d @ w > np.cos(np.radians(12.0))] = 20.0
        path.parent.mkdir(parents=True, exist_ok=True)
        tmp = path.with_suffix(".tmp.npy")
        np.save(tmp, img)
        os.replace(tmp, path)
    return path


def measurement_scene(distance: float, kind: str = "flakes", size: int = 128, width: int = 64,
                      height: int = 48, lights: str = "point") -> dict:
    """A glinty plane seen from ``distance`` (camera and light scaled together, so the image is
    the same apart from the footprint size, ~proportional to the distance).

    ``lights``: ``"point"``; ``"quad"`` (a square of side ``0.16 distance`` at the point light's
    place, facing the plane's centre, with the point light's on-axis intensity); or
    ``"environment"`` (:func:`measurement_environment`)."""
    d = float(distance)
    if lights == "point":
        light = [{"type": "point", "position": [0, 0.6 * d, -d], "intensity": [5 * d * d] * 3}]
    elif lights == "quad":
        c = np.array([0.0, 0.6 * d, -d])
        nrm = -c / np.linalg.norm(c)
        a = np.array([1.0, 0.0, 0.0])
        b = np.cross(nrm, a)
        h = 0.08 * d
        v = [c - h * a - h * b, c + h * a - h * b, c + h * a + h * b, c - h * a + h * b]
        if np.dot(np.cross(v[1] - v[0], v[2] - v[0]), nrm) < 0:
            v = v[::-1]
        light = [{"type": "quad", "vertices": [list(map(float, x)) for x in v],
                  "radiance": [5.0 / (4 * 0.08**2)] * 3}]
    elif lights == "environment":
        light = [{"type": "environment", "image": str(measurement_environment())}]
    else:
        raise PrefilterError(f"lights: expected 'point', 'quad' or 'environment', got {lights!r}")
    return {"camera": {"origin": [0, 0.6 * d, d], "target": [0, 0, 0], "up": [0, 1, 0],
                       "fov": 30, "width": width, "height": height},
            "objects": [{"type": "plane", "center": [0, 0, 0], "normal": [0, 1, 0],
                         "tangent": [1, 0, 0], "size": [40 * d, 40 * d],
                         "uv_scale": [160 * d] * 2,
                         "material": {"alpha": 0.1, "base_color": [0, 0, 0],
                                      "f0": [0.9, 0.9, 0.9],
                                      "normal_map": {"procedural": kind, "size": size,
                                                     "seed": 1}}}],
            "lights": light}
