"""The glint microfacet BRDF (glints tensor-prefiltering paper, eq. 1 and sec. 5.1).

``f(wo, wi) = F(wi.h) G(wo, wi, h) D_P(h) / (4 |wo.n| |wi.n|)`` in the *geometric* tangent frame
(``x`` along texture ``+u`` = normal-map columns, ``y`` along ``+v`` = rows, ``z`` the macro
normal), where the NDF ``D_P`` is the P-NDF of the pixel footprint:

* ``sigma_p >= sigma_min`` (:attr:`GlintSurface.sigma_min`): the compressed point query; by
  default Gaussian resampling of a finer pyramid level (the footprint's own P-NDF up to aliasing,
  :func:`prefilter.glints.pyramid.resample_weights`) with the NDF interpolated bilinearly between
  the stored pixel averages; ``interp="trilinear"`` gives the paper's 8-image blend (which moves
  sparse glints between the pyramid samples). Footprints larger than the top level are clamped
  to it (the top has converged to a smooth NDF, sec. 5.1);
* ``sigma_p < sigma_min`` (``sigma0``, or ``~1.12 sigma0`` where resampling starts): the direct
  P-NDF of Yan et al. 2016 (:func:`prefilter.glints.pndf.pndf`), cheap for such footprints; without
  the normal map the footprint is clamped to level 0 instead.

``D(m) = D_p(m_xy)`` on the hemisphere (see ``pndf``): a density w.r.t. projected normals that
weights macro area, so ``integral D(m) m_z dm`` is the mass of ``D_p`` (1, or the mass inside the
stored support for the compressed NDF).

Masking-shadowing: the V-cavity term of Cook and Torrance 1982,
``G(wo, wi, m) = min(1, 2 m_z wo_z / (wo.m), 2 m_z wi_z / (wi.m))``. A Smith term needs a
Lambda of the NDF, which a tabulated glint NDF does not have in closed form; the V-cavity term is
defined for any NDF, reciprocal, and satisfies the projected-area normalisation for symmetric NDFs
(tested on GGX). Fresnel: Schlick with reflectance ``f0`` at normal incidence (as the renderer's
material model).
"""

from __future__ import annotations

import math
import weakref
from dataclasses import dataclass

import numpy as np

from prefilter.jit import njit_inline, njit_parallel, prange, serial
from prefilter.validation import as_directions, as_float_array, broadcast_batch
from prefilter.errors import PrefilterError
from prefilter.glints.pndf import (DEFAULT_ROUGHNESS, SIGMA_H, as_intrinsic_roughness, texel_window,
                                   as_normal_map, element_moments, elements, map_digest, pndf)
from prefilter.glints._qkernels import _rect_mass
from prefilter.glints._simd import exp_neg, fdiv
from prefilter.glints.query import point_flat
from prefilter.glints.sample import quadtree_draw
from prefilter.glints.store import GlintsMap


@dataclass(frozen=True)
class GlintSurface:
    """A compressed glints map with (optionally) the normal map it was baked from.

    Build it with :func:`surface`. ``normal_map`` and ``elements_`` are ``None`` when the
    direct-P-NDF fallback below the finest level is not available (then level 0 is used).
    """

    gm: GlintsMap | None
    normal_map: np.ndarray | None
    elements_: tuple | None
    intrinsic_roughness: float
    interp: str = "resample"
    bilinear: bool = True

    @property
    def sigma0(self) -> float:
        return self.gm.pyramid.sigma0 if self.gm is not None else np.inf

    @property
    def sigma_min(self) -> float:
        """Footprint std below which :func:`glint_ndf` uses the direct P-NDF (when the normal
        map is known): ``sigma0``, or the smallest resampled std for ``interp="resample"``."""
        if self.gm is None:
            return np.inf
        if self.interp == "resample":
            from prefilter.glints.pyramid import resample_min_sigma

            return resample_min_sigma(self.gm.pyramid)
        return self.gm.pyramid.sigma0

    @property
    def shape(self) -> tuple[int, int]:
        if self.normal_map is not None:
            return self.normal_map.shape[:2]
        p = self.gm.pyramid
        return p.height, p.width


def surface(gm: GlintsMap | None = None, normal_map=None, *, check: bool = True,
            intrinsic_roughness: float | None = None, interp: str = "resample",
            bilinear: bool = True) -> GlintSurface:
    """Bundle a baked map and its normal map (the direct P-NDF for tiny footprints).

    ``gm=None`` gives a direct-only surface (every query by :func:`prefilter.glints.pndf.pndf`, the
    ``glints-direct`` method). ``check`` verifies that ``normal_map`` is the one ``gm`` was baked
    from (SHA-1 of the float64 normals recorded by the bake). ``intrinsic_roughness``: that of
    the direct P-NDF (default: the bake's, else Yan et al.'s 0.005). ``interp``: how
    :func:`glint_ndf` evaluates compressed footprints (:func:`prefilter.glints.query.weights`):
    ``"resample"`` (default; Gaussian resampling, the footprint's exact P-NDF up to compression)
    or ``"trilinear"`` (the paper's 8-image blend); ``bilinear``: NDF values interpolated between
    the stored pixel averages (default) instead of the pixel's value.
    """
    from prefilter.glints.query import check_interp

    check_interp(interp)
    if gm is None and normal_map is None:
        raise PrefilterError("surface: expected a GlintsMap, a normal map, or both; got neither")
    if gm is not None and not isinstance(gm, GlintsMap):
        raise PrefilterError(f"gm: expected a GlintsMap (prefilter.glints.load), got "
                             f"{type(gm).__name__}")
    nm = el = None
    if normal_map is not None:
        nm = as_normal_map(normal_map)
        el = elements(nm)
        if gm is not None and check:
            digest = map_digest(nm)
            baked = gm.header.get("map_sha1")
            if baked is not None and baked != digest:
                raise PrefilterError("normal_map: expected the normal map the glints map was baked "
                                     f"from (SHA-1 {baked[:12]}...), got one with SHA-1 "
                                     f"{digest[:12]}...")
    if gm is not None:
        sr = float(gm.header.get("settings", {}).get("intrinsic_roughness", DEFAULT_ROUGHNESS))
    else:
        sr = DEFAULT_ROUGHNESS
    if intrinsic_roughness is not None:
        sr = as_intrinsic_roughness(intrinsic_roughness)
    return GlintSurface(gm, nm, el, sr, interp, bool(bilinear))


