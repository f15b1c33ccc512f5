"""Small analytic normal maps for the glints tests (built here, not from the library)."""

from __future__ import annotations

import numpy as np


def normals_from_s(sx, sy):
    return np.stack([sx, sy, np.sqrt(1.0 - sx**2 - sy**2)], axis=-1)


def sinusoid_s(u, ax=0.2, ay=0.1, px=32, py=16):
    """The analytic field ``s(u) = (ax sin(2 pi x / px), ay cos(2 pi y / py))``, ``u (..., 2)``."""
    return np.stack([ax * np.sin(2 * np.pi * u[..., 0] / px),
                     ay * np.cos(2 * np.pi * u[..., 1] / py)], axis=-1)


def sinusoid(size=64, ax=0.2, ay=0.1, px=32, py=16):
    """Normal map sampling :func:`sinusoid_s` at the texel centres ``i + 0.5`` (periodic)."""
    x = np.arange(size) + 0.5
    X, Y = np.meshgrid(x, x)
    return normals_from_s(ax * np.sin(2 * np.pi * X / px), ay * np.cos(2 * np.pi * Y / py))


def gaussian_heightfield(size=128, corr=4.0, slope_std=0.15, seed=0):
    """Normals of a periodic Gaussian random heightfield (Gaussian spectrum, spectral slopes).

    Returns the normal map and the empirical slope covariance ``(2, 2)`` of its texels.
    """
    rng = np.random.default_rng(seed)
    k = 2 * np.pi * np.fft.fftfreq(size)
    KX, KY = np.meshgrid(k, k)
    spec = np.exp(-(KX**2 + KY**2) * corr**2 / 4) * np.fft.fft2(rng.standard_normal((size, size)))
    hx = np.real(np.fft.ifft2(1j * KX * spec))
    hy = np.real(np.fft.ifft2(1j * KY * spec))
    scale = slope_std / np.sqrt(0.5 * (hx.var() + hy.var()))
    hx, hy = hx * scale, hy * scale
    n = np.stack([-hx, -hy, np.ones_like(hx)], axis=-1)
    n /= np.linalg.norm(n, axis=-1, keepdims=True)
    slopes = np.stack([hx.ravel(), hy.ravel()])
    return n, np.cov(slopes)


def bilinear_s(normal_map, u):
    """Bilinearly interpolated projected normals at positions ``u (n, 2)`` (periodic)."""
    H, W = normal_map.shape[:2]
    s = normal_map[..., :2]
    g = u - 0.5  # texel centres sit at i + 0.5
    x0 = np.floor(g[:, 0]).astype(int)
    y0 = np.floor(g[:, 1]).astype(int)
    fx = (g[:, 0] - x0)[:, None]
    fy = (g[:, 1] - y0)[:, None]
    x0, y0 = x0 % W, y0 % H
    x1, y1 = (x0 + 1) % W, (y0 + 1) % H
    return ((1 - fy) * ((1 - fx) * s[y0, x0] + fx * s[y0, x1])
            + fy * ((1 - fx) * s[y1, x0] + fx * s[y1, x1]))
