"""Exact hierarchical importance sampling of footprint NDFs (glints paper, sec. 5.2).

For a footprint ``(center, sigma_p)`` the NDF image is the trilinear blend of 8 compressed pyramid
images (as in :func:`prefilter.glints.point`). Sampling, per query (one Numba kernel):

1. choose an angular block with probability proportional to its mass (block means of the blended
   image, from the CP prefix sums:
   ``sum_c w_c sum_r c_r[k_c] (A_r[B] - A_r[0]) (B_r[B] - B_r[0])``);
2. descend the block's quadtree: split the current rectangle of pixels into (up to) four, the
   children's masses by range queries (eq. 7, products of prefix-sum differences), choose one
   proportionally, until one pixel remains;
3. jitter uniformly inside the pixel.

The image is piecewise constant and the child masses add up exactly to the parent's, so the pdf
of ``s`` is ``value(pixel) / (M h^2)`` with ``M`` the sum of all pixel values and ``h`` the pixel
pitch: the sampler returns the product of the probabilities it actually used (over ``h^2``), and
the tests check that it equals the evaluated normalised NDF :func:`ndf_pdf`.

Directions: the half vector ``m = (s, sqrt(1 - |s|^2))`` has solid-angle pdf ``pdf_s(s) m_z``
(``dw = ds / m_z``), i.e. samples follow ``D(m) m_z / M``; ``wi = reflect(wo, m)`` has pdf
``pdf_m / (4 |wo.m|)``.
"""

from __future__ import annotations

import math
import weakref

import numpy as np

from prefilter.jit import kernel_array, njit_inline, njit_parallel, njit_serial, prange, serial
from prefilter.validation import as_directions, as_float_array, as_rng
from prefilter.errors import PrefilterError
from prefilter.glints._qkernels import _quad_masses, _rect_mass
from prefilter.glints._simd import exp_neg
from prefilter.glints.brdf import (_ANGULAR_CUT, _element_planes, _exponents, _footprint_columns,
                                   _row_gaussians, _serial_below, direct_ndf)
from prefilter.glints.pndf import (SIGMA_H, TRUNCATION, as_footprints, choose_texel,
                                   element_density, element_draw, element_gaussian,
                                   footprint_weights, footprint_window, pndf, wide_limit2)
from prefilter.glints.pyramid import interp_weights
from prefilter.glints.query import kernel_args, point, wrap_centers
from prefilter.glints.store import GlintsMap
from prefilter.glints.surface import GlintSurface, as_surface


@njit_parallel
def _block_masses(A, Bp, C, block_index, image_cell, granks, idx, wts, out):
    """Masses ``out (N, nb, nb)`` (sums of pixel values) of every block of the blended images."""
    B = A.shape[1] - 1
    nb = block_index.shape[1]
    for q in prange(out.shape[0]):
        for bi in range(nb):
            for bj in range(nb):
                out[q, bi, bj] = _rect_mass(A, Bp, C, block_index, image_cell, granks, idx, wts, q,
                                            bi, bj, 0, B, 0, B)


@njit_serial
def choose_index(masses, n, u):
    """Index ``k`` in ``[0, n)`` drawn by the uniform ``u`` with probability ``masses[k] / sum``
    of ``masses (>= n,)``, and that probability; ``(-1, 0)`` if all are zero."""
    tot = 0.0
    for k in range(n):
        tot += masses[k]
    if not tot > 0.0:
        return -1, 0.0
    t = u * tot
    last = -1
    run = 0.0
    for k in range(n):
        if masses[k] > 0.0:
            last = k
            run += masses[k]
            if t < run:
                return k, masses[k] / tot
    return last, masses[last] / tot


