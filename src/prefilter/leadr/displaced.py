"""Ground truth for LEADR: the displaced microsurface itself, by exact height-field ray marching.

The surface is the bilinear interpolation ``z = h(x, y)`` of a periodic height grid (texel
units, texel ``(i, j)`` at ``x = j, y = i``). Its slopes are the bilinear patches' gradients, whose
moments over a cell are closed-form, so LEADR statistics of any block of cells are exact
(:func:`block_moments`; moments are linear, so a block is the box average of its cells).

:func:`displaced_radiance` averages, over parallel view rays through a uniform grid of points of a
block of the mean plane (radiance per projected area, as LEADR defines it), the radiance of the
first hit lit by a directional light, with a shadow ray: masking and shadowing come from the
geometry. :func:`normal_mapped_radiance` shades the same block's normals without geometry, and
:func:`naive_radiance` shades the block's single mip-averaged normal. Own Numba ray marcher (no
external ray tracer is installed; a height field needs none).
"""

from __future__ import annotations

import numpy as np
from numba import njit

from prefilter._numba import njit_parallel, prange
from prefilter._validate import as_directions, as_float_array, as_positive_int
from prefilter.errors import PrefilterError
from prefilter.microfacet import Beckmann


@njit_parallel
def _march(h, ox, oy, oz, dx, dy, dz, hmin, hmax, step, max_steps):  # pragma: no cover
    """Parameter ``t >= 0`` of the first hit of rays ``o + t d`` with the bilinear height field,
    ``inf`` if the ray leaves the slab ``[hmin, hmax]`` first (fixed steps, then bisection)."""
    n = ox.size
    ny, nx = h.shape
    out = np.empty(n)
    for r in prange(n):
        res = np.inf
        if oz[r] - _bilerp(h, ox[r], oy[r], ny, nx) <= 0.0:
            res = 0.0
        else:
            t0 = 0.0
            for _ in range(max_steps):
                t1 = t0 + step
                z1 = oz[r] + t1 * dz[r]
                f1 = z1 - _bilerp(h, ox[r] + t1 * dx[r], oy[r] + t1 * dy[r], ny, nx)
                if f1 <= 0.0:
                    a, b = t0, t1
                    for _k in range(40):
                        m = 0.5 * (a + b)
                        fm = oz[r] + m * dz[r] - _bilerp(h, ox[r] + m * dx[r],
                                                         oy[r] + m * dy[r], ny, nx)
                        if fm > 0.0:
                            a = m
                        else:
                            b = m
                    res = 0.5 * (a + b)
                    break
                if (dz[r] < 0.0 and z1 < hmin) or (dz[r] > 0.0 and z1 > hmax):
                    break
                t0 = t1
        out[r] = res
    return out


@njit(fastmath=True, cache=True)
def _bilerp(h, x, y, ny, nx):  # pragma: no cover - compiled
    fx = np.floor(x)
    fy = np.floor(y)
    tx = x - fx
    ty = y - fy
    j0 = int(fx) % nx
    i0 = int(fy) % ny
    j1 = (j0 + 1) % nx
    i1 = (i0 + 1) % ny
    return ((h[i0, j0] * (1 - tx) + h[i0, j1] * tx) * (1 - ty)
            + (h[i1, j0] * (1 - tx) + h[i1, j1] * tx) * ty)


def _gradient(h, x, y):
    """Bilinear gradient ``(..., 2)`` at points ``x, y`` (periodic)."""
    ny, nx = h.shape
    fx, fy = np.floor(x), np.floor(y)
    tx, ty = x - fx, y - fy
    j0, i0 = fx.astype(np.int64) % nx, fy.astype(np.int64) % ny
    j1, i1 = (j0 + 1) % nx, (i0 + 1) % ny
    h00, h01, h10, h11 = h[i0, j0], h[i0, j1], h[i1, j0], h[i1, j1]
    sx = (h01 - h00) * (1 - ty) + (h11 - h10) * ty
    sy = (h10 - h00) * (1 - tx) + (h11 - h01) * tx
    return np.stack([sx, sy], -1)


def cell_moments(height) -> np.ndarray:
    """Exact slope moments ``(H, W, 5)`` of each bilinear cell (cell ``(i, j)`` spans texels
    ``i..i+1, j..j+1``): ``sx = a (1 - y) + b y``, ``sy = c (1 - x) + d x`` give
    ``E[sx^2] = (a^2 + ab + b^2) / 3``, ``E[sx sy] = (a + b)(c + d) / 4``."""
    h = as_float_array(height, "height", ndim_min=2)
    r = lambda a, k, ax: np.roll(a, -k, axis=ax)  # noqa: E731
    a = r(h, 1, 1) - h
    b = r(a, 1, 0)
    c = r(h, 1, 0) - h
    d = r(c, 1, 1)
    return np.stack([(a + b) / 2, (c + d) / 2, (a * a + a * b + b * b) / 3,
                     (c * c + c * d + d * d) / 3, (a + b) * (c + d) / 4], -1)


