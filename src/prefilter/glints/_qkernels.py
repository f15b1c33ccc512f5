"""Numba kernels of the compressed queries (kept apart from ``query.py``, whose public ``range``
would shadow the builtin inside compiled code).

Every kernel takes the prefix sums ``A``, ``Bp`` rank-contiguous, ``(G, B + 1, R)``
(:func:`prefilter.glints.query._prefix_t`, what ``query._args`` passes): the kernels read all
components of a group at one or two NDF pixels, which the stored ``(G, R, B + 1)`` layout spreads
over one cache line per component (17 floats apart)."""

from __future__ import annotations

import math

import numpy as np

from prefilter._numba import njit_inline, njit_parallel, njit_serial, prange


@njit_serial
def _rect_mass(A, Bp, C, block_index, image_cell, granks, idx, wts, q, bi, bj, i0, i1, j0, j1):
    """Sum of the blended image's pixel values over rows ``[i0, i1)``, columns ``[j0, j1)`` of
    block ``(bi, bj)`` (block-local pixel indices). ``granks``: the rank of each CP group (its
    components come first; adaptive-rank maps pad the others with zeros, skipped here)."""
    nb = block_index.shape[1]
    acc = 0.0
    for c in range(idx.shape[1]):
        w = wts[q, c]
        if w == 0.0:
            continue
        img = idx[q, c]
        k = block_index[img, bi, bj]
        if k < 0:
            continue
        g = image_cell[img] * nb * nb + bi * nb + bj
        s = 0.0
        for r in range(granks[g]):
            s += C[k, r] * ((A[g, i1, r] - A[g, i0, r]) * (Bp[g, j1, r] - Bp[g, j0, r]))
        acc += w * s
    return acc


@njit_parallel
def point_kernel(A, Bp, C, block_index, image_cell, granks, idx, wts, sx, sy, lo, h, out):
    R = block_index.shape[1] * (A.shape[1] - 1)
    B = A.shape[1] - 1
    for q in prange(out.shape[0]):
        fx = (sx[q] - lo) / h
        fy = (sy[q] - lo) / h
        acc = 0.0
        if fx >= 0.0 and fy >= 0.0 and fx < R and fy < R:
            j = int(fx)
            i = int(fy)
            bi, bj = i // B, j // B
            i0, j0 = i - bi * B, j - bj * B
            acc = _rect_mass(A, Bp, C, block_index, image_cell, granks, idx, wts, q, bi, bj, i0,
                             i0 + 1, j0, j0 + 1)
        out[q] = acc


@njit_serial
def _prefix_at(P, g, u):
    """Integral over ``[0, u]`` pixels of the factors of group ``g`` (prefix sums linear inside a
    pixel), written to ``P``'s row of the group: ``P (G, B + 1, R)`` is rank-contiguous, so the
    group's components at one ``u`` are a few cache lines; returns the row index and weight."""
    B = P.shape[1] - 1
    if u <= 0.0:
        return 0, 0.0
    if u >= B:
        return B, 0.0
    n = int(u)
    return n, u - n