def bilinear_bake_roughness(intrinsic_roughness: float, support: float, ndf_res: int) -> float:
    """Intrinsic roughness to bake with so that the bilinear lookup reproduces ``sigma_r``.

    A bilinear interpolation of pixel averages (pitch ``h = 2 support / ndf_res``) blurs the NDF
    by the pixel box (variance ``h^2 / 12``) and the tent (``h^2 / 6``), i.e. adds ``(h / 2)^2``
    to the variance of every element's Gaussian: baking with ``sqrt(sigma_r^2 - (h/2)^2)`` puts it
    back (not below ``sigma_r / 2`` when the pixels are too coarse for that)."""
    sr = as_intrinsic_roughness(intrinsic_roughness)
    hh = float(support) / int(ndf_res)
    return max(math.sqrt(max(sr * sr - hh * hh, 0.0)), 0.5 * sr)


def as_surface(surf) -> GlintSurface:
    """``surf`` as a :class:`GlintSurface`: a surface is returned as is, a :class:`GlintsMap`
    is wrapped by :func:`surface` (compressed queries only); anything else is an error."""
    if isinstance(surf, GlintSurface):
        return surf
    if isinstance(surf, GlintsMap):
        return surface(surf)
    raise PrefilterError(f"surf: expected a GlintSurface (prefilter.glints.brdf.surface) or a "
                         f"GlintsMap, got {type(surf).__name__}")


#: Spatial truncation the render methods use for the direct P-NDF fallback below the finest
#: level, in stds of the element weights per axis (as ``pndf``). Cutting it to 3 visits (3/4)^2
#: of the texels and changes the NDF by only 0.6 % relative L2, but drops the glints of texels
#: 3-4 stds away: HDR-FLIP of the near measurement frame vs glints-direct went 0.067 -> 0.174
#: (3.5: 0.104), so the render keeps 4 (the separable kernel still saves one exp per texel).
FALLBACK_TRUNCATION = 4.0


@njit_parallel
def _direct_points(s_el, J, jn, cx, cy, sp, qx, qy, sr, sh, trunc, out):
    """Yan et al. 2016 P-NDF at points (as ``pndf``'s kernel) with separable footprint weights
    (one exp per row and column instead of one per texel), the angular Gaussian evaluated only
    within 6 of its stds (``exp(-18)`` relative), and texels rejected before their Jacobian is
    read when even the bound ``|e| >= |q - n_i| - f |J|_F |d|``, ``quad >= |e|^2 / tr(cov)``
    puts them beyond that (``jn`` = per-texel Frobenius norms of ``J``)."""
    H, W = s_el.shape[0], s_el.shape[1]
    sh2 = sh * sh
    sr2 = sr * sr
    for q in prange(out.shape[0]):
        sp2 = sp[q] * sp[q]
        tot2 = sp2 + sh2
        f = sh2 / tot2
        var = sp2 * sh2 / tot2
        sv = math.sqrt(var)
        rad = trunc * math.sqrt(tot2)
        x0, x1 = texel_window(cx[q], rad)
        y0, y1 = texel_window(cy[q], rad)
        nx = x1 - x0 + 1
        wx = np.empty(nx)
        col = np.empty(nx, np.int64)
        sx = 0.0
        for i in range(nx):
            dx = cx[q] - (x0 + i + 0.5)
            wx[i] = math.exp(-dx * dx / (2.0 * tot2))
            sx += wx[i]
            col[i] = (x0 + i) % W
        acc = 0.0
        sy = 0.0
        for y in range(y0, y1 + 1):
            dy = cy[q] - (y + 0.5)
            wy = math.exp(-dy * dy / (2.0 * tot2))
            sy += wy
            r = y % H
            for i in range(nx):
                c = col[i]
                dx = cx[q] - (x0 + i + 0.5)
                e0x = abs(qx[q] - s_el[r, c, 0])
                e0y = abs(qy[q] - s_el[r, c, 1])
                g = jn[r, c]
                # |e| >= max|e0| - f g (|dx| + |dy|) and sqrt(tr cov) <= sqrt2 sr + sv g
                if max(e0x, e0y) - f * g * (abs(dx) + abs(dy)) > 6.0 * (1.4142135623730951 * sr
                                                                       + sv * g):
                    continue
                j00, j01, j10, j11 = J[r, c, 0, 0], J[r, c, 0, 1], J[r, c, 1, 0], J[r, c, 1, 1]
                ex = qx[q] - s_el[r, c, 0] - f * (j00 * dx + j01 * dy)
                ey = qy[q] - s_el[r, c, 1] - f * (j10 * dx + j11 * dy)
                a = sr2 + var * (j00 * j00 + j01 * j01)
                d = sr2 + var * (j10 * j10 + j11 * j11)
                # quad >= |e|^2 / trace(cov): cheap rejection before the exact form
                if ex * ex + ey * ey > 36.0 * (a + d):
                    continue
                b = var * (j00 * j10 + j01 * j11)
                det = a * d - b * b
                quad = (d * ex * ex - 2.0 * b * ex * ey + a * ey * ey) / det
                if quad < 36.0:
                    acc += wy * wx[i] * math.exp(-0.5 * quad) / (2.0 * math.pi * math.sqrt(det))
        out[q] = acc / (sx * sy)


@njit_inline
def _footprint_columns(cx, cy, sp, sh2, trunc, W):  # pragma: no cover - compiled
    """A footprint's texel window and its column factors for the row kernels (Yan et al. 2016
    weights ``exp(-|u_p - u_i|^2 / (2 (sigma_p^2 + sigma_h^2)))``, separable): mean-shift factor
    ``f``, element variance ``var``, ``inv = 1 / (2 tot2)``, window ``x0, y0, y1``, ``nx``
    columns starting at ``xs`` in the doubled planes (width ``2 W``), column weights ``wx`` and
    their sum ``sx``, and ``fdx = f dx`` per column."""
    sp2 = sp * sp
    tot2 = sp2 + sh2
    f = sh2 / tot2
    var = sp2 * sh2 / tot2
    rad = trunc * math.sqrt(tot2)
    x0, x1 = texel_window(cx, rad)
    y0, y1 = texel_window(cy, rad)
    nx = x1 - x0 + 1
    wx = np.empty(nx)
    fdx = np.empty(nx)
    inv = 1.0 / (2.0 * tot2)
    sx = 0.0
    for i in range(nx):
        dx = cx - (x0 + i + 0.5)
        fdx[i] = f * dx
        wx[i] = math.exp(-dx * dx * inv)
        sx += wx[i]
    return f, var, inv, x0, y0, y1, nx, x0 % W, wx, fdx, sx


