"""Numba kernels of the compressed queries (kept apart from ``query.py``, whose public ``range``
would shadow the builtin inside compiled code).

Every kernel takes the packed arrays of :func:`prefilter.glints.query.kernel_args`, in this
order:

* ``Pa``, ``Pb`` ``(M, B + 1)`` (``M``: sum of the groups' ranks): the 1D prefix sums of the row /
  column factors, each group's block of ``r_g (B + 1)`` values rank-innermost (flat index
  ``m_g (B + 1) + i r_g + r``), so a group's components at one NDF pixel are adjacent;
* ``C``: the tuple ``(cq, wsc, Fa, Fb)``: the third factors, flat (row ``k`` of group ``g`` at
  ``cb_g + k stride_g``), the scale of each component ``(M,)`` and the factors
  themselves ``(M, B)`` (flat ``m_g B + i r_g + r``);
* ``block_index``, ``image_cell`` (as in :class:`prefilter.glints.store.GlintsMap`);
* ``meta (G, 4)`` int32 (int64 for very large maps) per group: ``r_g``, ``m_g``, ``cb_g``,
  ``stride_g``; row ``k`` of ``cq`` starts at ``cb_g + k stride_g``.

A pixel of a block of group ``g`` is ``sum_r wsc[m_g + r] cq[k, r] Fa[i, r] Fb[j, r]`` and a
rectangle's sum the same with prefix-sum differences. For version-3 maps these are the stored 8- or
16-bit codes (uint8 or uint16 ``cq``, ``Fa``, ``Fb``; integer prefix sums, exact in uint16 / uint32)
and ``wsc = c_scale / (Q S_a S_b)`` (``Q`` 255 / 65535) with ``S`` the code sums (the loader's
renormalisation), i.e. the values the float arrays ``A``, ``Bp``, ``C`` hold, without their float32
prefix-sum rounding, at 1/4 to 1/8 of their memory traffic; other maps pass float32 arrays and
``wsc = 1`` (Numba compiles one specialisation per dtype)."""

from __future__ import annotations

import math

import numpy as np
from llvmlite import ir
from numba import types
from numba.core import cgutils
from numba.extending import intrinsic, overload

from prefilter.jit import njit_inline, njit_parallel, njit_serial, prange

#: Queries ahead of the one being computed whose ``block_index`` entries (``_AHEAD_INDEX``) and
#: factor rows (``_AHEAD_ROWS``) the point and range kernels prefetch. A random query stream over
#: a 512^2 map misses the cache ~6 times per level-0 point query (``block_index``, ``cq``, ``Fa``,
#: ``Fb``, ``wsc`` lines, each a DRAM latency with little overlap: a chain of dependent loads);
#: prefetching them a few queries ahead overlaps the misses of several queries. Distances 2/4
#: were the best of 2/4 .. 16/32 (level-0 point kernel 0.28 -> 0.18 us, CPU time, 1 thread).
_AHEAD_ROWS = 2
_AHEAD_INDEX = 4


@intrinsic
def _prefetch(typingctx, arr, index):
    """Hint the cache to load the line of ``arr[index]`` (integer or tuple index, no bounds or
    wrap-around check: the address must lie inside the array): LLVM's ``llvm.prefetch``."""
    if not isinstance(arr, types.Array):
        return None
    if isinstance(index, types.Integer):
        n_idx = 1
    elif isinstance(index, types.UniTuple) and isinstance(index.dtype, types.Integer):
        n_idx = index.count
    else:
        return None
    if n_idx != arr.ndim:
        return None

    def codegen(context, builder, signature, args):
        aryty, idxty = signature.args
        ary = context.make_array(aryty)(context, builder, args[0])
        if n_idx == 1:
            idx = [args[1]]
        else:
            idx = [builder.extract_value(args[1], i) for i in range(n_idx)]
        ptr = cgutils.get_item_pointer(context, builder, aryty, ary, idx, wraparound=False)
        i8p = builder.bitcast(ptr, ir.IntType(8).as_pointer())
        i32 = ir.IntType(32)
        fnty = ir.FunctionType(ir.VoidType(), [i8p.type, i32, i32, i32])
        fn = cgutils.get_or_insert_function(builder.module, fnty, "llvm.prefetch.p0")
        # read, high temporal locality, data cache
        builder.call(fn, [i8p, ir.Constant(i32, 0), ir.Constant(i32, 3), ir.Constant(i32, 1)])
        return context.get_dummy_value()

    return types.void(arr, index), codegen


@njit_inline
def _tap_rows(block_index, image_cell, meta, idx, wts, q, c, bi, bj, nb):  # pragma: no cover
    """Footprint ``q``'s tap ``c`` at block ``(bi, bj)``: its weight ``w`` (0 for a zero weight
    or a blank block), its group's rank ``nr``, first component ``m`` and the offset ``kc`` of
    its code row (shared by :func:`_rect_mass` and :func:`_quad_masses`)."""
    w = wts[q, c]
    if w == 0.0:
        return 0.0, 0, 0, 0
    img = idx[q, c]
    k = block_index[img, bi, bj]
    if k < 0:
        return 0.0, 0, 0, 0
    g = image_cell[img] * nb * nb + bi * nb + bj
    return w, meta[g, 0], meta[g, 1], meta[g, 2] + k * meta[g, 3]


