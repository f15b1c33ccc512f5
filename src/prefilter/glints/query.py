"""Constant-time NDF queries on a compressed glints map (glints paper, eqs. 6-7).

``point`` evaluates the NDF image of any footprint at projected half vectors ``s`` (eq. 6, with
trilinear interpolation over the footprint pyramid); ``range`` returns the mean of that image over
an axis-aligned rectangle of ``s`` (eq. 7: products of 1D factor means from prefix sums, split at
block boundaries). Both are densities w.r.t. ``s`` like :func:`prefilter.glints.pndf.pndf`, and
cost O(8 * rank) (O(8 * rank * blocks spanned) for ranges) whatever the footprint size.

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

from prefilter.jit import serial
from prefilter.validation import as_float_array, broadcast_batch
from prefilter.errors import PrefilterError
from prefilter.glints._qkernels import (bilinear_kernel, point_kernel, range_kernel,
                                       range_multi_kernel, resample_point_kernel)
from prefilter.glints.pndf import as_sigma_p
from prefilter.glints.pyramid import (RESAMPLE_Q_MIN, RESAMPLE_TRUNCATION, interp_weights,
                                      resample_weights)
from prefilter.glints.store import PREFIX_MAX, GlintsMap, code_levels, rank_major

INTERP = ("trilinear", "resample")
#: Footprint centres (texels) are used as given up to this magnitude, where float64 still
#: resolves 2^-20 texel; beyond it (up to any finite value) they are reduced modulo the map size
#: before any kernel: the map tiles, so the footprint is the same, and the kernels' integer texel
#: indices stay far from int64 overflow (which begins near 9.2e18 texels).
CENTER_EXACT = 2.0**32
#: Query kernels run serially below this many items: their work per item is ~1-10 us, and on the
#: shared 2-core machine waking the thread pool made a frame's few hundred queries cost ~20 ms.
SERIAL_BELOW = 1 << 15


def wrap_centers(center, shape) -> np.ndarray:
    """Footprint centres ``(..., 2)`` (x, y in texels) of a periodic map of ``shape = (height,
    width)`` texels: coordinates beyond :data:`CENTER_EXACT` in magnitude reduced modulo the
    map's width (x) or height (y) in float64, the others returned unchanged."""
    c = np.asarray(center, dtype=np.float64)
    far = np.abs(c) >= CENTER_EXACT
    if not np.any(far):
        return c
    period = np.array([float(shape[1]), float(shape[0])])
    return np.where(far, np.mod(c, period), c)


def _map_shape(gm) -> tuple[int, int]:
    return gm.pyramid.height, gm.pyramid.width


def _check_map(gm):
    if not isinstance(gm, GlintsMap):
        raise PrefilterError(f"gm: expected a GlintsMap (prefilter.glints.store.load), got "
                             f"{type(gm).__name__}")


def check_interp(interp: str) -> None:
    """Validate an NDF interpolation mode across the pyramid: one of :data:`INTERP`
    (``"trilinear"``: the paper's 8-image blend, ``"resample"``: Gaussian resampling of a finer
    level). Raises :class:`~prefilter.errors.PrefilterError` otherwise."""
    if interp not in INTERP:
        raise PrefilterError(f"interp: expected one of {INTERP}, got {interp!r}")


def weights(gm: GlintsMap, center, sigma_p, *, interp: str = "trilinear"):
    """Pyramid images and weights of flat footprints ``center (N, 2)``, ``sigma_p (N,)``.

    Returns ``idx (N, K)``, ``w (N, K)`` (zero-padded) and ``resampled (N,)``: True where
    ``interp="resample"`` applied (elsewhere the trilinear weights: footprints below
    :func:`prefilter.glints.pyramid.resample_min_sigma` or at/above the top level)."""
    _check_map(gm)
    check_interp(interp)
    c = wrap_centers(as_float_array(center, "center", ndim_min=2, last_dim=2), _map_shape(gm))
    sp = as_sigma_p(sigma_p)
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
    arrs, lo, h = kernel_args(gm)
    s = np.asarray(s, dtype=np.float64)
    out = np.empty(idx.shape[0])
    sx, sy = np.ascontiguousarray(s[:, 0]), np.ascontiguousarray(s[:, 1])
    if bilinear:
        serial(bilinear_kernel, _n(idx))(*arrs, idx, w, sx, sy, lo, h, out)
    else:
        serial(point_kernel, _n(idx))(*arrs, idx, w, sx, sy, lo, h, _n_prefetch(gm), out)
    return out


