"""Numba kernels of the renderer's hot paths: primary rays + G-buffer, trilinear footprint
lookups and the fused LTC quad-light shader (the ``ltc`` method and, through per-material
roughness rows, the isotropic ``ltc-multiscale`` methods: Tao et al. 2021, eqs. 4-7 per sample,
with optional anisotropic taps of the normal map for small elongated footprints).

Each kernel writes every output element from exactly one loop iteration (no parallel reductions),
so results do not depend on the thread count. The NumPy implementations they replace stay in
:mod:`prefilter.render.camera` (``_intersect_numpy``) and :mod:`prefilter.render.shading`
(``_shade_ltc_numpy``) as cross-checks for the tests.
"""

from __future__ import annotations

import math
import weakref

import numpy as np

from prefilter.jit import (  # noqa: F401
    SERIAL_BELOW, njit_inline, njit_parallel, njit_serial, prange, serial)
from prefilter.ltc.polygon import _DET_RTOL2, _INV_2PI, _clipped_edge_sum

_EPS = 1e-9  # smallest ray parameter of a hit (as camera._EPS)
_TWO_PI = 2.0 * math.pi
_BLOCK = 256  # shading points per scratch buffer in the fused shader
#: Batches smaller than this run the serial twin of a kernel: waking the thread pool costs more
#: than the work (see ``serial``).

# -- G-buffer ---------------------------------------------------------------------------------

# packed object parameters, one row per object (OBJ_* are column offsets)
OBJ_CENTER, OBJ_N, OBJ_T, OBJ_B = 0, 3, 6, 9
OBJ_SIZE, OBJ_UVS, OBJ_RADIUS, OBJ_WIDTH = 12, 14, 16, 17
TYPE_PLANE, TYPE_SPHERE = 0, 1


def pack_objects(objects) -> tuple[np.ndarray, np.ndarray]:
    """``(types (K,) int64, params (K, OBJ_WIDTH))`` of planes and spheres for the kernels.

    Planes store ``normal, tangent, normal x tangent``; spheres ``pole, axis_x, axis_x x pole``.
    """
    k = len(objects)
    types = np.zeros(k, np.int64)
    params = np.zeros((k, OBJ_WIDTH))
    for i, obj in enumerate(objects):
        row = params[i]
        row[OBJ_CENTER:OBJ_CENTER + 3] = obj.center
        row[OBJ_UVS:OBJ_UVS + 2] = obj.uv_scale
        if obj.type == "plane":
            types[i] = TYPE_PLANE
            row[OBJ_N:OBJ_N + 3] = obj.normal
            row[OBJ_T:OBJ_T + 3] = obj.tangent
            row[OBJ_B:OBJ_B + 3] = np.cross(obj.normal, obj.tangent)
            row[OBJ_SIZE:OBJ_SIZE + 2] = obj.size
        else:
            types[i] = TYPE_SPHERE
            row[OBJ_N:OBJ_N + 3] = obj.pole
            row[OBJ_T:OBJ_T + 3] = obj.axis_x
            row[OBJ_B:OBJ_B + 3] = np.cross(obj.axis_x, obj.pole)
            row[OBJ_RADIUS] = obj.radius
    return types, params