@njit_serial
def _rect_mass(Pa, Pb, C, block_index, image_cell, meta, idx, wts, q, bi, bj, i0, i1, j0, j1):
    """Sum of the blended image's pixel values over rows ``[i0, i1)``, columns ``[j0, j1)`` of
    block ``(bi, bj)`` (block-local pixel indices, integers): exact prefix-sum differences."""
    cq, wsc = C[0], C[1]
    pa = Pa.ravel()
    pb = Pb.ravel()
    B1 = Pa.shape[1]
    nb = block_index.shape[1]
    acc = 0.0
    for c in range(idx.shape[1]):
        w, nr, m, kc = _tap_rows(block_index, image_cell, meta, idx, wts, q, c, bi, bj, nb)
        if w == 0.0:
            continue
        base = m * B1
        # slices: indices from range() are known non-negative, so the loop vectorises (flat
        # indices with a computed offset kept a wrap-around check per element: 3x slower)
        a1, a0 = pa[base + i1 * nr:base + (i1 + 1) * nr], pa[base + i0 * nr:base + (i0 + 1) * nr]
        b1, b0 = pb[base + j1 * nr:base + (j1 + 1) * nr], pb[base + j0 * nr:base + (j0 + 1) * nr]
        cr, wr = cq[kc:kc + nr], wsc[m:m + nr]
        s = 0.0
        for r in range(nr):
            s += wr[r] * (float(cr[r]) * (float(a1[r]) - float(a0[r]))
                          * (float(b1[r]) - float(b0[r])))
        acc += w * s
    return acc


@njit_inline
def _quad_masses(Pa, Pb, C, block_index, image_cell, meta, idx, wts, q, bi, bj, i0, im, i1, j0,
                 jm, j1, out):  # pragma: no cover - compiled
    """:func:`_rect_mass` of the four sub-rectangles ``[i0, im) | [im, i1)`` x ``[j0, jm) |
    [jm, j1)`` of block ``(bi, bj)`` in one pass over the images and components (they share the
    prefix-sum rows), written to ``out[0..3]`` (row-major; an empty interval gives 0). Each sum
    is formed with :func:`_rect_mass`'s arithmetic, in its order."""
    cq, wsc = C[0], C[1]
    pa = Pa.ravel()
    pb = Pb.ravel()
    B1 = Pa.shape[1]
    nb = block_index.shape[1]
    out[0] = out[1] = out[2] = out[3] = 0.0
    for c in range(idx.shape[1]):
        w, nr, m, kc = _tap_rows(block_index, image_cell, meta, idx, wts, q, c, bi, bj, nb)
        if w == 0.0:
            continue
        base = m * B1
        a0, am = pa[base + i0 * nr:base + (i0 + 1) * nr], pa[base + im * nr:base + (im + 1) * nr]
        a1 = pa[base + i1 * nr:base + (i1 + 1) * nr]
        b0, bm = pb[base + j0 * nr:base + (j0 + 1) * nr], pb[base + jm * nr:base + (jm + 1) * nr]
        b1 = pb[base + j1 * nr:base + (j1 + 1) * nr]
        cr, wr = cq[kc:kc + nr], wsc[m:m + nr]
        s00 = s01 = s10 = s11 = 0.0
        for r in range(nr):
            da0 = float(am[r]) - float(a0[r])
            da1 = float(a1[r]) - float(am[r])
            db0 = float(bm[r]) - float(b0[r])
            db1 = float(b1[r]) - float(bm[r])
            cf = float(cr[r])
            s00 += wr[r] * (cf * da0 * db0)
            s01 += wr[r] * (cf * da0 * db1)
            s10 += wr[r] * (cf * da1 * db0)
            s11 += wr[r] * (cf * da1 * db1)
        out[0] += w * s00
        out[1] += w * s01
        out[2] += w * s10
        out[3] += w * s11


@njit_inline
def _pixel(sx, sy, lo, h, R, B):
    """Block ``(bi, bj)`` and in-block pixel ``(i0, j0)`` of ``s``; ``bi = -1`` outside."""
    fx = (sx - lo) / h
    fy = (sy - lo) / h
    if fx >= 0.0 and fy >= 0.0 and fx < R and fy < R:
        i = int(fy)
        j = int(fx)
        bi, bj = i // B, j // B
        return bi, bj, i - bi * B, j - bj * B
    return -1, -1, 0, 0


