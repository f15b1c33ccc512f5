"""Compiled per-pixel shading of colour-mapped textures, noise and heights (Numba).

The same computations as the NumPy path (:mod:`prefilter.colormap.texture`,
:func:`prefilter.colormap.height.filter_height_footprint`), fused per pixel as a shader would run
them: footprint axes, anisotropic trilinear fetches of a mip chain (as
:meth:`prefilter.texture.mip.MipChain.lookup_footprint`, with :mod:`prefilter.texture.fetch`),
then one table lookup (:func:`prefilter.colormap.table.lookup_one`, as
:meth:`~prefilter.colormap.table.ColormapTable.lookup`). Each method reads
only what it needs (naive: the one-channel mean mip and row 0 of the table; filtered: the moments
mip and the 2D table), so their time ratio is the cost of filtering
(``benchmarks/bench_colormap.py``).
The tests check these kernels against the NumPy path and brute-force footprint averages.
"""

from __future__ import annotations

import math

import numpy as np

from prefilter.colormap.table import kernel_args, lookup_one
from prefilter.jit import njit_parallel, njit_serial, prange
from prefilter.microfacet.beckmann import beckmann_lambda_jit
from prefilter.validation import as_float_array, as_positive_int
from prefilter.errors import PrefilterError
from prefilter.texture.fetch import WRAP, bilinear_add, footprint_axes_jit, trilinear_add
from prefilter.texture.mip import MipChain

__all__ = ["PackedChain", "shade_height", "shade_noise", "shade_texture"]


class PackedChain:
    """A :class:`MipChain` flattened for the kernels (:attr:`MipChain.packed`):
    ``data (total, C)``, per-level ``offsets``, ``heights``, ``widths``."""

    def __init__(self, chain: MipChain):
        if not isinstance(chain, MipChain):
            raise PrefilterError(f"chain: expected a MipChain, got {type(chain).__name__}")
        self.channels = chain.shape[2]
        self.data, self.offsets, self.heights, self.widths = chain.packed


@njit_serial
def _fetch(data, offs, hs, ws, u, v, j00, j01, j10, j11, aniso, max_aniso, c, out,
           ivar):  # pragma: no cover - compiled
    """Footprint lookup (isotropic or anisotropic, as ``MipChain.lookup_footprint``) into
    ``out[:c]``; returns the LOD used and the area LOD ``log2(sqrt(major minor))``. With ``ivar``
    (two-channel moments) and LOD < 1, ``ivar[0]`` receives the level-0 interpolation variance
    averaged over the taps (``texture.footprint_stats``)."""
    w = ws[0]
    h = hs[0]
    major, minor, dx, dy = footprint_axes_jit(h, w, j00, j01, j10, j11)
    for k in range(c):
        out[k] = 0.0
    area_lod = 0.5 * math.log2(max(major * minor, 1.0))
    taps = 1
    au = 0.0
    av = 0.0
    if aniso:
        if minor > 0:
            taps = int(min(max(math.ceil(major / minor), 1.0), max_aniso))
        else:
            taps = max_aniso
        lod = math.log2(max(max(minor, major / max_aniso), 1.0))
        au = dx * major / w
        av = dy * major / h
    else:
        lod = math.log2(max(major, 1.0))
    want = ivar.shape[0] > 0 and lod < 1.0
    if want:
        ivar[0] = 0.0
    t = max(lod, 0.0) if offs.shape[0] > 1 else 0.0
    for i in range(taps):
        o = (i + 0.5) / taps - 0.5 if aniso else 0.0
        if not want:
            trilinear_add(data, offs, hs, ws, u + o * au, v + o * av, lod, c, 1.0 / taps, WRAP,
                          out)
            continue
        # the trilinear lookup by hand, keeping the unweighted level-0 moments of the tap
        ivar[1] = 0.0
        ivar[2] = 0.0
        bilinear_add(data, offs[0], hs[0], ws[0], u + o * au, v + o * av, 2, 1.0, WRAP,
                     ivar[1:3])
        out[0] += (1.0 - t) / taps * ivar[1]
        out[1] += (1.0 - t) / taps * ivar[2]
        if t > 0.0:
            bilinear_add(data, offs[1], hs[1], ws[1], u + o * au, v + o * av, 2, t / taps, WRAP,
                         out)
        ivar[0] += (ivar[2] - ivar[1] * ivar[1]) / taps
    return lod, area_lod


