"""Bilinear and trilinear texel fetches of packed mip levels, for compiled kernels and the arrays.

A chain of levels ``(H_l, W_l, C)`` is packed as one ``(sum H_l W_l, C)`` array with per-level
row offsets, heights and widths (:func:`pack_levels`): texel ``(i, j)`` of level ``l`` is row
``offsets[l] + i W_l + j``, its centre at ``u = (j + 0.5) / W_l``, ``v = (i + 0.5) / H_l``.
``u`` and ``v`` wrap (periodic textures); with :data:`CLAMP_V` ``v`` is clamped to the first and
last rows (lat-long maps, whose rows end at the poles), with :data:`CLAMP_UV` both are clamped to
the edge texels (a light's texture).
"""

from __future__ import annotations

import math

import numpy as np

from prefilter.jit import kernel_array, njit_inline, njit_parallel, prange, serial

#: Edge rules of the fetches: both coordinates wrap, ``v`` is clamped, both are clamped.
WRAP, CLAMP_V, CLAMP_UV = 0, 1, 2


def pack_levels(levels) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """``(data (sum H_l W_l, C), offsets (L,), heights (L,), widths (L,))`` of levels
    ``(H_l, W_l, C)``."""
    heights = np.array([lv.shape[0] for lv in levels], np.int64)
    widths = np.array([lv.shape[1] for lv in levels], np.int64)
    offsets = np.concatenate([[0], np.cumsum(heights * widths)[:-1]]).astype(np.int64)
    data = np.ascontiguousarray(
        np.concatenate([np.asarray(lv, np.float64).reshape(-1, lv.shape[2]) for lv in levels]))
    return data, offsets, heights, widths


@njit_inline
def footprint_axes_jit(h, w, d00, d01, d10, d11):  # pragma: no cover - compiled
    """``(major, minor, dir_x, dir_y)``: the footprint ellipse of the Jacobian ``dudv = d..`` in
    texels of an ``h x w`` level 0, the major direction a unit vector in texel space (the
    singular values and left singular vector of ``diag(w, h) dudv``,
    :func:`prefilter.texture.mip.footprint_axes`)."""
    j00, j01, j10, j11 = d00 * w, d01 * w, d10 * h, d11 * h
    # eigen-decomposition of J J^T = [[p, q], [q, r]] in closed form
    p = j00 * j00 + j01 * j01
    r = j10 * j10 + j11 * j11
    q = j00 * j10 + j01 * j11
    mid = 0.5 * (p + r)
    disc = math.sqrt(max(0.25 * (p - r) ** 2 + q * q, 0.0))
    l1 = mid + disc
    l2 = max(mid - disc, 0.0)
    # eigenvector of l1: (q, l1 - p) or (l1 - r, q), whichever is longer (stable)
    dx, dy = q, l1 - p
    if dx * dx + dy * dy < (l1 - r) ** 2 + q * q:
        dx, dy = l1 - r, q
    nrm = math.sqrt(dx * dx + dy * dy)
    if nrm > 0.0:
        return math.sqrt(l1), math.sqrt(l2), dx / nrm, dy / nrm
    return math.sqrt(l1), math.sqrt(l2), 1.0, 0.0


@njit_parallel
def footprint_axes_kernel(h, w, dudv, out):  # pragma: no cover - compiled
    """``out (N, 4)``: :func:`footprint_axes_jit` of each ``dudv (N, 2, 2)``."""
    for q in prange(dudv.shape[0]):
        out[q, 0], out[q, 1], out[q, 2], out[q, 3] = footprint_axes_jit(
            h, w, dudv[q, 0, 0], dudv[q, 0, 1], dudv[q, 1, 0], dudv[q, 1, 1])
    return out