@njit_parallel
def range_kernel(A, Bp, C, block_index, image_cell, granks, idx, wts, x0, y0, x1, y1, lo, h, out):
    """Mean of the piecewise-constant NDF image over ``[x0, x1] x [y0, y1]`` (zero outside the
    support); the rectangle is split at block boundaries (paper, sec. 4.4). ``A``, ``Bp``: the
    prefix sums rank-contiguous, ``(G, B + 1, R)`` (:func:`prefilter.glints.query._prefix_t`)."""
    B = A.shape[1] - 1
    nb = block_index.shape[1]
    R = nb * B
    for q in prange(out.shape[0]):
        px0 = (x0[q] - lo) / h
        px1 = (x1[q] - lo) / h
        py0 = (y0[q] - lo) / h
        py1 = (y1[q] - lo) / h
        area = (px1 - px0) * (py1 - py0)
        cx0, cx1 = max(px0, 0.0), min(px1, float(R))
        cy0, cy1 = max(py0, 0.0), min(py1, float(R))
        acc = 0.0
        if cx1 > cx0 and cy1 > cy0:
            bj0 = int(cx0) // B
            bj1 = min(int(math.ceil(cx1)) // B, nb - 1)
            bi0 = int(cy0) // B
            bi1 = min(int(math.ceil(cy1)) // B, nb - 1)
            for c in range(idx.shape[1]):
                w = wts[q, c]
                if w == 0.0:
                    continue
                img = idx[q, c]
                for bi in range(bi0, bi1 + 1):
                    v0 = cy0 - bi * B
                    v1 = cy1 - bi * B
                    for bj in range(bj0, bj1 + 1):
                        k = block_index[img, bi, bj]
                        if k < 0:
                            continue
                        u0 = cx0 - bj * B
                        u1 = cx1 - bj * B
                        g = image_cell[img] * nb * nb + bi * nb + bj
                        na1, ta1 = _prefix_at(A, g, v1)
                        na0, ta0 = _prefix_at(A, g, v0)
                        nb1, tb1 = _prefix_at(Bp, g, u1)
                        nb0, tb0 = _prefix_at(Bp, g, u0)
                        s = 0.0
                        for r in range(granks[g]):
                            a1 = A[g, na1, r]
                            if ta1 != 0.0:
                                a1 += ta1 * (A[g, na1 + 1, r] - a1)
                            a0 = A[g, na0, r]
                            if ta0 != 0.0:
                                a0 += ta0 * (A[g, na0 + 1, r] - a0)
                            b1 = Bp[g, nb1, r]
                            if tb1 != 0.0:
                                b1 += tb1 * (Bp[g, nb1 + 1, r] - b1)
                            b0 = Bp[g, nb0, r]
                            if tb0 != 0.0:
                                b0 += tb0 * (Bp[g, nb0 + 1, r] - b0)
                            s += C[k, r] * (a1 - a0) * (b1 - b0)
                        acc += w * s
        out[q] = acc / area


@njit_inline
def _block_tap(p0, w0, w1, d, B):
    """Tap ``d`` (0, 1) of an axis's bilinear pair ``p0, p0 + 1`` (weights ``w0, w1``) split at
    the B-pixel block boundaries: ``(block, offset in block, weight, weight of pixel + 1)``,
    where the second weight is nonzero when both taps lie in one block (handled together at
    ``d == 0``); block ``-1``: nothing to add for this tap."""
    w = w0 if d == 0 else w1
    if w == 0.0:
        return -1, 0, 0.0, 0.0
    p = p0 + d
    blk = p // B
    if d == 1 and w0 != 0.0 and (p0 // B) == blk:
        return -1, 0, 0.0, 0.0
    wn = w1 if (d == 0 and w1 != 0.0 and (p0 + 1) // B == blk) else 0.0
    return blk, p - blk * B, w, wn


@njit_parallel
def bilinear_kernel(A, Bp, C, block_index, image_cell, granks, idx, wts, sx, sy, lo, h, out):
    """Point values of the blended images reconstructed bilinearly between pixel centres.

    The CP image of a block is ``sum_r c_r a_r (x) b_r``, so a bilinear combination of pixels of
    one block is ``sum_r c_r (sum_i u_i a_r[i]) (sum_j v_j b_r[j])``: two factor lookups per axis
    instead of four pixel values; neighbours in another block are taken from that block."""
    B = A.shape[1] - 1
    nb = block_index.shape[1]
    R = nb * B
    for q in prange(out.shape[0]):
        i0, u0, u1 = _axis_taps2((sy[q] - lo) / h, R, True)
        j0, v0, v1 = _axis_taps2((sx[q] - lo) / h, R, True)
        acc = 0.0
        for di in range(2):
            bi, ia, wa0, wa1 = _block_tap(i0, u0, u1, di, B)
            if bi < 0:
                continue
            for dj in range(2):
                bj, ja, wb0, wb1 = _block_tap(j0, v0, v1, dj, B)
                if bj < 0:
                    continue
                for c in range(idx.shape[1]):
                    w = wts[q, c]
                    if w == 0.0:
                        continue
                    img = idx[q, c]
                    k = block_index[img, bi, bj]
                    if k < 0:
                        continue
                    g = image_cell[img] * nb * nb + bi * nb + bj
                    s = 0.0
                    for r in range(granks[g]):
                        fa = wa0 * (A[g, ia + 1, r] - A[g, ia, r])
                        if wa1 != 0.0:
                            fa += wa1 * (A[g, ia + 2, r] - A[g, ia + 1, r])
                        fb = wb0 * (Bp[g, ja + 1, r] - Bp[g, ja, r])
                        if wb1 != 0.0:
                            fb += wb1 * (Bp[g, ja + 2, r] - Bp[g, ja + 1, r])
                        s += C[k, r] * fa * fb
                    acc += w * s
        out[q] = acc


@njit_serial
def _axis_taps2(f, R, bilinear):
    """Bilinear taps along one axis at pixel coordinate ``f`` (pixel centres at ``k + 0.5``):
    pixels ``p0, p0 + 1`` with weights ``1 - t, t``, pixels outside ``[0, R)`` weight 0; or the
    pixel containing ``f`` with weight 1 (``bilinear`` False)."""
    if not bilinear:
        p = int(math.floor(f))
        return p, (1.0 if 0 <= p < R else 0.0), 0.0
    g = f - 0.5
    p0 = int(math.floor(g))
    t = g - p0
    return p0, (1.0 - t if 0 <= p0 < R else 0.0), (t if 0 <= p0 + 1 < R else 0.0)

#: CP groups whose weighted C rows :func:`resample_point_kernel` accumulates at once (taps of a
#: level-0 footprint span up to 3 x 3 cells; more are flushed and restarted, still exact)
_SLOTS = 16


@njit_serial
def _flush_slots(Pa, Pb, granks, gs, cw, ns, wi, wa1, wj, wb1, ia, ja):
    """``sum_slots sum_r cw[slot, r] fa_r fb_r`` with each slot's group factors at the bilinear
    NDF taps (rows ``ia, ia + 1`` weighted ``wi, wa1``; columns ``ja, ja + 1``: ``wj, wb1``).
    ``Pa``, ``Pb`` ``(G, B + 1, R)``: the factors' prefix sums, rank-contiguous."""
    acc = 0.0
    for t in range(ns):
        g = gs[t]
        s = 0.0
        for rr in range(granks[g]):
            a = wi * (Pa[g, ia + 1, rr] - Pa[g, ia, rr])
            if wa1 != 0.0:
                a += wa1 * (Pa[g, ia + 2, rr] - Pa[g, ia + 1, rr])
            b = wj * (Pb[g, ja + 1, rr] - Pb[g, ja, rr])
            if wb1 != 0.0:
                b += wb1 * (Pb[g, ja + 2, rr] - Pb[g, ja + 1, rr])
            s += cw[t, rr] * a * b
        acc += s
    return acc


@njit_parallel
def resample_point_kernel(Pa, Pb, C, block_index, image_cell, granks, offs, ny_l, nx_l, sig_l,
                          st_l, cx, cy, sp, sx, sy, lo, h, trunc, q_min, bilinear, out, done):
    """Point values of Gaussian-resampled footprints (:func:`prefilter.glints.pyramid.
    resample_weights`, the same level choice and taps) without materialising the tap lists:
    taps of one CP group share its factor values at ``s``, which are read once per group.
    ``granks``: the rank of each group (its components come first; adaptive-rank maps pad the
    rest with zeros). ``Pa``, ``Pb`` ``(G, B + 1, R)``: the prefix sums ``A``, ``Bp`` with the
    rank innermost (:func:`prefilter.glints.query._prefix_t`): a group's factors at one NDF
    pixel are a few cache lines instead of one per component (``A[g, :, i]``: 17 floats apart),
    which made level-0 footprints, spread over many groups, 2x slower per tap than upper levels.
    ``done[q] = False`` where no level qualifies (the caller uses another
    path)."""
    B = Pa.shape[1] - 1
    nb = block_index.shape[1]
    R = nb * B
    L = sig_l.shape[0]
    rank = C.shape[1]
    for q in prange(out.shape[0]):
        s = sp[q]
        m = -1
        if s < sig_l[L - 1]:
            for lv in range(L - 1, -1, -1):
                if sig_l[lv] < s:
                    qq = math.sqrt(1.0 - (sig_l[lv] / s) ** 2) * sig_l[lv] / st_l[lv]
                    if qq >= q_min:
                        m = lv
                        break
        if m < 0:
            done[q] = False
            out[q] = 0.0
            continue
        done[q] = True
        r = math.sqrt(s * s - sig_l[m] * sig_l[m])
        st = st_l[m]
        half = trunc * r / st
        gx = (cx[q] - 0.5) / st
        gy = (cy[q] - 0.5) / st
        kx0 = int(math.ceil(gx - half))
        kx1 = int(math.floor(gx + half))
        ky0 = int(math.ceil(gy - half))
        ky1 = int(math.floor(gy + half))
        nx = nx_l[m]
        ny = ny_l[m]
        wx = np.empty(kx1 - kx0 + 1)
        wy = np.empty(ky1 - ky0 + 1)
        sxw = 0.0
        for i in range(kx1 - kx0 + 1):
            d = ((kx0 + i) * st + 0.5 - cx[q]) / r
            wx[i] = math.exp(-0.5 * d * d)
            sxw += wx[i]
        syw = 0.0
        for i in range(ky1 - ky0 + 1):
            d = ((ky0 + i) * st + 0.5 - cy[q]) / r
            wy[i] = math.exp(-0.5 * d * d)
            syw += wy[i]
        i0, u0, u1 = _axis_taps2((sy[q] - lo) / h, R, bilinear)
        j0, v0, v1 = _axis_taps2((sx[q] - lo) / h, R, bilinear)
        # per CP group, the weighted sum of its taps' C rows first (nr multiply-adds per tap),
        # then one product with the group's factor values: taps spanning several cells no
        # longer recompute the factors at every change of group (the mid frame's level-0 taps)
        cw = np.empty((_SLOTS, rank))
        gs = np.empty(_SLOTS, np.int64)
        acc = 0.0
        for di in range(2):
            bi, ia, wi, wa1 = _block_tap(i0, u0, u1, di, B)
            if bi < 0:
                continue
            for dj in range(2):
                bj, ja, wj, wb1 = _block_tap(j0, v0, v1, dj, B)
                if bj < 0:
                    continue
                ns = 0
                last = -1
                slot = 0
                for ty in range(ky1 - ky0 + 1):
                    row = offs[m] + ((ky0 + ty) % ny) * nx
                    for tx in range(kx1 - kx0 + 1):
                        img = row + (kx0 + tx) % nx
                        k = block_index[img, bi, bj]
                        if k < 0:
                            continue
                        g = image_cell[img] * nb * nb + bi * nb + bj
                        nr = granks[g]
                        if g != last:
                            slot = -1
                            for t in range(ns):
                                if gs[t] == g:
                                    slot = t
                                    break
                            if slot < 0:
                                if ns == _SLOTS:
                                    acc += _flush_slots(Pa, Pb, granks, gs, cw, ns, wi, wa1, wj,
                                                        wb1, ia, ja)
                                    ns = 0
                                slot = ns
                                gs[slot] = g
                                for rr in range(nr):
                                    cw[slot, rr] = 0.0
                                ns += 1
                            last = g
                        wt = wy[ty] * wx[tx]
                        for rr in range(nr):
                            cw[slot, rr] += wt * C[k, rr]
                acc += _flush_slots(Pa, Pb, granks, gs, cw, ns, wi, wa1, wj, wb1, ia, ja)
        out[q] = acc / (sxw * syw)