@njit_parallel
def _direct_rows(SX, SY, J00, J01, J10, J11, cx, cy, sp, qx, qy, sr, sh, trunc, out):
    """:func:`_direct_points` over planes of the elements doubled along ``x`` (``(H, 2 W)``: a
    footprint row of at most ``W`` texels is one contiguous slice, no index wrap). Each row's
    quadratic forms are computed for all its texels in a branch-free loop (SIMD), the
    exponentials only where ``quad < 36``: the bound-then-branch of :func:`_direct_points`
    rejected 2/3 of the near frame's texels but paid a mispredicted branch and three scattered
    loads for each (10.8 -> 4.6 ms on the near measurement frame, same values to 1e-15)."""
    H = SX.shape[0]
    W = SX.shape[1] // 2
    sh2 = sh * sh
    sr2 = sr * sr
    for q in prange(out.shape[0]):
        f, var, inv, x0, y0, y1, nx, xs, wx, fdx, sx = _footprint_columns(
            cx[q], cy[q], sp[q], sh2, trunc, W)
        quad = np.empty(nx)
        det = np.empty(nx)
        qxq = qx[q]
        qyq = qy[q]
        acc = 0.0
        sy = 0.0
        for y in range(y0, y1 + 1):
            dy = cy[q] - (y + 0.5)
            wy = math.exp(-dy * dy * inv)
            sy += wy
            r = y % H
            fdy = f * dy
            sxr = SX[r, xs:xs + nx]
            syr = SY[r, xs:xs + nx]
            a0 = J00[r, xs:xs + nx]
            a1 = J01[r, xs:xs + nx]
            b0 = J10[r, xs:xs + nx]
            b1 = J11[r, xs:xs + nx]
            for i in range(nx):
                j00, j01, j10, j11 = a0[i], a1[i], b0[i], b1[i]
                ex = qxq - sxr[i] - (j00 * fdx[i] + j01 * fdy)
                ey = qyq - syr[i] - (j10 * fdx[i] + j11 * fdy)
                a = sr2 + var * (j00 * j00 + j01 * j01)
                d = sr2 + var * (j10 * j10 + j11 * j11)
                b = var * (j00 * j10 + j01 * j11)
                det[i] = a * d - b * b  # >= sr^4 > 0 (Cauchy-Schwarz)
                quad[i] = d * ex * ex - 2.0 * b * ex * ey + a * ey * ey
            racc = 0.0
            for i in range(nx):
                if quad[i] < 36.0 * det[i]:
                    racc += wx[i] * math.exp(-0.5 * quad[i] / det[i]) / math.sqrt(det[i])
            acc += wy * racc
        out[q] = acc / (2.0 * math.pi * sx * sy)


_JNORM: dict = {}
_PLANES: dict = {}


def _element_planes(s_el, J):
    """``(SX, SY, J00, J01, J10, J11)``, each ``(H, 2 W)`` contiguous: the elements' ``s`` and
    Jacobian entries, the map repeated once along ``x`` (cached while ``J`` lives)."""
    key = id(J)
    hit = _PLANES.get(key)
    if hit is None or hit[0]() is not J or hit[1]() is not s_el:
        planes = tuple(np.ascontiguousarray(np.concatenate([p, p], axis=1), dtype=np.float64)
                       for p in (s_el[..., 0], s_el[..., 1], J[..., 0, 0], J[..., 0, 1],
                                 J[..., 1, 0], J[..., 1, 1]))
        hit = _PLANES[key] = (weakref.ref(J), weakref.ref(s_el), planes)
        weakref.finalize(J, _PLANES.pop, key, None)
    return hit[2]


def _jacobian_norms(J):
    hit = _JNORM.get(id(J))
    if hit is None or hit[0] is not J:
        hit = _JNORM[id(J)] = (J, np.ascontiguousarray(np.sqrt(np.sum(J * J, axis=(-2, -1)))))
    return hit[1]


def direct_ndf(surf, center, sigma_p, s, *, truncation: float = FALLBACK_TRUNCATION):
    """The direct P-NDF (Yan et al. 2016) of ``surf``'s normal map at flat footprints
    ``center (N, 2)``, ``sigma_p (N,)`` and points ``s (N, 2)``, truncated at ``truncation``
    stds per axis (4 reproduces :func:`prefilter.glints.pndf.pndf` to rounding)."""
    if surf.elements_ is None:
        raise PrefilterError("surf: the direct P-NDF needs the normal map "
                             "(surface(gm, normal_map))")
    if not (1.0 <= float(truncation) <= 8.0):
        raise PrefilterError(f"truncation: expected a number of stds in [1, 8], got {truncation}")
    s_el, J = surf.elements_
    c = np.ascontiguousarray(center, dtype=np.float64)
    q = np.ascontiguousarray(s, dtype=np.float64)
    out = np.empty(c.shape[0])
    cc = np.ascontiguousarray
    sp = cc(np.broadcast_to(np.asarray(sigma_p, dtype=np.float64), c.shape[:1]))
    # rows of at most W texels are contiguous slices of the doubled planes; wider footprints
    # (larger than the map) wrap more than once: the per-texel kernel
    W = s_el.shape[1]
    rad = float(truncation) * np.sqrt(sp * sp + SIGMA_H * SIGMA_H)
    wide = 2.0 * rad + 2.0 > W
    args = (surf.intrinsic_roughness, SIGMA_H, float(truncation))
    if not np.all(wide):
        k = ~wide
        o = np.empty(int(k.sum()))
        _serial_below(_direct_rows, o.size)(
            *_element_planes(s_el, J), cc(c[k, 0]), cc(c[k, 1]), sp[k], cc(q[k, 0]),
            cc(q[k, 1]), *args, o)
        out[k] = o
    if np.any(wide):
        o = np.empty(int(wide.sum()))
        _serial_below(_direct_points, o.size)(
            s_el, J, _jacobian_norms(J), cc(c[wide, 0]), cc(c[wide, 1]), sp[wide],
            cc(q[wide, 0]), cc(q[wide, 1]), *args, o)
        out[wide] = o
    return out