@njit_serial
def _trace(k, ox, oy, oz, dx, dy, dz, xx, xy_, xz, yx, yy, yz, types, params,
           hit, oid, pos, nrm, tan, bit, uv, dudv, dpdx, dpdy, dist, view, dirn):
    """Nearest hit of one ray and its surface data, written to row ``k`` of the outputs."""
    best = np.inf
    kbest = -1
    for o in range(types.shape[0]):
        p = params[o]
        cx, cy, cz = p[0], p[1], p[2]
        if types[o] == TYPE_PLANE:
            nx, ny, nz = p[3], p[4], p[5]
            denom = dx * nx + dy * ny + dz * nz
            if not abs(denom) > 1e-12:
                continue
            t = ((cx - ox) * nx + (cy - oy) * ny + (cz - oz) * nz) / denom
            qx = ox + t * dx - cx
            qy = oy + t * dy - cy
            qz = oz + t * dz - cz
            a = qx * p[6] + qy * p[7] + qz * p[8]
            b = qx * p[9] + qy * p[10] + qz * p[11]
            if not (t > _EPS and abs(a) <= p[12] / 2 and abs(b) <= p[13] / 2):
                continue
        else:
            ocx, ocy, ocz = ox - cx, oy - cy, oz - cz
            b = ocx * dx + ocy * dy + ocz * dz
            c = ocx * ocx + ocy * ocy + ocz * ocz - p[16] * p[16]
            disc = b * b - c
            if not disc >= 0.0:
                continue
            s = math.sqrt(disc)
            t = -b - s
            if not t > _EPS:
                t = -b + s
            if not t > _EPS:
                continue
        if t < best:
            best = t
            kbest = o
    dirn[k, 0] = dx
    dirn[k, 1] = dy
    dirn[k, 2] = dz
    view[k, 0] = -dx
    view[k, 1] = -dy
    view[k, 2] = -dz
    dist[k] = best
    oid[k] = kbest
    if kbest < 0:
        hit[k] = False
        for i in range(3):
            pos[k, i] = 0.0
            nrm[k, i] = 0.0
            tan[k, i] = 0.0
            bit[k, i] = 0.0
            dpdx[k, i] = 0.0
            dpdy[k, i] = 0.0
        for i in range(2):
            uv[k, i] = 0.0
            dudv[k, i, 0] = 0.0
            dudv[k, i, 1] = 0.0
        return
    hit[k] = True
    p = params[kbest]
    t = best
    px, py, pz = ox + t * dx, oy + t * dy, oz + t * dz
    cx, cy, cz = p[0], p[1], p[2]
    su0, sv0 = p[14], p[15]
    if types[kbest] == TYPE_PLANE:
        nx, ny, nz = p[3], p[4], p[5]
        tx, ty, tz = p[6], p[7], p[8]
        bx, by, bz = p[9], p[10], p[11]
        qx, qy, qz = px - cx, py - cy, pz - cz
        su = su0 / p[12]
        sv = sv0 / p[13]
        u = (qx * tx + qy * ty + qz * tz) * su + 0.5 * su0
        v = (qx * bx + qy * by + qz * bz) * sv + 0.5 * sv0
        gu = su
        gv = sv
    else:
        r = p[16]
        ex0, ex1, ex2 = p[6], p[7], p[8]
        ey0, ey1, ey2 = p[3], p[4], p[5]
        ez0, ez1, ez2 = p[9], p[10], p[11]
        qx, qy, qz = (px - cx) / r, (py - cy) / r, (pz - cz) / r
        x = qx * ex0 + qy * ex1 + qz * ex2
        y = min(max(qx * ey0 + qy * ey1 + qz * ey2, -1.0), 1.0)
        z = qx * ez0 + qy * ez1 + qz * ez2
        theta = math.acos(y)
        phi = math.atan2(z, x)
        if phi < 0.0:
            phi += _TWO_PI
        st = max(math.sqrt(x * x + z * z), 1e-12)  # sin(theta), kept off the poles
        if x * x + z * z < 1e-24:  # the exact pole: phi = 0 keeps the frame orthonormal
            cp, sp = 1.0, 0.0
        else:
            cp, sp = x / st, z / st
        inv = 1.0 / math.sqrt(qx * qx + qy * qy + qz * qz)
        nx, ny, nz = qx * inv, qy * inv, qz * inv
        tx, ty, tz = -sp * ex0 + cp * ez0, -sp * ex1 + cp * ez1, -sp * ex2 + cp * ez2
        bx = y * cp * ex0 - st * ey0 + y * sp * ez0
        by = y * cp * ex1 - st * ey1 + y * sp * ez1
        bz = y * cp * ex2 - st * ey2 + y * sp * ez2
        u = phi / _TWO_PI * su0
        v = theta / math.pi * sv0
        # grad phi = tangent / (r sin theta), grad theta = bitangent / r
        gu = su0 / (_TWO_PI * r * st)
        gv = sv0 / (math.pi * r)
    # Igehy 1999: the hit point moves on the tangent plane
    dn = dx * nx + dy * ny + dz * nz
    fx = (xx * nx + xy_ * ny + xz * nz) / dn
    fy = (yx * nx + yy * ny + yz * nz) / dn
    ax, ay, az = t * (xx - fx * dx), t * (xy_ - fx * dy), t * (xz - fx * dz)
    bx2, by2, bz2 = t * (yx - fy * dx), t * (yy - fy * dy), t * (yz - fy * dz)
    pos[k, 0], pos[k, 1], pos[k, 2] = px, py, pz
    nrm[k, 0], nrm[k, 1], nrm[k, 2] = nx, ny, nz
    tan[k, 0], tan[k, 1], tan[k, 2] = tx, ty, tz
    bit[k, 0], bit[k, 1], bit[k, 2] = bx, by, bz
    uv[k, 0], uv[k, 1] = u, v
    dpdx[k, 0], dpdx[k, 1], dpdx[k, 2] = ax, ay, az
    dpdy[k, 0], dpdy[k, 1], dpdy[k, 2] = bx2, by2, bz2
    dudv[k, 0, 0] = gu * (tx * ax + ty * ay + tz * az)
    dudv[k, 0, 1] = gu * (tx * bx2 + ty * by2 + tz * bz2)
    dudv[k, 1, 0] = gv * (bx * ax + by * ay + bz * az)
    dudv[k, 1, 1] = gv * (bx * bx2 + by * by2 + bz * bz2)