@njit_parallel
def _texture_kernel(data, offs, hs, ws, uv, dudv, table, lo, hi, smax, edge, filtered, aniso,
                    max_aniso, scratch, out):  # pragma: no cover - compiled
    for p in prange(uv.shape[0]):
        m = scratch[p, 0:2]  # views of preallocated rows: no allocation per pixel
        iv = scratch[p, 2:5] if filtered else scratch[p, 2:2]
        c = 2 if filtered else 1
        lod, _ = _fetch(data, offs, hs, ws, uv[p, 0], uv[p, 1], dudv[p, 0, 0], dudv[p, 0, 1],
                        dudv[p, 1, 0], dudv[p, 1, 1], aniso, max_aniso, c, m, iv)
        sigma = -1.0
        if filtered:
            var = m[1] - m[0] * m[0]
            if lod < 1.0:  # magnification correction (texture.footprint_stats)
                var -= (1.0 - max(lod, 0.0)) * iv[0]
            sigma = math.sqrt(max(var, 0.0))
        lookup_one(table, lo, hi, smax, edge, m[0], sigma, out[p])


@njit_parallel
def _noise_kernel(data, offs, hs, ws, uv, dudv, std_var, table, lo, hi, smax, edge, filtered,
                  max_aniso, scratch, out):  # pragma: no cover - compiled
    nl = std_var.shape[0]
    for p in prange(uv.shape[0]):
        m = scratch[p, 0:1]
        _, area_lod = _fetch(data, offs, hs, ws, uv[p, 0], uv[p, 1], dudv[p, 0, 0],
                             dudv[p, 0, 1], dudv[p, 1, 0], dudv[p, 1, 1], True, max_aniso, 1, m,
                             scratch[p, 1:1])
        sigma = -1.0
        if filtered:
            t = min(max(area_lod, 0.0), nl - 1.0)
            l0 = min(int(t), nl - 2) if nl > 1 else 0
            f = t - l0
            v = std_var[l0] * (1 - f) + std_var[min(l0 + 1, nl - 1)] * f
            sigma = math.sqrt(max(v, 0.0))
        lookup_one(table, lo, hi, smax, edge, m[0], sigma, out[p])


_INV_SQRT_2PI = 0.3989422804014327


@njit_serial
def _lambda(wx, wy, wz, cxx, cxy, cyy):  # pragma: no cover - compiled
    """Smith Lambda of a centred Gaussian surface (Heitz et al. 2013, eq. 3) for ``w`` with
    ``w_z > 0``: ``a = cot(theta) / (sqrt(2) sigma_s)``."""
    r = math.sqrt(wx * wx + wy * wy)
    if r <= 0.0:
        return 0.0
    cx, cy = wx / r, wy / r
    s = math.sqrt(cxx * cx * cx + 2 * cxy * cx * cy + cyy * cy * cy)
    return beckmann_lambda_jit(wz / r / (s * math.sqrt(2.0)))


@njit_serial
def _log_cdf(z):  # pragma: no cover - compiled
    if z > -30.0:
        return math.log(0.5 * math.erfc(-z / math.sqrt(2.0)))
    return -0.5 * z * z - math.log(-z) - 0.5 * math.log(2 * math.pi)


@njit_serial
def _mills(z):  # pragma: no cover - compiled
    if z > -30.0:
        return _INV_SQRT_2PI * math.exp(-0.5 * z * z) / (0.5 * math.erfc(-z / math.sqrt(2.0)))
    return -z - 1.0 / z


# log2 of the mantissa on 1024 intervals: a float's exponent bits plus one lerp give log2 to
# 2e-7, enough to place L on the probit grid (spacing 0.17 in log2) without a libm log, which
# cost as much as the rest of the skew-normal terms
_LOG2_M = np.log2(1.0 + np.arange(1025) / 1024.0)


@njit_serial
def _log2_fast(x, tab):  # pragma: no cover - compiled
    """``log2(x)`` for normal ``x > 0`` (|error| < 2e-7)."""
    b = np.float64(x).view(np.int64)
    e = (b >> 52) - 1023
    i = (b >> 42) & 1023  # the top 10 mantissa bits select the interval
    f = (b & ((1 << 42) - 1)) * (1.0 / (1 << 42))
    return e + tab[i] + f * (tab[i + 1] - tab[i])


@njit_serial
def _probit(lam, t0, inv_dt, kappa, dd, tab):  # pragma: no cover - compiled
    """Probit ``(kappa_L, d_L)`` of ``P_h^L`` (height.py), linear in ``log L`` on its grid
    (``x = log2(L) inv_dt - t0`` in grid steps)."""
    if lam < 1e-4:  # == exp(grid[0]): no tilt below the table
        return 0.0, 40.0
    n = kappa.shape[0]
    x = _log2_fast(lam, tab) * inv_dt - t0
    i = min(max(int(x), 0), n - 2)
    f = min(max(x - i, 0.0), 1.0)
    return kappa[i] + f * (kappa[i + 1] - kappa[i]), dd[i] + f * (dd[i + 1] - dd[i])


# Phi and the Mills ratio M = phi / Phi on [-3, 8] as cubic Hermite pieces (Phi' = phi,
# M' = -M (z + M)): one 64-byte row of Horner coefficients per interval, error < 1e-8
_Z_LO, _Z_HI, _Z_STEP = -3.0, 8.0, 1.0 / 32


