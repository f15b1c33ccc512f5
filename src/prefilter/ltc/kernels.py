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
from prefilter.microfacet.ltc import ltc_lookup
from prefilter.sphere.polygon import clip_to_horizon_jit, polygon_integral_jit
from prefilter.render.kernels import gscratch, surface_sample

__all__ = ["BLOCK", "ltc_point", "ltc_quads_kernel", "ltc_samples_kernel", "ltc_scratch"]

#: Shading points per scratch buffer of the fused kernels.
BLOCK = 256


@njit_serial
def ltc_point(geo, mat, qv, qn, qrad, axis_t, axis_r, tab_m, tab_mag, tab_fres, view_z_min,
               P, C, ident, tm, mm, res):
    """Quad-light radiance of one shading point (Heitz et al. 2016, eqs. 10-11), added to
    ``res (3,)``. ``geo (5, 3)``: position, shading t, b, n, unit view; ``mat (7,)``: alpha,
    base colour, f0. Scratch: ``P (4, 3)``, ``C (5, 3)``, ``ident, tm (10,)``, ``mm (9,)``.
    Returns False when the interpolated LTC matrix is singular (nothing added)."""
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
    ok, mag, fres = ltc_lookup(wx, wy, wz, mat[0], axis_t, axis_r, tab_m, tab_mag, tab_fres,
                               mm, tm)
    if not ok:
        return False
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
        e_d = polygon_integral_jit(ident, P, 4)
        # cut at the shading horizon before the LTC transform (see prefilter.ltc.shading.shade_ltc)
        clip_to_horizon_jit(P, 4, C)
        e_s = polygon_integral_jit(tm, C, 5)
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