@njit_inline
def _camera_trace(k, cam, x, y, types, params, hit, oid, pos, nrm, tan, bit, uv, dudv, dpdx,
                  dpdy, dist, view, dirn):  # pragma: no cover - compiled
    """The primary ray through pixel position ``(x, y)`` (``cam`` as in
    :func:`gbuffer_camera_kernel`) with its differentials, traced into G-buffer slot ``k``."""
    rx, ry, rz = cam[3], cam[4], cam[5]
    ux, uy, uz = cam[6], cam[7], cam[8]
    sy = cam[12]
    px = (x - cam[13] / 2.0) * sy
    py = (cam[14] / 2.0 - y) * sy
    d0 = cam[9] + px * rx + py * ux
    d1 = cam[10] + px * ry + py * uy
    d2 = cam[11] + px * rz + py * uz
    inv = 1.0 / math.sqrt(d0 * d0 + d1 * d1 + d2 * d2)
    d0 *= inv
    d1 *= inv
    d2 *= inv
    # derivative of d / |d|: (I - dn dn^T) (dd/dx) / |d|, dd/dx = sy r, dd/dy = -sy u
    ex0, ex1, ex2 = sy * rx, sy * ry, sy * rz
    ey0, ey1, ey2 = -sy * ux, -sy * uy, -sy * uz
    a = d0 * ex0 + d1 * ex1 + d2 * ex2
    b = d0 * ey0 + d1 * ey1 + d2 * ey2
    _trace(k, cam[0], cam[1], cam[2], d0, d1, d2,
           (ex0 - a * d0) * inv, (ex1 - a * d1) * inv, (ex2 - a * d2) * inv,
           (ey0 - b * d0) * inv, (ey1 - b * d1) * inv, (ey2 - b * d2) * inv,
           types, params, hit, oid, pos, nrm, tan, bit, uv, dudv, dpdx, dpdy, dist, view, dirn)


@njit_parallel
def gbuffer_camera_kernel(cam, xy, types, params, hit, oid, pos, nrm, tan, bit, uv, dudv, dpdx,
                          dpdy, dist, view, dirn):
    """Primary rays through pixel positions ``xy (N, 2)`` and their G-buffer, in one pass.

    ``cam (16,)``: origin, right, up, forward (unit), ``sy`` (image-plane units per pixel),
    width, height, unused.
    """
    for k in prange(xy.shape[0]):
        _camera_trace(k, cam, xy[k, 0], xy[k, 1], types, params, hit, oid, pos, nrm, tan, bit,
                      uv, dudv, dpdx, dpdy, dist, view, dirn)


@njit_parallel
def gbuffer_rays_kernel(o, d, ddx, ddy, types, params, hit, oid, pos, nrm, tan, bit, uv, dudv,
                        dpdx, dpdy, dist, view, dirn):
    """G-buffer of given rays (all ``(N, 3)``)."""
    for k in prange(d.shape[0]):
        _trace(k, o[k, 0], o[k, 1], o[k, 2], d[k, 0], d[k, 1], d[k, 2],
               ddx[k, 0], ddx[k, 1], ddx[k, 2], ddy[k, 0], ddy[k, 1], ddy[k, 2],
               types, params, hit, oid, pos, nrm, tan, bit, uv, dudv, dpdx, dpdy, dist, view,
               dirn)


# -- trilinear footprint lookups ---------------------------------------------------------------

_PACKED = weakref.WeakKeyDictionary()


def pack_mip(chain) -> tuple[np.ndarray, np.ndarray]:
    """``(data (total,), info (L, 3) = offset, height, width)`` of a MipChain's levels (cached)."""
    try:
        return _PACKED[chain]
    except (KeyError, TypeError):
        pass
    info = np.zeros((chain.n_levels, 3), np.int64)
    off = 0
    for i, lv in enumerate(chain.levels):
        info[i] = off, lv.shape[0], lv.shape[1]
        off += lv.size
    data = np.concatenate([np.ascontiguousarray(lv, np.float64).reshape(-1) for lv in chain.levels])
    try:
        _PACKED[chain] = (data, info)
    except TypeError:
        pass
    return data, info


@njit_serial
def _bilinear_add(data, info, level, stride, c, u, v, wgt, out, k):
    """Add ``wgt`` times the bilinear (wrapped) lookup of channels ``:c`` of a level stored with
    ``stride`` channels per texel to ``out[k, :c]``."""
    off, h, w = info[level, 0], info[level, 1], info[level, 2]
    x = u * w - 0.5
    y = v * h - 0.5
    x0 = math.floor(x)
    y0 = math.floor(y)
    fx = x - x0
    fy = y - y0
    i0 = np.int64(y0) % h
    j0 = np.int64(x0) % w
    i1 = (i0 + 1) % h
    j1 = (j0 + 1) % w
    for ch in range(c):
        t00 = data[off + (i0 * w + j0) * stride + ch]
        t01 = data[off + (i0 * w + j1) * stride + ch]
        t10 = data[off + (i1 * w + j0) * stride + ch]
        t11 = data[off + (i1 * w + j1) * stride + ch]
        top = t00 * (1 - fx) + t01 * fx
        bottom = t10 * (1 - fx) + t11 * fx
        out[k, ch] += wgt * (top * (1 - fy) + bottom * fy)