def glint_ndf(surf, center, sigma_p, s, *, fallback_truncation: float | None = None) -> np.ndarray:
    """Footprint NDF ``D_P(s)`` (density w.r.t. projected half vectors ``s``), sec. 5.1.

    Parameters
    ----------
    surf : GlintSurface (or GlintsMap: no fallback, tiny footprints use level 0).
    center : (..., 2) footprint centres in texels; sigma_p : (...) stds in texels.
    s : (..., 2) projected half vectors; all broadcast.

    Returns
    -------
    (...) compressed point query (``surf.interp``, ``surf.bilinear``) for
    ``sigma_p >= surf.sigma_min``, direct P-NDF below when the normal map is known; top-level
    clamp above the pyramid. ``fallback_truncation``: evaluate
    that direct P-NDF by :func:`direct_ndf` truncated at this many stds (faster, approximate;
    ``None``: :func:`prefilter.glints.pndf.pndf` exactly).
    """
    surf = as_surface(surf)
    c = as_float_array(center, "center", ndim_min=1, last_dim=2)
    sp = as_float_array(sigma_p, "sigma_p")
    q = as_float_array(s, "s", ndim_min=1, last_dim=2)
    if np.any(sp < 0):
        raise PrefilterError(f"sigma_p: expected footprint stds >= 0, got min {sp.min()}")
    shape = broadcast_batch(center=c.shape[:-1], sigma_p=sp.shape, s=q.shape[:-1])
    c = np.broadcast_to(c, shape + (2,)).reshape(-1, 2)
    q = np.broadcast_to(q, shape + (2,)).reshape(-1, 2)
    sp = np.broadcast_to(sp, shape).reshape(-1)
    out = np.zeros(c.shape[0])
    direct = sp < surf.sigma_min if surf.normal_map is not None else np.zeros(sp.shape, bool)
    if np.any(direct) and fallback_truncation is not None:
        out[direct] = direct_ndf(surf, c[direct], sp[direct], q[direct],
                                 truncation=fallback_truncation)
    elif np.any(direct):
        out[direct] = pndf(surf.normal_map, c[direct], sp[direct], q[direct],
                           surf.intrinsic_roughness, elements_=surf.elements_)
    if surf.gm is not None and not np.all(direct):
        k = ~direct
        out[k] = point_flat(surf.gm, c[k], sp[k], q[k], interp=surf.interp,
                            bilinear=surf.bilinear)
    return out.reshape(shape)


#: The render methods' kernels run serially below this many items. Their work per item is a few
#: microseconds, and on the shared 2-core machine (load ~10) waking the thread pool made a frame's
#: 2 560 fallback evaluations 3x slower (23.6 ms parallel vs 7.3 ms serial, best of 15).
RENDER_SERIAL_BELOW = 1 << 15


def _serial_below(kernel, n):
    return serial(kernel, 0) if n < RENDER_SERIAL_BELOW else kernel




def vcavity_g1(w, m) -> np.ndarray:
    """V-cavity masking ``min(1, 2 m_z w_z / (w.m))`` for ``w.m > 0`` (Cook and Torrance 1982),
    else 0; ``w``, ``m`` ``(..., 3)`` unit vectors in the tangent frame."""
    w = np.asarray(w, dtype=np.float64)
    m = np.asarray(m, dtype=np.float64)
    wm = np.sum(w * m, axis=-1)
    g = 2.0 * m[..., 2] * w[..., 2] / np.where(wm > 0.0, wm, 1.0)
    return np.where((wm > 0.0) & (w[..., 2] > 0.0), np.clip(g, 0.0, 1.0), 0.0)


def vcavity_g2(wo, wi, m) -> np.ndarray:
    """V-cavity masking-shadowing ``min(G1(wo, m), G1(wi, m))`` (Cook and Torrance 1982)."""
    return np.minimum(vcavity_g1(wo, m), vcavity_g1(wi, m))


def schlick(f0, cos_theta) -> np.ndarray:
    """Schlick Fresnel ``f0 + (1 - f0)(1 - cos)^5``; ``f0 (..., C)``, ``cos_theta (...)``."""
    c = np.clip(np.asarray(cos_theta, dtype=np.float64), 0.0, 1.0)
    f0 = np.asarray(f0, dtype=np.float64)
    return f0 + (1.0 - f0) * ((1.0 - c) ** 5)[..., None]


def half(wo, wi):
    """Unit half vectors ``(..., 3)`` of unit ``wo``, ``wi`` ``(..., 3)``, without input checks
    (a zero sum stays zero; the callers have validated the directions)."""
    h = wo + wi
    ln = np.linalg.norm(h, axis=-1, keepdims=True)
    return h / np.maximum(ln, 1e-300)


def glint_brdf_cos(surf, center, sigma_p, wo, wi, f0=1.0, *,
                   fallback_truncation: float | None = None) -> np.ndarray:
    """Cosine-weighted glint BRDF ``f(wo, wi) wi_z`` (paper eq. 1 with ``D`` = footprint NDF).

    Parameters
    ----------
    surf : GlintSurface (or GlintsMap).
    center : (..., 2) footprint centres (texels); sigma_p : (...) footprint stds (texels).
    wo, wi : (..., 3) unit view / light directions in the geometric tangent frame (lengths within
        1e-3 of 1 are renormalised, others rejected).
    f0 : (..., C) or scalar Schlick reflectance at normal incidence.

    Returns
    -------
    (..., C) ``F(wi.h) G(wo, wi, h) D_P(h_xy) / (4 wo_z)`` (``C = 1`` for a scalar ``f0``); zero
    when ``wo`` or ``wi`` is below the horizon. ``fallback_truncation``: see :func:`glint_ndf`.
    """
    wo = as_directions(wo, "wo")
    wi = as_directions(wi, "wi")
    f0 = np.atleast_1d(as_float_array(f0, "f0"))
    if np.any((f0 < 0) | (f0 > 1)):
        raise PrefilterError(f"f0: expected reflectances in [0, 1], got min {f0.min()} max "
                             f"{f0.max()}")
    # named here: glint_ndf only sees the half vectors (its `s`)
    broadcast_batch(center=as_float_array(center, "center", ndim_min=1, last_dim=2).shape[:-1],
                    sigma_p=as_float_array(sigma_p, "sigma_p").shape, wo=wo.shape[:-1],
                    wi=wi.shape[:-1], f0=f0.shape[:-1])
    h = half(wo, wi)
    D = glint_ndf(surf, center, sigma_p, h[..., :2], fallback_truncation=fallback_truncation)
    return brdf_cos_from_ndf(wo, wi, h, D, f0)