def range_weighted(gm: GlintsMap, idx, w, s_min, s_max) -> np.ndarray:
    """Mean NDF values ``(N,)`` over ``[s_min, s_max]`` (``(N, 2)`` each, ``s_max > s_min``) of
    the blends ``(idx, w)`` of :func:`weights`."""
    lo_ = np.asarray(s_min, dtype=np.float64)
    hi_ = np.asarray(s_max, dtype=np.float64)
    if np.any(hi_ <= lo_):
        raise PrefilterError("s_max: expected s_max > s_min in both coordinates")
    arrs, lo, h = kernel_args(gm)
    out = np.empty(idx.shape[0])
    c = np.ascontiguousarray
    serial(range_kernel, _n(idx))(*arrs, idx, w, c(lo_[:, 0]), c(lo_[:, 1]), c(hi_[:, 0]),
                                  c(hi_[:, 1]), lo, h, _n_prefetch(gm), out)
    return out


def range_multi(gm: GlintsMap, idx, w, s_min, s_max, active=None) -> np.ndarray:
    """Mean NDF values ``(N, K)`` over ``K`` rectangles per footprint, ``[s_min, s_max]``
    (``(N, K, 2)`` each, ``s_max > s_min``), of the blends ``(idx, w)`` ``(N, T)`` of
    :func:`weights`: :func:`range_weighted` of each rectangle (glints paper, eq. 7), the taps
    walked once per block for all the rectangles touching it. ``active (N, K)`` bool: the
    rectangles to evaluate, the others are 0 at no cost (default: all).

    Version-3 maps with 8-bit ``c`` codes compute in float32 (the taps' 8-bit code rows summed
    as in :func:`point_flat`'s resampling kernel; the integer prefix sums exact, the rest sums
    of nonnegative terms): relative differences to :func:`range_weighted` measured <= 3e-7,
    tested at rtol 1e-5; 16-bit ``c`` codes and float maps in float64."""
    _check_map(gm)
    idx = np.asarray(idx)
    w = np.asarray(w, dtype=np.float64)
    lo_ = np.asarray(s_min, dtype=np.float64)
    hi_ = np.asarray(s_max, dtype=np.float64)
    if idx.ndim != 2 or w.shape != idx.shape or not np.issubdtype(idx.dtype, np.integer):
        raise PrefilterError(f"idx, w: expected integer idx and weights of one shape (N, T), got "
                             f"{idx.dtype} {idx.shape} and {w.shape}")
    n_img = gm.block_index.shape[0]
    if idx.size and (idx.min() < 0 or idx.max() >= n_img):
        raise PrefilterError(f"idx: expected image indices in [0, {n_img}), got range "
                             f"[{idx.min()}, {idx.max()}]")
    if lo_.ndim != 3 or lo_.shape[0] != idx.shape[0] or lo_.shape[2] != 2 \
            or hi_.shape != lo_.shape:
        raise PrefilterError(f"s_min, s_max: expected shapes (N, K, 2) with N = {idx.shape[0]}, "
                             f"got {lo_.shape} and {hi_.shape}")
    if np.any(hi_ <= lo_):
        raise PrefilterError("s_max: expected s_max > s_min in both coordinates")
    N, K = lo_.shape[:2]
    if active is not None:
        act = np.asarray(active)
        if act.dtype != bool or act.shape != (N, K):
            raise PrefilterError(f"active: expected a bool array of shape {(N, K)}, got "
                                 f"{act.dtype} {act.shape}")
    if active is not None:
        # inactive ones: a unit square outside the support (no block touched, value 0)
        lo_ = np.where(act[..., None], lo_, 4.0 * gm.support)
        hi_ = np.where(act[..., None], hi_, 4.0 * gm.support + 1.0)
    arrs, lo, h = kernel_args(gm)
    out = np.empty((N, K))
    if N == 0 or K == 0:
        return out
    c = np.ascontiguousarray
    proto = np.empty(0, np.float32 if arrs[2][0].dtype == np.uint8 else np.float64)
    serial(range_multi_kernel, 0 if N * K < SERIAL_BELOW else 1 << 30)(
        *arrs, c(idx), c(w), c(lo_[..., 0]), c(lo_[..., 1]), c(hi_[..., 0]), c(hi_[..., 1]), lo,
        h, proto, out)
    return out


