"""The footprint pyramid of NDF images (glints tensor-prefiltering paper, sec. 4.1).

Level ``l`` samples footprint centres on a periodic grid of stride ``stride0 * 2^l`` texels, at
``u = (k_x stride_l + 0.5, k_y stride_l + 0.5)`` (texel centres sit at ``i + 0.5``), with Gaussian
footprints of std ``sigma0 * 2^l``. Centres of level ``l`` are a subset of those of level ``l - 1``.

Only level 0 is computed directly (``pndf_image``). The P-NDF is linear in the footprint and
``G_{2 sigma} = G_sigma * G_{sqrt(3) sigma}``, so level ``l`` is the level ``l - 1`` image grid
filtered by a periodic Gaussian of std ``sqrt(3) sigma_{l-1}`` and decimated by 2. The filter is
sampled at the level-``l - 1`` stride; the sampled sum equals the integral up to aliasing of order
``exp(-3 pi^2 / 2 (sigma / stride)^2)`` (< 4e-7 for ``sigma0 = stride0``), so the upper levels are
exact P-NDFs, not approximations of them.

Queries between samples use trilinear interpolation: bilinear over the (periodic) centre grid of
two levels and linear in ``log2(sigma_p)`` between them; footprints smaller than ``sigma0`` or
larger than the top level are clamped to it (the paper switches to the direct P-NDF below level 0).
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from prefilter.glints.levels import LevelFile, over_peaks
from prefilter.jit import njit_parallel, njit_serial, prange
from prefilter.validation import as_float_array, as_positive_int
from prefilter.errors import PrefilterError


@dataclass(frozen=True)
class Pyramid:
    """Geometry of the footprint pyramid of an ``height x width`` periodic normal map."""

    height: int
    width: int
    stride0: int
    sigma0: float
    n_levels: int

    def stride(self, level: int) -> int:
        return self.stride0 << level

    def sigma(self, level: int) -> float:
        return self.sigma0 * 2.0**level

    def shape(self, level: int) -> tuple[int, int]:
        """Number of centres ``(ny, nx)`` of ``level``."""
        st = self.stride(level)
        return self.height // st, self.width // st

    @property
    def offsets(self) -> np.ndarray:
        """Index of the first image of each level in the flat image list, plus the total."""
        sizes = [int(np.prod(self.shape(lv))) for lv in range(self.n_levels)]
        return np.concatenate([[0], np.cumsum(sizes)]).astype(np.int64)

    @property
    def n_images(self) -> int:
        return int(self.offsets[-1])

    def centers(self, level: int) -> np.ndarray:
        """Footprint centres ``(ny, nx, 2)`` of ``level`` in texels ``(x, y)``."""
        ny, nx = self.shape(level)
        st = self.stride(level)
        X, Y = np.meshgrid(np.arange(nx) * st + 0.5, np.arange(ny) * st + 0.5)
        return np.stack([X, Y], axis=-1)

    def with_levels(self, n_levels: int) -> "Pyramid":
        return Pyramid(self.height, self.width, self.stride0, self.sigma0, n_levels)

    def to_dict(self) -> dict:
        return {"height": self.height, "width": self.width, "stride0": self.stride0,
                "sigma0": self.sigma0, "n_levels": self.n_levels}


def plan(height: int, width: int, stride0: int = 4, sigma0: float | None = None,
         max_levels: int | None = None) -> Pyramid:
    """The tallest pyramid for a map: levels while the stride divides both map sides.

    The top level has one centre per axis when the sides are ``stride0`` times a power of two; its
    footprint then covers the map.
    """
    H = as_positive_int(height, "height")
    W = as_positive_int(width, "width")
    st = as_positive_int(stride0, "stride0")
    s0 = float(st if sigma0 is None else sigma0)
    if not (0.5 * st <= s0 <= 4.0 * st):
        raise PrefilterError(
            f"sigma0: expected a footprint std in [stride0/2, 4 stride0], got {s0}")
    if H % st or W % st:
        raise PrefilterError(f"stride0: expected a divisor of the map size {H}x{W}, got {st}")
    n = 1
    while H % (st << n) == 0 and W % (st << n) == 0 and (st << n) <= min(H, W):
        n += 1
    if max_levels is not None:
        n = min(n, as_positive_int(max_levels, "max_levels"))
    return Pyramid(H, W, st, s0, n)


@njit_parallel
def _decimate_axis1(src, w, taps, out):
    """``out[y, xo] = sum_t w[t] src[y, (2 xo + taps[t]) mod nx]`` over images ``(..., R, R)``,
    accumulated in float64 (each output image from one iteration: no parallel reduction)."""
    ny, nx = src.shape[0], src.shape[1]
    nxo = out.shape[1]
    R0, R1 = src.shape[2], src.shape[3]
    for n in prange(ny * nxo):
        y = n // nxo
        xo = n - y * nxo
        acc = np.zeros((R0, R1))
        for t in range(taps.shape[0]):
            x = (2 * xo + taps[t]) % nx
            wt = w[t]
            for i in range(R0):
                for j in range(R1):
                    acc[i, j] += wt * src[y, x, i, j]
        for i in range(R0):
            for j in range(R1):
                out[y, xo, i, j] = acc[i, j]


def filter_taps(sigma_over_stride: float) -> tuple[np.ndarray, np.ndarray]:
    """Taps ``(T,)`` (offsets in strides) and weights ``(T,)`` (summing to 1) of the periodic
    Gaussian of std ``sqrt(3) sigma_over_stride`` strides that makes level ``l + 1`` from level
    ``l``, cut at 4 stds."""
    std = math.sqrt(3.0) * sigma_over_stride
    taps = np.arange(-math.ceil(4 * std), math.ceil(4 * std) + 1)
    w = np.exp(-0.5 * (taps / std) ** 2)
    return taps, w / w.sum()


def next_level(images: np.ndarray, sigma_over_stride: float, out: np.ndarray | None = None,
               chunk: int = 8) -> np.ndarray:
    """Level ``l + 1`` images ``(ny/2, nx/2, R, R)`` from level ``l`` images ``(ny, nx, R, R)``.

    Periodic separable Gaussian filter of std ``sqrt(3) sigma_l`` (in strides:
    ``sqrt(3) * sigma_over_stride``) sampled at the even centres; weights normalised to sum 1.
    ``images`` may be a float32 memory map; ``chunk`` is unused (kept for callers).
    :func:`next_level_rows` computes the same values from the level read row by row.
    """
    ny, nx = images.shape[:2]
    if ny % 2 or nx % 2:
        raise PrefilterError(f"images: expected an even centre grid, got {ny}x{nx}")
    taps, w = filter_taps(sigma_over_stride)
    src = np.asarray(images)
    if src.dtype != np.float32:
        src = src.astype(np.float32)
    tmp = np.empty((ny, nx // 2) + images.shape[2:], dtype=np.float32)
    _decimate_axis1(src, w, taps, tmp)
    if out is None:
        out = np.zeros((ny // 2, nx // 2) + images.shape[2:], dtype=np.float32)
    res = np.empty((nx // 2, ny // 2) + images.shape[2:], dtype=np.float32)
    # the second pass filters along y through a transposed view (no copy of the images)
    _decimate_axis1(tmp.transpose(1, 0, 2, 3), w, taps, res)
    out[...] = res.transpose(1, 0, 2, 3)
    return out


@njit_parallel
def _combine_rows(rows, slots, w, out):
    """``out[x] = sum_t w[t] rows[slots[t], x]`` over images ``(..., R, R)``, accumulated in
    float64 in the order of ``t`` (the sums of :func:`_decimate_axis1`, term for term)."""
    R0, R1 = rows.shape[2], rows.shape[3]
    for x in prange(out.shape[0]):
        acc = np.zeros((R0, R1))
        for t in range(slots.shape[0]):
            wt = w[t]
            for i in range(R0):
                for j in range(R1):
                    acc[i, j] += wt * rows[slots[t], x, i, j]
        for i in range(R0):
            for j in range(R1):
                out[x, i, j] = acc[i, j]


def next_level_rows(read_row, shape: tuple[int, int], sigma_over_stride: float, write_row,
                    image_shape: tuple[int, int]) -> None:
    """:func:`next_level` streamed: the level below is read one row of centres at a time
    (``read_row(y) -> (nx, R, R)`` float32) and each output row is handed to
    ``write_row(yo, (nx/2, R, R) float32)`` in order, so memory holds the filter's window of
    x-filtered rows (``T (nx/2) R^2`` floats, ``T`` taps) instead of whole levels. The values are
    :func:`next_level`'s bit for bit (the same float64 sums in the same order).

    Parameters
    ----------
    shape : ``(ny, nx)`` centres of the level below (even).
    image_shape : ``(R, R)``.
    """
    ny, nx = shape
    if ny % 2 or nx % 2:
        raise PrefilterError(f"images: expected an even centre grid, got {ny}x{nx}")
    taps, w = filter_taps(sigma_over_stride)
    n_slots = min(len(taps), ny)
    ring = np.empty((n_slots, nx // 2) + tuple(image_shape), np.float32)
    slot_of: dict[int, int] = {}  # input row -> slot of its x-filtered images
    last_use = np.full(n_slots, -1)
    out = np.empty((nx // 2,) + tuple(image_shape), np.float32)
    for yo in range(ny // 2):
        need = [(2 * yo + int(t)) % ny for t in taps]
        for y in need:
            if y in slot_of:
                continue
            # the slot whose row is not needed now and was used longest ago
            busy = {slot_of[r] for r in need if r in slot_of}
            free = [k for k in range(n_slots) if k not in busy]
            k = min(free, key=lambda k: last_use[k])
            slot_of = {r: s for r, s in slot_of.items() if s != k}
            _decimate_axis1(np.asarray(read_row(y), np.float32)[None], w, taps,
                            ring[k:k + 1])
            slot_of[y] = k
        slots = np.array([slot_of[y] for y in need], np.int64)
        last_use[slots] = yo
        _combine_rows(ring, slots, w, out)
        write_row(yo, out)


def strip_plan(nx: int, sigma_over_stride: float, width: int) -> list[tuple[int, int, int]]:
    """Column strips of :func:`next_level_rows` on a level of ``nx`` centres per row: per strip
    ``(xo0, xo1, start)``, its output columns ``xo0 .. xo1 - 1`` of the next level and the
    first input column ``start`` (periodic) of the ``2 (xo1 - xo0 + p)`` input columns it reads,
    ``p`` the filter's reach in taps rounded up to even. Run on those columns as a level of
    their own, :func:`next_level_rows` gives the strip's outputs at its columns
    ``p / 2 .. p / 2 + xo1 - xo0 - 1`` without wrapping, the same sums term for term. One strip
    of all columns (``start`` 0) when ``width >= nx / 2``."""
    taps, _ = filter_taps(sigma_over_stride)
    reach = int(np.max(np.abs(taps)))
    p = reach + reach % 2
    half = nx // 2
    if width >= half:
        return [(0, half, 0)]
    return [(x, min(x + width, half), 2 * x - p) for x in range(0, half, width)]


def filter_matrix(n: int, sigma_over_stride: float) -> np.ndarray:
    """Weights ``(n / 2, n)`` of :func:`filter_taps` on a periodic axis of ``n`` centres:
    output ``o`` is ``sum_i W[o, i] in[i]`` (taps that wrap onto the same centre add up)."""
    taps, w = filter_taps(sigma_over_stride)
    W = np.zeros((n // 2, n))
    for o in range(n // 2):
        for t, wt in zip(taps, w):
            W[o, (2 * o + int(t)) % n] += wt
    return W


@njit_parallel
def _weighted_images(W, X, out):
    """``out[o] = sum_i W[o, i] X[i]`` over flattened images ``X (n, P)`` float32, each pixel's
    sum in float64 in the order of ``i``."""
    m, n = W.shape
    P = X.shape[1]
    nchunk = (P + 4095) // 4096
    for c in prange(nchunk):
        p0 = c * 4096
        p1 = min(P, p0 + 4096)
        acc = np.empty(p1 - p0)
        for o in range(m):
            acc[:] = 0.0
            for i in range(n):
                wi = W[o, i]
                if wi != 0.0:
                    xi = X[i, p0:p1]
                    for p in range(p1 - p0):
                        acc[p] += wi * xi[p]
            for p in range(p1 - p0):
                out[o, p0 + p] = acc[p]


@njit_parallel
def _add_rows(acc, idx, a, X):
    """``acc[idx[k]] += a X[k]`` over flattened images ``(., P)`` float32."""
    P = X.shape[1]
    nchunk = (P + 4095) // 4096
    for c in prange(nchunk):
        p0 = c * 4096
        p1 = min(P, p0 + 4096)
        for k in range(idx.shape[0]):
            row = acc[idx[k], p0:p1]
            xk = X[k, p0:p1]
            for p in range(p1 - p0):
                row[p] += a * xk[p]


@njit_serial
def _difference_norms(c, d):
    """``(sum (c - d)^2, sum c^2)`` in float64 of two float32 arrays ``(n, P)``."""
    dd = 0.0
    cc = 0.0
    for i in range(c.shape[0]):
        for p in range(c.shape[1]):
            x = np.float64(c[i, p])
            e = x - np.float64(d[i, p])
            dd += e * e
            cc += x * x
    return dd, cc


class LevelStream:
    """Level ``l + 1`` built while the images of level ``l`` arrive in any order: the scatter
    form of :func:`next_level` (the same periodic filter, decimated by 2), so a bake never holds
    or stores a whole level.

    :meth:`add` takes the images of one row of level ``l`` (all of it or a run of columns): they
    are filtered along x at once (each output image's sum in float64) and added, times their
    y weight, to the float32 accumulators of the level-``l + 1`` rows they reach; :meth:`arrived`
    marks rows of level ``l`` complete and returns the level-``l + 1`` rows that then have all
    their terms. The sums follow the order of arrival (deterministic for a fixed order; they
    equal :func:`next_level`'s up to float32 rounding). Accumulators are kept in memory while
    rows keep reaching them; :meth:`spill` moves the others to ``.npy`` files in ``spill_dir``
    (read back when a row reaches them again). The relative L2 difference between level
    ``l + 1`` and level ``l`` at the same centres (:attr:`difference`) is summed as rows complete.

    Parameters
    ----------
    shape : ``(ny, nx)`` centres of level ``l`` (even).
    image_shape : ``(R, R)``.
    """

    def __init__(self, shape: tuple[int, int], sigma_over_stride: float,
                 image_shape: tuple[int, int], spill_dir=None, name: str = "level"):
        ny, nx = (int(v) for v in shape)
        if ny % 2 or nx % 2:
            raise PrefilterError(f"images: expected an even centre grid, got {ny}x{nx}")
        self.ny, self.nx, self.image_shape = ny, nx, tuple(int(v) for v in image_shape)
        self.P = int(np.prod(self.image_shape))
        self.Wx = filter_matrix(nx, sigma_over_stride)
        Wy = filter_matrix(ny, sigma_over_stride)
        self.users = [[(int(o), float(Wy[o, y])) for o in np.flatnonzero(Wy[:, y])]
                      for y in range(ny)]
        self.left = {o: set(np.flatnonzero(Wy[o]).tolist()) for o in range(ny // 2)}
        self.spill_dir = None if spill_dir is None else Path(spill_dir)
        self.name = name
        self._mem: dict = {}  # (kind, yo) -> (nx/2, P) float32 in memory
        self._disk: set = set()  # (kind, yo) in spill files
        self._even_scale: dict = {}  # yo -> (nx/2,) float32 peaks of the float16 even images
        self._touched: set = set()
        self._norms = np.zeros(2)

    @property
    def difference(self) -> float:
        """Relative L2 difference of the completed rows of level ``l + 1`` and level ``l`` at
        their centres."""
        return math.sqrt(self._norms[0]) / max(math.sqrt(self._norms[1]), 1e-300)

    def _path(self, key) -> Path:
        return self.spill_dir / f"{self.name}-{key[0]}{key[1]}.npy"

    def _even_file(self, yo: int) -> LevelFile:
        # only the level difference reads them (a 1 % convergence test): float16 of each image
        # over its peak (relative rounding 5e-4) halves the largest spill files
        return LevelFile(self._path(("even", yo)), (1, self.nx // 2) + self.image_shape,
                         np.float16)

    def _get(self, key) -> np.ndarray:
        arr = self._mem.get(key)
        if arr is None:
            if key in self._disk:
                arr = np.load(self._path(key))
                os.remove(self._path(key))
                self._disk.discard(key)
            else:
                arr = np.zeros((self.nx // 2, self.P), np.float32)
            self._mem[key] = arr
        self._touched.add(key)
        return arr

    def _pop(self, key) -> np.ndarray:
        arr = self._get(key)
        del self._mem[key]
        self._touched.discard(key)
        return arr

    def add(self, y: int, x0: int, images: np.ndarray) -> None:
        """Images ``(k, R, R)`` of level ``l`` at row ``y``, columns ``x0 .. x0 + k - 1``."""
        X = np.ascontiguousarray(np.asarray(images, np.float32).reshape(-1, self.P))
        cols = self.Wx[:, x0:x0 + X.shape[0]]
        reach = np.flatnonzero(cols.any(axis=1))
        part = np.empty((reach.size, self.P), np.float32)
        _weighted_images(np.ascontiguousarray(cols[reach]), X, part)
        for yo, wy in self.users[y]:
            _add_rows(self._get(("acc", yo)), reach.astype(np.int64), wy, part)
        if y % 2 == 0:  # the images at level l + 1's centres (its difference to level l)
            xs = np.arange(x0 + x0 % 2, x0 + X.shape[0], 2)
            if xs.size and self.spill_dir is None:
                self._get(("even", y // 2))[xs // 2] = X[xs - x0]
            elif xs.size:  # straight to their file: read once, when the row completes
                scaled, peak = over_peaks(X[xs - x0].reshape((-1,) + self.image_shape))
                self._even_scale.setdefault(y // 2, np.ones(self.nx // 2, np.float32))[
                    xs // 2] = peak
                self._even_file(y // 2).write_columns(0, int(xs[0]) // 2, scaled)

    def arrived(self, rows) -> list[tuple[int, np.ndarray]]:
        """Mark rows of level ``l`` complete; the level-``l + 1`` rows ``(yo, (nx/2, R, R))``
        float32 that this completes, in increasing ``yo``."""
        reached = set()
        for y in rows:
            for yo, _ in self.users[int(y)]:
                self.left[yo].discard(int(y))
                reached.add(yo)
        out = []
        for yo in sorted(reached):
            if not self.left[yo] and (("acc", yo) in self._mem or ("acc", yo) in self._disk):
                c = self._pop(("acc", yo))
                if self.spill_dir is None:
                    d = self._pop(("even", yo))
                else:
                    f = self._even_file(yo)
                    d = (f.read(0, 1).reshape(c.shape).astype(np.float32)
                         * self._even_scale.pop(yo)[:, None])
                    os.remove(f.path)
                self._norms += _difference_norms(c, d)
                out.append((yo, c.reshape((self.nx // 2,) + self.image_shape)))
        return out

    def spill(self) -> None:
        """Move the accumulators no row reached since the last call to spill files."""
        if self.spill_dir is None:
            return
        for key in [k for k in self._mem if k not in self._touched]:
            np.save(self._path(key), self._mem.pop(key))
            self._disk.add(key)
        self._touched.clear()


def level_difference(prev: np.ndarray, cur: np.ndarray) -> float:
    """Relative L2 difference of level ``l`` images from level ``l - 1`` at the same centres."""
    p = np.asarray(prev[::2, ::2], dtype=np.float64)
    c = np.asarray(cur, dtype=np.float64)
    return float(np.linalg.norm(c - p) / max(np.linalg.norm(c), 1e-300))


def interp_weights(pyr: Pyramid, center, sigma_p) -> tuple[np.ndarray, np.ndarray]:
    """Trilinear interpolation: 8 flat image indices ``(..., 8)`` and weights ``(..., 8)``.

    Parameters
    ----------
    center : (..., 2) footprint centres in texels (any value; the map is periodic).
    sigma_p : (...) footprint stds in texels, clamped to ``[sigma0, sigma_top]``.
    """
    c = as_float_array(center, "center", ndim_min=1, last_dim=2)
    sp = as_float_array(sigma_p, "sigma_p")
    if np.any(sp < 0):
        raise PrefilterError(f"sigma_p: expected footprint stds >= 0, got min {sp.min()}")
    shape = np.broadcast_shapes(c.shape[:-1], sp.shape)
    c = np.broadcast_to(c, shape + (2,))
    sp = np.broadcast_to(sp, shape)
    top = pyr.n_levels - 1
    with np.errstate(divide="ignore"):
        t = np.clip(np.log2(np.maximum(sp, 1e-300) / pyr.sigma0), 0.0, float(top))
    l0 = np.minimum(np.floor(t).astype(np.int64), max(top - 1, 0))
    fl = t - l0
    if top == 0:
        fl = np.zeros_like(t)
    idx = np.empty(shape + (8,), dtype=np.int64)
    wts = np.empty(shape + (8,))
    offs = pyr.offsets
    strides = np.array([pyr.stride(lv) for lv in range(pyr.n_levels)])
    shapes = np.array([pyr.shape(lv) for lv in range(pyr.n_levels)])
    for dl in (0, 1):
        lv = np.minimum(l0 + dl, top)
        wl = fl if dl else 1.0 - fl
        st = strides[lv]
        ny, nx = shapes[lv, 0], shapes[lv, 1]
        gx = (c[..., 0] - 0.5) / st
        gy = (c[..., 1] - 0.5) / st
        x0 = np.floor(gx).astype(np.int64)
        y0 = np.floor(gy).astype(np.int64)
        fx, fy = gx - x0, gy - y0
        k = 4 * dl
        for dy in (0, 1):
            for dx in (0, 1):
                ix = (x0 + dx) % nx
                iy = (y0 + dy) % ny
                idx[..., k] = offs[lv] + iy * nx + ix
                wts[..., k] = wl * (fx if dx else 1 - fx) * (fy if dy else 1 - fy)
                k += 1
    return idx, wts


#: Gaussian resampling (:func:`resample_weights`): taps within ``RESAMPLE_TRUNCATION`` stds of the
#: resampling kernel per axis, and the smallest allowed std of the product of that kernel with a
#: tap's footprint, in strides of its level (``exp(-2 pi^2 q^2)`` aliasing: 8e-4 at 0.6).
RESAMPLE_TRUNCATION = 3.0
RESAMPLE_Q_MIN = 0.45


def resample_weights(pyr: Pyramid, center, sigma_p, *, truncation: float = RESAMPLE_TRUNCATION,
                     q_min: float = RESAMPLE_Q_MIN):
    """Gaussian-resampling weights: flat image indices ``(N, K)``, weights ``(N, K)`` (padded with
    zero weights) and ``ok (N,)``.

    The P-NDF is linear in the footprint and ``G_sigma = G_r * G_{sigma_m}`` with
    ``r^2 = sigma^2 - sigma_m^2``, so the footprint ``(c, sigma)`` is the sum over the centres
    ``c_k`` of a finer level ``m`` of ``G_r(c_k - c)``-weighted level-``m`` footprints (the
    construction of the upper levels themselves, :func:`next_level`, at any centre and std). The
    Riemann sum over the centre grid aliases like ``exp(-2 pi^2 q^2)``, ``q`` the std of the
    product ``G_r(c_k - c) G_{sigma_m}(u - c_k)`` in strides, ``q = r sigma_m / (sigma stride_m)``:
    the coarsest level with ``q >= q_min`` is used (fewest taps), with taps within
    ``truncation r`` per axis, weights normalised to sum 1. Trilinear interpolation
    (:func:`interp_weights`) instead blends 8 footprints of the wrong sizes and places, which
    moves sparse glints.

    ``ok`` is False where no level qualifies (``sigma_p`` within ``~1.25 sigma0`` of the finest
    level or below it: the caller uses the direct P-NDF there) and at or above the top level
    (converged: the clamped trilinear weights are used); rows with ``ok`` False hold the
    trilinear weights.

    Parameters
    ----------
    center : (N, 2) footprint centres in texels; sigma_p : (N,) footprint stds in texels.
    """
    c = as_float_array(center, "center", ndim_min=2, last_dim=2).reshape(-1, 2)
    sp = np.broadcast_to(as_float_array(sigma_p, "sigma_p"), c.shape[:1]).astype(np.float64)
    if np.any(sp < 0):
        raise PrefilterError(f"sigma_p: expected footprint stds >= 0, got min {sp.min()}")
    L = pyr.n_levels
    sig = np.array([pyr.sigma(lv) for lv in range(L)])
    st = np.array([pyr.stride(lv) for lv in range(L)], dtype=np.float64)
    m = np.full(sp.shape, -1, np.int64)
    top = sig[-1]
    for lv in range(L):
        with np.errstate(invalid="ignore", divide="ignore"):
            q = np.sqrt(np.maximum(1.0 - (sig[lv] / sp) ** 2, 0.0)) * sig[lv] / st[lv]
        m = np.where((sig[lv] < sp) & (q >= q_min) & (sp < top), lv, m)
    ok = m >= 0
    tidx, tw = interp_weights(pyr, c, sp)
    if not np.any(ok):
        return tidx, tw, ok
    mo = m[ok]
    co = c[ok]
    r = np.sqrt(sp[ok] ** 2 - sig[mo] ** 2)
    stm = st[mo]
    shapes = np.array([pyr.shape(lv) for lv in range(L)])
    ny, nx = shapes[mo, 0], shapes[mo, 1]
    half = truncation * r / stm
    g = (co - 0.5) / stm[:, None]
    k0 = np.ceil(g - half[:, None]).astype(np.int64)
    n = np.floor(g + half[:, None]).astype(np.int64) - k0 + 1  # (n_ok, 2) taps per axis
    kx, ky = int(n[:, 0].max()), int(n[:, 1].max())
    jx, jy = np.arange(kx), np.arange(ky)
    cx = (k0[:, :1] + jx) * stm[:, None] + 0.5
    cy = (k0[:, 1:] + jy) * stm[:, None] + 0.5
    wx = np.where(jx < n[:, :1], np.exp(-0.5 * ((cx - co[:, :1]) / r[:, None]) ** 2), 0.0)
    wy = np.where(jy < n[:, 1:], np.exp(-0.5 * ((cy - co[:, 1:]) / r[:, None]) ** 2), 0.0)
    w = (wy[:, :, None] * wx[:, None, :]).reshape(len(mo), -1)
    w /= w.sum(axis=1, keepdims=True)
    ix = (k0[:, :1] + jx) % nx[:, None]
    iy = (k0[:, 1:] + jy) % ny[:, None]
    offs = pyr.offsets
    idx_ok = (offs[mo][:, None, None] + iy[:, :, None] * nx[:, None, None]
              + ix[:, None, :]).reshape(len(mo), -1)
    K = max(8, idx_ok.shape[1])
    idx = np.zeros((len(sp), K), np.int64)
    wts = np.zeros((len(sp), K))
    idx[~ok, :8], wts[~ok, :8] = tidx[~ok], tw[~ok]
    idx[ok, :idx_ok.shape[1]], wts[ok, :idx_ok.shape[1]] = idx_ok, w
    return idx, wts, ok


def resample_min_sigma(pyr: Pyramid, q_min: float = RESAMPLE_Q_MIN) -> float:
    """Smallest footprint std that :func:`resample_weights` resamples (from level 0):
    ``sigma0 / sqrt(1 - (q_min stride0 / sigma0)^2)``; ``inf`` when level 0 never qualifies."""
    a = q_min * pyr.stride0 / pyr.sigma0
    return pyr.sigma0 / math.sqrt(1.0 - a * a) if a < 1.0 else math.inf