@njit_serial
def _major_texels(h0, w0, d00, d01, d10, d11):
    """Major axis (texels of an ``h0 x w0`` level 0) of the footprint ellipse of the Jacobian
    ``d..``: the largest singular value of ``diag(w0, h0) dudv`` (``texture.footprint_axes``)."""
    return _footprint_axes(h0, w0, d00, d01, d10, d11)[0]


@njit_serial
def _footprint_axes(h0, w0, d00, d01, d10, d11):
    """``(major, minor, dir_x, dir_y)`` of the footprint ellipse in texels of an ``h0 x w0``
    level 0, the major direction a unit vector in texel space (``texture.footprint_axes``)."""
    j00 = d00 * w0
    j01 = d01 * w0
    j10 = d10 * h0
    j11 = d11 * h0
    p = j00 * j00 + j01 * j01
    r = j10 * j10 + j11 * j11
    q = j00 * j10 + j01 * j11
    disc = math.sqrt(max(0.25 * (p - r) ** 2 + q * q, 0.0))
    l1 = 0.5 * (p + r) + disc
    l2 = max(0.5 * (p + r) - disc, 0.0)
    # eigenvector of l1: (q, l1 - p) or (l1 - r, q), whichever is longer (stable)
    ax, ay = q, l1 - p
    bx, by = l1 - r, q
    if ax * ax + ay * ay < bx * bx + by * by:
        ax, ay = bx, by
    nv = math.sqrt(ax * ax + ay * ay)
    if nv > 0.0:
        ax /= nv
        ay /= nv
    else:
        ax, ay = 1.0, 0.0
    return math.sqrt(l1), math.sqrt(l2), ax, ay


@njit_serial
def _taps_into(data, info, first, n_levels, stride, c, u, v, h0, w0, major, dir_x, dir_y, n,
               lod, norm0, out, k):
    """Mean of ``n`` trilinear taps at ``lod`` spread over the major axis (``major`` texels
    along the unit texel-space direction ``dir``), as ``MipChain.lookup_footprint``'s
    anisotropic branch: channels ``:c`` into ``out[k, :c]``, ``out[k + 1]`` is scratch.
    ``norm0``: below LOD 1 the level-0 bilinear read is renormalised (channels ``:3``) before
    it is blended with level 1."""
    lodc = min(max(lod, 0.0), n_levels - 1.0)
    au = dir_x * major / w0
    av = dir_y * major / h0
    for ch in range(c):
        out[k, ch] = 0.0
    for i in range(n):
        s = (i + 0.5) / n - 0.5
        if norm0 and lodc < 1.0 and n_levels > 1:
            for ch in range(c):
                out[k + 1, ch] = 0.0
            _bilinear_add(data, info, first, stride, c, u + s * au, v + s * av, 1.0, out, k + 1)
            ln = math.sqrt(out[k + 1, 0] ** 2 + out[k + 1, 1] ** 2 + out[k + 1, 2] ** 2)
            sc = (1.0 - lodc) / ln if ln > 0.0 else 1.0 - lodc
            for ch in range(c):
                out[k + 1, ch] *= sc
            _bilinear_add(data, info, first + 1, stride, c, u + s * au, v + s * av, lodc, out,
                          k + 1)
        else:
            _trilinear_into(data, info, first, n_levels, stride, c, u + s * au, v + s * av,
                            lod, out, k + 1)
        for ch in range(c):
            out[k, ch] += out[k + 1, ch] / n


@njit_serial
def _footprint_into(data, info, first, n_levels, stride, c, u, v, d00, d01, d10, d11, out, k):
    """``MipChain.lookup_footprint`` (isotropic) of the chain whose levels are
    ``info[first:first + n_levels]`` (``stride`` channels per texel) at ``uv = (u, v)``,
    Jacobian ``d..``: channels ``:c`` into ``out[k, :c]``."""
    lod = math.log2(max(_major_texels(info[first, 1], info[first, 2], d00, d01, d10, d11), 1.0))
    _trilinear_into(data, info, first, n_levels, stride, c, u, v, lod, out, k)