def brdf_cos_from_ndf(wo, wi, h, D, f0):
    """:func:`glint_brdf_cos` given its unit ``wo``, ``wi``, half vector ``h`` (..., 3), NDF
    value ``D (...)`` and ``f0 (..., C)`` (the quad lights' fused MIS and ``glints-wang``)."""
    G = vcavity_g2(wo, wi, h)
    ok = (wo[..., 2] > 0.0) & (wi[..., 2] > 0.0) & (h[..., 2] > 0.0)
    val = np.where(ok, D * G / (4.0 * np.where(ok, wo[..., 2], 1.0)), 0.0)
    return val[..., None] * schlick(f0, np.sum(wi * h, axis=-1))


# ------------------------------------------------------- several points per footprint (quad MIS)
# The quad lights' MIS (prefilter.glints.render.quad_mis) needs, per footprint, the NDF at its
# 2 QUAD_MIS half vectors, the direct sampler's QUAD_MIS draws and their exact densities. The
# kernels below evaluate all points of a footprint in one walk over its texels, with the
# arithmetic of the single-point kernels per point (the same values to rounding), so that each
# texel's element is loaded, and its covariance formed, once instead of once per point. Their
# per-texel loops are written to vectorise (prefilter.glints._simd: division without Numba's
# zero check, a polynomial exp) and run over a footprint's whole window: on the near quad
# frame's 2 560 footprints (950 000 texels, 8 points each) the one-walk kernel went 52 -> 29 ms.

#: Exponent below which an element's angular Gaussian is dropped from the NDF: ``exp(-18)``, 6 of
#: its stds (the cut ``quad < 36`` of :func:`_direct_rows`).
_ANGULAR_CUT = -18.0


@njit_inline
def _row_gaussians(J00, J01, J10, J11, SX, SY, r, xs, nx, fdx, fdy, var, sr2, wx, wy, T, o):
    """Texels ``xs .. xs + nx - 1`` of row ``r`` of the element planes as Gaussians in ``s``
    (Yan et al. 2016: the element's slope marginal conditioned on the footprint), written to
    ``T[:, o:o + nx]`` (``T (6, >= o + nx)``): the shifted means ``T[0], T[1]`` (``s_i + J_i
    (f dx, f dy)``), the exponent's coefficients ``T[2..4]`` (``-e^T cov^-1 e / 2 = T2 ex^2 + T3
    ex ey + T4 ey^2`` for the covariance ``sr2 + var J J^T``) and the weight ``T[5] = wy wx /
    sqrt(det cov)`` (footprint weights ``wy`` of the row, ``wx`` of the columns). Branch- and
    check-free, so it vectorises."""
    a0 = J00[r, xs:xs + nx]
    a1 = J01[r, xs:xs + nx]
    b0 = J10[r, xs:xs + nx]
    b1 = J11[r, xs:xs + nx]
    sxr = SX[r, xs:xs + nx]
    syr = SY[r, xs:xs + nx]
    for i in range(nx):
        j00, j01, j10, j11 = a0[i], a1[i], b0[i], b1[i]
        a = sr2 + var * (j00 * j00 + j01 * j01)
        d = sr2 + var * (j10 * j10 + j11 * j11)
        b = var * (j00 * j10 + j01 * j11)
        det = a * d - b * b  # >= sr^4 > 0 (Cauchy-Schwarz)
        nh = fdiv(-0.5, det)
        T[0, o + i] = sxr[i] + (j00 * fdx[i] + j01 * fdy)
        T[1, o + i] = syr[i] + (j10 * fdx[i] + j11 * fdy)
        T[2, o + i] = d * nh
        T[3, o + i] = -2.0 * b * nh
        T[4, o + i] = a * nh
        T[5, o + i] = fdiv(wy * wx[i], math.sqrt(det))


@njit_inline
def _exponents(qx, qy, T, n, t):  # pragma: no cover - compiled
    """``t[i]``: the exponent of Gaussian ``i < n`` of ``T`` (:func:`_row_gaussians`) at the
    point ``(qx, qy)`` (vectorised; callers test it against the cut before the exponential)."""
    for i in range(n):
        ex = qx - T[0, i]
        ey = qy - T[1, i]
        t[i] = T[2, i] * ex * ex + T[3, i] * ex * ey + T[4, i] * ey * ey


@njit_parallel
def _direct_rows_k(SX, SY, J00, J01, J10, J11, cx, cy, sp, qx, qy, sr, sh, trunc, out):
    """:func:`_direct_rows` at ``K`` points per footprint: ``qx, qy, out (N, K)``. The window's
    Gaussians (:func:`_row_gaussians`) are formed once and shared by the ``K`` points; each
    point's sum is one loop over the whole window (rows of ~20 texels left most of the vector
    loops' work to their scalar remainders)."""
    H = SX.shape[0]
    W = SX.shape[1] // 2
    K = qx.shape[1]
    sh2 = sh * sh
    sr2 = sr * sr
    for q in prange(out.shape[0]):
        f, var, inv, x0, y0, y1, nx, xs, wx, fdx, sx = _footprint_columns(
            cx[q], cy[q], sp[q], sh2, trunc, W)
        n = nx * (y1 - y0 + 1)
        T = np.empty((6, n))
        t = np.empty(n)
        sy = 0.0
        for y in range(y0, y1 + 1):
            dy = cy[q] - (y + 0.5)
            wy = math.exp(-dy * dy * inv)
            sy += wy
            _row_gaussians(J00, J01, J10, J11, SX, SY, y % H, xs, nx, fdx, f * dy, var, sr2, wx,
                           wy, T, (y - y0) * nx)
        for k in range(K):
            _exponents(qx[q, k], qy[q, k], T, n, t)
            acc = 0.0
            for i in range(n):
                if t[i] > _ANGULAR_CUT:
                    acc += T[5, i] * exp_neg(t[i])
            out[q, k] = acc / (2.0 * math.pi * sx * sy)


