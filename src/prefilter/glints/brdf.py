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

import numpy as np

from prefilter.jit import njit_inline, njit_parallel, prange, serial
from prefilter.validation import as_directions, as_float_array, broadcast_batch
from prefilter.errors import PrefilterError
from prefilter.microfacet.fresnel import schlick
from prefilter.glints.pndf import (SIGMA_H, as_footprints, element_covariance, element_density,
                                   element_gaussian, footprint_window, pndf)
from prefilter.glints._simd import exp_neg, fdiv
from prefilter.glints.query import point_flat
from prefilter.glints.surface import GlintSurface, as_surface, surface  # noqa: F401  (public here)


#: Spatial truncation the render methods use for the direct P-NDF fallback below the finest
#: level, in stds of the element weights per axis (as ``pndf``). Cutting it to 3 visits (3/4)^2
#: of the texels and changes the NDF by only 0.6 % relative L2, but drops the glints of texels
#: 3-4 stds away (HDR-FLIP of the near measurement frame vs glints-direct 0.174 at 3, 0.104 at
#: 3.5, 0.067 at 4).
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
        x0, x1, y0, y1, f, var, tot2, _ = footprint_window(cx[q], cy[q], sp[q], sh2, trunc, H, W,
                                                           np.inf)
        sv = math.sqrt(var)
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
                mx, my, a, b, d = element_gaussian(s_el, J, r, c, dx, dy, f, var, sr2)
                ex = qx[q] - mx
                ey = qy[q] - my
                # quad >= |e|^2 / trace(cov): cheap rejection before the exact form
                if ex * ex + ey * ey > 36.0 * (a + d):
                    continue
                acc += wy * wx[i] * element_density(ex, ey, a, b, d, 36.0)
        out[q] = acc / (sx * sy)


@njit_inline
def _footprint_columns(cx, cy, sp, sh2, trunc, W):  # pragma: no cover - compiled
    """A footprint's texel window and its column factors for the row kernels (Yan et al. 2016
    weights ``exp(-|u_p - u_i|^2 / (2 (sigma_p^2 + sigma_h^2)))``, separable): mean-shift factor
    ``f``, element variance ``var``, ``inv = 1 / (2 tot2)``, window ``x0, y0, y1``, ``nx``
    columns starting at ``xs`` in the doubled planes (width ``2 W``), column weights ``wx`` and
    their sum ``sx``, and ``fdx = f dx`` per column."""
    x0, x1, y0, y1, f, var, tot2, _ = footprint_window(cx, cy, sp, sh2, trunc, 0, W, np.inf)
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
    rejects 2/3 of the near frame's texels but pays a mispredicted branch and three scattered
    loads for each (this kernel takes about half its time, the same values to 1e-15)."""
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
                a, b, d = element_covariance(j00, j01, j10, j11, var, sr2)
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
    q = as_float_array(s, "s", ndim_min=1, last_dim=2)
    c, sp, shape = as_footprints(center, sigma_p, s=q.shape[:-1])
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
    return val[..., None] * schlick(f0, np.sum(wi * h, axis=-1)[..., None])


# ------------------------------------------------------- several points per footprint (quad MIS)
# The quad lights' MIS (prefilter.glints.render.quad_mis) needs, per footprint, the NDF at its
# 2 QUAD_MIS half vectors, the direct sampler's QUAD_MIS draws and their exact densities. The
# kernels below evaluate all points of a footprint in one walk over its texels, with the
# arithmetic of the single-point kernels per point (the same values to rounding), so that each
# texel's element is loaded, and its covariance formed, once instead of once per point. Their
# per-texel loops are written to vectorise (prefilter.glints._simd: division without Numba's
# zero check, a polynomial exp) and run over a footprint's whole window (on the near quad
# frame's 2 560 footprints, 950 000 texels, 8 points each, about half the time of per-point
# walks).

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
        a, b, d = element_covariance(j00, j01, j10, j11, var, sr2)
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
