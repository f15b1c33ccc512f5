"""Integral of an LTC over polygonal lights, with exact horizon clipping.

Heitz, Dupuy, Hill, Neubelt 2016 (LTC, polygon integral of Do; Lambert's formula as used by
Baum et al. 1989); equations.md section 2. The integral of ``D`` over a polygon ``P`` is the
integral of the clamped cosine ``Do`` over ``M^-1 P``; after clipping to ``z >= 0`` it is a sum of
one term per edge of the spherical polygon.

Winding convention (all functions here): a polygon's *front face* is the side from which its
vertices appear counter-clockwise, i.e. the right-hand normal ``(v1 - v0) x (v2 - v0)`` points
toward the shading point. A front-facing polygon has a positive signed integral ``E``. This is the
opposite sign of the edge sum as written in equations.md, which is positive for a polygon wound
counter-clockwise seen from its far side (e.g. from above a ceiling light); magnitudes agree.
One-sided lights return ``max(0, E)`` (back faces give 0), two-sided lights ``|E|``. The winding
refers to the polygon as given (before ``M^-1``): a matrix with negative determinant mirrors the
lobe but not which face of the light emits.

Polygons whose plane passes through the shading point (edge-on lights, vertices at the shading
point) and zero-area polygons (repeated or collinear vertices) subtend no solid angle and give
exactly 0. The tests, on the transformed vertices ``M^-1 v`` with Newell normal ``N``, centroid
``c`` and largest absolute coordinate ``r``: ``|N . c| <= 1e-12 |N| r`` or ``|N| <= 1e-14 n r^2``
(a sliver thinner than ~1e-14 of its length gives 0 instead of a value of that order).
Coordinates are used unnormalised (the edge terms are scale invariant), so keep them within about
``1e-100 .. 1e100``.
"""

from __future__ import annotations

import math

import numpy as np

from prefilter.jit import njit_inline, njit_parallel, njit_serial, prange, serial
from prefilter.validation import as_float_array
from prefilter.errors import PrefilterError

__all__ = ["clamped_cosine_integral", "polygon_integral", "polygon_integral_minv"]

_PLANE_RTOL = 1e-12  # plane-through-origin test, relative to the polygon's size
_AREA_RTOL = 1e-14  # |Newell normal| below this x size^2 is rounding noise (about 100 ulps)
DET_RTOL2 = 1e-24  # (|det| / product of column norms)^2 below this counts as singular
INV_2PI = 1.0 / (2.0 * math.pi)


# --------------------------------------------------------------------------------------------
# Numba kernel
# --------------------------------------------------------------------------------------------


# atan(y) = y (1 + z P(z)), z = y^2, |y| <= tan(pi/8): degree-9 Chebyshev fit of
# (atan(y)/y - 1) / y^2 in z, weighted by z, converted to monomials; max relative error 3e-16
_ATAN_P = (
    -0.33333333333329607,
    0.19999999998970805,
    -0.1428571418619693,
    0.1111110631284765,
    -0.0909077513779585,
    0.07689973710082709,
    -0.0664035587472378,
    0.056887710975983274,
    -0.04348755732734442,
    0.021138573606647313,
)
_TAN_PI_8 = math.tan(math.pi / 8)
_TAN2_PI_8 = _TAN_PI_8 * _TAN_PI_8


@njit_serial
def _atan_poly(z):
    """``P(z)`` with ``atan(y) = y (1 + z P(z))``, ``z = y^2 <= tan^2(pi/8)`` (Horner)."""
    p = _ATAN_P[9]
    p = p * z + _ATAN_P[8]
    p = p * z + _ATAN_P[7]
    p = p * z + _ATAN_P[6]
    p = p * z + _ATAN_P[5]
    p = p * z + _ATAN_P[4]
    p = p * z + _ATAN_P[3]
    p = p * z + _ATAN_P[2]
    p = p * z + _ATAN_P[1]
    return p * z + _ATAN_P[0]


@njit_serial
def _atan2_pos(s, d):
    """``atan2(s, d)`` for ``s >= 0`` (in ``[0, pi]``) within a few ulp; about twice as fast as
    libm's general atan2 here: the reduction needs one division and no special cases."""
    ad = abs(d)
    hi = max(s, ad)
    lo = min(s, ad)
    if lo <= _TAN_PI_8 * hi:
        y = lo / hi
        base = 0.0
    else:  # atan(x) = pi/4 + atan((x - 1) / (x + 1)) with x = lo / hi
        y = (lo - hi) / (lo + hi)
        base = 0.25 * math.pi
    z = y * y
    r = base + (y + y * z * _atan_poly(z))
    if s > ad:
        r = 0.5 * math.pi - r
    if d < 0.0:
        r = math.pi - r
    return r