def direct_ndf_k(surf, center, sigma_p, s, *, truncation: float = FALLBACK_TRUNCATION):
    """:func:`direct_ndf` at ``K`` points per footprint: ``center (N, 2)``, ``sigma_p (N,)``,
    ``s (N, K, 2)`` -> ``(N, K)``, each footprint's texels walked once for its ``K`` points
    (footprints wider than the map: :func:`direct_ndf` point by point)."""
    if surf.elements_ is None:
        raise PrefilterError("surf: the direct P-NDF needs the normal map "
                             "(surface(gm, normal_map))")
    if not (1.0 <= float(truncation) <= 8.0):
        raise PrefilterError(f"truncation: expected a number of stds in [1, 8], got {truncation}")
    s_el, J = surf.elements_
    cc = np.ascontiguousarray
    c = cc(center, dtype=np.float64)
    q = np.asarray(s, dtype=np.float64)
    N, K = q.shape[:2]
    sp = cc(np.broadcast_to(np.asarray(sigma_p, dtype=np.float64), (N,)))
    out = np.empty((N, K))
    W = s_el.shape[1]
    wide = 2.0 * float(truncation) * np.sqrt(sp * sp + SIGMA_H * SIGMA_H) + 2.0 > W
    k = ~wide
    if np.any(k):
        o = np.empty((int(k.sum()), K))
        _serial_below(_direct_rows_k, o.shape[0])(
            *_element_planes(s_el, J), cc(c[k, 0]), cc(c[k, 1]), sp[k], cc(q[k, :, 0]),
            cc(q[k, :, 1]), surf.intrinsic_roughness, SIGMA_H, float(truncation), o)
        out[k] = o
    if np.any(wide):
        n = int(wide.sum())
        out[wide] = direct_ndf(surf, np.repeat(c[wide], K, 0), np.repeat(sp[wide], K),
                               q[wide].reshape(n * K, 2), truncation=truncation).reshape(n, K)
    return out


@njit_parallel
def _direct_sample_k(s_el, J, cx, cy, sp, sr, sh, trunc, lim2, u, out_s, out_pdf):
    """``K`` draws per footprint from the direct P-NDF's element mixture (the arithmetic of
    :func:`prefilter.glints.sample._direct_kernel`, uniforms ``u (N, K, 3)``) and their exact
    densities (that of :func:`prefilter.glints.pndf.pndf`'s kernel, cut at ``quad < 8 trunc^2``):
    the footprint weights are computed once and serve the element choices and the densities.
    Footprints at the sigma_p -> inf limit (``tot2 >= lim2``) are left to the caller."""
    H, W = s_el.shape[0], s_el.shape[1]
    K = u.shape[1]
    sh2 = sh * sh
    cut = 2.0 * trunc * trunc * 4.0
    for q in prange(out_pdf.shape[0]):
        sp2 = sp[q] * sp[q]
        tot2 = sp2 + sh2
        if tot2 >= lim2:
            continue
        f = sh2 / tot2
        var = sp2 * sh2 / tot2
        rad = trunc * math.sqrt(tot2)
        x0, x1 = texel_window(cx[q], rad)
        y0, y1 = texel_window(cy[q], rad)
        nx = x1 - x0 + 1
        wb = np.empty(nx * (y1 - y0 + 1))
        wsum = 0.0
        n = 0
        for y in range(y0, y1 + 1):
            dy = cy[q] - (y + 0.5)
            for x in range(x0, x1 + 1):
                dx = cx[q] - (x + 0.5)
                wb[n] = math.exp(-(dx * dx + dy * dy) / (2.0 * tot2))
                wsum += wb[n]
                n += 1
        for k in range(K):
            t = u[q, k, 0] * wsum
            run = 0.0
            n = 0
            bx, by = x1, y1
            done = False
            for y in range(y0, y1 + 1):
                for x in range(x0, x1 + 1):
                    run += wb[n]
                    n += 1
                    if t < run:
                        bx, by = x, y
                        done = True
                        break
                if done:
                    break
            dx = cx[q] - (bx + 0.5)
            dy = cy[q] - (by + 0.5)
            mx, my, a, b, d = element_moments(s_el, J, by % H, bx % W, dx, dy, f, var)
            a += sr * sr
            d += sr * sr
            l11 = math.sqrt(a)
            l21 = b / l11
            l22 = math.sqrt(max(d - l21 * l21, 0.0))
            rr = math.sqrt(-2.0 * math.log(1.0 - u[q, k, 1]))
            z1 = rr * math.cos(2.0 * math.pi * u[q, k, 2])
            z2 = rr * math.sin(2.0 * math.pi * u[q, k, 2])
            out_s[q, k, 0] = mx + l11 * z1
            out_s[q, k, 1] = my + l21 * z1 + l22 * z2
        acc = np.zeros(K)
        n = 0
        for y in range(y0, y1 + 1):
            dy = cy[q] - (y + 0.5)
            r = y % H
            for x in range(x0, x1 + 1):
                dx = cx[q] - (x + 0.5)
                w = wb[n]
                n += 1
                mx, my, a, b, d = element_moments(s_el, J, r, x % W, dx, dy, f, var)
                a += sr * sr
                d += sr * sr
                det = a * d - b * b
                for k in range(K):
                    ex = out_s[q, k, 0] - mx
                    ey = out_s[q, k, 1] - my
                    quad = (d * ex * ex - 2.0 * b * ex * ey + a * ey * ey) / det
                    if quad < cut:
                        acc[k] += w * math.exp(-0.5 * quad) / (2.0 * math.pi * math.sqrt(det))
        for k in range(K):
            out_pdf[q, k] = acc[k] / wsum


def sample_s_direct_k(surf, center, sigma_p, u):
    """:func:`prefilter.glints.sample.sample_s_direct` for ``K`` draws per footprint:
    ``center (N, 2)``, ``sigma_p (N,)``, uniforms ``u (N, K, 3)`` -> ``s (N, K, 2)``,
    ``pdf (N, K)`` (the same draws and densities to rounding, in one walk per footprint)."""
    from prefilter.glints.pndf import TRUNCATION, wide_limit2
    from prefilter.glints.sample import sample_s_direct

    if surf.elements_ is None:
        raise PrefilterError("surf: direct sampling needs the normal map (surface(gm, normal_map))")
    cc = np.ascontiguousarray
    c = cc(center, dtype=np.float64)
    uu = cc(u, dtype=np.float64)
    N, K = uu.shape[:2]
    sp = cc(np.broadcast_to(np.asarray(sigma_p, dtype=np.float64), (N,)))
    s_el, J = surf.elements_
    lim2 = wide_limit2(s_el)
    s = np.zeros((N, K, 2))
    pdf = np.zeros((N, K))
    _serial_below(_direct_sample_k, N)(s_el, J, cc(c[:, 0]), cc(c[:, 1]), sp,
                                       surf.intrinsic_roughness, SIGMA_H, TRUNCATION, lim2, uu,
                                       s, pdf)
    wide = sp * sp + SIGMA_H * SIGMA_H >= lim2
    if np.any(wide):  # the sigma_p -> inf limit of pndf: the single-point functions
        n = int(wide.sum())
        sw, pw = sample_s_direct(surf, np.repeat(c[wide], K, 0), np.repeat(sp[wide], K),
                                 u=uu[wide].reshape(n * K, 3))
        s[wide], pdf[wide] = sw.reshape(n, K, 2), pw.reshape(n, K)
    return s, pdf