@njit_inline
def quadtree_draw(A, Bp, C, block_index, image_cell, granks, idx, wts, q, bm, u, lo, h, cm, ci):
    """One draw ``(s_x, s_y, pdf)`` from footprint ``q``'s blended NDF (sec. 5.2): a block by
    its mass ``bm (nb * nb,)`` (uniform ``u[0]``), a quadtree descent by the exact masses of the
    sub-rectangles (``u[1:]``, one per level), uniform jitter in the final pixel (the last two);
    ``(0, 0, 0)`` where every block is empty. ``cm (4,)``, ``ci (4, 4) int64``: scratch for the
    children's masses and bounds (allocated once per footprint by the callers)."""
    B = A.shape[1] - 1
    nb = block_index.shape[1]
    kb, p = choose_index(bm, nb * nb, u[0])
    if kb < 0:
        return 0.0, 0.0, 0.0
    bi, bj = kb // nb, kb % nb
    i0, i1, j0, j1 = 0, B, 0, B
    lev = 1
    ci0, ci1, cj0, cj1 = ci[0], ci[1], ci[2], ci[3]
    while i1 - i0 > 1 or j1 - j0 > 1:
        im = (i0 + i1) // 2 if i1 - i0 > 1 else i1
        jm = (j0 + j1) // 2 if j1 - j0 > 1 else j1
        # the 2-4 children's masses in one pass (they share the parent's prefix-sum rows), then
        # the non-empty ones compacted in place (n <= 2 ra + rb)
        _quad_masses(A, Bp, C, block_index, image_cell, granks, idx, wts, q, bi, bj, i0, im, i1,
                     j0, jm, j1, cm)
        n = 0
        for ra in range(2):
            a0, a1 = (i0, im) if ra == 0 else (im, i1)
            if a1 <= a0:
                continue
            for rb in range(2):
                b0, b1 = (j0, jm) if rb == 0 else (jm, j1)
                if b1 <= b0:
                    continue
                ci0[n], ci1[n], cj0[n], cj1[n] = a0, a1, b0, b1
                cm[n] = cm[2 * ra + rb]
                n += 1
        k, pk = choose_index(cm, n, u[lev])
        p *= pk
        i0, i1, j0, j1 = ci0[k], ci1[k], cj0[k], cj1[k]
        lev += 1
    return (lo + (bj * B + j0 + u[lev]) * h, lo + (bi * B + i0 + u[lev + 1]) * h,
            p / (h * h))


def n_uniforms(gm: GlintsMap) -> int:
    """Uniform numbers used per sample: block choice, one per quadtree level, 2 for the jitter."""
    return 3 + int(math.ceil(math.log2(max(gm.block, 1)))) if gm.block > 1 else 3


def _period(surf) -> tuple[int, int]:
    """``(height, width)`` in texels of the tiling of a GlintsMap or GlintSurface."""
    if isinstance(surf, GlintsMap):
        return surf.pyramid.height, surf.pyramid.width
    if surf.normal_map is not None:
        return surf.normal_map.shape[:2]
    return surf.gm.pyramid.height, surf.gm.pyramid.width


def _prep(gm, center, sigma_p):
    if not isinstance(gm, GlintsMap):
        raise PrefilterError(f"gm: expected a GlintsMap (prefilter.glints.load), got "
                             f"{type(gm).__name__}")
    c, sp, shape = as_footprints(center, sigma_p)
    c = np.broadcast_to(wrap_centers(c, (gm.pyramid.height, gm.pyramid.width)), shape + (2,))
    c = c.reshape(-1, 2)
    sp = np.broadcast_to(sp, shape).reshape(-1)
    idx, w = interp_weights(gm.pyramid, c, sp)
    arrs = kernel_args(gm)[0]
    return shape, arrs, np.ascontiguousarray(idx), np.ascontiguousarray(w)


def block_masses(gm: GlintsMap, center, sigma_p) -> np.ndarray:
    """Sum of pixel values of each angular block ``(..., nb, nb)`` of the footprints' blended
    NDF images (the paper's block means times ``B^2``)."""
    shape, arrs, idx, w = _prep(gm, center, sigma_p)
    nb = gm.block_index.shape[1]
    out = np.empty((idx.shape[0], nb, nb))
    serial(_block_masses, len(out))(*arrs, idx, w, out)
    return out.reshape(shape + (nb, nb))


def mass(gm: GlintsMap, center, sigma_p) -> np.ndarray:
    """Integral ``M_s`` of the footprints' NDF images over the support (``(...)``; <= ~1)."""
    h = 2.0 * gm.support / gm.resolution
    return block_masses(gm, center, sigma_p).sum(axis=(-2, -1)) * h * h


def ndf_pdf(gm: GlintsMap, center, sigma_p, s) -> np.ndarray:
    """Normalised footprint NDF ``D_P(s) / M_s``: the density w.r.t. ``s`` that :func:`sample_s`
    samples (0 where the image is empty)."""
    s = as_float_array(s, "s", ndim_min=1, last_dim=2)
    v = point(gm, center, sigma_p, s)
    M = np.broadcast_to(mass(gm, center, sigma_p), v.shape)
    return np.where(M > 0, v / np.where(M > 0, M, 1.0), 0.0)