@njit_serial
def _edge(ax, ay, az, bx, by, bz):
    """Arc a->b times the z of its unit normal; scale-invariant, so a and b need not be unit."""
    cx = ay * bz - az * by
    cy = az * bx - ax * bz
    cz = ax * by - ay * bx
    s2 = cx * cx + cy * cy + cz * cz
    d = ax * bx + ay * by + az * bz
    if s2 <= 0.0:
        # a, b parallel: zero-length arc, or antipodal (only on edge-on polygons, which are 0)
        return 0.0
    # theta = atan2(s, d) keeps full precision for short edges, where acos(dot) does not
    if d > 0.0 and s2 <= _TAN2_PI_8 * (d * d):
        # the common short-edge case: theta / s = (1 + z P(z)) / d with z = (s / d)^2,
        # which needs neither s nor a second division
        inv_d = 1.0 / d
        z = s2 * (inv_d * inv_d)
        return cz * inv_d * (1.0 + z * _atan_poly(z))
    s = math.sqrt(s2)
    return _atan2_pos(s, d) * (cz / s)


@njit_inline
def clipped_edge_sum(t00, t01, t02, t10, t11, t12, t20, t21, t22, verts, n):
    """Edge sum of the polygon ``T verts[:n]`` clipped to ``z >= 0`` (Heitz et al. 2016, eq. 11
    before the ``-1/2pi`` factor), for ``T`` rows ``(t00, t01, t02), ...`` scaled to a largest
    entry of 1. Returns ``(acc, ok)``; ``ok`` is False for polygons with no solid angle (edge-on,
    zero area, collinear). Shared by :func:`_polygon_kernel` and the renderer's fused shader.
    """
    # one pass over the transformed vertices: stream the edges through Sutherland-Hodgman
    # clipping against z = 0 without storing the clipped polygon (a pending exit point is
    # joined to the next entry point by an arc along the horizon), and accumulate the
    # Newell normal, centroid and size for the edge-on test (invariant under M^-1)
    x = verts[0, 0]
    y = verts[0, 1]
    z = verts[0, 2]
    fx = t00 * x + t01 * y + t02 * z
    fy = t10 * x + t11 * y + t12 * z
    fz = t20 * x + t21 * y + t22 * z
    px, py, pz = fx, fy, fz
    nx = 0.0
    ny = 0.0
    nz = 0.0
    sx = fx
    sy = fy
    sz = fz
    vmax = max(abs(fx), abs(fy), abs(fz))
    acc = 0.0
    ex = 0.0
    ey = 0.0
    has_exit = False
    gx = 0.0
    gy = 0.0
    has_first = False
    for j in range(1, n + 1):
        if j < n:
            x = verts[j, 0]
            y = verts[j, 1]
            z = verts[j, 2]
            qx = t00 * x + t01 * y + t02 * z
            qy = t10 * x + t11 * y + t12 * z
            qz = t20 * x + t21 * y + t22 * z
            sx += qx
            sy += qy
            sz += qz
            vmax = max(vmax, abs(qx), abs(qy), abs(qz))
        else:
            qx, qy, qz = fx, fy, fz
        nx += py * qz - pz * qy
        ny += pz * qx - px * qz
        nz += px * qy - py * qx
        if pz >= 0.0:
            if qz >= 0.0:
                acc += _edge(px, py, pz, qx, qy, qz)
            else:
                t = pz / (pz - qz)
                ex = px + t * (qx - px)
                ey = py + t * (qy - py)
                acc += _edge(px, py, pz, ex, ey, 0.0)
                has_exit = True
        elif qz >= 0.0:
            t = pz / (pz - qz)
            ix = px + t * (qx - px)
            iy = py + t * (qy - py)
            if has_exit:
                acc += _edge(ex, ey, 0.0, ix, iy, 0.0)
                has_exit = False
            else:
                gx = ix
                gy = iy
                has_first = True
            acc += _edge(ix, iy, 0.0, qx, qy, qz)
        px, py, pz = qx, qy, qz
    if has_exit and has_first:
        acc += _edge(ex, ey, 0.0, gx, gy, 0.0)

    # plane through the shading point (edge-on) or no area (repeated or collinear
    # vertices, where N is rounding noise): no solid angle
    nn = math.sqrt(nx * nx + ny * ny + nz * nz)
    if nn <= _AREA_RTOL * n * vmax * vmax or (
        abs(nx * sx + ny * sy + nz * sz) <= _PLANE_RTOL * n * nn * vmax
    ):
        return acc, False
    return acc, True


