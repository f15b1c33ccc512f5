"""Numba kernels of the compressed queries (kept apart from ``query.py``, whose public ``range``
would shadow the builtin inside compiled code)."""

from __future__ import annotations

import math

from prefilter._numba import njit_parallel, njit_serial, prange


@njit_serial
def _rect_mass(A, Bp, C, block_index, image_cell, idx, wts, q, bi, bj, i0, i1, j0, j1):
    """Sum of the blended image's pixel values over rows ``[i0, i1)``, columns ``[j0, j1)`` of
    block ``(bi, bj)`` (block-local pixel indices)."""
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
        for r in range(C.shape[1]):
            s += C[k, r] * ((A[g, r, i1] - A[g, r, i0]) * (Bp[g, r, j1] - Bp[g, r, j0]))
        acc += w * s
    return acc


@njit_parallel
def point_kernel(A, Bp, C, block_index, image_cell, idx, wts, sx, sy, lo, h, out):
    R = block_index.shape[1] * (A.shape[2] - 1)
    B = A.shape[2] - 1
    for q in prange(out.shape[0]):
        fx = (sx[q] - lo) / h
        fy = (sy[q] - lo) / h
        acc = 0.0
        if fx >= 0.0 and fy >= 0.0 and fx < R and fy < R:
            j = int(fx)
            i = int(fy)
            bi, bj = i // B, j // B
            i0, j0 = i - bi * B, j - bj * B
            acc = _rect_mass(A, Bp, C, block_index, image_cell, idx, wts, q, bi, bj, i0, i0 + 1,
                             j0, j0 + 1)
        out[q] = acc


@njit_serial
def _prefix_at(P, g, r, u):
    """Integral of factor ``r`` over ``[0, u]`` pixels (prefix sum, linear inside a pixel)."""
    B = P.shape[2] - 1
    if u <= 0.0:
        return 0.0
    if u >= B:
        return P[g, r, B]
    n = int(u)
    return P[g, r, n] + (u - n) * (P[g, r, n + 1] - P[g, r, n])


@njit_parallel
def range_kernel(A, Bp, C, block_index, image_cell, idx, wts, x0, y0, x1, y1, lo, h, out):
    """Mean of the piecewise-constant NDF image over ``[x0, x1] x [y0, y1]`` (zero outside the
    support); the rectangle is split at block boundaries (paper, sec. 4.4)."""
    B = A.shape[2] - 1
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
                        s = 0.0
                        for r in range(C.shape[1]):
                            ia = _prefix_at(A, g, r, v1) - _prefix_at(A, g, r, v0)
                            ib = _prefix_at(Bp, g, r, u1) - _prefix_at(Bp, g, r, u0)
                            s += C[k, r] * ia * ib
                        acc += w * s
        out[q] = acc / area
