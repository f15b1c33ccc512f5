"""Constant-time NDF queries on a compressed glints map (glints paper, eqs. 6-7).

``point`` evaluates the NDF image of any footprint at projected half vectors ``s`` (eq. 6, with
trilinear interpolation over the footprint pyramid); ``range`` returns the mean of that image over
an axis-aligned rectangle of ``s`` (eq. 7: products of 1D factor means from prefix sums, split at
block boundaries). Both are densities w.r.t. ``s`` like :func:`prefilter.glints.pndf`, and cost
O(8 * rank) (O(8 * rank * blocks spanned) for ranges) whatever the footprint size.

``interp="resample"`` replaces the trilinear blend by Gaussian resampling of a finer level
(:func:`prefilter.glints.pyramid.resample_weights`: the exact footprint up to aliasing, ~10-100
pyramid images per query instead of 8, still independent of the footprint size).

Batch API (flat arrays, no broadcasting, for callers that evaluate several things per footprint):
:func:`weights` once per batch, then :func:`point_weighted` / :func:`range_weighted`. Kernels run
serially below :data:`SERIAL_BELOW` items (waking Numba's thread pool costs more than a
render-sized batch).
"""

from __future__ import annotations

import weakref

import numpy as np

from prefilter._numba import serial
from prefilter._validate import as_float_array, broadcast_batch
from prefilter.errors import PrefilterError
from prefilter.glints._qkernels import (bilinear_kernel, point_kernel, range_kernel,
                                       resample_point_kernel)
from prefilter.glints.pndf import _as_sigma_p
from prefilter.glints.pyramid import (RESAMPLE_Q_MIN, RESAMPLE_TRUNCATION, interp_weights,
                                      resample_weights)
from prefilter.glints.store import GlintsMap

INTERP = ("trilinear", "resample")
#: Query kernels run serially below this many items: their work per item is ~1-10 us, and on the
#: shared 2-core machine waking the thread pool made a frame's few hundred queries cost ~20 ms.
SERIAL_BELOW = 1 << 15


def _check_map(gm):
    if not isinstance(gm, GlintsMap):
        raise PrefilterError(f"gm: expected a GlintsMap (prefilter.glints.store.load), got "
                             f"{type(gm).__name__}")


def _check_interp(interp):
    if interp not in INTERP:
        raise PrefilterError(f"interp: expected one of {INTERP}, got {interp!r}")


def weights(gm: GlintsMap, center, sigma_p, *, interp: str = "trilinear"):
    """Pyramid images and weights of flat footprints ``center (N, 2)``, ``sigma_p (N,)``.

    Returns ``idx (N, K)``, ``w (N, K)`` (zero-padded) and ``resampled (N,)``: True where
    ``interp="resample"`` applied (elsewhere the trilinear weights: footprints below
    :func:`prefilter.glints.pyramid.resample_min_sigma` or at/above the top level)."""
    _check_map(gm)
    _check_interp(interp)
    c = as_float_array(center, "center", ndim_min=2, last_dim=2)
    sp = _as_sigma_p(sigma_p)
    if c.ndim != 2 or sp.shape != c.shape[:1]:
        raise PrefilterError(f"center, sigma_p: expected shapes (N, 2) and (N,), got {c.shape} "
                             f"and {sp.shape}")
    if interp == "resample":
        idx, w, ok = resample_weights(gm.pyramid, c, sp)
    else:
        idx, w = interp_weights(gm.pyramid, c, sp)
        ok = np.zeros(sp.shape, bool)
    return np.ascontiguousarray(idx), np.ascontiguousarray(w), ok


def point_weighted(gm: GlintsMap, idx, w, s, *, bilinear: bool = False) -> np.ndarray:
    """NDF values ``(N,)`` at ``s (N, 2)`` of the blends ``(idx, w)`` of :func:`weights`;
    ``bilinear``: interpolated between the NDF pixel centres instead of the pixel's value."""
    arrs, lo, h = _args(gm)
    s = np.asarray(s, dtype=np.float64)
    out = np.empty(idx.shape[0])
    kern = bilinear_kernel if bilinear else point_kernel
    serial(kern, _n(idx))(*arrs, idx, w, np.ascontiguousarray(s[:, 0]),
                                  np.ascontiguousarray(s[:, 1]), lo, h, out)
    return out


def range_weighted(gm: GlintsMap, idx, w, s_min, s_max) -> np.ndarray:
    """Mean NDF values ``(N,)`` over ``[s_min, s_max]`` (``(N, 2)`` each, ``s_max > s_min``) of
    the blends ``(idx, w)`` of :func:`weights`."""
    lo_ = np.asarray(s_min, dtype=np.float64)
    hi_ = np.asarray(s_max, dtype=np.float64)
    if np.any(hi_ <= lo_):
        raise PrefilterError("s_max: expected s_max > s_min in both coordinates")
    arrs, lo, h = _args(gm)
    out = np.empty(idx.shape[0])
    c = np.ascontiguousarray
    serial(range_kernel, _n(idx))(*arrs, idx, w, c(lo_[:, 0]), c(lo_[:, 1]), c(hi_[:, 0]),
                                  c(hi_[:, 1]), lo, h, out)
    return out