def _uniforms(gm, n, rng, u):
    k = n_uniforms(gm)
    if u is None:
        return as_rng(rng).random((n, k))
    a = as_float_array(u, "u")
    if a.shape != (n, k) or np.any((a < 0) | (a >= 1)):
        raise PrefilterError(f"u: expected uniform numbers in [0, 1) of shape {(n, k)}, got shape "
                             f"{a.shape}")
    return np.ascontiguousarray(a)


def sample_s(gm: GlintsMap, center, sigma_p, rng=0, *, u=None):
    """Projected half vectors ``s (..., 2)`` distributed as the footprints' NDF images.

    Parameters
    ----------
    gm : GlintsMap.
    center : (..., 2) footprint centres (texels); sigma_p : (...) stds (texels); they broadcast and
        give the sample shape ``(...)`` (repeat a footprint to draw many samples of it).
    rng : numpy Generator or int seed (ignored when ``u`` is given).
    u : optional ``(n, n_uniforms(gm))`` uniforms in ``[0, 1)``, ``n`` = number of samples.

    Returns
    -------
    s : (..., 2) samples; pdf : (...) their density w.r.t. ``s`` (product of the hierarchical
    choice probabilities over the pixel area); 0 (and ``s = 0``) for an empty image.
    """
    shape, arrs, idx, w = _prep(gm, center, sigma_p)
    uu = _uniforms(gm, idx.shape[0], rng, u)
    h = 2.0 * gm.support / gm.resolution
    n = idx.shape[0]
    nb = gm.block_index.shape[1]
    bm = np.empty((n, nb, nb))
    serial(_block_masses, n)(*arrs, idx, w, bm)
    s = np.empty((n, 1, 2))
    pdf = np.empty((n, 1))
    serial(_sample_masses_k, n)(*arrs, idx, w, bm.reshape(n, -1), uu.reshape(n, 1, -1),
                                -gm.support, h, s, pdf)
    return s.reshape(shape + (2,)), pdf.reshape(shape)


def half_from_s(s) -> np.ndarray:
    """Half vectors ``(..., 3)`` on the upper hemisphere from projected ones (``|s| <= 1``)."""
    s = np.asarray(s, dtype=np.float64)
    z = np.sqrt(np.maximum(1.0 - np.sum(s * s, axis=-1), 0.0))
    return np.concatenate([s, z[..., None]], axis=-1)


def sample_wi(gm, center, sigma_p, wo, rng=0, *, u=None):
    """Light directions by NDF sampling: ``m ~ D(m) m_z / M``, ``wi = 2 (wo.m) m - wo``.

    Parameters
    ----------
    gm : GlintsMap, or a :class:`prefilter.glints.surface.GlintSurface` with its normal map, in
        which case footprints below the finest level are drawn from the direct P-NDF
        (:func:`sample_s_direct`, as :func:`prefilter.glints.brdf.glint_ndf` evaluates them).
    wo : (..., 3) unit view directions in the geometric tangent frame (broadcast with the
        footprints).
    u : optional ``(n, k)`` uniforms in ``[0, 1)``, ``n`` = number of samples: ``k =
        n_uniforms(gm)`` for a GlintsMap; for a GlintSurface ``k >= 3`` (its map's
        ``n_uniforms`` when footprints use the compressed sampler), the direct sampler uses the
        first 3 columns.

    Returns
    -------
    wi : (..., 3); pdf : (...) solid-angle density of ``wi`` (``pdf_s m_z / (4 |wo.m|)``);
    samples with ``pdf == 0`` (empty image, ``|s| >= 1``, ``wo.m <= 0``) carry no estimate.
    """
    wo = as_directions(wo, "wo")
    c, sp, shape = as_footprints(center, sigma_p, wo=wo.shape[:-1])
    if isinstance(gm, (GlintSurface, GlintsMap)):  # others are refused below
        c = wrap_centers(c, _period(gm))
    c = np.broadcast_to(c, shape + (2,))
    sp = np.broadcast_to(sp, shape)
    if isinstance(gm, GlintSurface):
        surf = gm
        small = (sp < surf.sigma0) if surf.normal_map is not None else np.zeros(shape, bool)
        gen = as_rng(rng)
        s = np.zeros(shape + (2,))
        ps = np.zeros(shape)
        uf = None
        if u is not None:
            uf = as_float_array(u, "u")
            n = int(np.prod(shape))
            if uf.ndim != 2 or uf.shape[0] != n or uf.shape[1] < 3:
                raise PrefilterError(f"u: expected uniforms of shape ({n}, k >= 3), got "
                                     f"{uf.shape}")
            uf = uf.reshape(shape + (uf.shape[1],))
        if np.any(small):
            s[small], ps[small] = sample_s_direct(
                surf, c[small], sp[small], gen, u=None if uf is None else uf[small][:, :3])
        if np.any(~small):
            if surf.gm is None:
                raise PrefilterError("gm: footprints at or above sigma0 need a compressed map")
            k = n_uniforms(surf.gm)
            if uf is not None and uf.shape[-1] < k:
                raise PrefilterError(f"u: expected at least {k} uniforms per sample for this map, "
                                     f"got {uf.shape[-1]}")
            s[~small], ps[~small] = sample_s(surf.gm, c[~small], sp[~small], gen,
                                             u=None if uf is None else uf[~small][:, :k])
    else:
        s, ps = sample_s(gm, c, sp, rng, u=u)
    wo = np.broadcast_to(wo, shape + (3,))
    m = half_from_s(s)
    wom = np.sum(wo * m, axis=-1)
    ok = (ps > 0) & (np.sum(s * s, axis=-1) < 1.0) & (wom > 0)
    wi = 2.0 * wom[..., None] * m - wo
    pdf = np.where(ok, ps * m[..., 2] / (4.0 * np.where(ok, wom, 1.0)), 0.0)
    return wi, pdf