def point_flat(gm: GlintsMap, center, sigma_p, s, *, interp: str = "trilinear",
               bilinear: bool = False) -> np.ndarray:
    """:func:`point` on flat arrays ``center (N, 2)``, ``sigma_p (N,)``, ``s (N, 2)`` (the
    renderer's batch call). Resampled footprints go through one fused kernel (taps generated
    in place, factor values shared by the taps of a CP group); the rest as :func:`point`."""
    _check_map(gm)
    check_interp(interp)
    c = np.ascontiguousarray(wrap_centers(center, _map_shape(gm)))
    sp = np.ascontiguousarray(sigma_p, dtype=np.float64)
    q = np.ascontiguousarray(s, dtype=np.float64)
    out = np.zeros(sp.shape[0])
    todo = np.ones(sp.shape[0], bool)
    if interp == "resample" and sp.size:
        pyr = gm.pyramid
        L = pyr.n_levels
        levels = [int(lv) for lv in np.arange(L)]  # `range` is this module's range query
        shapes = np.array([pyr.shape(lv) for lv in levels], dtype=np.int64)
        arrs, lo, h = kernel_args(gm)
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
        check_interp(interp)
    c = wrap_centers(as_float_array(center, "center", ndim_min=1, last_dim=2), _map_shape(gm))
    sp = as_sigma_p(sigma_p)
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


def kernel_args(gm: GlintsMap):
    """Arguments of the query kernels of :mod:`prefilter.glints._qkernels` for map ``gm``.

    Returns ``(arrs, lo, h)``: ``arrs = (Pa, Pb, C, block_index, image_cell, meta)``, the leading
    arguments of every kernel (from :func:`packed`; ``Pa``, ``Pb`` ``(M, B + 1)`` factor prefix
    sums, ``C = (cq, wsc, Fa, Fb)``, ``block_index (N, nb, nb)`` with the image innermost in
    memory, ``image_cell (N,)``, ``meta (G, 4)``; layout in :mod:`prefilter.glints._qkernels`),
    ``lo = -support``, the NDF images' lower corner in ``s`` (both axes), and ``h = 2 support /
    R``, their pixel pitch."""
    h = 2.0 * gm.support / gm.resolution
    pa, pb, c, meta, index, _ = packed(gm)
    return (pa, pb, c, index, gm.image_cell, meta), -gm.support, h


_PACKED: dict = {}


def packed(gm: GlintsMap):
    """The query kernels' arrays ``(Pa, Pb, (cq, wsc, Fa, Fb), meta, block_index)`` of a map
    (layout in :mod:`prefilter.glints._qkernels`; ``block_index`` with the image innermost) and
    the number of images whose data the kernels prefetch; built once per map (cached while the
    map lives).

    Version-3 maps: the stored codes (uint8 or uint16 factors, their integer prefix sums, exact
    in uint16 / uint32, and ``wsc = c_scale / (Q S_a S_b)``, ``Q`` 255 or 65535, ``S``: each
    component's code sum, the loader's renormalisation), so every value is the float64
    evaluation of what the file stores. Other
    maps: the float32 arrays ``A``, ``Bp``, ``C`` (``wsc = 1``)."""
    key = id(gm)
    hit = _PACKED.get(key)
    # the kernels read the codes when there are any: A, C are then not decoded (GlintsMap)
    src = (gm.codes,) if gm.codes is not None else (gm.A, gm.C)
    if hit is not None and hit[0]() is gm and all(x is y for x, y in zip(hit[1], src)):
        return hit[2]
    arrs = _pack_codes(gm.codes) if gm.codes is not None else _pack_float(gm)
    # block_index with the image innermost (same shape and indexing): the pyramid neighbours a
    # query blends, at one block position, share cache lines
    bt = np.ascontiguousarray(gm.block_index.transpose(1, 2, 0)).transpose(2, 0, 1)
    pa, _, (cq, wsc, fa, _), meta = arrs
    arrs = arrs + (bt, _count_prefetch(gm, pa, wsc, fa, cq, meta))
    _PACKED[key] = (weakref.ref(gm), src, arrs)
    weakref.finalize(gm, _PACKED.pop, key, None)
    return arrs