@njit_parallel
def _sample_masses_k(A, Bp, C, block_index, image_cell, granks, idx, wts, bm, u, lo, h, out_s,
                     out_pdf):
    """:func:`prefilter.glints.sample._sample_kernel` for ``K`` draws per footprint (uniforms
    ``u (N, K, k)``) with the footprint's block masses ``bm (N, nb * nb)`` given: they depend on
    the footprint only, and were the kernel's cost (every block's mass for every draw)."""
    for q in prange(out_pdf.shape[0]):
        cm = np.empty(4)
        ci = np.empty((4, 4), np.int64)
        for kk in range(u.shape[1]):
            out_s[q, kk, 0], out_s[q, kk, 1], out_pdf[q, kk] = quadtree_draw(
                A, Bp, C, block_index, image_cell, granks, idx, wts, q, bm[q], u[q, kk], lo, h,
                cm, ci)


@njit_parallel
def _block_sums(A, Bp, C, block_index, image_cell, granks, idx, wts, out):
    """Pixel sum of every stored block of every image, ``out (n_images, nb, nb)`` (0 where the
    block is dropped): ``_rect_mass`` of image ``idx[q, 0] = q`` with weight 1 over the block."""
    B = A.shape[1] - 1
    nb = block_index.shape[1]
    for q in prange(out.shape[0]):
        for bi in range(nb):
            for bj in range(nb):
                out[q, bi, bj] = _rect_mass(A, Bp, C, block_index, image_cell, granks, idx, wts,
                                            q, bi, bj, 0, B, 0, B)


@njit_parallel
def _block_masses_from_sums(T, block_index, idx, wts, out):
    """Block masses ``out (N, nb, nb)`` of blends ``(idx, wts)`` from the per-image block sums
    ``T`` (:func:`_block_sums`), in ``_rect_mass``'s order of terms (the same values)."""
    nb = block_index.shape[1]
    for q in prange(out.shape[0]):
        for bi in range(nb):
            for bj in range(nb):
                acc = 0.0
                for c in range(idx.shape[1]):
                    w = wts[q, c]
                    if w == 0.0:
                        continue
                    img = idx[q, c]
                    if block_index[img, bi, bj] < 0:
                        continue
                    acc += w * T[img, bi, bj]
                out[q, bi, bj] = acc


_SUMS: dict = {}


def _block_sum_table(gm):
    """:func:`_block_sums` of ``gm`` (cached while the map lives; 1365 x 16 x 16 for the 128^2
    render map: 2.8 MB)."""
    from prefilter.glints.query import kernel_args

    key = id(gm)
    hit = _SUMS.get(key)
    if hit is None or hit[0]() is not gm:
        arrs = kernel_args(gm)[0]
        n, nb = gm.block_index.shape[0], gm.block_index.shape[1]
        T = np.empty((n, nb, nb))
        _serial_below(_block_sums, n)(*arrs, np.arange(n, dtype=np.int64)[:, None],
                                      np.ones((n, 1)), T)
        hit = _SUMS[key] = (weakref.ref(gm), T)
        weakref.finalize(gm, _SUMS.pop, key, None)
    return hit[1]


def sample_s_k(gm: GlintsMap, center, sigma_p, u):
    """:func:`prefilter.glints.sample.sample_s` for ``K`` draws per footprint: ``center (N, 2)``,
    ``sigma_p (N,)``, uniforms ``u (N, K, n_uniforms(gm))`` -> ``s (N, K, 2)``, ``pdf (N, K)``
    and the footprints' NDF masses ``M (N,)`` (:func:`prefilter.glints.sample.mass`), the block
    masses computed once per footprint (the same draws, densities and masses to rounding)."""
    from prefilter.glints.pyramid import interp_weights
    from prefilter.glints.query import kernel_args

    cc = np.ascontiguousarray
    c = cc(center, dtype=np.float64)
    uu = cc(u, dtype=np.float64)
    N, K = uu.shape[:2]
    sp = cc(np.broadcast_to(np.asarray(sigma_p, dtype=np.float64), (N,)))
    # the block masses from per-image block sums: 8 products per block instead of 8 rank-long
    # sums (the compressed sampler's cost: every block for every draw and density)
    idx, w = interp_weights(gm.pyramid, c, sp)
    idx, w = cc(idx), cc(w)
    bm = np.empty((N,) + gm.block_index.shape[1:])
    _serial_below(_block_masses_from_sums, N)(_block_sum_table(gm), gm.block_index, idx, w, bm)
    h = 2.0 * gm.support / gm.resolution
    M = bm.sum(axis=(-2, -1)) * h * h
    s = np.empty((N, K, 2))
    pdf = np.empty((N, K))
    _serial_below(_sample_masses_k, N)(*kernel_args(gm)[0], idx, w, cc(bm.reshape(N, -1)), uu,
                                       -gm.support, h, s, pdf)
    return s, pdf, M