@njit_serial
def _trilinear_into(data, info, first, n_levels, stride, c, u, v, lod, out, k):
    """The trilinear read of :func:`_footprint_into` at a given ``lod`` (clamped)."""
    lod = min(max(lod, 0.0), n_levels - 1.0)
    for ch in range(c):
        out[k, ch] = 0.0
    if n_levels > 1:
        l0 = min(np.int64(math.floor(lod)), n_levels - 2)
        t = lod - l0
        _bilinear_add(data, info, first + l0, stride, c, u, v, 1.0 - t, out, k)
        _bilinear_add(data, info, first + l0 + 1, stride, c, u, v, t, out, k)
    else:
        _bilinear_add(data, info, first, stride, c, u, v, 1.0, out, k)


@njit_parallel
def footprint_lookup_kernel(data, info, c, uv, dudv, out):
    """Isotropic trilinear lookup at ``lod = log2(max(major axis in texels, 1))``, as
    ``MipChain.lookup_footprint`` (anisotropic=False); ``out (N, c)`` is overwritten."""
    for k in prange(uv.shape[0]):
        _footprint_into(data, info, 0, info.shape[0], c, c, uv[k, 0], uv[k, 1], dudv[k, 0, 0],
                        dudv[k, 0, 1], dudv[k, 1, 0], dudv[k, 1, 1], out, k)