def pdf_wi(surf, center, sigma_p, wo, wi) -> np.ndarray:
    """Solid-angle density ``(...)`` with which :func:`sample_wi` (given ``surf``, a
    :class:`prefilter.glints.surface.GlintSurface` or a GlintsMap) draws ``wi (..., 3)`` from
    ``wo``:
    ``pdf_s(h_xy) h_z / (4 wo.h)`` with ``h`` the half vector; ``pdf_s`` is the direct P-NDF below
    the finest level (or everywhere for a surface without a compressed map), else
    :func:`ndf_pdf`. For multiple importance sampling with light samples."""
    surf = surf if isinstance(surf, GlintSurface) else as_surface(surf)
    wo = as_directions(wo, "wo")
    wi = as_directions(wi, "wi")
    c, sp, shape = as_footprints(center, sigma_p, wo=wo.shape[:-1], wi=wi.shape[:-1])
    c = np.broadcast_to(wrap_centers(c, _period(surf)), shape + (2,)).reshape(-1, 2)
    sp = np.broadcast_to(sp, shape).reshape(-1)
    wo = np.broadcast_to(wo, shape + (3,)).reshape(-1, 3)
    wi = np.broadcast_to(wi, shape + (3,)).reshape(-1, 3)
    h = wo + wi
    h = h / np.maximum(np.linalg.norm(h, axis=-1, keepdims=True), 1e-300)
    woh = np.sum(wo * h, -1)
    ok = (h[:, 2] > 0) & (woh > 0) & (wo[:, 2] > 0)
    small = (sp < surf.sigma0) if surf.normal_map is not None else np.zeros(sp.shape, bool)
    ps = np.zeros(sp.shape)
    d = ok & small
    if np.any(d):
        ps[d] = direct_ndf(surf, c[d], sp[d], h[d, :2], truncation=TRUNCATION)
    k = ok & ~small
    if np.any(k):
        if surf.gm is None:
            raise PrefilterError("gm: footprints at or above sigma0 need a compressed map")
        ps[k] = ndf_pdf(surf.gm, c[k], sp[k], h[k, :2])
    pdf = np.where(ok, ps * h[:, 2] / (4.0 * np.where(ok, woh, 1.0)), 0.0)
    return pdf.reshape(shape)


# ---------------------------------------------------------------------- direct P-NDF sampling


@njit_parallel
def _direct_kernel(s_el, J, cx, cy, sp, sr, sh, trunc, u, out):
    """Draw from the element mixture of Yan et al. 2016: element ``i`` with probability
    ``w_i / sum w``, then its Gaussian ``N(n_i + J_i mu_i, sr^2 I + var J_i J_i^T)``."""
    H, W = s_el.shape[0], s_el.shape[1]
    sh2 = sh * sh
    sr2 = sr * sr
    for q in prange(out.shape[0]):
        x0, x1, y0, y1, f, var, tot2, _ = footprint_window(cx[q], cy[q], sp[q], sh2, trunc, H, W,
                                                           np.inf)
        wb = np.empty((x1 - x0 + 1) * (y1 - y0 + 1))
        wsum = footprint_weights(cx[q], cy[q], x0, x1, y0, y1, tot2, wb)
        bx, by = choose_texel(wb, wsum, x0, x1, y0, y1, u[q, 0])
        mx, my, a, b, d = element_gaussian(s_el, J, by % H, bx % W, cx[q] - (bx + 0.5),
                                           cy[q] - (by + 0.5), f, var, sr2)
        out[q, 0], out[q, 1] = element_draw(mx, my, a, b, d, u[q, 1], u[q, 2])


