"""Numba kernels of the ``ltc`` shader (Heitz et al. 2016, eqs. 10-11): one shading point's
quad lights (:func:`ltc_point`), over flat arrays (:func:`ltc_quads_kernel`) and fused with the
renderer's per-sample surface (:func:`ltc_samples_kernel`, the whole ``ltc`` method for quad
lights; methods that only change the roughness compose the same parts with their own, as
``prefilter.multiscale.kernels`` does).

Each kernel writes every output element from exactly one loop iteration (no parallel reductions),
so results do not depend on the thread count. Their NumPy twin is a check in
``tests/ltc/ltc_numpy.py``.
"""

from __future__ import annotations

import math

import numpy as np

from prefilter.jit import njit_parallel, njit_serial, prange
from prefilter.ltc.polygon import _DET_RTOL2, _INV_2PI, _clipped_edge_sum
from prefilter.render.kernels import gscratch, surface_sample

__all__ = ["BLOCK", "ltc_point", "ltc_quads_kernel", "ltc_samples_kernel", "ltc_scratch"]

#: Shading points per scratch buffer of the fused kernels.
BLOCK = 256


@njit_serial
def _interp_index(x, xp):
    """``np.interp(x, xp, arange(len(xp)))`` for increasing ``xp``."""
    n = xp.shape[0]
    if x <= xp[0]:
        return 0.0
    if x >= xp[n - 1]:
        return n - 1.0
    lo = 0
    hi = n - 1
    while hi - lo > 1:  # xp[lo] <= x < xp[hi]
        mid = (lo + hi) // 2
        if xp[mid] <= x:
            lo = mid
        else:
            hi = mid
    return lo + (x - xp[lo]) / (xp[lo + 1] - xp[lo])


@njit_serial
def _polygon(t, verts, n):
    """Heitz et al. 2016 (eq. 11 after clipping): integral of the clamped cosine over
    ``t verts[:n]`` (one-sided), as ``prefilter.ltc.polygon._polygon_kernel`` with
    ``invert=False``: ``t[:9]`` an invertible matrix (row-major, largest entry 1), ``t[9]`` the
    sign of its determinant."""
    acc, ok = _clipped_edge_sum(t[0], t[1], t[2], t[3], t[4], t[5], t[6], t[7], t[8], verts, n)
    if not ok:
        return 0.0
    return max(0.0, -t[9] * acc * _INV_2PI)


@njit_serial
def _clip_to_horizon(P, n, out):
    """Sutherland-Hodgman of ``P[:n]`` against ``z >= 0`` into ``out[:n + 1]``, padded by
    repeating the last vertex (all zeros when nothing is above), as ``ltc.clip_to_horizon``."""
    count = 0
    for i in range(n):
        ia = i - 1 if i > 0 else n - 1
        az = P[ia, 2]
        bz = P[i, 2]
        a_in = az >= 0.0
        b_in = bz >= 0.0
        if a_in != b_in:
            s = az / (az - bz)
            out[count, 0] = P[ia, 0] + s * (P[i, 0] - P[ia, 0])
            out[count, 1] = P[ia, 1] + s * (P[i, 1] - P[ia, 1])
            out[count, 2] = 0.0
            count += 1
        if b_in:
            out[count, 0] = P[i, 0]
            out[count, 1] = P[i, 1]
            out[count, 2] = bz
            count += 1
    if count == 0:
        for j in range(n + 1):
            out[j, 0] = 0.0
            out[j, 1] = 0.0
            out[j, 2] = 0.0
    else:
        for j in range(count, n + 1):
            out[j, 0] = out[count - 1, 0]
            out[j, 1] = out[count - 1, 1]
            out[j, 2] = out[count - 1, 2]