# -- fused LTC shader ---------------------------------------------------------------------------


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
def _ltc_point(geo, mat, qv, qn, qrad, axis_t, axis_r, tab_m, tab_mag, tab_fres, view_z_min,
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
        # cut at the shading horizon before the LTC transform (see shading.shade_ltc)
        _clip_to_horizon(P, 4, C)
        e_s = _polygon(tm, C, 5)
        res[0] += (mat[1] * e_d + sp0 * e_s) * qrad[q, 0]
        res[1] += (mat[2] * e_d + sp1 * e_s) * qrad[q, 1]
        res[2] += (mat[3] * e_d + sp2 * e_s) * qrad[q, 2]
    return True


@njit_serial
def _scratch():
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
    (:func:`_ltc_point` per point); ``status[k] = 1`` flags a singular LTC matrix."""
    n_pts = position.shape[0]
    n_blocks = (n_pts + _BLOCK - 1) // _BLOCK
    for blk in prange(n_blocks):
        geo, mat, P, C, ident, tm, mm, res = _scratch()
        for k in range(blk * _BLOCK, min(n_pts, (blk + 1) * _BLOCK)):
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
            if _ltc_point(geo, mat, qv, qn, qrad, axis_t, axis_r, tab_m, tab_mag, tab_fres,
                          view_z_min, P, C, ident, tm, mm, res):
                for c in range(3):
                    out[k, c] += res[c]
            else:
                status[k] = 1


# -- the whole ``ltc`` method per sample ------------------------------------------------------

MAT_WIDTH = 8  # alpha_x, alpha_y, base colour (3), f0 (3)

# Per-material roughness rows of :func:`ltc_samples_kernel` (``RGH_*`` are column offsets):
# how the shading roughness follows from the footprint (``RGH_MODE``), the meso-scale inverse of
# Tao et al. 2021 eq. 4 (``RGH_MESO``), alpha_micro, the coefficients of alpha_total, r(alpha_micro)
# for mean-resultant-length matching, eq. 5's rational coefficients (num r^4..r^0, den r^3..r^0)
# the footprint scale of the normal-map lookup (2^lod_bias) and, for a bias that ramps in with
# the footprint (``RGH_RAMP = 1``: ``bias = clip(lod - start, 0, lod_bias)``), ``lod_bias`` and
# ``start`` (a flag, not a NaN sentinel: fastmath folds isnan away).
RGH_MODE, RGH_MESO, RGH_ALPHA, RGH_COEF, RGH_MRL, RGH_EQ5, RGH_NSCALE = 0, 1, 2, 3, 7, 8, 17
RGH_BIAS, RGH_START, RGH_RAMP = 18, 19, 20
# Anisotropic taps of the normal map (``RGH_TAPS`` > 0, the largest tap count): footprints whose
# major axis is below ``RGH_TAPS_BELOW`` texels and longer than ``RGH_TAPS_RATIO`` times the
# minor axis are read as the mean of ``clip(ceil(major / minor), 2, RGH_TAPS)`` unnormalised
# trilinear taps along the major axis at the minor axis' LOD; all other footprints as before.
# ``RGH_TAPS_NORM`` = 1: each tap's level-0 bilinear read is renormalised before the blend with
# level 1 (interpolating between unit texels shortens them although the surface barely turns).
RGH_TAPS, RGH_TAPS_BELOW, RGH_TAPS_RATIO, RGH_TAPS_NORM = 21, 22, 23, 24
RGH_WIDTH = 25
#: ``RGH_MODE`` values: ``sqrt(alpha_x alpha_y)`` (the ``ltc`` method); our form of eq. 7
#: (``multiscale.convolution``, "fit"); eq. 7's polynomial ("paper"); mean-resultant-length
#: matching ("mrl").
ROUGH_LTC, ROUGH_FIT, ROUGH_EQ7, ROUGH_MRL = 0, 1, 2, 3
#: ``RGH_MESO`` values: the tabulated exact inverse of eq. 4, or eq. 5 (clamped as the paper).
MESO_TABLE, MESO_EQ5 = 0, 1


def plain_roughness(n_objects: int) -> tuple[np.ndarray, np.ndarray]:
    """Roughness rows of the ``ltc`` method (``sqrt(alpha_x alpha_y)``) and an unused table."""
    rough = np.zeros((n_objects, RGH_WIDTH))
    rough[:, RGH_NSCALE] = 1.0
    return rough, np.zeros(2)


@njit_serial
def _interp_uniform(x, tab):
    """Linear interpolation of ``tab`` sampled at ``linspace(0, 1, len(tab))``, ``x`` clamped."""
    n = tab.shape[0]
    f = min(max(x, 0.0), 1.0) * (n - 1)
    i = min(np.int64(f), n - 2)
    t = f - i
    return tab[i] * (1.0 - t) + tab[i + 1] * t


@njit_serial
def _multiscale_alpha(row, r, meso_tab):
    """Tao et al. 2021, eqs. 4-7: ``alpha_total`` from the length ``r`` of the footprint's
    averaged normal. ``meso_tab``: ``alpha_meso`` at ``x = sqrt(3 (1 - r))`` uniform in [0, 1]
    (``x`` makes the inverse of eq. 4 nearly linear)."""
    a = row[RGH_ALPHA]
    rc = min(max(r, 2.0 / 3.0), 1.0)
    if row[RGH_MESO] == MESO_TABLE:
        b = _interp_uniform(math.sqrt(min(max(3.0 * (1.0 - r), 0.0), 1.0)), meso_tab)
    else:
        e = RGH_EQ5
        num = (((row[e] * rc + row[e + 1]) * rc + row[e + 2]) * rc + row[e + 3]) * rc + row[e + 4]
        den = ((row[e + 5] * rc + row[e + 6]) * rc + row[e + 7]) * rc + row[e + 8]
        b = min(max(num / den, 0.0), 1.0)
    c = RGH_COEF
    mode = row[RGH_MODE]
    if mode == ROUGH_FIT:
        p = a + b
        q = a * b
        out = math.sqrt(max(a * a + b * b + q * (row[c] + p * (row[c + 1] + row[c + 2] * p)
                                                 + row[c + 3] * q), 0.0))
    elif mode == ROUGH_EQ7:
        out = row[c] * a * a + row[c + 1] * a + row[c + 2] * b + row[c + 3] * a * b
    else:
        # mean resultant lengths multiply under convolution; r(alpha_meso) is r itself (clamped)
        rr = row[RGH_MRL] * rc
        out = _interp_uniform(math.sqrt(min(max(3.0 * (1.0 - rr), 0.0), 1.0)), meso_tab)
    return min(max(out, 0.0), 1.0)


def pack_materials(objects):
    """Materials and their textures for :func:`ltc_samples_kernel`, or ``None`` when a texture
    has too few channels for the fused path (normal maps need 3, height maps 2).

    Returns ``(mat_f (K, 8), mat_i (K, 3) texture indices of normal / height / colour map or -1,
    data (total,), info (L, 3) = offset, height, width per level, tex (T, 3) = first level,
    level count, channels)``.
    """
    mat_f = np.zeros((len(objects), MAT_WIDTH))
    mat_i = np.full((len(objects), 3), -1, np.int64)
    datas, infos, texs = [], [], []
    offset = level = 0
    for k, obj in enumerate(objects):
        m = obj.material
        mat_f[k] = [m.alpha_x, m.alpha_y, *np.broadcast_to(m.base_color, 3),
                    *np.broadcast_to(m.f0, 3)]
        for slot, ref in enumerate((m.normal_map, m.height_map, m.color_map)):
            if ref is None or (slot == 1 and m.normal_map is not None):
                continue  # normal maps take precedence over height maps
            chain = ref.mip()
            c = chain.shape[2]
            if (slot == 0 and c < 3) or (slot == 1 and c < 2):
                return None
            data, info = pack_mip(chain)
            datas.append(data)
            shifted = info.copy()
            shifted[:, 0] += offset
            infos.append(shifted)
            texs.append((level, len(info), c))
            mat_i[k, slot] = len(texs) - 1
            offset += len(data)
            level += len(info)
    data = np.concatenate(datas) if datas else np.zeros(1)
    info = np.concatenate(infos) if infos else np.zeros((1, 3), np.int64)
    tex = np.asarray(texs, np.int64).reshape(-1, 3)
    return mat_f, mat_i, data, info, tex


@njit_serial
def _gscratch():
    return (np.empty(1, np.bool_), np.empty(1, np.int32), np.empty((1, 3)), np.empty((1, 3)),
            np.empty((1, 3)), np.empty((1, 3)), np.empty((1, 2)), np.empty((1, 2, 2)),
            np.empty((1, 3)), np.empty((1, 3)), np.empty(1), np.empty((1, 3)), np.empty((1, 3)))


@njit_parallel
def ltc_samples_kernel(cam, xy, types, params, mat_f, mat_i, data, info, tex, rough, meso_tab,
                       qv, qn, qrad, axis_t, axis_r, tab_m, tab_mag, tab_fres, view_z_min, rad,
                       status):
    """The ``ltc`` method for quad lights per sample, without intermediate arrays: the primary
    ray through ``xy (N, 2)`` (``cam`` as in :func:`gbuffer_camera_kernel`), its hit, the
    footprint's trilinear texture reads, the shading frame (as ``shading.shading_frame``, the
    frame flipped on back faces) and :func:`_ltc_point`. Writes ``rad (N, 3)`` (0 on misses).

    ``rough (K, RGH_WIDTH)``: per-material roughness rows (:func:`plain_roughness` for ``ltc``;
    the ``ltc-multiscale`` methods take ``alpha_total`` of the averaged normal's length,
    :func:`_multiscale_alpha`, with ``meso_tab``)."""
    n_pts = xy.shape[0]
    n_blocks = (n_pts + _BLOCK - 1) // _BLOCK
    for blk in prange(n_blocks):
        geo, mat, P, C, ident, tm, mm, res = _scratch()
        hit, oid, pos, nrm, tan, bit, uv, dudv, dpdx, dpdy, dist, view, dirn = _gscratch()
        tx = np.empty((2, 4))
        for k in range(blk * _BLOCK, min(n_pts, (blk + 1) * _BLOCK)):
            _camera_trace(0, cam, xy[k, 0], xy[k, 1], types, params, hit, oid, pos, nrm, tan,
                          bit, uv, dudv, dpdx, dpdy, dist, view, dirn)
            rad[k, 0] = 0.0
            rad[k, 1] = 0.0
            rad[k, 2] = 0.0
            if not hit[0]:
                continue
            o = oid[0]
            # two-sided surfaces: flip the frame of hits seen from behind
            flip = -1.0 if (view[0, 0] * nrm[0, 0] + view[0, 1] * nrm[0, 1]
                            + view[0, 2] * nrm[0, 2]) < 0.0 else 1.0
            gt0, gt1, gt2 = tan[0, 0], tan[0, 1], tan[0, 2]
            gb0, gb1, gb2 = bit[0, 0] * flip, bit[0, 1] * flip, bit[0, 2] * flip
            gn0, gn1, gn2 = nrm[0, 0] * flip, nrm[0, 1] * flip, nrm[0, 2] * flip
            u, v = uv[0, 0], uv[0, 1]
            du00, du01, du10, du11 = dudv[0, 0, 0], dudv[0, 0, 1], dudv[0, 1, 0], dudv[0, 1, 1]
            has_map = False
            m0 = m1 = m2 = 0.0
            t_n = mat_i[o, 0]
            t_h = mat_i[o, 1]
            if t_n >= 0:
                first = tex[t_n, 0]
                # the footprint scaled by 2^lod_bias (1 for ``ltc``), as MipChain.lookup_footprint
                ns = rough[o, RGH_NSCALE]
                h0, w0 = info[first, 1], info[first, 2]
                major = _major_texels(h0, w0, du00, du01, du10, du11)
                lod = math.log2(max(ns * major, 1.0))
                bias = 0.0
                if rough[o, RGH_RAMP] != 0.0:
                    # a bias that ramps in with the footprint (start >= 0, so the scaled
                    # footprint is > 1 texel wherever the bias is > 0: plain addition in LOD)
                    bias = min(max(lod - rough[o, RGH_START], 0.0), rough[o, RGH_BIAS])
                    lod += bias
                n_taps = 1
                if rough[o, RGH_TAPS] > 0.0 and major < rough[o, RGH_TAPS_BELOW]:
                    major, minor, dxx, dyy = _footprint_axes(h0, w0, du00, du01, du10, du11)
                    if major > rough[o, RGH_TAPS_RATIO] * minor:
                        # elongated: the minor axis' LOD, taps along the major axis, and the
                        # unnormalised mean keeps r the footprint's mean resultant length
                        n_taps = np.int64(min(max(math.ceil(major / max(minor, 1e-300)), 2.0),
                                              rough[o, RGH_TAPS]))
                        lod_t = math.log2(max(ns * max(minor, major / n_taps), 1.0)) + bias
                        _taps_into(data, info, first, tex[t_n, 1], tex[t_n, 2], 3, u, v, h0,
                                   w0, major, dxx, dyy, n_taps, lod_t,
                                   rough[o, RGH_TAPS_NORM] != 0.0, tx, 0)
                if n_taps == 1:
                    _trilinear_into(data, info, first, tex[t_n, 1], tex[t_n, 2], 3, u, v, lod,
                                    tx, 0)
                m0, m1, m2 = tx[0, 0], tx[0, 1], tx[0, 2]
                has_map = True
            elif t_h >= 0:
                _footprint_into(data, info, tex[t_h, 0], tex[t_h, 1], tex[t_h, 2], 2, u, v,
                                du00, du01, du10, du11, tx, 0)
                # normalize(-s_x, -s_y, 1) of the mean slopes
                m0, m1, m2 = -tx[0, 0], -tx[0, 1], 1.0
                il = 1.0 / math.sqrt(m0 * m0 + m1 * m1 + 1.0)
                m0 *= il
                m1 *= il
                m2 *= il
                has_map = True
            if has_map:
                # shading.shading_frame: tilt the normal, Gram-Schmidt the tangent, keep hand
                s0 = m0 * gt0 + m1 * gb0 + m2 * gn0
                s1 = m0 * gt1 + m1 * gb1 + m2 * gn1
                s2 = m0 * gt2 + m1 * gb2 + m2 * gn2
                ln = math.sqrt(s0 * s0 + s1 * s1 + s2 * s2)
                if ln > 1e-12:
                    s0 /= ln
                    s1 /= ln
                    s2 /= ln
                else:
                    s0, s1, s2 = gn0, gn1, gn2
                dt = gt0 * s0 + gt1 * s1 + gt2 * s2
                q0, q1, q2 = gt0 - dt * s0, gt1 - dt * s1, gt2 - dt * s2
                lt = math.sqrt(q0 * q0 + q1 * q1 + q2 * q2)
                if lt > 1e-9:
                    q0 /= lt
                    q1 /= lt
                    q2 /= lt
                else:  # a shading normal along the tangent: the bitangent side
                    q0 = gb1 * s2 - gb2 * s1
                    q1 = gb2 * s0 - gb0 * s2
                    q2 = gb0 * s1 - gb1 * s0
                    la = math.sqrt(q0 * q0 + q1 * q1 + q2 * q2)
                    q0 /= la
                    q1 /= la
                    q2 /= la
                hx = gn1 * gt2 - gn2 * gt1
                hy = gn2 * gt0 - gn0 * gt2
                hz = gn0 * gt1 - gn1 * gt0
                hand = 1.0 if hx * gb0 + hy * gb1 + hz * gb2 >= 0.0 else -1.0
                geo[1, 0], geo[1, 1], geo[1, 2] = q0, q1, q2
                geo[2, 0] = hand * (s1 * q2 - s2 * q1)
                geo[2, 1] = hand * (s2 * q0 - s0 * q2)
                geo[2, 2] = hand * (s0 * q1 - s1 * q0)
                geo[3, 0], geo[3, 1], geo[3, 2] = s0, s1, s2
            else:
                geo[1, 0], geo[1, 1], geo[1, 2] = gt0, gt1, gt2
                geo[2, 0], geo[2, 1], geo[2, 2] = gb0, gb1, gb2
                geo[3, 0], geo[3, 1], geo[3, 2] = gn0, gn1, gn2
            for c in range(3):
                geo[0, c] = pos[0, c]
                geo[4, c] = view[0, c]
                mat[1 + c] = mat_f[o, 2 + c]
                mat[4 + c] = mat_f[o, 5 + c]
                res[c] = 0.0
            t_c = mat_i[o, 2]
            if t_c >= 0:
                nc = tex[t_c, 2]
                _footprint_into(data, info, tex[t_c, 0], tex[t_c, 1], nc, min(nc, 3), u, v, du00,
                                du01, du10, du11, tx, 0)
                for c in range(3):
                    mat[1 + c] *= tx[0, c] if nc >= 3 else tx[0, 0]
            if rough[o, RGH_MODE] == ROUGH_LTC:
                # the isotropic table at sqrt(alpha_x alpha_y)
                mat[0] = math.sqrt(mat_f[o, 0] * mat_f[o, 1])
            else:
                # the unnormalised average's length; height maps and plain materials are flat
                r = min(math.sqrt(m0 * m0 + m1 * m1 + m2 * m2), 1.0) if t_n >= 0 else 1.0
                mat[0] = _multiscale_alpha(rough[o], r, meso_tab)
            if _ltc_point(geo, mat, qv, qn, qrad, axis_t, axis_r, tab_m, tab_mag, tab_fres,
                          view_z_min, P, C, ident, tm, mm, res):
                rad[k, 0] = res[0]
                rad[k, 1] = res[1]
                rad[k, 2] = res[2]
            else:
                status[k] = 1


