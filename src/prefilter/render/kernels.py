"""Numba kernels of the renderer's hot paths: primary rays + G-buffer, trilinear footprint
lookups, and the surface of one sample (:func:`surface_sample`: ray, hit, texture reads over the
footprint or at level 0, shading frame and material) that fused shading kernels
(``prefilter.ltc.kernels``, the ``reference`` method's) build on.

Each kernel writes every output element from exactly one loop iteration (no parallel reductions),
so results do not depend on the thread count. The NumPy twin of the ray cast is a check in
``tests/render/gbuffer_numpy.py``.
"""

from __future__ import annotations

import math
import weakref

import numpy as np

from prefilter.jit import (  # noqa: F401
    SERIAL_BELOW, njit_inline, njit_parallel, njit_serial, prange, serial)

_EPS = 1e-9  # smallest ray parameter of a hit (as camera._EPS)
_TWO_PI = 2.0 * math.pi

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


@njit_inline
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
def camera_trace(k, cam, x, y, types, params, hit, oid, pos, nrm, tan, bit, uv, dudv, dpdx,
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
        camera_trace(k, cam, xy[k, 0], xy[k, 1], types, params, hit, oid, pos, nrm, tan, bit,
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


@njit_serial
def _level0_into(data, info, first, stride, c, u, v, out, k):
    """The bilinear read of level ``first`` (a chain's level 0): channels ``:c`` into
    ``out[k, :c]``."""
    for ch in range(c):
        out[k, ch] = 0.0
    _bilinear_add(data, info, first, stride, c, u, v, 1.0, out, k)


@njit_parallel
def footprint_lookup_kernel(data, info, c, uv, dudv, out):
    """Isotropic trilinear lookup at ``lod = log2(max(major axis in texels, 1))``, as
    ``MipChain.lookup_footprint`` (anisotropic=False); ``out (N, c)`` is overwritten."""
    for k in prange(uv.shape[0]):
        _footprint_into(data, info, 0, info.shape[0], c, c, uv[k, 0], uv[k, 1], dudv[k, 0, 0],
                        dudv[k, 0, 1], dudv[k, 1, 0], dudv[k, 1, 1], out, k)


# -- the surface of one sample -----------------------------------------------------------------

MAT_WIDTH = 8  # alpha_x, alpha_y, base colour (3), f0 (3)

# Per-material settings of the normal map's footprint read in :func:`surface_sample`
# (``READ_*`` are column offsets): the footprint scale (2^lod_bias) and, for a bias that ramps in
# with the footprint (``READ_RAMP = 1``: ``bias = clip(lod - start, 0, lod_bias)``),
# ``lod_bias`` and ``start`` (a flag, not a NaN sentinel: fastmath folds isnan away).
# Anisotropic taps (``READ_TAPS`` > 0, the largest tap count): footprints whose major axis is
# below ``READ_TAPS_BELOW`` texels and longer than ``READ_TAPS_RATIO`` times the minor axis are
# read as the mean of ``clip(ceil(major / minor), 2, READ_TAPS)`` unnormalised trilinear taps
# along the major axis at the minor axis' LOD; all other footprints by one isotropic tap.
# ``READ_TAPS_NORM`` = 1: each tap's level-0 bilinear read is renormalised before the blend with
# level 1 (interpolating between unit texels shortens them although the surface barely turns).
# ``READ_LEVEL0`` = 1: every texture of the material (normal, height and colour maps) is read at
# level 0, bilinearly, whatever the footprint (supersampled ground truth, ``MipChain.lookup(uv,
# 0)``); the other settings are then ignored.
READ_SCALE, READ_BIAS, READ_START, READ_RAMP = 0, 1, 2, 3
READ_TAPS, READ_TAPS_BELOW, READ_TAPS_RATIO, READ_TAPS_NORM = 4, 5, 6, 7
READ_LEVEL0 = 8
READ_WIDTH = 9


def plain_read(n_objects: int) -> np.ndarray:
    """Normal-map read settings ``(K, READ_WIDTH)`` of the isotropic footprint (one trilinear
    tap at the LOD of the footprint's major axis, as ``MipChain.lookup_footprint``)."""
    read = np.zeros((n_objects, READ_WIDTH))
    read[:, READ_SCALE] = 1.0
    return read


def level0_read(n_objects: int) -> np.ndarray:
    """Texture read settings ``(K, READ_WIDTH)`` of level 0, bilinear, for every texture (the
    ``reference`` method's full-resolution reads)."""
    read = plain_read(n_objects)
    read[:, READ_LEVEL0] = 1.0
    return read


def pack_materials(objects):
    """Materials and their textures for :func:`surface_sample`, or ``None`` when a texture
    has too few channels for the fused path (normal maps need 3, height maps 2) or an object is
    a mesh (Embree traces meshes outside Numba: the staged path).

    Returns ``(mat_f (K, 8), mat_i (K, 3) texture indices of normal / height / colour map or -1,
    data (total,), info (L, 3) = offset, height, width per level, tex (T, 3) = first level,
    level count, channels)``.
    """
    if any(obj.type == "mesh" for obj in objects):
        return None
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
def gscratch():
    """Scratch G-buffer of one sample for :func:`surface_sample`."""
    return (np.empty(1, np.bool_), np.empty(1, np.int32), np.empty((1, 3)), np.empty((1, 3)),
            np.empty((1, 3)), np.empty((1, 3)), np.empty((1, 2)), np.empty((1, 2, 2)),
            np.empty((1, 3)), np.empty((1, 3)), np.empty(1), np.empty((1, 3)), np.empty((1, 3)))


# inlined (as _trace): a call with its ~30 array arguments cost more than the surface itself
# (0.67 vs 0.28 us per sample of the reference's fused kernel, one thread)
@njit_inline
def surface_sample(cam, x, y, types, params, mat_f, mat_i, data, info, tex, read, gs, tx, geo,
                   mat):  # pragma: no cover - compiled
    """The surface seen through pixel position ``(x, y)`` (``cam`` as in
    :func:`gbuffer_camera_kernel`): the primary ray, its hit, the texture reads (trilinear over
    the footprint, the normal map as set by ``read (K, READ_WIDTH)``, or all at level 0), the
    shading frame (as ``driver.shading_frame``, the frame flipped on back faces) and the
    material.

    Writes ``geo (5, 3)``: position, shading t, b, n, unit view; ``mat[1:7]``: base colour (times
    the colour map), f0. ``gs``: :func:`gscratch`, ``tx (2, 4)``: scratch.
    Returns ``(hit, object index, r)``, ``r`` the length of the footprint's unnormalised averaged
    normal (1 without a normal map)."""
    hit, oid, pos, nrm, tan, bit, uv, dudv, dpdx, dpdy, dist, view, dirn = gs
    camera_trace(0, cam, x, y, types, params, hit, oid, pos, nrm, tan, bit, uv, dudv, dpdx,
                 dpdy, dist, view, dirn)
    if not hit[0]:
        return False, -1, 1.0
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
    level0 = read[o, READ_LEVEL0] != 0.0
    if t_n >= 0 and level0:
        _level0_into(data, info, tex[t_n, 0], tex[t_n, 2], 3, u, v, tx, 0)
        m0, m1, m2 = tx[0, 0], tx[0, 1], tx[0, 2]
        has_map = True
    elif t_n >= 0:
        first = tex[t_n, 0]
        # the footprint scaled by 2^lod_bias (1: as MipChain.lookup_footprint)
        ns = read[o, READ_SCALE]
        h0, w0 = info[first, 1], info[first, 2]
        major = _major_texels(h0, w0, du00, du01, du10, du11)
        lod = math.log2(max(ns * major, 1.0))
        bias = 0.0
        if read[o, READ_RAMP] != 0.0:
            # a bias that ramps in with the footprint (start >= 0, so the scaled
            # footprint is > 1 texel wherever the bias is > 0: plain addition in LOD)
            bias = min(max(lod - read[o, READ_START], 0.0), read[o, READ_BIAS])
            lod += bias
        n_taps = 1
        if read[o, READ_TAPS] > 0.0 and major < read[o, READ_TAPS_BELOW]:
            major, minor, dxx, dyy = _footprint_axes(h0, w0, du00, du01, du10, du11)
            if major > read[o, READ_TAPS_RATIO] * minor:
                # elongated: the minor axis' LOD, taps along the major axis, and the
                # unnormalised mean keeps r the footprint's mean resultant length
                n_taps = np.int64(min(max(math.ceil(major / max(minor, 1e-300)), 2.0),
                                      read[o, READ_TAPS]))
                lod_t = math.log2(max(ns * max(minor, major / n_taps), 1.0)) + bias
                _taps_into(data, info, first, tex[t_n, 1], tex[t_n, 2], 3, u, v, h0,
                           w0, major, dxx, dyy, n_taps, lod_t,
                           read[o, READ_TAPS_NORM] != 0.0, tx, 0)
        if n_taps == 1:
            _trilinear_into(data, info, first, tex[t_n, 1], tex[t_n, 2], 3, u, v, lod,
                            tx, 0)
        m0, m1, m2 = tx[0, 0], tx[0, 1], tx[0, 2]
        has_map = True
    elif t_h >= 0:
        if level0:
            _level0_into(data, info, tex[t_h, 0], tex[t_h, 2], 2, u, v, tx, 0)
        else:
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
        # driver.shading_frame: tilt the normal, Gram-Schmidt the tangent, keep hand
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
    t_c = mat_i[o, 2]
    if t_c >= 0:
        nc = tex[t_c, 2]
        if level0:
            _level0_into(data, info, tex[t_c, 0], nc, min(nc, 3), u, v, tx, 0)
        else:
            _footprint_into(data, info, tex[t_c, 0], tex[t_c, 1], nc, min(nc, 3), u, v, du00,
                            du01, du10, du11, tx, 0)
        for c in range(3):
            mat[1 + c] *= tx[0, c] if nc >= 3 else tx[0, 0]
    # the unnormalised average's length; height maps and plain materials are flat
    r = min(math.sqrt(m0 * m0 + m1 * m1 + m2 * m2), 1.0) if t_n >= 0 else 1.0
    return True, o, r