@njit_serial
def ltc_point(geo, mat, qv, qn, qrad, axis_t, axis_r, tab_m, tab_mag, tab_fres, view_z_min,
               P, C, ident, tm, mm, res):
    """Quad-light radiance of one shading point (Heitz et al. 2016, eqs. 10-11), added to
    ``res (3,)``. ``geo (5, 3)``: position, shading t, b, n, unit view; ``mat (7,)``: alpha,
    base colour, f0. Scratch: ``P (4, 3)``, ``C (5, 3)``, ``ident, tm (10,)``, ``mm (9,)``.
    Returns False when the interpolated LTC matrix is singular (nothing added)."""
    nt = axis_t.shape[0]
    nr = axis_r.shape[0]
    a_min = axis_r[0] * axis_r[0]
    t0, t1, t2 = geo[1, 0], geo[1, 1], geo[1, 2]
    b0, b1, b2 = geo[2, 0], geo[2, 1], geo[2, 2]
    n0, n1, n2 = geo[3, 0], geo[3, 1], geo[3, 2]
    v0, v1, v2 = geo[4, 0], geo[4, 1], geo[4, 2]
    # the view in the shading frame, clamped to the shading hemisphere
    wx = v0 * t0 + v1 * t1 + v2 * t2
    wy = v0 * b0 + v1 * b1 + v2 * b2
    wz = max(v0 * n0 + v1 * n1 + v2 * n2, view_z_min)
    inv = 1.0 / math.sqrt(wx * wx + wy * wy + wz * wz)
    wx *= inv
    wy *= inv
    wz *= inv
    # bilinear table lookup in (sqrt(1 - cos theta), sqrt(alpha))
    ft = _interp_index(math.sqrt(max(0.0, 1.0 - wz)), axis_t)
    fr = _interp_index(math.sqrt(min(max(mat[0], a_min), 1.0)), axis_r)
    i = min(np.int64(math.floor(ft)), nt - 2)
    j = min(np.int64(math.floor(fr)), nr - 2)
    a = ft - i
    b = fr - j
    w00 = (1 - a) * (1 - b)
    w10 = a * (1 - b)
    w01 = (1 - a) * b
    w11 = a * b
    for e in range(9):
        r_ = e // 3
        c_ = e % 3
        mm[e] = (w00 * tab_m[i, j, r_, c_] + w10 * tab_m[i + 1, j, r_, c_]
                 + w01 * tab_m[i, j + 1, r_, c_] + w11 * tab_m[i + 1, j + 1, r_, c_])
    mag = (w00 * tab_mag[i, j] + w10 * tab_mag[i + 1, j] + w01 * tab_mag[i, j + 1]
           + w11 * tab_mag[i + 1, j + 1])
    fres = (w00 * tab_fres[i, j] + w10 * tab_fres[i + 1, j] + w01 * tab_fres[i, j + 1]
            + w11 * tab_fres[i + 1, j + 1])
    # Rz(phi) M Rz(phi)^T, phi the view's azimuth
    rho = math.sqrt(wx * wx + wy * wy)
    if rho > 0.0:
        c = wx / rho
        s = wy / rho
    else:
        c = 1.0
        s = 0.0
    r00 = c * mm[0] - s * mm[3]
    r01 = c * mm[1] - s * mm[4]
    r02 = c * mm[2] - s * mm[5]
    r10 = s * mm[0] + c * mm[3]
    r11 = s * mm[1] + c * mm[4]
    r12 = s * mm[2] + c * mm[5]
    a00 = r00 * c - r01 * s
    a01 = r00 * s + r01 * c
    a02 = r02
    a10 = r10 * c - r11 * s
    a11 = r10 * s + r11 * c
    a12 = r12
    a20 = mm[6] * c - mm[7] * s
    a21 = mm[6] * s + mm[7] * c
    a22 = mm[8]
    # sign(det) adj(M) = |det M| M^-1 (the integral only needs M^-1 up to a positive factor)
    k00 = a11 * a22 - a12 * a21
    k01 = a12 * a20 - a10 * a22
    k02 = a10 * a21 - a11 * a20
    det = a00 * k00 + a01 * k01 + a02 * k02
    c0 = a00 * a00 + a10 * a10 + a20 * a20
    c1 = a01 * a01 + a11 * a11 + a21 * a21
    c2 = a02 * a02 + a12 * a12 + a22 * a22
    if not (det * det > _DET_RTOL2 * (c0 * c1 * c2)):
        return False
    sg = 1.0 if det > 0.0 else -1.0
    tm[0] = sg * k00
    tm[1] = sg * (a02 * a21 - a01 * a22)
    tm[2] = sg * (a01 * a12 - a02 * a11)
    tm[3] = sg * k01
    tm[4] = sg * (a00 * a22 - a02 * a20)
    tm[5] = sg * (a02 * a10 - a00 * a12)
    tm[6] = sg * k02
    tm[7] = sg * (a01 * a20 - a00 * a21)
    tm[8] = sg * (a00 * a11 - a01 * a10)
    tmax = 0.0
    for e in range(9):
        tmax = max(tmax, abs(tm[e]))
    for e in range(9):
        tm[e] /= tmax
    tm[9] = sg  # det(|det| M^-1) has the sign of det M: undo the mirror
    # Schlick through the table's (n, f5): f0 (n - f5) + f5
    sp0 = mat[4] * (mag - fres) + fres
    sp1 = mat[5] * (mag - fres) + fres
    sp2 = mat[6] * (mag - fres) + fres
    px, py, pz = geo[0, 0], geo[0, 1], geo[0, 2]
    for q in range(qv.shape[0]):
        front = ((px - qv[q, 0, 0]) * qn[q, 0] + (py - qv[q, 0, 1]) * qn[q, 1]
                 + (pz - qv[q, 0, 2]) * qn[q, 2]) > 0.0
        if not front:  # one-sided lights
            continue
        for vtx in range(4):
            dx = qv[q, vtx, 0] - px
            dy = qv[q, vtx, 1] - py
            dz = qv[q, vtx, 2] - pz
            P[vtx, 0] = dx * t0 + dy * t1 + dz * t2
            P[vtx, 1] = dx * b0 + dy * b1 + dz * b2
            P[vtx, 2] = dx * n0 + dy * n1 + dz * n2
        e_d = _polygon(ident, P, 4)
        # cut at the shading horizon before the LTC transform (see prefilter.ltc.shading.shade_ltc)
        _clip_to_horizon(P, 4, C)
        e_s = _polygon(tm, C, 5)
        res[0] += (mat[1] * e_d + sp0 * e_s) * qrad[q, 0]
        res[1] += (mat[2] * e_d + sp1 * e_s) * qrad[q, 1]
        res[2] += (mat[3] * e_d + sp2 * e_s) * qrad[q, 2]
    return True


