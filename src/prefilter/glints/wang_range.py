"""Range queries over the implicit Wang tiling: the mean of a footprint's NDF over rectangles of
projected half vectors (glints paper eq. 7), summed over the tiles under the footprint.

``ndf_ranges(wn, center, sigma_p, s_min, s_max)``: per footprint, ``K`` rectangles. Regimes of
:mod:`prefilter.glints.wang_ndf`:

* per-tile pyramids (``min_sigma <= sigma_p < wide_sigma``): the resampling taps of every tile
  under the footprint (:func:`prefilter.glints.wang_query.tile_taps`), their code rows summed
  per CP group and NDF block (:func:`prefilter.glints.wang_query.type_codes`), then the group's
  factor masses over each rectangle from the prefix sums (``_qkernels._flush_rects``, the
  ``glints`` range kernel's arithmetic), the taps summed per tile type first
  (:func:`prefilter.glints.wang_query.type_weights`: once for all the blocks); the dependent
  texels (left out of the tiles' pyramids) from the vertex pyramids the same way on the
  implicit tiling, otherwise (explicit maps, no vertex pyramids) by their exact elements'
  masses over the rectangles (the pixel splatting of the images, with rectangle masses);
* tile-type shares and the expected tiling (``sigma_p >= wide_sigma``): the per-type
  ``sigma_p -> inf`` images' rectangle means from summed-area tables (exact for the
  piecewise-constant images);
* below ``min_sigma`` (direct P-NDF): not answered (``done`` False; callers use point values or
  light samples there, as ``glints`` does below its finest level).

Ranges cross tile borders freely: the tiles are summed per footprint, not per rectangle.
"""

from __future__ import annotations

import math

import numpy as np

from prefilter.errors import PrefilterError
from prefilter.glints._qkernels import _flush_rects, _rect, _touching
from prefilter.glints.pndf import (SIGMA_H, TRUNCATION, as_sigma_p, element_covariance,
                                   element_node, element_nodes, element_split, normal_cdf,
                                   principal_axis)
from prefilter.glints.wang_ndf import (_Q_MIN, _TAP_TRUNCATION, TiledNDF, _as_index,
                                      _vertex_tables, dep_gaussian, moment_weights,
                                      shares_args, shares_moments, weighted_dot,
                                      dependent_neighbours, footprint_rows, level_window,
                                      _valid, vertex_args, vertex_config, vertex_window)
from prefilter.glints.wang_query import (empty_pack, gauss_row, type_codes,
                                         type_weights)
from prefilter.jit import njit_parallel, njit_serial, prange, serial

#: Rectangles of at least this many coarse pixels per side (:attr:`prefilter.glints.wang_ndf.
#: TiledNDF.coarse`) are read from the coarse pyramids (an edge then cuts a coarse pixel over up
#: to a third of the side, whose mass counts by its covered fraction). The environment's
#: lobe rectangles (15.6 pixels of the default 256^2 images) qualify: mid-distance frames 3x
#: faster, FLIP 0.034 / 0.0085 (mid / far) against the full-resolution ranges, and the
#: 32-seed averages' FLIP against ``glints-direct`` 0.0845 instead of 0.0850 (docs/glints-wang.md).
COARSE_MIN = 3

def summed_tables(wn: TiledNDF) -> np.ndarray:
    """Summed-area tables ``(R + 1, R + 1, 17)`` float64 of the 16 ``tile_means`` and of
    ``mean`` (index 16), in pixel units, position-major: ``S[i, j, t]`` the sum of rows
    ``< i``, columns ``< j`` of image ``t`` (cached per instance)."""
    hit = wn.__dict__.get("_sat")
    if hit is None:
        imgs = np.concatenate([np.asarray(wn.tile_means, np.float64),
                               np.asarray(wn.mean, np.float64)[None]])
        R = imgs.shape[1]
        hit = np.zeros((R + 1, R + 1, 17))
        hit[1:, 1:] = imgs.cumsum(axis=1).cumsum(axis=2).transpose(1, 2, 0)
        object.__setattr__(wn, "_sat", hit)
    return hit