@njit_inline
def signed_adjugate(a00, a01, a02, a10, a11, a12, a20, a21, a22):
    """``sign(det M) adj(M) = |det M| M^-1`` of ``M = [[a00, a01, a02], ...]`` (row-major, 9
    scalars), a positive multiple of the inverse (all the polygon integral needs):
    ``(ok, sign(det M), t00, ..., t22)``; ``ok`` is False (zeros) when ``M`` is singular,
    ``|det M|`` below ``sqrt(DET_RTOL2)`` times the product of its column norms."""
    # cofactors of row 0 give the determinant and the first column of the adjugate
    k00 = a11 * a22 - a12 * a21
    k01 = a12 * a20 - a10 * a22
    k02 = a10 * a21 - a11 * a20
    det = a00 * k00 + a01 * k01 + a02 * k02
    c0 = a00 * a00 + a10 * a10 + a20 * a20
    c1 = a01 * a01 + a11 * a11 + a21 * a21
    c2 = a02 * a02 + a12 * a12 + a22 * a22
    if not (det * det > DET_RTOL2 * (c0 * c1 * c2)):  # |det| vs product of column norms
        return False, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0
    sgn = 1.0 if det > 0.0 else -1.0
    return (True, sgn, sgn * k00, sgn * (a02 * a21 - a01 * a22), sgn * (a01 * a12 - a02 * a11),
            sgn * k01, sgn * (a00 * a22 - a02 * a20), sgn * (a02 * a10 - a00 * a12),
            sgn * k02, sgn * (a01 * a20 - a00 * a21), sgn * (a00 * a11 - a01 * a10))


@njit_parallel
def _polygon_kernel(mats, m_mode, m_idx, verts, v_mode, v_idx, invert, two_sided, out, status):
    nb = out.shape[0]
    n = verts.shape[1]
    for k in prange(nb):
        # broadcasting without copies: mode 0 = same batch, 1 = single item, 2 = index array
        mi = np.int64(k)  # the prange index is unsigned; keep one signed index type
        if m_mode == 1:
            mi = 0
        elif m_mode == 2:
            mi = m_idx[k]
        vi = np.int64(k)
        if v_mode == 1:
            vi = 0
        elif v_mode == 2:
            vi = v_idx[k]
        a00 = mats[mi, 0, 0]
        a01 = mats[mi, 0, 1]
        a02 = mats[mi, 0, 2]
        a10 = mats[mi, 1, 0]
        a11 = mats[mi, 1, 1]
        a12 = mats[mi, 1, 2]
        a20 = mats[mi, 2, 0]
        a21 = mats[mi, 2, 1]
        a22 = mats[mi, 2, 2]
        ok, sgn, i00, i01, i02, i10, i11, i12, i20, i21, i22 = signed_adjugate(
            a00, a01, a02, a10, a11, a12, a20, a21, a22)
        if not ok:
            status[k] = 1
            out[k] = 0.0
            continue
        if invert:
            # |det| M^-1: a positive multiple projects to the same polygon
            t00, t01, t02 = i00, i01, i02
            t10, t11, t12 = i10, i11, i12
            t20, t21, t22 = i20, i21, i22
        else:
            t00, t01, t02 = a00, a01, a02
            t10, t11, t12 = a10, a11, a12
            t20, t21, t22 = a20, a21, a22
        tmax = max(abs(t00), abs(t01), abs(t02), abs(t10), abs(t11), abs(t12))
        tmax = max(tmax, abs(t20), abs(t21), abs(t22))

        sc = 1.0 / tmax
        t00 *= sc
        t01 *= sc
        t02 *= sc
        t10 *= sc
        t11 *= sc
        t12 *= sc
        t20 *= sc
        t21 *= sc
        t22 *= sc
        acc, ok = clipped_edge_sum(t00, t01, t02, t10, t11, t12, t20, t21, t22, verts[vi], n)
        if not ok:
            out[k] = 0.0
            continue

        # the edge sum is positive for clockwise-from-the-origin winding: flip to front = CCW,
        # and undo the mirror of a negative-determinant transform
        e = -sgn * acc * INV_2PI
        if two_sided:
            out[k] = abs(e)
        else:
            out[k] = max(0.0, e)