@njit_serial
def ltc_scratch():
    """Scratch arrays of :func:`ltc_point` (and the identity as a polygon transform)."""
    ident = np.zeros(10)
    ident[0] = 1.0
    ident[4] = 1.0
    ident[8] = 1.0
    ident[9] = 1.0
    return (np.empty((5, 3)), np.empty(7), np.empty((4, 3)), np.empty((5, 3)), ident,
            np.empty(10), np.empty(9), np.empty(3))


@njit_parallel
def ltc_quads_kernel(position, ts, bs, ns, view, alpha, base, f0, qv, qn, qrad, axis_t, axis_r,
                     tab_m, tab_mag, tab_fres, view_z_min, out, status):
    """Quad-light radiance of the ``ltc`` shader added to ``out (N, 3)`` for flat arrays
    (:func:`ltc_point` per point); ``status[k] = 1`` flags a singular LTC matrix."""
    n_pts = position.shape[0]
    n_blocks = (n_pts + BLOCK - 1) // BLOCK
    for blk in prange(n_blocks):
        geo, mat, P, C, ident, tm, mm, res = ltc_scratch()
        for k in range(blk * BLOCK, min(n_pts, (blk + 1) * BLOCK)):
            for c in range(3):
                geo[0, c] = position[k, c]
                geo[1, c] = ts[k, c]
                geo[2, c] = bs[k, c]
                geo[3, c] = ns[k, c]
                geo[4, c] = view[k, c]
                mat[1 + c] = base[k, c]
                mat[4 + c] = f0[k, c]
                res[c] = 0.0
            mat[0] = alpha[k]
            if ltc_point(geo, mat, qv, qn, qrad, axis_t, axis_r, tab_m, tab_mag, tab_fres,
                          view_z_min, P, C, ident, tm, mm, res):
                for c in range(3):
                    out[k, c] += res[c]
            else:
                status[k] = 1


@njit_parallel
def ltc_samples_kernel(cam, xy, types, params, mat_f, mat_i, data, info, tex, read, qv, qn, qrad,
                       axis_t, axis_r, tab_m, tab_mag, tab_fres, view_z_min, rad, status):
    """The ``ltc`` method for quad lights per sample, without intermediate arrays: the surface
    seen through ``xy (N, 2)`` (:func:`prefilter.render.kernels.surface_sample`, ``read`` the
    per-material normal-map read) and :func:`ltc_point` with the isotropic table at
    ``sqrt(alpha_x alpha_y)``. Writes ``rad (N, 3)`` (0 on misses); ``status[k] = 1`` flags a
    singular LTC matrix."""
    n_pts = xy.shape[0]
    n_blocks = (n_pts + BLOCK - 1) // BLOCK
    for blk in prange(n_blocks):
        geo, mat, P, C, ident, tm, mm, res = ltc_scratch()
        gs = gscratch()
        tx = np.empty((2, 4))
        for k in range(blk * BLOCK, min(n_pts, (blk + 1) * BLOCK)):
            rad[k, 0] = 0.0
            rad[k, 1] = 0.0
            rad[k, 2] = 0.0
            hit, o, _r = surface_sample(cam, xy[k, 0], xy[k, 1], types, params, mat_f, mat_i,
                                       data, info, tex, read, gs, tx, geo, mat)
            if not hit:
                continue
            mat[0] = math.sqrt(mat_f[o, 0] * mat_f[o, 1])
            for c in range(3):
                res[c] = 0.0
            if ltc_point(geo, mat, qv, qn, qrad, axis_t, axis_r, tab_m, tab_mag, tab_fres,
                         view_z_min, P, C, ident, tm, mm, res):
                rad[k, 0] = res[0]
                rad[k, 1] = res[1]
                rad[k, 2] = res[2]
            else:
                status[k] = 1