def block_moments(height, block: int) -> np.ndarray:
    """Moments ``(H / block, W / block, 5)`` of aligned ``block x block`` cell blocks."""
    m = cell_moments(height)
    hh, ww = m.shape[:2]
    if hh % block or ww % block:
        raise PrefilterError(
            f"block: expected a divisor of the map size {m.shape[:2]}, got {block}")
    return m.reshape(hh // block, block, ww // block, block, 5).mean(axis=(1, 3))


def _block_points(i0: int, j0: int, block: int, k: int):
    """``k x k`` stratified-centre points of the block whose first cell is ``(i0, j0)``."""
    u = (np.arange(k) + 0.5) / k * block
    y, x = np.meshgrid(i0 + u, j0 + u, indexing="ij")
    return x.ravel(), y.ravel()


def _micro(wo, wi, n, sigma_b, albedo, specular):
    """Cosine-weighted micro BRDF at unit normals ``n (N, 3)``: Lambert or isotropic centred
    Beckmann of slope std ``sigma_b`` around ``n`` (both directions expressed in n's frame)."""
    if not specular:
        return albedo / np.pi * np.maximum(np.sum(n * wi, -1), 0.0) * (np.sum(n * wo, -1) > 0)
    t = np.cross(n, np.array([0.0, 1.0, 0.0]))
    t /= np.linalg.norm(t, axis=-1, keepdims=True)
    b = np.cross(n, t)
    loc = lambda w: np.stack([np.sum(w * t, -1), np.sum(w * b, -1), np.sum(w * n, -1)], -1)  # noqa
    lo, li = loc(np.broadcast_to(wo, n.shape)), loc(np.broadcast_to(wi, n.shape))
    ok = (lo[:, 2] > 1e-9) & (li[:, 2] > 1e-9)
    val = np.zeros(len(n))
    if np.any(ok):
        model = Beckmann.isotropic(np.sqrt(2.0) * sigma_b)
        val[ok] = model.eval(lo[ok], li[ok])
    return val


def _normals(s):
    n = np.concatenate([-s, np.ones(s.shape[:-1] + (1,))], -1)
    return n / np.linalg.norm(n, axis=-1, keepdims=True)


def displaced_radiance(height, block: int, i0: int, j0: int, wo, wi, *, k: int = 64,
                       sigma_b: float = 0.1, albedo: float = 1.0, specular: bool = True,
                       shadowing: bool = True, step: float = 0.1) -> float:
    """Radiance towards ``wo`` of a block of the displaced surface under a unit directional
    light from ``wi`` (per projected area of the block, ``k x k`` parallel view rays)."""
    h = np.ascontiguousarray(as_float_array(height, "height", ndim_min=2))
    wo = as_directions(wo, "wo")
    wi = as_directions(wi, "wi")
    if wo[2] <= 0.05:
        raise PrefilterError(f"wo: expected a view above the mean plane (z > 0.05), got {wo}")
    k = as_positive_int(k, "k")
    x, y = _block_points(i0, j0, block, k)
    hmax, hmin = float(h.max()), float(h.min())
    # Start each ray above every height, on the line through the mean-plane point along wo.
    t_up = (hmax + 1e-6) / wo[2]
    ox, oy, oz = x + t_up * wo[0], y + t_up * wo[1], np.full(x.shape, hmax + 1e-6)
    d = -wo
    dn = step / max(np.hypot(d[0], d[1]), abs(d[2]))
    max_steps = int(4 * (h.shape[0] + h.shape[1]) / step) + 16
    t = _march(h, ox, oy, oz, np.full(x.shape, d[0]), np.full(x.shape, d[1]),
               np.full(x.shape, d[2]), hmin, hmax + 1e-3, dn, max_steps)
    hit = np.isfinite(t)
    px, py, pz = ox + t * d[0], oy + t * d[1], oz + t * d[2]
    n = _normals(_gradient(h, px, py))
    val = _micro(wo, wi, n, sigma_b, albedo, specular)
    if shadowing:
        lit = np.ones(x.shape, bool)
        cand = hit & (val > 0)
        if np.any(cand) and wi[2] > 0.0:
            eps = 1e-4
            sx, sy, sz = px[cand] + eps * wi[0], py[cand] + eps * wi[1], pz[cand] + eps * wi[2]
            dn_i = step / max(np.hypot(wi[0], wi[1]), abs(wi[2]))
            ts = _march(h, sx, sy, sz, np.full(sx.shape, wi[0]), np.full(sx.shape, wi[1]),
                        np.full(sx.shape, wi[2]), hmin - 1.0, hmax, dn_i, max_steps)
            lit[cand] = ~np.isfinite(ts)
        val = val * lit
    return float(np.mean(np.where(hit, val, 0.0)))


def normal_mapped_radiance(height, block: int, i0: int, j0: int, wo, wi, *, k: int = 64,
                           sigma_b: float = 0.1, albedo: float = 1.0,
                           specular: bool = True) -> float:
    """The same block shaded by its normals on the flat mean plane (no masking or shadowing by
    the geometry), averaged uniformly over the block."""
    h = as_float_array(height, "height", ndim_min=2)
    x, y = _block_points(i0, j0, block, k)
    n = _normals(_gradient(h, x, y))
    return float(np.mean(_micro(as_directions(wo, "wo"), as_directions(wi, "wi"), n, sigma_b,
                                albedo, specular)))


def naive_radiance(height, block: int, i0: int, j0: int, wo, wi, *, k: int = 64,
                   sigma_b: float = 0.1, albedo: float = 1.0, specular: bool = True) -> float:
    """Naive mip-mapped normal mapping: one normal, the normalised block average of the normals,
    with the micro roughness only."""
    h = as_float_array(height, "height", ndim_min=2)
    x, y = _block_points(i0, j0, block, k)
    nbar = _normals(_gradient(h, x, y)).mean(axis=0)
    nbar /= np.linalg.norm(nbar)
    return float(_micro(as_directions(wo, "wo"), as_directions(wi, "wi"), nbar[None], sigma_b,
                        albedo, specular)[0])