# --------------------------------------------------------------------------------------------
# Python wrappers
# --------------------------------------------------------------------------------------------


def _as_vertices(vertices) -> np.ndarray:
    v = as_float_array(vertices, "vertices", ndim_min=2, last_dim=3)
    if v.shape[-2] < 3:
        raise PrefilterError(
            f"vertices: expected at least 3 vertices per polygon (shape (..., n, 3), n >= 3), "
            f"got shape {v.shape}"
        )
    return v


def _as_matrices(M, name: str) -> np.ndarray:
    M = as_float_array(M, name, ndim_min=2)
    if M.shape[-2:] != (3, 3):
        raise PrefilterError(f"{name}: expected shape (..., 3, 3), got shape {M.shape}")
    return M


def _batch_index(shape: tuple, batch: tuple) -> tuple[int, np.ndarray]:
    """How the flattened ``batch`` reads an array of batch ``shape``: (mode, index array)."""
    none = np.empty(0, np.int64)
    if tuple(shape) == tuple(batch):
        return 0, none
    if math.prod(shape) == 1:
        return 1, none
    size = math.prod(shape)
    idx = np.broadcast_to(np.arange(size, dtype=np.int64).reshape(shape), batch)
    return 2, np.ascontiguousarray(idx).reshape(-1)


def _integrate(mats, name, V, *, invert: bool, two_sided) -> np.ndarray:
    if not isinstance(two_sided, (bool, np.bool_)):
        raise PrefilterError(f"two_sided: expected a bool, got {two_sided!r}")
    m_shape, v_shape = mats.shape[:-2], V.shape[:-2]
    try:
        batch = np.broadcast_shapes(m_shape, v_shape)
    except ValueError:
        raise PrefilterError(
            f"{name} and vertices: batch shapes {m_shape} and {v_shape} do not broadcast "
            f"(shapes {mats.shape} and {V.shape})"
        ) from None
    nb = math.prod(batch)
    out = np.empty(nb, np.float64)
    if nb == 0:
        return out.reshape(batch)
    status = np.zeros(nb, np.uint8)
    m_mode, m_idx = _batch_index(m_shape, batch)
    v_mode, v_idx = _batch_index(v_shape, batch)
    mf = np.ascontiguousarray(mats.reshape(-1, 3, 3))
    vf = np.ascontiguousarray(V.reshape(-1, V.shape[-2], 3))
    serial(_polygon_kernel, nb)(mf, m_mode, m_idx, vf, v_mode, v_idx, invert, bool(two_sided),
                                out, status)
    if status.any():
        k = int(np.flatnonzero(status)[0])
        mi = k if m_mode == 0 else (0 if m_mode == 1 else int(m_idx[k]))
        where = tuple(int(i) for i in np.unravel_index(k, batch))
        raise PrefilterError(
            f"{name}: expected invertible matrices, got a singular one at batch index "
            f"{where}: {np.array2string(mf[mi], precision=4)}"
        )
    return out.reshape(batch)


def polygon_integral(M, vertices, *, two_sided: bool = False) -> np.ndarray:
    """Integral of the LTC with matrix ``M`` over polygonal lights: ``int_P D(w) dw``.

    Heitz et al. 2016: ``int_P D = int_{M^-1 P} Do`` (Lambert's edge sum after clipping ``M^-1 P``
    to ``z >= 0``, the support of ``Do``). The clipping is exact in the cosine's space; when ``M``
    tilts the lobe below the shading horizon, the part of ``P`` below it still counts (as in
    Heitz et al.'s shaders). To integrate over the upper hemisphere only, clip ``P`` to ``z >= 0``
    first (:func:`clip_to_horizon`). For ``M = I`` the two coincide.

    Parameters
    ----------
    M : array_like, shape (..., 3, 3)
        LTC matrices (not inverted), invertible. Inverted here (adjugate, once per polygon).
    vertices : array_like, shape (..., n, 3)
        Polygon vertices relative to the shading point, in the local frame (z = normal),
        ``n >= 3``; convex planar polygons (quads, triangles, n-gons). Batch dims broadcast
        against those of ``M``.
    two_sided : bool
        ``False``: only the front face emits (vertices counter-clockwise seen from the shading
        point); back-facing polygons give 0. ``True``: both faces emit.

    Returns
    -------
    ndarray, shape (...)
        The integral, in ``[0, 1]``. Edge-on, zero-area or collinear polygons give 0.
    """
    return _integrate(_as_matrices(M, "M"), "M", _as_vertices(vertices), invert=True,
                      two_sided=two_sided)