@njit_serial
def _weighted_at(S, w, y, x):  # pragma: no cover - compiled
    """``sum_k w[k]`` times the integral of piecewise-constant image ``k`` over ``[0, y] x
    [0, x]`` (pixel units, clamped to the image): the summed-area tables ``S (R + 1, R + 1,
    K)`` interpolated bilinearly (exact for such images). The float32 moment tables' entries
    are multiplied by the float64 weights before any difference is taken."""
    R = S.shape[0] - 1
    y = min(max(y, 0.0), float(R))
    x = min(max(x, 0.0), float(R))
    i = min(int(y), R - 1)
    j = min(int(x), R - 1)
    ty, tx = y - i, x - j
    return ((1 - ty) * ((1 - tx) * weighted_dot(S, w, i, j) + tx * weighted_dot(S, w, i, j + 1))
            + ty * ((1 - tx) * weighted_dot(S, w, i + 1, j)
                    + tx * weighted_dot(S, w, i + 1, j + 1)))


@njit_serial
def _weighted_rect(S, w, py0, py1, px0, px1):  # pragma: no cover - compiled
    """``sum_k w[k]`` times image ``k``'s integral over ``[py0, py1] x [px0, px1]``."""
    return ((_weighted_at(S, w, py1, px1) - _weighted_at(S, w, py0, px1))
            - (_weighted_at(S, w, py1, px0) - _weighted_at(S, w, py0, px0)))


@njit_serial
def _iso_mass(mx, my, siso, w, x0, x1, y0, y1, trunc):  # pragma: no cover - compiled
    """``w`` times the mass of ``N((mx, my), siso^2 I)`` over ``[x0, x1] x [y0, y1]``; 0 when
    the rectangle is beyond ``trunc`` stds along an axis (``pndf.splat``'s cut)."""
    rad = trunc * siso
    if mx + rad < x0 or mx - rad > x1 or my + rad < y0 or my - rad > y1:
        return 0.0
    inv = 1.0 / siso
    return w * ((normal_cdf((x1 - mx) * inv) - normal_cdf((x0 - mx) * inv))
                * (normal_cdf((y1 - my) * inv) - normal_cdf((y0 - my) * inv)))


@njit_serial
def _rect_element(mx, my, a, b, d, w, sr, x0, x1, y0, y1, trunc):  # pragma: no cover
    """``w`` times the mass of an element over ``[x0, x1] x [y0, y1]``: the split of
    ``wang_ndf._nb_element`` (isotropic part, three or a line of isotropic nodes for the
    rank-one part; ``pndf._pndf_images``' splatting) with rectangle masses instead of pixel
    masses."""
    nu1, siso, kappa = element_split(a, b, d, sr)
    return _rect_split(mx, my, a, b, d, nu1, siso, kappa, w, x0, x1, y0, y1, trunc)


@njit_serial
def _rect_split(mx, my, a, b, d, nu1, siso, kappa, w, x0, x1, y0, y1,
                trunc):  # pragma: no cover - compiled
    """:func:`_rect_element` given the element's :func:`~prefilter.glints.pndf.element_split`
    ``(nu1, siso, kappa)`` (computed once for all the rectangles of a footprint): the nodes of
    :func:`~prefilter.glints.pndf.element_nodes`' rule, rectangle masses of their isotropic
    parts."""
    ext = trunc * (kappa + siso)
    if mx + ext < x0 or mx - ext > x1 or my + ext < y0 or my - ext > y1:
        return 0.0
    n, norm = element_nodes(kappa, siso, trunc)
    vx, vy = principal_axis(a, b, d, nu1) if n > 1 else (0.0, 0.0)
    qa, qb = 0, n - 1
    if n > 5:
        # the line nodes t (in kappa units) whose isotropic part reaches the rectangle: the
        # line's interval inside it, grown by trunc siso (a long element crosses a small
        # rectangle with a few of its nodes)
        step = 2.0 * trunc / (n - 1)
        rn = trunc * siso
        tlo, thi = -trunc, trunc
        for v, m, a0, a1 in ((vx, mx, x0, x1), (vy, my, y0, y1)):
            if abs(v) > 1e-12:
                ta = (a0 - rn - m) / (kappa * v)
                tb = (a1 + rn - m) / (kappa * v)
                tlo = max(tlo, min(ta, tb))
                thi = min(thi, max(ta, tb))
            elif m + rn < a0 or m - rn > a1:
                return 0.0
        if tlo > thi:
            return 0.0
        qa = max(0, int(math.floor((tlo + trunc) / step)))
        qb = min(n - 1, int(math.ceil((thi + trunc) / step)))
    acc = 0.0
    for q in range(qa, qb + 1):
        t, num, den, cut = element_node(kappa, trunc, n, norm, q)
        acc += _iso_mass(mx + t * vx, my + t * vy, siso, w * num / den, x0, x1, y0, y1, cut)
    return acc