def sample_s_direct(surf, center, sigma_p, rng=0, *, u=None):
    """Projected half vectors ``(..., 2)`` from the *direct* P-NDF of ``surf`` (a
    :class:`prefilter.glints.surface.GlintSurface` with its normal map) and their density
    ``pndf(s)`` (the exact mixture density, Yan et al. 2016). For footprints below the finest
    pyramid level, where :func:`prefilter.glints.brdf.glint_ndf` evaluates the direct P-NDF.
    ``u``: optional ``(n, 3)`` uniforms in ``[0, 1)`` (element choice, Box-Muller pair)."""
    surf = as_surface(surf)
    if surf.normal_map is None:
        raise PrefilterError("surf: direct sampling needs the normal map (surface(gm, normal_map))")
    c, sp, shape = as_footprints(center, sigma_p)
    c = wrap_centers(c, _period(surf))
    cf = kernel_array(c, shape + (2,)).reshape(-1, 2)
    spf = kernel_array(sp, shape, np.float64).reshape(-1)
    if u is None:
        u = as_rng(rng).random((cf.shape[0], 3))
    else:
        u = as_float_array(u, "u")
        if u.shape != (cf.shape[0], 3) or np.any((u < 0) | (u >= 1)):
            raise PrefilterError(f"u: expected uniforms in [0, 1) of shape {(cf.shape[0], 3)}, "
                                 f"got shape {u.shape}")
        u = np.ascontiguousarray(u)
    s = np.empty((cf.shape[0], 2))
    s_el, J = surf.elements_
    cc = np.ascontiguousarray
    serial(_direct_kernel, len(s))(s_el, J, cc(cf[:, 0]), cc(cf[:, 1]), spf,
                                   surf.intrinsic_roughness, SIGMA_H, TRUNCATION, u, s)
    pdf = pndf(surf.normal_map, cf, spf, s, surf.intrinsic_roughness, elements_=surf.elements_)
    return s.reshape(shape + (2,)), pdf.reshape(shape)


# ------------------------------------------------ several draws per footprint (quad MIS)


@njit_parallel
def _direct_sample_k(s_el, J, cx, cy, sp, sr, sh, trunc, lim2, u, out_s, out_pdf):
    """``K`` draws per footprint from the direct P-NDF's element mixture (the arithmetic of
    :func:`_direct_kernel`, uniforms ``u (N, K, 3)``) and their exact
    densities (that of :func:`prefilter.glints.pndf.pndf`'s kernel, cut at ``quad < 8 trunc^2``):
    the footprint weights are computed once and serve the element choices and the densities.
    Footprints at the sigma_p -> inf limit (``tot2 >= lim2``) are left to the caller."""
    H, W = s_el.shape[0], s_el.shape[1]
    K = u.shape[1]
    sh2 = sh * sh
    sr2 = sr * sr
    cut = 8.0 * trunc * trunc
    for q in prange(out_pdf.shape[0]):
        x0, x1, y0, y1, f, var, tot2, wide = footprint_window(cx[q], cy[q], sp[q], sh2, trunc,
                                                              H, W, lim2)
        if wide:
            continue
        wb = np.empty((x1 - x0 + 1) * (y1 - y0 + 1))
        wsum = footprint_weights(cx[q], cy[q], x0, x1, y0, y1, tot2, wb)
        for k in range(K):
            bx, by = choose_texel(wb, wsum, x0, x1, y0, y1, u[q, k, 0])
            mx, my, a, b, d = element_gaussian(s_el, J, by % H, bx % W, cx[q] - (bx + 0.5),
                                               cy[q] - (by + 0.5), f, var, sr2)
            out_s[q, k, 0], out_s[q, k, 1] = element_draw(mx, my, a, b, d, u[q, k, 1],
                                                          u[q, k, 2])
        acc = np.zeros(K)
        n = 0
        for y in range(y0, y1 + 1):
            dy = cy[q] - (y + 0.5)
            r = y % H
            for x in range(x0, x1 + 1):
                w = wb[n]
                n += 1
                mx, my, a, b, d = element_gaussian(s_el, J, r, x % W, cx[q] - (x + 0.5), dy, f,
                                                   var, sr2)
                for k in range(K):
                    acc[k] += w * element_density(out_s[q, k, 0] - mx, out_s[q, k, 1] - my, a, b,
                                                  d, cut)
        for k in range(K):
            out_pdf[q, k] = acc[k] / wsum