@njit_inline
def _prefetch_index(block_index, image_cell, meta, idx, wts, p, n_pf, bi0, bi1, bj0, bj1):
    """Prefetch the ``block_index`` entries and group records of query ``p``'s images below
    ``n_pf`` over blocks ``[bi0, bi1] x [bj0, bj1]``."""
    nb = block_index.shape[1]
    for c in range(idx.shape[1]):
        img = idx[p, c]
        if wts[p, c] == 0.0 or img >= n_pf:
            continue
        for bi in range(bi0, bi1 + 1):
            for bj in range(bj0, bj1 + 1):
                _prefetch(block_index, (img, bi, bj))
                _prefetch(meta, (image_cell[img] * nb * nb + bi * nb + bj, 0))


@njit_parallel
def point_kernel(Pa, Pb, C, block_index, image_cell, meta, idx, wts, sx, sy, lo, h, n_pf, out):
    """Values of the blended images at ``(sx, sy)``: the stored pixel's factor values. The data
    of images below ``n_pf`` (the levels too large for the cache) is prefetched a few queries
    ahead."""
    cq, wsc, Fa, Fb = C
    B = Pa.shape[1] - 1
    nb = block_index.shape[1]
    R = nb * B
    n = out.shape[0]
    for q in prange(n):
        p = q + _AHEAD_INDEX
        if p < n and idx[p, 0] < n_pf:
            bi, bj, i0, j0 = _pixel(sx[p], sy[p], lo, h, R, B)
            if bi >= 0:
                _prefetch_index(block_index, image_cell, meta, idx, wts, p, n_pf, bi, bi, bj,
                                bj)
        p = q + _AHEAD_ROWS
        if p < n and idx[p, 0] < n_pf:
            bi, bj, i0, j0 = _pixel(sx[p], sy[p], lo, h, R, B)
            if bi >= 0:
                last = -1
                for c in range(idx.shape[1]):
                    img = idx[p, c]
                    if wts[p, c] == 0.0 or img >= n_pf:
                        continue
                    k = block_index[img, bi, bj]
                    if k < 0:
                        continue
                    g = image_cell[img] * nb * nb + bi * nb + bj
                    nr, m = meta[g, 0], meta[g, 1]
                    kc = meta[g, 2] + k * meta[g, 3]
                    _prefetch(cq, kc)
                    _prefetch(cq, kc + nr - 1)
                    if g != last:  # the blended neighbours usually share the group's rows
                        last = g
                        _prefetch(Fa, m * B + i0 * nr)
                        _prefetch(Fb, m * B + j0 * nr)
                        _prefetch(wsc, m)
        bi, bj, i0, j0 = _pixel(sx[q], sy[q], lo, h, R, B)
        acc = 0.0
        if bi >= 0:
            # corners in runs of 4 (a pyramid level's bilinear neighbours): when the run's
            # images all lie in one CP group (one cell), the group's factor product is read once
            # and the code rows are blended first
            for c0 in range(0, idx.shape[1], 4):
                n4 = min(4, idx.shape[1] - c0)
                gq = -1
                kp = 0
                one = n4 == 4
                # scalars, not arrays: an allocation per query cost as much as the upper levels'
                # whole query
                k0 = k1 = k2 = k3 = 0
                w0 = w1 = w2 = w3 = 0.0
                for t in range(n4):
                    w = wts[q, c0 + t]
                    if w == 0.0:
                        continue
                    img = idx[q, c0 + t]
                    k = block_index[img, bi, bj]
                    if k < 0:
                        continue
                    g = image_cell[img] * nb * nb + bi * nb + bj
                    if gq < 0:
                        gq = g
                    elif g != gq:
                        one = False
                    kp = k
                    if t == 0:
                        k0, w0 = k, w
                    elif t == 1:
                        k1, w1 = k, w
                    elif t == 2:
                        k2, w2 = k, w
                    else:
                        k3, w3 = k, w
                if gq < 0:
                    continue
                if one:
                    nr, m = meta[gq, 0], meta[gq, 1]
                    fa = m * B + i0 * nr
                    fb = m * B + j0 * nr
                    ar, br, wr = Fa[fa:fa + nr], Fb[fb:fb + nr], wsc[m:m + nr]
                    cb, st = meta[gq, 2], meta[gq, 3]
                    # absent corners: weight 0 on a present row
                    e0 = cb + (k0 if w0 != 0.0 else kp) * st
                    e1 = cb + (k1 if w1 != 0.0 else kp) * st
                    e2 = cb + (k2 if w2 != 0.0 else kp) * st
                    e3 = cb + (k3 if w3 != 0.0 else kp) * st
                    r0, r1, r2, r3 = cq[e0:e0 + nr], cq[e1:e1 + nr], cq[e2:e2 + nr], \
                        cq[e3:e3 + nr]
                    s = 0.0
                    for r in range(nr):
                        cw = (w0 * float(r0[r]) + w1 * float(r1[r]) + w2 * float(r2[r])
                              + w3 * float(r3[r]))
                        s += wr[r] * (cw * float(ar[r]) * float(br[r]))
                    acc += s
                    continue
                for t in range(n4):
                    w = wts[q, c0 + t]
                    if w == 0.0:
                        continue
                    img = idx[q, c0 + t]
                    k = block_index[img, bi, bj]
                    if k < 0:
                        continue
                    g = image_cell[img] * nb * nb + bi * nb + bj
                    nr, m = meta[g, 0], meta[g, 1]
                    kc = meta[g, 2] + k * meta[g, 3]
                    fa = m * B + i0 * nr
                    fb = m * B + j0 * nr
                    ar, br, cr, wr = Fa[fa:fa + nr], Fb[fb:fb + nr], cq[kc:kc + nr], wsc[m:m + nr]
                    s = 0.0
                    for r in range(nr):
                        s += wr[r] * (float(cr[r]) * float(ar[r]) * float(br[r]))
                    acc += w * s
        out[q] = acc