@njit_parallel
def _ranges_kernel(cx, cy, sp, x0, y0, x1, y1, act, tiles, seed, index, Pa, Pb, cq,
                   wsc, Fa, Fb, bidx, meta, offs, goff, crops, B, k0, st0, sigma0, dep, depn, vel,
                   sat, mbasis, msat,
                   lo, h, min_sigma, wide_sigma, uniform_sigma, q_min, tap_trunc, trunc, sh,
                   point_sr, proto, has_vertex, vFa, vFb, vwsc, vcq, vbidx, vmeta, voffs, vgoff,
                   vk0, vcrops, vPa, vPb, has_coarse, cPa, cPb, ccq, cwsc, cbidx, cmeta, cgoff,
                   cvPa, cvPb, cvcq, cvwsc, cvbidx, cvmeta, cvgoff, valid, out,
                   done):  # pragma: no cover - compiled
    """``out[q, k]``: mean NDF of footprint ``(cx, cy, sp)[q]`` over ``[x0, x1] x [y0, y1]``
    ``[q, k]`` (0 for inactive rectangles); ``done[q]`` False below ``min_sigma`` (module
    docstring). Accumulation of the code rows in ``proto``'s dtype (float32 for 8-bit codes).
    ``has_vertex``: on the implicit tiling the dependent texels come from the vertex pyramids
    (``vFa`` ..., :func:`prefilter.glints.wang_ndf.vertex_window`). ``has_coarse``: the
    rectangles of at least ``COARSE_MIN`` pixels per side of the coarse pyramids (``c...``,
    vertex ``cv...``: :attr:`~prefilter.glints.wang_ndf.TiledNDF.coarse`, the same centres,
    its own groups) are read from them."""
    T = tiles.shape[1]
    nb = bidx.shape[0]
    R = nb * B
    N, K = out.shape
    L = crops.shape[0]
    rank = 1
    for g in range(meta.shape[0]):
        rank = max(rank, meta[g, 0])
    pa = Pa.ravel()
    pb = Pb.ravel()
    vpa = vPa.ravel()
    vpb = vPb.ravel()
    use_v = has_vertex and valid
    cpa = cPa.ravel()
    cpb = cPb.ravel()
    cvpa = cvPa.ravel()
    cvpb = cvPb.ravel()
    cnb = cbidx.shape[0]
    hc = h * R / max(cnb * B, 1)  # a coarse pixel
    for q in prange(N):
        for k in range(K):
            out[q, k] = 0.0
        s = sp[q]
        c0, c1 = cx[q], cy[q]
        done[q] = s >= min_sigma
        if not done[q]:
            continue
        # the rectangles in pixels, their blocks and areas
        rbk = np.empty((K, 4), np.int64)
        rcl = np.empty((K, 4))
        area = np.empty(K)
        ubi0, ubi1, ubj0, ubj1 = nb, -1, nb, -1
        for k in range(K):
            if not act[q, k]:
                rbk[k, 0], rbk[k, 1], rbk[k, 2], rbk[k, 3] = 0, -1, 0, -1
                area[k] = 1.0
                continue
            ax0, ax1, ay0, ay1, bi0, bi1, bj0, bj1, a = _rect(x0[q, k], y0[q, k], x1[q, k],
                                                              y1[q, k], lo, h, R, B, nb)
            rcl[k, 0], rcl[k, 1], rcl[k, 2], rcl[k, 3] = ax0, ax1, ay0, ay1
            rbk[k, 0], rbk[k, 1], rbk[k, 2], rbk[k, 3] = bi0, bi1, bj0, bj1
            area[k] = a
            if bi0 <= bi1 and bj0 <= bj1:
                ubi0, ubi1 = min(ubi0, bi0), max(ubi1, bi1)
                ubj0, ubj1 = min(ubj0, bj0), max(ubj1, bj1)
        tot2, rad, wx0, wx1, wy0, wy1 = footprint_rows(c0, c1, s, sh, trunc)
        if s >= wide_sigma:
            w17 = np.zeros(17)
            n_m = msat.shape[2] // 16
            wm = np.zeros(0)
            if s >= uniform_sigma:
                w17[16] = 1.0
            else:  # tile-type shares and in-tile moments (wang_ndf.type_moments)
                mom = shares_moments(wx0, wx1, wy0, wy1, gauss_row(c0, wx0, wx1, tot2),
                                     gauss_row(c1, wy0, wy1, tot2), T, mbasis, seed, index,
                                     1 + n_m)
                w17[:16] = mom[:, 0]
                wm = moment_weights(mom)
            for k in range(K):
                if not act[q, k] or rbk[k, 0] > rbk[k, 1]:
                    continue
                v = _weighted_rect(sat, w17, rcl[k, 2], rcl[k, 3], rcl[k, 0], rcl[k, 1])
                if wm.shape[0]:
                    v += _weighted_rect(msat, wm, rcl[k, 2], rcl[k, 3], rcl[k, 0], rcl[k, 1])
                out[q, k] = max(v, 0.0) / area[k]
            continue
        (m, n, ti0, tj0, types, jlo, jhi, ilo, ihi, wyt, wxt, kyl, kyh, kxl,
         kxh) = level_window(s, c0, c1, sigma0, st0, L, q_min, tap_trunc, crops, k0, rad, T,
                             seed, index)
        # the wide rectangles from the coarse pyramids: their coarse pixels and blocks, and the
        # fine blocks of the others
        crbk = np.empty((K, 4), np.int64)
        crcl = np.empty((K, 4))
        carea = np.ones(K)
        cbi0, cbi1, cbj0, cbj1 = cnb, -1, cnb, -1
        for k in range(K):
            crbk[k, 0], crbk[k, 1], crbk[k, 2], crbk[k, 3] = 0, -1, 0, -1
        fbk = rbk  # the rectangles' fine blocks (none for the wide ones)
        if has_coarse:
            fbk = rbk.copy()
            ubi0, ubi1, ubj0, ubj1 = nb, -1, nb, -1
            for k in range(K):
                if not act[q, k] or rbk[k, 0] > rbk[k, 1]:
                    continue
                if (x1[q, k] - x0[q, k] >= COARSE_MIN * hc
                        and y1[q, k] - y0[q, k] >= COARSE_MIN * hc):
                    ax0, ax1, ay0, ay1, bi0, bi1, bj0, bj1, a = _rect(
                        x0[q, k], y0[q, k], x1[q, k], y1[q, k], lo, hc, cnb * B, B, cnb)
                    crcl[k, 0], crcl[k, 1], crcl[k, 2], crcl[k, 3] = ax0, ax1, ay0, ay1
                    crbk[k, 0], crbk[k, 1], crbk[k, 2], crbk[k, 3] = bi0, bi1, bj0, bj1
                    carea[k] = a
                    fbk[k, 0], fbk[k, 1] = 0, -1  # not from the fine pyramids
                    if bi0 <= bi1 and bj0 <= bj1:
                        cbi0, cbi1 = min(cbi0, bi0), max(cbi1, bi1)
                        cbj0, cbj1 = min(cbj0, bj0), max(cbj1, bj1)
                else:
                    ubi0, ubi1 = min(ubi0, rbk[k, 0]), max(ubi1, rbk[k, 1])
                    ubj0, ubj1 = min(ubj0, rbk[k, 2]), max(ubj1, rbk[k, 3])
        cw = np.empty((16, rank), proto.dtype)
        gs = np.empty(16, np.int64)
        tt = np.empty(9, proto.dtype)
        rp = np.empty((K, 8), np.int64)
        rt = np.empty((K, 8))
        touch = np.empty(K, np.int64)
        acc = np.zeros(K)
        # the taps summed per tile type (and vertex configuration) once for all the blocks
        W = np.empty((16, n, n))
        box = np.empty((16, 4), np.int64)
        type_weights(types, jlo - tj0, ilo - ti0, wyt, wxt, kyl, kyh, kxl, kxh, n, W, box)
        vn = vcrops[m] if use_v else 0
        vW = np.empty((16, vn, vn))
        vbox = np.empty((16, 4), np.int64)
        if use_v:
            vt, vwy, vwx, vkyl, vkyh, vkxl, vkxh = vertex_window(
                s, c0, c1, m, vn, sigma0, st0, tap_trunc, vk0[m], rad, T, types, ti0, tj0)
            type_weights(vt, 0, 0, vwy, vwx, vkyl, vkyh, vkxl, vkxh, vn, vW, vbox)
        blocks = (ubi0, ubi1, ubj0, ubj1)
        _block_masses(blocks, fbk, rcl, B, offs[m], voffs[m], n, vn, (pa, pb, wsc, meta, cq, bidx,
                      goff[m]), (vpa, vpb, vwsc, vmeta, vcq, vbidx, vgoff[m]), use_v, W, box,
                      vW, vbox, cw, gs, touch, rp, rt, tt, acc)
        cacc = np.zeros(K)
        blocks = (cbi0, cbi1, cbj0, cbj1)
        _block_masses(blocks, crbk, crcl, B, offs[m], voffs[m], n, vn, (cpa, cpb, cwsc, cmeta,
                      ccq, cbidx, cgoff[m]), (cvpa, cvpb, cvwsc, cvmeta, cvcq, cvbidx,
                                              cvgoff[m]), use_v, W, box, vW, vbox, cw, gs,
                      touch, rp, rt, tt, cacc)
        for k in range(K):
            out[q, k] = acc[k] / area[k] + cacc[k] / carea[k]
        if use_v:
            continue
        # the dependent texels: their exact elements' masses over the rectangles (clipped to
        # the support, as the images)
        f = sh * sh / tot2
        var = s * s * sh * sh / tot2
        gxw = gauss_row(c0, wx0, wx1, tot2)
        gyw = gauss_row(c1, wy0, wy1, tot2)
        sx = gxw.sum()
        sy = gyw.sum()
        hi = lo + R * h
        if valid:
            # by grid vertex, no neighbour lookups (a valid tiling)
            _vertex_rects(vel, T, types, tj0, ti0, jlo, jhi, ilo, ihi, wx0, wx1, wy0, wy1, gxw,
                          gyw, c0, c1, f, var, sx * sy, point_sr, act[q], rbk, x0[q], x1[q],
                          y0[q], y1[q], lo, hi, trunc, out[q])
            continue
        for j in range(jlo, jhi + 1):
            for i in range(ilo, ihi + 1):
                for e in range(dep.shape[0]):
                    x = i * T + dep[e, 1]
                    y = j * T + dep[e, 0]
                    if not (wx0 <= x <= wx1 and wy0 <= y <= wy1):
                        continue
                    w, mx, my, a, b, d = dep_gaussian(tiles, types, j - tj0, i - ti0, depn[e],
                                                      x, y, c0, c1, f, var, tot2)
                    w /= sx * sy
                    for k in range(K):
                        if not act[q, k] or rbk[k, 0] > rbk[k, 1]:
                            continue
                        ar = (x1[q, k] - x0[q, k]) * (y1[q, k] - y0[q, k])
                        out[q, k] += _rect_element(mx, my, a, b, d, w, point_sr,
                                                   max(x0[q, k], lo), min(x1[q, k], hi),
                                                   max(y0[q, k], lo), min(y1[q, k], hi),
                                                   trunc) / ar