def _hermite_rows():
    """Horner coefficients ``(n, 8)`` in ``t = (z - z_i) / step`` of the cubic Hermite
    interpolants of ``Phi`` (columns 0-3) and ``M`` (4-7) on each interval."""
    from scipy.special import log_ndtr, ndtr
    z = np.arange(_Z_LO, _Z_HI + 0.5 * _Z_STEP, _Z_STEP)
    phi = np.exp(-0.5 * z * z) * _INV_SQRT_2PI
    big = ndtr(z)
    mills = np.exp(-0.5 * z * z - log_ndtr(z)) * _INV_SQRT_2PI
    dmills = -mills * (z + mills)
    rows = np.empty((z.size - 1, 8))
    for col, (y, dy) in enumerate(((big, phi), (mills, dmills))):
        y0, y1 = y[:-1], y[1:]
        m0, m1 = dy[:-1] * _Z_STEP, dy[1:] * _Z_STEP
        d = y1 - y0
        rows[:, 4 * col] = y0
        rows[:, 4 * col + 1] = m0
        rows[:, 4 * col + 2] = 3 * d - 2 * m0 - m1
        rows[:, 4 * col + 3] = m0 + m1 - 2 * d
    return rows


_HERMITE = _hermite_rows()


@njit_serial
def _phi_mills(z, rows):  # pragma: no cover - compiled
    """``(Phi(z), phi(z) / Phi(z))`` for ``z >= -3``."""
    t = (z - _Z_LO) * (1.0 / _Z_STEP)
    if t >= rows.shape[0]:
        return 1.0, 0.0
    i = int(t)
    t -= i
    return (rows[i, 0] + t * (rows[i, 1] + t * (rows[i, 2] + t * rows[i, 3])),
            rows[i, 4] + t * (rows[i, 5] + t * (rows[i, 6] + t * rows[i, 7])))


@njit_serial
def _phi_cdf(z, rows):  # pragma: no cover - compiled
    t = (z - _Z_LO) * (1.0 / _Z_STEP)
    if t >= rows.shape[0]:
        return 1.0
    i = int(t)
    t -= i
    return rows[i, 0] + t * (rows[i, 1] + t * (rows[i, 2] + t * rows[i, 3]))


@njit_parallel
def _height_kernel(data, offs, hs, ws, uv, dudv, wo, wi, cov, sigma_h, grid, kappa, dd, l2tab,
                   rows, table, lo, hi, smax, edge, filtered, max_aniso, scratch,
                   out):  # pragma: no cover - compiled
    cxx, cxy, cyy = cov[0, 0], cov[0, 1], cov[1, 1]
    inv_sh = 1.0 / sigma_h
    inv_sh2 = inv_sh * inv_sh
    # position on the probit grid (step dt in log L) from log2: x = log2(L) inv_dt - t0
    inv_dt = math.log(2.0) / (grid[1] - grid[0])
    t0 = grid[0] / (grid[1] - grid[0])
    for p in prange(uv.shape[0]):
        lam_o = _lambda(wo[p, 0], wo[p, 1], wo[p, 2], cxx, cxy, cyy)
        lam_i = _lambda(wi[p, 0], wi[p, 1], wi[p, 2], cxx, cxy, cyy)
        m = scratch[p, 0:2]
        iv = scratch[p, 2:5] if filtered else scratch[p, 2:2]
        c = 2 if filtered else 1
        lod, _ = _fetch(data, offs, hs, ws, uv[p, 0], uv[p, 1], dudv[p, 0, 0], dudv[p, 0, 1],
                        dudv[p, 1, 0], dudv[p, 1, 1], True, max_aniso, c, m, iv)
        if not filtered:
            lookup_one(table, lo, hi, smax, edge, m[0], -1.0, out[p])
            vb = (1.0 + lam_o) / (1.0 + lam_o + lam_i)
            for k in range(out.shape[1]):
                out[p, k] *= vb
            continue
        var = m[1] - m[0] * m[0]
        if lod < 1.0:
            var -= (1.0 - max(lod, 0.0)) * iv[0]
        x = m[0] * inv_sh
        v = max(var, 0.0) * inv_sh2
        k1, d1 = _probit(lam_o + lam_i, t0, inv_dt, kappa, dd, l2tab)
        ir1 = 1.0 / math.sqrt(1.0 + k1 * k1 * v)
        z1 = (k1 * x + d1) * ir1
        k0, d0 = _probit(lam_o, t0, inv_dt, kappa, dd, l2tab)
        z0 = (k0 * x + d0) / math.sqrt(1.0 + k0 * k0 * v)
        if z1 > -3.0 and z0 > -3.0:  # the usual case: tabulated Phi and Mills ratio
            cdf1, lz = _phi_mills(z1, rows)
            vb = cdf1 / _phi_cdf(z0, rows)
        else:  # deep shadow: log-space tails
            lz = _mills(z1)
            vb = math.exp(_log_cdf(z1) - _log_cdf(z0))
        a = k1 * v * ir1
        mean = x + a * lz
        vv = max(v - a * a * lz * (z1 + lz), 0.0)
        lookup_one(table, lo, hi, smax, edge, mean * sigma_h, math.sqrt(vv) * sigma_h, out[p])
        for k in range(out.shape[1]):
            out[p, k] *= vb