def polygon_integral_minv(M_inv, vertices, *, two_sided: bool = False) -> np.ndarray:
    """As :func:`polygon_integral`, for callers already holding ``M_inv (..., 3, 3) = M^-1``.

    Heitz et al. 2016 (polygon integral of Do over ``M^-1 P``). Only the direction of ``M_inv``
    matters up to a positive factor, so ``|det M| M^-1`` (the signed adjugate) works too.
    """
    return _integrate(_as_matrices(M_inv, "M_inv"), "M_inv", _as_vertices(vertices),
                      invert=False, two_sided=two_sided)


def clamped_cosine_integral(vertices, *, two_sided: bool = False) -> np.ndarray:
    """Integral of ``Do(w) = max(0, w_z) / pi`` over polygons ``(..., n, 3)`` -> ``(...)``.

    Lambert's formula (Heitz et al. 2016 with ``M = I``): the form factor from a differential
    surface element to a polygonal light. Winding and ``two_sided`` as in :func:`polygon_integral`.
    """
    return _integrate(np.eye(3), "M", _as_vertices(vertices), invert=False, two_sided=two_sided)


def clip_to_horizon(vertices) -> np.ndarray:
    """Convex polygons ``(..., n, 3)`` clipped to the upper hemisphere ``z >= 0``.

    Sutherland-Hodgman against the surface plane, so parts of a light below the horizon are
    removed before the LTC transform (``polygon_integral`` clips ``M^-1 P`` in the cosine's own
    space, which keeps the LTC's mass below the horizon). Returns ``(..., n + 1, 3)``: the clipped
    polygon padded by repeating its last vertex (zero-length edges add nothing to the edge sum);
    all-zero vertices when nothing is above the horizon.
    """
    V = as_float_array(vertices, "vertices", ndim_min=2, last_dim=3)
    n = V.shape[-2]
    batch = V.shape[:-2]
    Vf = V.reshape(-1, n, 3)
    rows = np.arange(len(Vf))
    out = np.zeros((len(Vf), n + 1, 3))
    count = np.zeros(len(Vf), np.intp)
    for i in range(n):
        a, b = Vf[:, i - 1], Vf[:, i]
        a_in, b_in = a[:, 2] >= 0.0, b[:, 2] >= 0.0
        cross = a_in != b_in
        with np.errstate(divide="ignore", invalid="ignore"):
            t = np.where(cross, a[:, 2] / (a[:, 2] - b[:, 2]), 0.0)
        q = a + t[:, None] * (b - a)
        q[:, 2] = 0.0
        out[rows[cross], count[cross]] = q[cross]
        count += cross
        out[rows[b_in], count[b_in]] = b[b_in]
        count += b_in
    last = out[rows, np.maximum(count - 1, 0)]
    pad = np.arange(n + 1)[None, :] >= count[:, None]
    out = np.where(pad[..., None], last[:, None, :], out)
    return out.reshape(batch + (n + 1, 3))


# --------------------------------------------------------------------------------------------
# Jitted helpers for one polygon (the shading kernels)
# --------------------------------------------------------------------------------------------


@njit_serial
def polygon_integral_jit(t, verts, n):
    """Heitz et al. 2016 (eq. 11 after clipping): integral of the clamped cosine over
    ``t verts[:n]`` (one-sided), as :func:`polygon_integral_minv` with
    ``invert=False``: ``t[:9]`` an invertible matrix (row-major, largest entry 1), ``t[9]`` the
    sign of its determinant."""
    acc, ok = clipped_edge_sum(t[0], t[1], t[2], t[3], t[4], t[5], t[6], t[7], t[8], verts, n)
    if not ok:
        return 0.0
    return max(0.0, -t[9] * acc * INV_2PI)


@njit_serial
def clip_to_horizon_jit(P, n, out):
    """Sutherland-Hodgman of ``P[:n]`` against ``z >= 0`` into ``out[:n + 1]``, padded by
    repeating the last vertex (all zeros when nothing is above), as :func:`clip_to_horizon`."""
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