def _rank_major(f, ranks):
    """Factors ``f (M, n)`` of groups of ``ranks`` (consecutive components) reordered so that
    group ``g``'s block of ``r_g n`` values is ``[i, r]``: flat index ``m_g n + i r_g + r``
    (:func:`prefilter.glints.store.rank_major`)."""
    return rank_major(f, ranks)


def _meta(ranks, k0, c0, stride):
    """Group records ``(G, 4)``: rank, first component, code-row base ``c0 - k0 stride`` (row
    ``k`` of the group starts at ``base + k stride``) and stride; int32 when every value and
    code index fits (a quarter of the int64 record's cache footprint)."""
    r = np.asarray(ranks, np.int64)
    m = np.concatenate([[0], np.cumsum(r)])[:-1]
    stride = np.asarray(stride, np.int64)
    meta = np.stack([r, m, np.asarray(c0, np.int64) - np.asarray(k0, np.int64) * stride, stride],
                    axis=1)
    big = max(int(np.abs(meta).max(initial=0)), int(m[-1] + r[-1]) if r.size else 0)
    dt = np.int32 if big < 2**31 // 4 else np.int64
    return np.ascontiguousarray(meta.astype(dt))


def _pack_codes(codes):
    ranks = np.asarray(codes["ranks"], np.int64)
    a, b = codes["a"], codes["b"]
    Q = code_levels(codes["c"].dtype)
    # uint16 prefix sums whenever the codes allow (store.factor_codes): half the memory traffic
    # of uint32 ones, which made the range queries ~1.1x slower (bench_glints_codes.py)
    top = max((int(f.sum(axis=1, dtype=np.int64).max(initial=0)) for f in (a, b)), default=0)
    pdt = np.uint16 if top <= PREFIX_MAX else np.uint32
    prefix = [np.concatenate([np.zeros((f.shape[0], 1), pdt), np.cumsum(f, axis=1, dtype=pdt)],
                             axis=1) for f in (a, b)]
    sa, sb = (p[:, -1].astype(np.float64) for p in prefix)
    den = Q * sa * sb
    wsc = np.divide(codes["c_scale"].astype(np.float64), den, out=np.zeros_like(den),
                    where=den > 0).astype(np.float32)
    rows = np.asarray(codes["group_rows"], np.int64)
    n_rows = np.diff(rows)
    c0 = np.concatenate([[0], np.cumsum(n_rows * ranks)])[:-1]
    fa, fb = (_rank_major(f, ranks).ravel() for f in (a, b))
    pa, pb = (_rank_major(p, ranks) for p in prefix)
    return pa, pb, (np.ascontiguousarray(codes["c"]), wsc, fa, fb), _meta(ranks, rows[:-1], c0,
                                                                           ranks)


def _pack_float(gm):
    G, W = gm.A.shape[:2]
    ranks = _group_ranks(gm)
    comp_g = np.repeat(np.arange(G), ranks)
    comp_r = np.arange(comp_g.size) - np.concatenate([[0], np.cumsum(ranks)])[:-1][comp_g]
    pa, pb = (_rank_major(P[comp_g, comp_r], ranks) for P in (gm.A, gm.Bp))
    fa, fb = (_rank_major(np.diff(P[comp_g, comp_r], axis=1), ranks).ravel()
              for P in (gm.A, gm.Bp))
    zeros = np.zeros(G, np.int64)
    C = np.ascontiguousarray(gm.C, dtype=np.float32)
    return pa, pb, (C.ravel(), np.ones(comp_g.size, np.float32), fa, fb), _meta(
        ranks, zeros, zeros, np.full(G, C.shape[1], np.int64))