@njit_inline
def _texel_pair(x, n, clamp):  # pragma: no cover - compiled
    """The texels ``i0, i1`` around ``x`` (texel units, centres at integers) on an axis of ``n``
    texels, and the weight of ``i1``: wrapped, or with ``clamp`` held at the edge texels."""
    if clamp:
        x = min(max(x, 0.0), n - 1.0)
        x0 = min(math.floor(x), max(n - 2, 0))
        i0 = int(x0)
        return i0, min(i0 + 1, n - 1), x - x0
    x0 = math.floor(x)
    i0 = int(x0) % n
    return i0, (i0 + 1) % n, x - x0


@njit_inline
def bilinear_add(data, offset, h, w, u, v, nc, weight, clamp, out):  # pragma: no cover
    """``out[:nc] += weight * bilinear(level, u, v)`` for the level at row ``offset`` of
    ``data``, ``h x w`` texels; ``clamp`` (:data:`WRAP`, :data:`CLAMP_V`, :data:`CLAMP_UV`, or a
    bool for the first two) says which coordinates stop at the edge texels instead of
    wrapping."""
    j0, j1, fx = _texel_pair(u * w - 0.5, w, clamp >= CLAMP_UV)
    i0, i1, fy = _texel_pair(v * h - 0.5, h, clamp >= CLAMP_V)
    for c in range(nc):
        a = data[offset + i0 * w + j0, c] * (1 - fx) + data[offset + i0 * w + j1, c] * fx
        b = data[offset + i1 * w + j0, c] * (1 - fx) + data[offset + i1 * w + j1, c] * fx
        out[c] += weight * (a * (1 - fy) + b * fy)


@njit_inline
def trilinear_add(data, offsets, heights, widths, u, v, lod, nc, weight, clamp,
                  out):  # pragma: no cover
    """``out[:nc] += weight * trilinear(u, v, lod)``: the two levels around ``lod`` (clamped
    to the chain), blended linearly; a level of zero weight is not read."""
    n = offsets.shape[0]
    lod = min(max(lod, 0.0), n - 1.0)
    l0 = min(int(math.floor(lod)), max(n - 2, 0))
    t = lod - l0
    if t < 1.0:
        bilinear_add(data, offsets[l0], heights[l0], widths[l0], u, v, nc, weight * (1.0 - t),
                     clamp, out)
    if t > 0.0:
        bilinear_add(data, offsets[l0 + 1], heights[l0 + 1], widths[l0 + 1], u, v, nc,
                     weight * t, clamp, out)


@njit_parallel
def trilinear_kernel(data, offsets, heights, widths, uv, lod, clamp,
                     out):  # pragma: no cover - compiled
    """``out (N, C)``: :func:`trilinear_add` at ``uv (N, 2)``, ``lod (N,)``."""
    for q in prange(uv.shape[0]):
        for c in range(out.shape[1]):
            out[q, c] = 0.0
        trilinear_add(data, offsets, heights, widths, uv[q, 0], uv[q, 1], lod[q], out.shape[1],
                      1.0, clamp, out[q])
    return out


def trilinear(packed, uv, lod, *, clamp: int = WRAP) -> np.ndarray:
    """Trilinear lookups ``(..., C)`` of packed levels ``packed`` (:func:`pack_levels`) at
    ``uv (..., 2)`` and ``lod (...)`` (broadcast together; clamped to the chain), edges as
    ``clamp`` says (:data:`WRAP`, :data:`CLAMP_V` or :data:`CLAMP_UV`)."""
    data, offsets, heights, widths = packed
    uv = np.asarray(uv, np.float64)
    shape = np.broadcast_shapes(uv.shape[:-1], np.shape(lod))
    uvf = kernel_array(uv, shape + (2,)).reshape(-1, 2)
    lodf = kernel_array(lod, shape, np.float64).reshape(-1)
    out = np.empty((uvf.shape[0], data.shape[1]))
    serial(trilinear_kernel, len(uvf))(data, offsets, heights, widths, uvf, lodf, int(clamp), out)
    return out.reshape(shape + (data.shape[1],))