def sample_s_direct_k(surf, center, sigma_p, u):
    """:func:`sample_s_direct` for ``K`` draws per footprint:
    ``center (N, 2)``, ``sigma_p (N,)``, uniforms ``u (N, K, 3)`` -> ``s (N, K, 2)``,
    ``pdf (N, K)`` (the same draws and densities to rounding, in one walk per footprint)."""
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
    """``K`` draws per footprint (uniforms ``u (N, K, k)``, :func:`quadtree_draw`) given the
    footprints' block masses ``bm (N, nb * nb)``: they depend on the footprint only, so they are
    computed once for all its draws."""
    for q in prange(out_pdf.shape[0]):
        cm = np.empty(4)
        ci = np.empty((4, 4), np.int64)
        for kk in range(u.shape[1]):
            out_s[q, kk, 0], out_s[q, kk, 1], out_pdf[q, kk] = quadtree_draw(
                A, Bp, C, block_index, image_cell, granks, idx, wts, q, bm[q], u[q, kk], lo, h,
                cm, ci)


@njit_parallel
def _block_masses_from_sums(T, block_index, idx, wts, out):
    """Block masses ``out (N, nb, nb)`` of blends ``(idx, wts)`` from the per-image block sums
    ``T`` (:func:`_block_masses` of every image alone), in ``_rect_mass``'s order of terms (the
    same values)."""
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
    """Block sums of every image of ``gm`` (:func:`_block_masses`, image ``q`` with weight 1;
    cached while the map lives; 1365 x 16 x 16 for the 128^2 render map: 2.8 MB)."""
    key = id(gm)
    hit = _SUMS.get(key)
    if hit is None or hit[0]() is not gm:
        arrs = kernel_args(gm)[0]
        n, nb = gm.block_index.shape[0], gm.block_index.shape[1]
        T = np.empty((n, nb, nb))
        _serial_below(_block_masses, n)(*arrs, np.arange(n, dtype=np.int64)[:, None],
                                      np.ones((n, 1)), T)
        hit = _SUMS[key] = (weakref.ref(gm), T)
        weakref.finalize(gm, _SUMS.pop, key, None)
    return hit[1]


def sample_s_k(gm: GlintsMap, center, sigma_p, u):
    """:func:`sample_s` for ``K`` draws per footprint: ``center (N, 2)``,
    ``sigma_p (N,)``, uniforms ``u (N, K, n_uniforms(gm))`` -> ``s (N, K, 2)``, ``pdf (N, K)``
    and the footprints' NDF masses ``M (N,)`` (:func:`mass`), the block
    masses computed once per footprint (the same draws, densities and masses to rounding)."""
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
    :func:`_direct_kernel`) -> ``out_s (N, P, 2)``, their density (as ``pndf``: cut at
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
            mx, my, a, b, d = element_gaussian(s_el, J, (y0 + bj) % Hs, (x0 + bi) % Ws,
                                               cx[q] - (x0 + bi + 0.5), cy[q] - (y0 + bj + 0.5),
                                               f, var, sr2)
            qx[P + k], qy[P + k] = element_draw(mx, my, a, b, d, u[q, k, 1], u[q, k, 2])
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
    s_el = surf.elements_[0]
    tot2 = np.asarray(sigma_p, dtype=np.float64) ** 2 + SIGMA_H * SIGMA_H
    return (2.0 * TRUNCATION * np.sqrt(tot2) + 2.0 <= s_el.shape[1]) & (tot2 < wide_limit2(s_el))


def direct_mis_k(surf, center, sigma_p, q_light, u):
    """The quad MIS's direct P-NDF of footprints ``center (N, 2)``, ``sigma_p (N,)`` (all
    :func:`direct_mis_fits`) in one walk each (:func:`_direct_mis_k`, 4-std truncation):
    ``D_light (N, P)`` at ``q_light (N, P, 2)``; draws ``s (N, P, 2)`` for uniforms
    ``u (N, P, 3)`` as :func:`sample_s_direct`, their density
    ``pdf (N, P)`` (its ``pndf``) and ``D_draw (N, P)`` at them; all to rounding."""
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