@njit_inline
def _rect(x0, y0, x1, y1, lo, h, R, B, nb):
    """Pixel rectangle of ``[x0, x1] x [y0, y1]`` clipped to the support ``(cx0, cx1, cy0,
    cy1)``, its blocks ``bi0..bi1``, ``bj0..bj1`` (``bi0 > bi1``: empty) and its unclipped area
    in pixels."""
    px0 = (x0 - lo) / h
    px1 = (x1 - lo) / h
    py0 = (y0 - lo) / h
    py1 = (y1 - lo) / h
    area = (px1 - px0) * (py1 - py0)
    cx0, cx1 = max(px0, 0.0), min(px1, float(R))
    cy0, cy1 = max(py0, 0.0), min(py1, float(R))
    if cx1 > cx0 and cy1 > cy0:
        return (cx0, cx1, cy0, cy1, int(cy0) // B, min(int(math.ceil(cy1)) // B, nb - 1),
                int(cx0) // B, min(int(math.ceil(cx1)) // B, nb - 1), area)
    return cx0, cx1, cy0, cy1, 0, -1, 0, -1, area


@njit_parallel
def range_kernel(Pa, Pb, C, block_index, image_cell, meta, idx, wts, x0, y0, x1, y1, lo, h, n_pf,
                 out):
    """Mean of the piecewise-constant NDF image over ``[x0, x1] x [y0, y1]`` (zero outside the
    support); the rectangle is split at block boundaries (paper, sec. 4.4). Data of images below
    ``n_pf`` is prefetched a few queries ahead (as in :func:`point_kernel`)."""
    cq, wsc = C[0], C[1]
    pa = Pa.ravel()
    pb = Pb.ravel()
    B = Pa.shape[1] - 1
    nb = block_index.shape[1]
    R = nb * B
    n = out.shape[0]
    rmax = 1
    for g in range(meta.shape[0]):
        rmax = max(rmax, meta[g, 0])
    for q in prange(n):
        v = np.empty(rmax)
        p = q + _AHEAD_INDEX
        if p < n and idx[p, 0] < n_pf:
            g0 = _rect(x0[p], y0[p], x1[p], y1[p], lo, h, R, B, nb)
            _prefetch_index(block_index, image_cell, meta, idx, wts, p, n_pf, g0[4], g0[5],
                            g0[6], g0[7])
        p = q + _AHEAD_ROWS
        if p < n and idx[p, 0] < n_pf:
            cx0, cx1, cy0, cy1, bi0, bi1, bj0, bj1, _ = _rect(x0[p], y0[p], x1[p], y1[p], lo, h,
                                                              R, B, nb)
            for bi in range(bi0, bi1 + 1):
                na0 = _prefix_pos(cy0 - bi * B, B)[0]
                na1 = _prefix_pos(cy1 - bi * B, B)[0]
                for bj in range(bj0, bj1 + 1):
                    nb0 = _prefix_pos(cx0 - bj * B, B)[0]
                    nb1 = _prefix_pos(cx1 - bj * B, B)[0]
                    last = -1
                    for c in range(idx.shape[1]):
                        img = idx[p, c]
                        if wts[p, c] == 0.0 or img >= n_pf:
                            continue
                        k = block_index[img, bi, bj]
                        if k < 0:
                            continue
                        g = image_cell[img] * nb * nb + bi * nb + bj
                        nr, m = meta[g, 0], meta[g, 1]
                        _prefetch(cq, meta[g, 2] + k * meta[g, 3])
                        if g == last:
                            continue
                        last = g
                        base = m * (B + 1)
                        _prefetch(wsc, m)
                        if na0 > 0:  # row 0 is zero, never read
                            _prefetch(pa, base + na0 * nr)
                        _prefetch(pa, base + na1 * nr)
                        if nb0 > 0:
                            _prefetch(pb, base + nb0 * nr)
                        _prefetch(pb, base + nb1 * nr)
        cx0, cx1, cy0, cy1, bi0, bi1, bj0, bj1, area = _rect(x0[q], y0[q], x1[q], y1[q], lo, h,
                                                             R, B, nb)
        acc = 0.0
        # per block, the corners' images of one CP group (neighbours in the pyramid: usually all
        # of them) share the group's factor means v_r = wsc_r (da_r db_r): computed once per
        # group, then one dot product with each image's code row
        for bi in range(bi0, bi1 + 1):
            na0, ta0 = _prefix_pos(cy0 - bi * B, B)
            na1, ta1 = _prefix_pos(cy1 - bi * B, B)
            for bj in range(bj0, bj1 + 1):
                nb0, tb0 = _prefix_pos(cx0 - bj * B, B)
                nb1, tb1 = _prefix_pos(cx1 - bj * B, B)
                last = -1
                for c in range(idx.shape[1]):
                    w = wts[q, c]
                    if w == 0.0:
                        continue
                    img = idx[q, c]
                    k = block_index[img, bi, bj]
                    if k < 0:
                        continue
                    g = image_cell[img] * nb * nb + bi * nb + bj
                    nr, m = meta[g, 0], meta[g, 1]
                    if g != last:
                        last = g
                        base = m * (B + 1)
                        # rows n and n + 1 of each of the four prefix sums (the next row is read
                        # only with a nonzero weight: it may be past the block's end)
                        ea0 = ra0 = base + na0 * nr
                        ea1 = ra1 = base + na1 * nr
                        eb0 = rb0 = base + nb0 * nr
                        eb1 = rb1 = base + nb1 * nr
                        if ta0 != 0.0:
                            ea0 += nr
                        if ta1 != 0.0:
                            ea1 += nr
                        if tb0 != 0.0:
                            eb0 += nr
                        if tb1 != 0.0:
                            eb1 += nr
                        # prefix row 0 is zero: not read (its line is often the only one
                        # missing), the row-1 slice stands in with weight 0
                        ka0 = 0.0 if ea0 == base else 1.0
                        kb0 = 0.0 if eb0 == base else 1.0
                        if ea0 == base:
                            ra0 = ea0 = ra1
                        if eb0 == base:
                            rb0 = eb0 = rb1
                        a0s, a0e = pa[ra0:ra0 + nr], pa[ea0:ea0 + nr]
                        a1s, a1e = pa[ra1:ra1 + nr], pa[ea1:ea1 + nr]
                        b0s, b0e = pb[rb0:rb0 + nr], pb[eb0:eb0 + nr]
                        b1s, b1e = pb[rb1:rb1 + nr], pb[eb1:eb1 + nr]
                        wr = wsc[m:m + nr]
                        for r in range(nr):
                            a0 = float(a0s[r])
                            a0 = ka0 * (a0 + ta0 * (float(a0e[r]) - a0))
                            a1 = float(a1s[r])
                            a1 += ta1 * (float(a1e[r]) - a1)
                            b0 = float(b0s[r])
                            b0 = kb0 * (b0 + tb0 * (float(b0e[r]) - b0))
                            b1 = float(b1s[r])
                            b1 += tb1 * (float(b1e[r]) - b1)
                            v[r] = wr[r] * ((a1 - a0) * (b1 - b0))
                    kc = meta[g, 2] + k * meta[g, 3]
                    cr = cq[kc:kc + nr]
                    s = 0.0
                    for r in range(nr):
                        s += float(cr[r]) * v[r]
                    acc += w * s
        out[q] = acc / area


@njit_inline
def _prefix_pos(u, B):
    """Row ``n`` and weight ``t`` of the prefix sum at ``u`` pixels of a block (linear inside a
    pixel, clamped to ``[0, B]``): value ``P[n] + t (P[n + 1] - P[n])``."""
    if u <= 0.0:
        return 0, 0.0
    if u >= B:
        return B, 0.0
    n = int(u)
    return n, u - n


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
def bilinear_kernel(Pa, Pb, C, block_index, image_cell, meta, idx, wts, sx, sy, lo, h, out):
    """Point values of the blended images reconstructed bilinearly between pixel centres.

    The CP image of a block is ``sum_r c_r a_r (x) b_r``, so a bilinear combination of pixels of
    one block is ``sum_r c_r (sum_i u_i a_r[i]) (sum_j v_j b_r[j])``: two factor lookups per axis
    instead of four pixel values; neighbours in another block are taken from that block."""
    cq, wsc, Fa, Fb = C
    B = Pa.shape[1] - 1
    nb = block_index.shape[1]
    R = nb * B
    for q in prange(out.shape[0]):
        i0, u0, u1 = pixel_taps((sy[q] - lo) / h, R, True)
        j0, v0, v1 = pixel_taps((sx[q] - lo) / h, R, True)
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
                    nr, m = meta[g, 0], meta[g, 1]
                    kc = meta[g, 2] + k * meta[g, 3]
                    acc += w * _factor_dot(Fa, Fb, wsc, m, B, nr, ia, wa0, wa1, ja, wb0, wb1, cq,
                                           kc)
        out[q] = acc


@njit_inline
def _factor_dot(Fa, Fb, wsc, m, B, nr, ia, wa0, wa1, ja, wb0, wb1, cw, kc):
    """``sum_r wsc[m + r] cw[kc + r] fa_r fb_r`` over the ``nr`` components of the group whose
    factors start at flat index ``m B``, with ``fa_r = wa0 Fa[ia, r] + wa1 Fa[ia + 1, r]`` (the
    second tap skipped when ``wa1 == 0``; ``fb`` likewise)."""
    ra = m * B + ia * nr
    rb = m * B + ja * nr
    # the second row only with a nonzero weight (it may be past the group's block)
    ea = ra + nr if wa1 != 0.0 else ra
    eb = rb + nr if wb1 != 0.0 else rb
    a0, a1, b0, b1 = Fa[ra:ra + nr], Fa[ea:ea + nr], Fb[rb:rb + nr], Fb[eb:eb + nr]
    cr, wr = cw[kc:kc + nr], wsc[m:m + nr]
    s = 0.0
    for r in range(nr):
        fa = wa0 * float(a0[r]) + wa1 * float(a1[r])
        fb = wb0 * float(b0[r]) + wb1 * float(b1[r])
        s += wr[r] * (float(cr[r]) * fa * fb)
    return s


@njit_serial
def pixel_taps(f, R, bilinear):
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
def _flush_slots(Fa, Fb, wsc, meta, B, gs, cw, ns, wi, wa1, wj, wb1, ia, ja):
    """``sum_slots sum_r cw[slot, r] wsc_r fa_r fb_r`` with each slot's group factors at the
    bilinear NDF taps (rows ``ia, ia + 1`` weighted ``wi, wa1``; columns ``ja, ja + 1``: ``wj,
    wb1``)."""
    acc = 0.0
    for t in range(ns):
        g = gs[t]
        acc += _factor_dot(Fa, Fb, wsc, meta[g, 1], B, meta[g, 0], ia, wi, wa1, ja, wj, wb1,
                           cw[t], 0)
    return acc


@njit_parallel
def resample_point_kernel(Pa, Pb, C, block_index, image_cell, meta, offs, ny_l, nx_l, sig_l,
                          st_l, cx, cy, sp, sx, sy, lo, h, trunc, q_min, bilinear, out, done):
    """Point values of Gaussian-resampled footprints (:func:`prefilter.glints.pyramid.
    resample_weights`, the same level choice and taps) without materialising the tap lists:
    taps of one CP group share its factor values at ``s``, which are read once per group (the
    taps' ``cq`` rows are summed first). ``done[q] = False`` where no level qualifies (the
    caller uses another path)."""
    cq, wsc, Fa, Fb = C
    B = Pa.shape[1] - 1
    nb = block_index.shape[1]
    R = nb * B
    L = sig_l.shape[0]
    rank = 1
    for g in range(meta.shape[0]):
        rank = max(rank, meta[g, 0])
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
        i0, u0, u1 = pixel_taps((sy[q] - lo) / h, R, bilinear)
        j0, v0, v1 = pixel_taps((sx[q] - lo) / h, R, bilinear)
        # per CP group, the weighted sum of its taps' C rows first (nr multiply-adds per tap),
        # then one product with the group's factor values: taps spanning several cells no
        # longer recompute the factors at every change of group (the mid frame's level-0 taps)
        # float32 sums of weighted 8-bit rows (relative rounding ~1e-7, far below the codes'):
        # twice the vector width of float64, which the far frame's long rows of wide-rank
        # groups (up to 3x the budget) are bound by
        cw = np.empty((_SLOTS, rank), np.float32)
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
                        nr = meta[g, 0]
                        if g != last:
                            slot = -1
                            for t in range(ns):
                                if gs[t] == g:
                                    slot = t
                                    break
                            if slot < 0:
                                if ns == _SLOTS:
                                    acc += _flush_slots(Fa, Fb, wsc, meta, B, gs, cw, ns, wi,
                                                        wa1, wj, wb1, ia, ja)
                                    ns = 0
                                slot = ns
                                gs[slot] = g
                                for rr in range(nr):
                                    cw[slot, rr] = 0.0
                                ns += 1
                            last = g
                        wt = wy[ty] * wx[tx]
                        kc = meta[g, 2] + k * meta[g, 3]
                        cr = cq[kc:kc + nr]
                        wt32 = np.float32(wt)
                        for rr in range(nr):
                            cw[slot, rr] += wt32 * np.float32(cr[rr])
                acc += _flush_slots(Fa, Fb, wsc, meta, B, gs, cw, ns, wi, wa1, wj, wb1, ia, ja)
        out[q] = acc / (sxw * syw)


def _as_acc(x, like):
    """``x`` converted to the float type of ``like`` (compiled code only: Numba types a float32
    times a uint16 as float64)."""
    raise NotImplementedError


@overload(_as_acc, inline="always")
def _as_acc_impl(x, like):
    if isinstance(like, types.Float) and like.bitwidth == 32:
        return lambda x, like: np.float32(x)
    return lambda x, like: np.float64(x)


@njit_inline
def _axis_rows(u0, u1, B):
    """Prefix rows ``n0..n3`` and coefficients ``(k0, c0, cm, c1)`` of the mass of pixels
    ``[u0, u1]`` of one axis of a block (block-local, clamped to ``[0, B]``) as
    ``c0 (P[n1] - k0 P[n0]) + cm (P[n2] - P[n1]) + c1 (P[n3] - P[n2])``: partial first pixel,
    whole pixels, partial last pixel; nonnegative terms for nonnegative factors, so no
    cancellation (the 8-bit path sums them in float32). Rows not needed repeat a needed one
    (their difference is 0: row ``n + 1`` may lie past the block); row 0 (zero) is replaced by
    row ``n1`` with ``k0 = 0`` (its cache line is often the only one missing)."""
    na0, ta0 = _prefix_pos(u0, B)
    na1, ta1 = _prefix_pos(u1, B)
    if na1 > na0:
        n0, n1, n2 = na0, na0 + 1, na1
        n3 = na1 + 1 if ta1 != 0.0 else na1
        c0, cm, c1 = 1.0 - ta0, 1.0, ta1
    else:  # within one pixel
        n0 = na0
        n1 = na0 + 1 if ta1 > ta0 else na0
        n2 = n3 = n1
        c0, cm, c1 = ta1 - ta0, 0.0, 0.0
    k0 = 1.0
    if n0 == 0:
        n0, k0 = n1, 0.0
    return n0, n1, n2, n3, k0, c0, cm, c1


@njit_inline
def _touching(rbk, rcl, bi, bj, B, touch, rp, rt):  # pragma: no cover - compiled
    """The rectangles ``k`` (block ranges ``rbk (K, 4)``, clipped pixel bounds ``rcl (K, 4)``)
    that overlap block ``(bi, bj)``: their ids in ``touch[:nt]``, their :func:`_axis_rows` rows
    and weights within the block in ``rp[k]``, ``rt[k]`` (rows then columns). Returns ``nt``."""
    nt = 0
    for k in range(rbk.shape[0]):
        if rbk[k, 0] <= bi <= rbk[k, 1] and rbk[k, 2] <= bj <= rbk[k, 3]:
            touch[nt] = k
            nt += 1
            (rp[k, 0], rp[k, 1], rp[k, 2], rp[k, 3], rt[k, 0], rt[k, 1],
             rt[k, 2], rt[k, 3]) = _axis_rows(rcl[k, 2] - bi * B, rcl[k, 3] - bi * B, B)
            (rp[k, 4], rp[k, 5], rp[k, 6], rp[k, 7], rt[k, 4], rt[k, 5],
             rt[k, 6], rt[k, 7]) = _axis_rows(rcl[k, 0] - bj * B, rcl[k, 1] - bj * B, B)
    return nt


@njit_serial
def _flush_rects(pa, pb, wsc, meta, B, gs, cw, ns, rp, rt, touch, nt, tt, acc):
    """Add ``sum_r cw[slot, r] wsc_r da_r db_r`` of every slot's group to ``acc[k]`` of each
    rectangle ``k = touch[:nt]`` of the block, ``da_r``, ``db_r`` its factor masses over the
    rectangle from the prefix rows ``rp[k]`` and coefficients ``rt[k]`` of
    :func:`_axis_rows` (rows axis then columns axis). Computed in ``cw``'s dtype (``tt``: 9
    scratch values of it): float32 for the 8-bit codes, whose integer prefix sums (< 2^24) and
    their differences are exact in float32, the rest sums of nonnegative terms (relative
    rounding ~1e-7)."""
    B1 = B + 1
    for t in range(ns):
        g = gs[t]
        nr, m = meta[g, 0], meta[g, 1]
        base = m * B1
        wr = wsc[m:m + nr]
        cr = cw[t]
        for u in range(nt):
            k = touch[u]
            for e in range(8):
                tt[e] = rt[k, e]
            tt[8] = 1.0  # a float literal would promote the float32 arithmetic to float64
            ka, ca0, cam, ca1 = tt[0], tt[1], tt[2], tt[3]
            kb, cb0, cbm, cb1 = tt[4], tt[5], tt[6], tt[7]
            one = tt[8]
            o = base + rp[k, 0] * nr
            p0 = pa[o:o + nr]
            o = base + rp[k, 1] * nr
            p1 = pa[o:o + nr]
            o = base + rp[k, 2] * nr
            p2 = pa[o:o + nr]
            o = base + rp[k, 3] * nr
            p3 = pa[o:o + nr]
            o = base + rp[k, 4] * nr
            q0 = pb[o:o + nr]
            o = base + rp[k, 5] * nr
            q1 = pb[o:o + nr]
            o = base + rp[k, 6] * nr
            q2 = pb[o:o + nr]
            o = base + rp[k, 7] * nr
            q3 = pb[o:o + nr]
            s = one - one
            for r in range(nr):
                a1, a2 = _as_acc(p1[r], one), _as_acc(p2[r], one)
                b1, b2 = _as_acc(q1[r], one), _as_acc(q2[r], one)
                da = (ca0 * (a1 - ka * _as_acc(p0[r], one)) + cam * (a2 - a1)
                      + ca1 * (_as_acc(p3[r], one) - a2))
                db = (cb0 * (b1 - kb * _as_acc(q0[r], one)) + cbm * (b2 - b1)
                      + cb1 * (_as_acc(q3[r], one) - b2))
                s += cr[r] * (wr[r] * (da * db))
            acc[k] += s


@njit_parallel
def range_multi_kernel(Pa, Pb, C, block_index, image_cell, meta, idx, wts, x0, y0, x1, y1, lo,
                       h, proto, out):
    """:func:`range_kernel` for ``K`` rectangles per footprint: ``x0 .. y1 (N, K)``, one blend
    ``idx, wts (N, T)`` per footprint, ``out (N, K)``.

    Per block touched by any of a footprint's rectangles, the taps' code rows are summed per CP
    group first (weighted, in ``proto``'s dtype: float32 for 8-bit codes, as
    :func:`resample_point_kernel`), then one dot product of each group's sum with the group's
    factor differences per rectangle touching the block: the taps are walked once per block,
    not once per (block, rectangle)."""
    cq, wsc = C[0], C[1]
    pa = Pa.ravel()
    pb = Pb.ravel()
    B = Pa.shape[1] - 1
    nb = block_index.shape[1]
    R = nb * B
    N, K = out.shape
    T = idx.shape[1]
    rank = 1
    for g in range(meta.shape[0]):
        rank = max(rank, meta[g, 0])
    for q in prange(N):
        cw = np.empty((_SLOTS, rank), proto.dtype)
        one = np.empty(1, proto.dtype)  # the weight in the accumulator's dtype
        tt = np.empty(9, proto.dtype)
        gs = np.empty(_SLOTS, np.int64)
        rbk = np.empty((K, 4), np.int64)  # blocks bi0, bi1, bj0, bj1 (bi0 > bi1: empty)
        rcl = np.empty((K, 4))  # clipped pixel bounds cx0, cx1, cy0, cy1
        rp = np.empty((K, 8), np.int64)
        rt = np.empty((K, 8))
        area = np.empty(K)
        acc = np.zeros(K)
        touch = np.empty(K, np.int64)
        ubi0, ubi1, ubj0, ubj1 = nb, -1, nb, -1
        for k in range(K):
            cx0, cx1, cy0, cy1, bi0, bi1, bj0, bj1, a = _rect(x0[q, k], y0[q, k], x1[q, k],
                                                              y1[q, k], lo, h, R, B, nb)
            rcl[k, 0], rcl[k, 1], rcl[k, 2], rcl[k, 3] = cx0, cx1, cy0, cy1
            rbk[k, 0], rbk[k, 1], rbk[k, 2], rbk[k, 3] = bi0, bi1, bj0, bj1
            area[k] = a
            if bi0 <= bi1 and bj0 <= bj1:
                ubi0, ubi1 = min(ubi0, bi0), max(ubi1, bi1)
                ubj0, ubj1 = min(ubj0, bj0), max(ubj1, bj1)
        for bi in range(ubi0, ubi1 + 1):
            for bj in range(ubj0, ubj1 + 1):
                nt = _touching(rbk, rcl, bi, bj, B, touch, rp, rt)
                if nt == 0:
                    continue
                ns = 0
                last = -1
                slot = 0
                for c in range(T):
                    w = wts[q, c]
                    if w == 0.0:
                        continue
                    img = idx[q, c]
                    kb = block_index[img, bi, bj]
                    if kb < 0:
                        continue
                    g = image_cell[img] * nb * nb + bi * nb + bj
                    nr = meta[g, 0]
                    if g != last:
                        slot = -1
                        for t in range(ns):
                            if gs[t] == g:
                                slot = t
                                break
                        if slot < 0:
                            if ns == _SLOTS:
                                _flush_rects(pa, pb, wsc, meta, B, gs, cw, ns, rp, rt, touch,
                                             nt, tt, acc)
                                ns = 0
                            slot = ns
                            gs[slot] = g
                            for rr in range(nr):
                                cw[slot, rr] = 0.0
                            ns += 1
                        last = g
                    one[0] = w
                    wt = one[0]
                    kc = meta[g, 2] + kb * meta[g, 3]
                    cr = cq[kc:kc + nr]
                    for rr in range(nr):
                        cw[slot, rr] += wt * cr[rr]
                _flush_rects(pa, pb, wsc, meta, B, gs, cw, ns, rp, rt, touch, nt, tt, acc)
        for k in range(K):
            out[q, k] = acc[k] / area[k]