def point_flat(gm: GlintsMap, center, sigma_p, s, *, interp: str = "trilinear",
               bilinear: bool = False) -> np.ndarray:
    """:func:`point` on flat arrays ``center (N, 2)``, ``sigma_p (N,)``, ``s (N, 2)`` (the
    renderer's batch call). Resampled footprints go through one fused kernel (taps generated
    in place, factor values shared by the taps of a CP group); the rest as :func:`point`."""
    _check_map(gm)
    _check_interp(interp)
    c = np.ascontiguousarray(center, dtype=np.float64)
    sp = np.ascontiguousarray(sigma_p, dtype=np.float64)
    q = np.ascontiguousarray(s, dtype=np.float64)
    out = np.zeros(sp.shape[0])
    todo = np.ones(sp.shape[0], bool)
    if interp == "resample" and sp.size:
        pyr = gm.pyramid
        L = pyr.n_levels
        levels = [int(lv) for lv in np.arange(L)]  # `range` is this module's range query
        shapes = np.array([pyr.shape(lv) for lv in levels], dtype=np.int64)
        arrs, lo, h = _args(gm)
        done = np.zeros(sp.shape[0], bool)
        serial(resample_point_kernel, _n(sp))(
            *arrs, pyr.offsets, shapes[:, 0].copy(), shapes[:, 1].copy(),
            np.array([pyr.sigma(lv) for lv in levels]),
            np.array([float(pyr.stride(lv)) for lv in levels]),
            np.ascontiguousarray(c[:, 0]), np.ascontiguousarray(c[:, 1]), sp,
            np.ascontiguousarray(q[:, 0]), np.ascontiguousarray(q[:, 1]), lo, h,
            RESAMPLE_TRUNCATION, RESAMPLE_Q_MIN, bool(bilinear), out, done)
        todo = ~done
    if np.any(todo):
        idx, w = interp_weights(gm.pyramid, c[todo], sp[todo])
        out[todo] = point_weighted(gm, np.ascontiguousarray(idx), np.ascontiguousarray(w),
                                   q[todo], bilinear=bilinear)
    return out


def _n(idx):
    # serial() compares against the project-wide threshold; the query kernels use their own
    return 0 if idx.shape[0] < SERIAL_BELOW else 1 << 30


def _prepare(gm: GlintsMap, center, sigma_p, *points, interp="trilinear"):
    """Validated, broadcast, flattened inputs and (``interp`` not None) their weights; with
    ``interp=None`` the flat centres and stds instead of the weights."""
    _check_map(gm)
    if interp is not None:
        _check_interp(interp)
    c = as_float_array(center, "center", ndim_min=1, last_dim=2)
    sp = _as_sigma_p(sigma_p)
    pts = [as_float_array(p, name, ndim_min=1, last_dim=2) for p, name in points]
    shape = broadcast_batch(center=c.shape[:-1], sigma_p=sp.shape,
                            **{name: p.shape[:-1] for p, (_, name) in zip(pts, points)})
    c = np.broadcast_to(c, shape + (2,)).reshape(-1, 2)
    sp = np.broadcast_to(sp, shape).reshape(-1)
    pts = [np.broadcast_to(p, shape + (2,)).reshape(-1, 2) for p in pts]
    if interp is None:
        return shape, c, sp, pts
    idx, w, _ = weights(gm, c, sp, interp=interp)
    return shape, idx, w, pts


def _args(gm):
    h = 2.0 * gm.support / gm.resolution
    return (_prefix_t(gm) + (gm.C, gm.block_index, gm.image_cell, _group_ranks(gm)),
            -gm.support, h)


_PREFIX_T: dict = {}


def _prefix_t(gm):
    """The prefix sums ``A``, ``Bp`` as ``(G, B + 1, R)`` float32 (rank innermost): the layout of
    every query and sampler kernel, which read all components of a group at one or two NDF
    pixels. Cached per map while its ``A`` lives (weak references: a process that loads many
    maps does not keep their copies)."""
    key = id(gm.A)
    hit = _PREFIX_T.get(key)
    if hit is None or hit[0]() is not gm.A or hit[1]() is not gm.Bp:
        at, bt = (np.ascontiguousarray(f.transpose(0, 2, 1)) for f in (gm.A, gm.Bp))
        hit = _PREFIX_T[key] = (weakref.ref(gm.A), weakref.ref(gm.Bp), (at, bt))
        weakref.finalize(gm.A, _PREFIX_T.pop, key, None)
    return hit[2]


def _group_ranks(gm):
    """Rank of each CP group ``(G,)`` int64 (all of ``C``'s columns for single-rank maps)."""
    if gm.ranks is None:
        return np.full(gm.A.shape[0], gm.C.shape[1], np.int64)
    return np.ascontiguousarray(gm.ranks, dtype=np.int64)


def point(gm: GlintsMap, center, sigma_p, s, *, interp: str = "trilinear",
          bilinear: bool = False) -> np.ndarray:
    """NDF value (density w.r.t. ``s``) of footprints ``(center (..., 2), sigma_p (...))`` at
    ``s (..., 2)``; all broadcast. Zero outside the image support. ``interp``: see the module
    docstring; ``bilinear``: interpolate between NDF pixel centres (the stored images are pixel
    averages; the default returns the pixel's value, what :mod:`prefilter.glints.sample`
    samples)."""
    shape, c, sp, (s,) = _prepare(gm, center, sigma_p, (s, "s"), interp=None)
    return point_flat(gm, c, sp, s, interp=interp, bilinear=bool(bilinear)).reshape(shape)


def range_mean(gm: GlintsMap, center, sigma_p, s_min, s_max, *,
               interp: str = "trilinear") -> np.ndarray:
    """Mean NDF value over the rectangles ``[s_min, s_max]`` (``(..., 2)`` each, ``s_max > s_min``)
    of the footprints' NDF images; parts outside the support count as zero."""
    shape, idx, w, (lo_, hi_) = _prepare(gm, center, sigma_p, (s_min, "s_min"), (s_max, "s_max"),
                                         interp=interp)
    return range_weighted(gm, idx, w, lo_, hi_).reshape(shape)


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