@njit_serial
def _block_masses(blocks, rbk, rcl, B, off, voff, n, vn, P, VP, use_v, W, box, vW, vbox, cw, gs,
                  touch, rp, rt, tt, acc):  # pragma: no cover - compiled
    """``acc[k]`` += the masses over rectangle ``k`` (blocks ``rbk``, pixel bounds ``rcl``) of the
    tiles' pyramids ``P = (pa, pb, wsc, meta, cq, bidx, goff)`` at one level (images from
    ``off``, ``n`` centres per axis) weighted by their per-type taps ``W``, ``box``
    (:func:`prefilter.glints.wang_query.type_weights`), and with ``use_v`` of the vertex
    pyramids ``VP`` likewise, over the blocks ``blocks = (bi0, bi1, bj0, bj1)``: per block the
    code rows per CP group, then the groups' factor masses (``_qkernels._flush_rects``)."""
    pa, pb, wsc, meta, cq, bidx, goff = P
    vpa, vpb, vwsc, vmeta, vcq, vbidx, vgoff = VP
    nb = bidx.shape[0]
    for bi in range(blocks[0], blocks[1] + 1):
        for bj in range(blocks[2], blocks[3] + 1):
            nt = _touching(rbk, rcl, bi, bj, B, touch, rp, rt)
            if nt == 0:
                continue
            ns = type_codes(cq, bidx[bi, bj], meta, off, goff, n, (bi * nb + bj, nb * nb), W, box,
                            cw, gs)
            _flush_rects(pa, pb, wsc, meta, B, gs, cw, ns, rp, rt, touch, nt, tt, acc)
            if use_v:  # the dependent texels from their vertex pyramids
                ns = type_codes(vcq, vbidx[bi, bj], vmeta, voff, vgoff, vn, (bi * nb + bj,
                                                                            nb * nb), vW, vbox,
                                cw, gs)
                _flush_rects(vpa, vpb, vwsc, vmeta, B, gs, cw, ns, rp, rt, touch, nt, tt, acc)