@njit_parallel
def _direct_mis_k(SX, SY, J00, J01, J10, J11, s_el, J, cx, cy, sp, qlx, qly, u, sr, sh, trunc,
                  out_s, out_pdf, out_dl, out_db):
    """Everything the quad MIS needs of a footprint's direct P-NDF in one walk over its texels:
    the NDF (as :func:`_direct_rows`) at the ``P`` light samples' half vectors ``qlx, qly (N, P)``
    -> ``out_dl``; ``P`` draws from the element mixture (uniforms ``u (N, P, 3)``, as
    ``sample._direct_kernel``) -> ``out_s (N, P, 2)``, their density (as ``pndf``: cut at
    ``quad < 8 trunc^2``) -> ``out_pdf`` and the NDF at them (the BRDF sample's half vector is
    the draw) -> ``out_db``. The footprint weights are separable (one exp per row and column, the
    single-point kernels' per-texel weights to rounding) and shared by the draws and the sums;
    a texel's term is formed once for the density and the NDF of a draw."""
    H = SX.shape[0]
    W = SX.shape[1] // 2
    P = qlx.shape[1]
    Hs, Ws = s_el.shape[0], s_el.shape[1]
    sh2 = sh * sh
    sr2 = sr * sr
    pdf_cut = -4.0 * trunc * trunc  # quad < 8 trunc^2
    for q in prange(out_pdf.shape[0]):
        f, var, inv, x0, y0, y1, nx, xs, wx, fdx, sx = _footprint_columns(
            cx[q], cy[q], sp[q], sh2, trunc, W)
        ny = y1 - y0 + 1
        wy = np.empty(ny)
        sy = 0.0
        for j in range(ny):
            dy = cy[q] - (y0 + j + 0.5)
            wy[j] = math.exp(-dy * dy * inv)
            sy += wy[j]
        qx = np.empty(2 * P)
        qy = np.empty(2 * P)
        for k in range(P):
            qx[k] = qlx[q, k]
            qy[k] = qly[q, k]
            # the texel of weight wy_j wx_i / (sx sy): its row by the rows' masses wy_j sx, then
            # its column (ny + nx steps instead of a scan over the ny nx texels)
            tu = u[q, k, 0] * sy
            bj = ny - 1
            run = 0.0
            for j in range(ny):
                run += wy[j]
                if tu < run:
                    bj = j
                    break
            tu = (tu - (run - wy[bj])) * sx
            bi = nx - 1
            run = 0.0
            for i in range(nx):
                run += wy[bj] * wx[i]
                if tu < run:
                    bi = i
                    break
            mx, my, a, b, d = element_moments(s_el, J, (y0 + bj) % Hs, (x0 + bi) % Ws,
                                              cx[q] - (x0 + bi + 0.5), cy[q] - (y0 + bj + 0.5),
                                              f, var)
            a += sr2
            d += sr2
            # Cholesky of [[a, b], [b, d]] applied to a Box-Muller pair
            l11 = math.sqrt(a)
            l21 = b / l11
            l22 = math.sqrt(max(d - l21 * l21, 0.0))
            rr = math.sqrt(-2.0 * math.log(1.0 - u[q, k, 1]))
            z1 = rr * math.cos(2.0 * math.pi * u[q, k, 2])
            z2 = rr * math.sin(2.0 * math.pi * u[q, k, 2])
            qx[P + k] = mx + l11 * z1
            qy[P + k] = my + l21 * z1 + l22 * z2
            out_s[q, k, 0] = qx[P + k]
            out_s[q, k, 1] = qy[P + k]
        n = nx * ny
        T = np.empty((6, n))
        t = np.empty(n)
        for j in range(ny):
            y = y0 + j
            _row_gaussians(J00, J01, J10, J11, SX, SY, y % H, xs, nx, fdx, f * (cy[q] - (y + 0.5)),
                           var, sr2, wx, wy[j], T, j * nx)
        acc = np.zeros(2 * P)
        accp = np.zeros(P)
        for k in range(2 * P):
            _exponents(qx[k], qy[k], T, n, t)
            racc = 0.0
            if k < P:
                for i in range(n):
                    if t[i] > _ANGULAR_CUT:
                        racc += T[5, i] * exp_neg(t[i])
            else:
                pacc = 0.0
                for i in range(n):
                    if t[i] > pdf_cut:
                        e = T[5, i] * exp_neg(t[i])
                        pacc += e
                        if t[i] > _ANGULAR_CUT:
                            racc += e
                accp[k - P] = pacc
            acc[k] = racc
        for k in range(P):
            out_dl[q, k] = acc[k] / (2.0 * math.pi * sx * sy)
            out_db[q, k] = acc[P + k] / (2.0 * math.pi * sx * sy)
            out_pdf[q, k] = accp[k] / (2.0 * math.pi * sx * sy)


def direct_mis_fits(surf, sigma_p) -> np.ndarray:
    """Footprints ``(N,)`` whose direct P-NDF :func:`direct_mis_k` evaluates: rows narrower
    than the map and below the P-NDF's sigma_p -> inf limit (``pndf.wide_limit2``)."""
    from prefilter.glints.pndf import TRUNCATION, wide_limit2

    s_el = surf.elements_[0]
    tot2 = np.asarray(sigma_p, dtype=np.float64) ** 2 + SIGMA_H * SIGMA_H
    return (2.0 * TRUNCATION * np.sqrt(tot2) + 2.0 <= s_el.shape[1]) & (tot2 < wide_limit2(s_el))


def direct_mis_k(surf, center, sigma_p, q_light, u):
    """The quad MIS's direct P-NDF of footprints ``center (N, 2)``, ``sigma_p (N,)`` (all
    :func:`direct_mis_fits`) in one walk each (:func:`_direct_mis_k`, 4-std truncation):
    ``D_light (N, P)`` at ``q_light (N, P, 2)``; draws ``s (N, P, 2)`` for uniforms
    ``u (N, P, 3)`` as :func:`prefilter.glints.sample.sample_s_direct`, their density
    ``pdf (N, P)`` (its ``pndf``) and ``D_draw (N, P)`` at them; all to rounding."""
    from prefilter.glints.pndf import TRUNCATION

    cc = np.ascontiguousarray
    c = cc(center, dtype=np.float64)
    ql = np.asarray(q_light, dtype=np.float64)
    uu = cc(u, dtype=np.float64)
    N, P = uu.shape[:2]
    sp = cc(np.broadcast_to(np.asarray(sigma_p, dtype=np.float64), (N,)))
    if not np.all(direct_mis_fits(surf, sp)):
        raise PrefilterError("sigma_p: expected footprints narrower than the map "
                             "(direct_mis_fits)")
    s_el, J = surf.elements_
    s = np.empty((N, P, 2))
    pdf, dl, db = np.empty((N, P)), np.empty((N, P)), np.empty((N, P))
    _serial_below(_direct_mis_k, N)(*_element_planes(s_el, J), s_el, J, cc(c[:, 0]), cc(c[:, 1]),
                                    sp, cc(ql[..., 0]), cc(ql[..., 1]), uu,
                                    surf.intrinsic_roughness, SIGMA_H, TRUNCATION, s, pdf, dl, db)
    return dl, s, pdf, db
