"""Constant-time NDF queries on a compressed glints map (glints paper, eqs. 6-7).

``point`` evaluates the NDF image of any footprint at projected half vectors ``s`` (eq. 6, with
trilinear interpolation over the footprint pyramid); ``range`` returns the mean of that image over
an axis-aligned rectangle of ``s`` (eq. 7: products of 1D factor means from prefix sums, split at
block boundaries). Both are densities w.r.t. ``s`` like :func:`prefilter.glints.pndf`, and cost
O(8 * rank) (O(8 * rank * blocks spanned) for ranges) whatever the footprint size.
"""

from __future__ import annotations

import numpy as np

from prefilter._validate import as_float_array, broadcast_batch
from prefilter.errors import PrefilterError
from prefilter.glints._qkernels import point_kernel, range_kernel
from prefilter.glints.pndf import _as_sigma_p
from prefilter.glints.pyramid import interp_weights
from prefilter.glints.store import GlintsMap


def _prepare(gm: GlintsMap, center, sigma_p, *points):
    if not isinstance(gm, GlintsMap):
        raise PrefilterError(f"gm: expected a GlintsMap (prefilter.glints.store.load), got "
                             f"{type(gm).__name__}")
    c = as_float_array(center, "center", ndim_min=1, last_dim=2)
    sp = _as_sigma_p(sigma_p)
    pts = [as_float_array(p, name, ndim_min=1, last_dim=2) for p, name in points]
    shape = broadcast_batch(center=c.shape[:-1], sigma_p=sp.shape,
                            **{name: p.shape[:-1] for p, (_, name) in zip(pts, points)})
    c = np.broadcast_to(c, shape + (2,)).reshape(-1, 2)
    sp = np.broadcast_to(sp, shape).reshape(-1)
    idx, w = interp_weights(gm.pyramid, c, sp)
    pts = [np.broadcast_to(p, shape + (2,)).reshape(-1, 2) for p in pts]
    return shape, idx, w, pts


def _args(gm):
    h = 2.0 * gm.support / gm.resolution
    return (gm.A, gm.Bp, gm.C, gm.block_index, gm.image_cell), -gm.support, h


def point(gm: GlintsMap, center, sigma_p, s) -> np.ndarray:
    """NDF value (density w.r.t. ``s``) of footprints ``(center (..., 2), sigma_p (...))`` at
    ``s (..., 2)``; all broadcast. Zero outside the image support."""
    shape, idx, w, (s,) = _prepare(gm, center, sigma_p, (s, "s"))
    arrs, lo, h = _args(gm)
    out = np.empty(idx.shape[0])
    point_kernel(*arrs, idx, w, np.ascontiguousarray(s[:, 0]), np.ascontiguousarray(s[:, 1]),
                 lo, h, out)
    return out.reshape(shape)


def range_mean(gm: GlintsMap, center, sigma_p, s_min, s_max) -> np.ndarray:
    """Mean NDF value over the rectangles ``[s_min, s_max]`` (``(..., 2)`` each, ``s_max > s_min``)
    of the footprints' NDF images; parts outside the support count as zero."""
    shape, idx, w, (lo_, hi_) = _prepare(gm, center, sigma_p, (s_min, "s_min"), (s_max, "s_max"))
    if np.any(hi_ <= lo_):
        raise PrefilterError("s_max: expected s_max > s_min in both coordinates")
    arrs, lo, h = _args(gm)
    out = np.empty(idx.shape[0])
    c = np.ascontiguousarray
    range_kernel(*arrs, idx, w, c(lo_[:, 0]), c(lo_[:, 1]), c(hi_[:, 0]), c(hi_[:, 1]), lo, h, out)
    return out.reshape(shape)


range = range_mean  # the name; ``range_mean`` avoids shadowing the builtin on import *


def block_means(gm: GlintsMap, image: np.ndarray) -> np.ndarray:
    """Mean value of every block ``(..., nb, nb)`` of pyramid images ``image (...)`` (flat
    indices): ``sum_r c_r[k] / B^2`` since the ``a``, ``b`` factors sum to 1 (for sampling)."""
    raw = np.asarray(image)
    if not np.issubdtype(raw.dtype, np.integer):
        raise PrefilterError(f"image: expected integer image indices, got dtype {raw.dtype}")
    img = raw.astype(np.int64)
    n = gm.block_index.shape[0]
    if img.size and (img.min() < 0 or img.max() >= n):
        raise PrefilterError(f"image: expected indices in [0, {n}), got range [{img.min()}, "
                             f"{img.max()}]")
    k = gm.block_index[img]
    vals = gm.C.sum(axis=1, dtype=np.float64)[np.maximum(k, 0)] / gm.block**2
    return np.where(k >= 0, vals, 0.0)