@njit_serial
def _vertex_rects(vel, T, types, tj0, ti0, jlo, jhi, ilo, ihi, wx0, wx1, wy0, wy1, gxw, gyw, c0,
                  c1, f, var, norm, sr, act, rbk, x0, x1, y0, y1, lo, hi, trunc,
                  out):  # pragma: no cover - compiled
    """``out (K,)`` += the rectangle means of the dependent texels' elements (weights ``gxw``,
    ``gyw`` over the window ``[wx0, wx1] x [wy0, wy1]``, divided by ``norm``) of the ``T x T``
    tiles ``ilo..ihi`` x ``jlo..jhi``, by grid vertex: each vertex's elements are the row of
    ``wang_ndf.vertex_elements`` of its configuration (``types`` from tile ``(ti0, tj0)``, a
    valid tiling). Rectangles ``[x0, x1] x [y0, y1]`` clipped to ``[lo, hi]``."""
    for j in range(jlo, jhi + 2):
        for i in range(ilo, ihi + 2):
            ve = vel[vertex_config(types[j - 1 - tj0, i - 1 - ti0], types[j - tj0, i - ti0])]
            for e in range(ve.shape[0]):
                x = i * T + int(ve[e, 0])
                y = j * T + int(ve[e, 1])
                if not (wx0 <= x <= wx1 and wy0 <= y <= wy1):
                    continue
                dx = c0 - (x + 0.5)
                dy = c1 - (y + 0.5)
                mx = ve[e, 2] + f * (ve[e, 4] * dx + ve[e, 5] * dy)
                my = ve[e, 3] + f * (ve[e, 6] * dx + ve[e, 7] * dy)
                a, b, d = element_covariance(ve[e, 4], ve[e, 5], ve[e, 6], ve[e, 7], var, 0.0)
                nu1, siso, kappa = element_split(a, b, d, sr)
                w = gxw[x - wx0] * gyw[y - wy0] / norm
                for k in range(out.shape[0]):
                    if not act[k] or rbk[k, 0] > rbk[k, 1]:
                        continue
                    ar = (x1[k] - x0[k]) * (y1[k] - y0[k])
                    out[k] += _rect_split(mx, my, a, b, d, nu1, siso, kappa, w, max(x0[k], lo),
                                          min(x1[k], hi), max(y0[k], lo), min(y1[k], hi),
                                          trunc) / ar