def _flat(uv, dudv):
    uv = as_float_array(uv, "uv", ndim_min=1, last_dim=2)
    j = as_float_array(dudv, "dudv", ndim_min=2)
    if j.shape[-2:] != (2, 2) or j.shape[:-2] != uv.shape[:-1]:
        raise PrefilterError(f"dudv: expected shape {uv.shape[:-1] + (2, 2)}, got {j.shape}")
    return uv.shape[:-1], np.ascontiguousarray(uv.reshape(-1, 2)), \
        np.ascontiguousarray(j.reshape(-1, 2, 2))


def shade_texture(table, chain: PackedChain, uv, dudv, *, filtered: bool = True,
                  anisotropic: bool = True, max_aniso: int = 8) -> np.ndarray:
    """Colour-mapped tabulated texture (section 4.2), ``(..., C)``.

    ``chain``: packed moments chain (``E[f], E[f^2]``) for ``filtered``; for the naive method the
    packed one-channel mean chain (only its first channel is read either way)."""
    shape, uvf, jf = _flat(uv, dudv)
    if filtered and chain.channels != 2:
        raise PrefilterError("chain: the filtered method needs the two-channel moments chain")
    out = np.zeros((uvf.shape[0], table.table.shape[2]))
    _texture_kernel(chain.data, chain.offsets, chain.heights, chain.widths, uvf, jf,
                    *kernel_args(table), bool(filtered), bool(anisotropic),
                    as_positive_int(max_aniso, "max_aniso"), np.empty((uvf.shape[0], 5)), out)
    return out.reshape(shape + (out.shape[1],))


def shade_noise(table, chain: PackedChain, noise_std, uv, dudv, *, filtered: bool = True,
                max_aniso: int = 8) -> np.ndarray:
    """Colour-mapped procedural noise (section 4.2; anisotropic mean, std at the area LOD, as
    :func:`prefilter.colormap.texture.filter_noise`), ``(..., C)``."""
    shape, uvf, jf = _flat(uv, dudv)
    out = np.zeros((uvf.shape[0], table.table.shape[2]))
    _noise_kernel(chain.data, chain.offsets, chain.heights, chain.widths, uvf, jf,
                  np.ascontiguousarray(noise_std.variance, dtype=np.float64),
                  *kernel_args(table), bool(filtered), as_positive_int(max_aniso, "max_aniso"),
                  np.empty((uvf.shape[0], 5)), out)
    return out.reshape(shape + (out.shape[1],))


def shade_height(table, chain: PackedChain, uv, dudv, wo, wi, slope_cov, sigma_h=1.0, *,
                 filtered: bool = True, max_aniso: int = 8) -> np.ndarray:
    """Height-correlated colour over footprints (eq. 14 with
    :func:`prefilter.colormap.height.height_footprint`; naive: ``V_bar C(mean)``), ``(..., C)``.
    ``wo``, ``wi``: tangent-frame view and light directions ``(..., 3)`` (z > 0)."""
    from prefilter.colormap.height import _PROBIT_T, _probit_table

    shape, uvf, jf = _flat(uv, dudv)
    wo = np.ascontiguousarray(as_float_array(wo, "wo", last_dim=3).reshape(-1, 3))
    wi = np.ascontiguousarray(as_float_array(wi, "wi", last_dim=3).reshape(-1, 3))
    if np.any(wo[:, 2] <= 0) or np.any(wi[:, 2] <= 0):
        raise PrefilterError("wo, wi: expected directions above the surface (z > 0)")
    cov = as_float_array(slope_cov, "slope_cov")
    cov = cov * np.eye(2) if cov.ndim == 0 else cov
    kappa, dd = _probit_table()
    out = np.zeros((uvf.shape[0], table.table.shape[2]))
    _height_kernel(chain.data, chain.offsets, chain.heights, chain.widths, uvf, jf, wo, wi,
                   np.ascontiguousarray(cov), float(sigma_h), _PROBIT_T, np.asarray(kappa),
                   np.asarray(dd), _LOG2_M, _HERMITE, *kernel_args(table), bool(filtered),
                   as_positive_int(max_aniso, "max_aniso"), np.empty((uvf.shape[0], 5)), out)
    return out.reshape(shape + (out.shape[1],))