#: levels whose query data (factor rows and codes of their images) exceeds this many bytes are
#: prefetched by the point and range kernels: below it they stay in the cache (2 MB of L2 per
#: core here), where prefetching only costs instructions
PREFETCH_ABOVE = 1 << 20


def _n_prefetch(gm) -> int:
    """Images ``[0, n)`` whose data the kernels prefetch (cached with :func:`packed`)."""
    return packed(gm)[5]


def _count_prefetch(gm, pa, wsc, fa, cq, meta) -> int:
    """Images ``[0, n)`` whose data the kernels prefetch: the finest levels, while a level's
    factor bytes exceed :data:`PREFETCH_ABOVE` (levels are stored finest first)."""
    pyr = gm.pyramid
    nb2 = (gm.resolution // gm.block) ** 2
    offs = pyr.offsets
    per_comp = pa.itemsize * pa.shape[1] * 2 + fa.itemsize * gm.block * 2 + wsc.itemsize
    for lv in np.arange(pyr.n_levels):
        img = np.arange(offs[lv], offs[lv + 1])
        groups = np.unique(gm.image_cell[img]).astype(np.int64)
        g = (groups[:, None] * nb2 + np.arange(nb2)).ravel()
        kept = int(np.count_nonzero(gm.block_index[img] >= 0))
        nbytes = (int(meta[g, 0].sum()) * per_comp
                  + kept * cq.itemsize * float(meta[g, 0].mean() if g.size else 0))
        if nbytes <= PREFETCH_ABOVE:
            return int(offs[lv])
    return int(offs[-1])


def _group_ranks(gm):
    """Rank of each CP group ``(G,)`` int64 (all of ``C``'s columns for single-rank maps)."""
    if gm.ranks is None:
        return np.full(gm.A.shape[0], gm.C.shape[1], np.int64)
    return np.ascontiguousarray(gm.ranks, dtype=np.int64)


def point(gm: GlintsMap, center, sigma_p, s, *, interp: str = "trilinear",
          bilinear: bool = False) -> np.ndarray:
    """NDF value (density w.r.t. ``s``) of footprints ``(center (..., 2), sigma_p (...))`` at
    ``s (..., 2)``; all broadcast. Zero outside the image support. Centres may take any finite
    value (the map tiles; see :func:`wrap_centers`). ``interp``: see the module
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
    kept = k >= 0
    out = np.zeros(k.shape)
    if gm.codes is None:
        out[kept] = gm.C.sum(axis=1, dtype=np.float64)[k[kept]]
    else:
        out[kept] = _row_sums_from_codes(gm.codes, k[kept].astype(np.int64))
    return out / gm.block**2


def _row_sums_from_codes(codes, k):
    """``sum_r C[k, r]`` ``(n,)`` float64 of rows ``k (n,)`` from the 8-bit codes (the row's
    ``rank`` entries times their component's ``c_scale / 255``), without decoding ``C``."""
    ranks = np.asarray(codes["ranks"], np.int64)
    rows = np.asarray(codes["group_rows"], np.int64)
    m0 = np.concatenate([[0], np.cumsum(ranks)])
    c0 = np.concatenate([[0], np.cumsum(np.diff(rows) * ranks)])
    g = np.searchsorted(rows, k, side="right") - 1
    r = ranks[g]
    # one entry per (requested row, component): code position and component index
    rep = np.repeat(np.arange(k.size), r)
    j = np.arange(rep.size) - np.repeat(np.cumsum(r) - r, r)
    pos = c0[g][rep] + (k - rows[g])[rep] * r[rep] + j
    val = (codes["c"][pos].astype(np.float64) * codes["c_scale"][m0[g][rep] + j]
           / code_levels(codes["c"].dtype))
    return np.bincount(rep, weights=val, minlength=k.size)