def ndf_ranges(wn: TiledNDF, center, sigma_p, s_min, s_max, *, active=None, index=None,
               point_roughness: float | None = None):
    """Mean NDF values ``(N, K)`` of footprints ``center (N, 2)``, ``sigma_p (N,)`` over ``K``
    rectangles each, ``[s_min, s_max]`` (``(N, K, 2)``, ``s_max > s_min``) of compressed
    per-tile pyramids (module docstring), and ``done (N,)``: False below ``wn.min_sigma`` (the
    values are then 0). ``active (N, K)`` bool: rectangles to evaluate (others 0);
    ``point_roughness``: the dependent texels' intrinsic roughness (default
    ``wn.intrinsic_roughness``; the renderer passes its unbaked roughness, as for
    :func:`prefilter.glints.wang_ndf.ndf_points` with ``bilinear``)."""
    if not isinstance(wn, TiledNDF) or not wn.block:
        raise PrefilterError("wn: expected compressed per-tile pyramids (bake_tiles with rank)")
    c = np.ascontiguousarray(center, dtype=np.float64)
    sp = np.ascontiguousarray(as_sigma_p(sigma_p), dtype=np.float64)
    lo_ = np.asarray(s_min, dtype=np.float64)
    hi_ = np.asarray(s_max, dtype=np.float64)
    if c.ndim != 2 or c.shape[1] != 2 or sp.shape != c.shape[:1]:
        raise PrefilterError(f"center, sigma_p: expected shapes (N, 2) and (N,), got {c.shape} "
                             f"and {sp.shape}")
    N = c.shape[0]
    if lo_.ndim != 3 or lo_.shape[0] != N or lo_.shape[2] != 2 or hi_.shape != lo_.shape:
        raise PrefilterError(f"s_min, s_max: expected shapes (N, K, 2) with N = {N}, got "
                             f"{lo_.shape} and {hi_.shape}")
    if np.any(hi_ <= lo_):
        raise PrefilterError("s_max: expected s_max > s_min in both coordinates")
    K = lo_.shape[1]
    act = np.ones((N, K), bool) if active is None else np.asarray(active)
    if act.dtype != bool or act.shape != (N, K):
        raise PrefilterError(f"active: expected a bool array of shape {(N, K)}, got "
                             f"{act.dtype} {act.shape}")
    idx = _as_index(index)
    idx = np.zeros((0, 0), np.int64) if idx is None else np.ascontiguousarray(idx, np.int64)
    psr = wn.intrinsic_roughness if point_roughness is None else float(point_roughness)
    pk = wn.pack
    out = np.zeros((N, K))
    done = np.zeros(N, bool)
    if N == 0 or K == 0:
        return out, done
    cc = np.ascontiguousarray
    proto = np.empty(0, np.float32 if pk.cq.dtype == np.uint8 else np.float64)
    serial(_ranges_kernel, N * K)(
        cc(c[:, 0]), cc(c[:, 1]), sp, cc(lo_[..., 0]), cc(lo_[..., 1]), cc(hi_[..., 0]),
        cc(hi_[..., 1]), cc(act), cc(wn.wang.tiles[..., :2]),
        np.uint64(wn.wang.seed), idx, pk.Pa, pk.Pb, pk.cq, pk.wsc, pk.Fa, pk.Fb, pk.bidx,
        pk.meta, pk.offs, pk.goff, np.array([wn.crop(lv) for lv in range(wn.n_levels)],
                                            np.int64),
        int(wn.block), np.asarray(wn.k0, np.int64), float(wn.stride0), wn.sigma0,
        cc(wn.dependent, dtype=np.int64), dependent_neighbours(wn), _vertex_tables(wn)[0],
        summed_tables(wn), *shares_args(wn), -wn.support,
        2.0 * wn.support / wn.resolution, wn.min_sigma, wn.wide_sigma, wn.uniform_sigma, _Q_MIN,
        _TAP_TRUNCATION, TRUNCATION, SIGMA_H, psr, proto, *vertex_args(wn),
        *_coarse_args(wn), _valid(idx), out, done)
    return out, done


def _coarse_args(wn: TiledNDF) -> tuple:
    """``(has_coarse, Pa, Pb, cq, wsc, bidx, meta, goff)`` of ``wn.coarse``'s tile pyramids,
    then the same of its vertex pyramids (empty arrays of the tiles' dtypes without them)."""
    c = wn.coarse

    def parts(pk):
        return (pk.Pa, pk.Pb, pk.cq, pk.wsc, pk.bidx, pk.meta, pk.goff)

    # the wide rectangles' dependent texels come from the coarse vertex pyramids when the
    # queries read vertex pyramids at all (otherwise exactly, for every rectangle)
    use = c is not None and (wn.vertex_pack is None or c.vertex_pack is not None)
    blank = empty_pack(wn.n_levels, like=wn.pack)
    vp = c.vertex_pack if use and c.vertex_pack is not None else blank
    return (use,) + parts(c.pack if use else blank) + parts(vp)
