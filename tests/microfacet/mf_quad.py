"""Reference quadrature and helpers shared by the microfacet tests (independent of the models)."""

from __future__ import annotations

import numpy as np

from prefilter.microfacet import GGX
from prefilter.sphere import frame_from_normal, slope_warp, to_world, warp_integral


def sphere_integral(f, axis=(0.0, 0.0, 1.0), width=0.3, n_polar=400, n_azimuth=1024):
    """Integral of ``f(w (..., 3))`` over the whole sphere.

    Polar angle psi about ``axis`` via ``tan(psi / 2) = width * tan(pi v / 2)`` (nodes cluster
    within ``~width`` radians of the axis, for narrow lobes), Gauss-Legendre in v, periodic
    trapezoid in the azimuth.
    """
    axis = np.asarray(axis, float) / np.linalg.norm(axis)
    t, b = frame_from_normal(axis)
    xg, wg = np.polynomial.legendre.leggauss(n_polar)
    v, wv = (xg + 1) / 2, wg / 2
    T = np.tan(np.pi * v / 2)
    psi = 2 * np.arctan(width * T)
    dpsi = 2 * width / (1 + (width * T) ** 2) * (np.pi / 2) * (1 + T * T)
    phi = 2 * np.pi * np.arange(n_azimuth) / n_azimuth
    P, Phi = np.meshgrid(psi, phi, indexing="ij")
    local = np.stack([np.sin(P) * np.cos(Phi), np.sin(P) * np.sin(Phi), np.cos(P)], -1)
    w = to_world(local, t, b, axis)
    vals = np.asarray(f(w), float)
    weights = (wv * dpsi * np.sin(psi))[:, None] * (2 * np.pi / n_azimuth)
    return float(np.sum(vals * weights))


def hemisphere_integral(f, wo=None, width=0.3, n_polar=300, n_azimuth=512):
    """Integral of ``f(m (..., 3))`` over ``m_z > 0`` (and ``wo.m > 0`` if ``wo`` is given).

    Polar angle psi from z with ``tan(psi / 2) = width * tan(pi v / 2)``, Gauss-Legendre in v up
    to the equator (where GGX's D jumps to 0). With ``wo``, each ring is cut to the arc where
    ``wo.m > 0`` (Gauss-Legendre on the arc) so the kink of ``max(0, wo.m)`` is on the boundary.
    """
    v_half = 2 / np.pi * np.arctan(1 / width)
    xg, wg = np.polynomial.legendre.leggauss(n_polar)
    v, wv = v_half * (xg + 1) / 2, v_half * wg / 2
    T = np.tan(np.pi * v / 2)
    psi = 2 * np.arctan(width * T)
    dpsi = 2 * width / (1 + (width * T) ** 2) * (np.pi / 2) * (1 + T * T)
    ring = wv * dpsi * np.sin(psi)
    if wo is None:
        phi = 2 * np.pi * np.arange(n_azimuth) / n_azimuth
        P, Phi = np.meshgrid(psi, phi, indexing="ij")
        wphi = np.full((n_polar, n_azimuth), 2 * np.pi / n_azimuth)
    else:
        wo = np.asarray(wo, float)
        phi_o = np.arctan2(wo[1], wo[0])
        sin_o = np.hypot(wo[0], wo[1])
        with np.errstate(divide="ignore", invalid="ignore"):
            rhs = -np.cos(psi) * wo[2] / (np.sin(psi) * sin_o)
        half = np.arccos(np.clip(np.where(np.isfinite(rhs), rhs, -1.0), -1.0, 1.0))
        xa, wa = np.polynomial.legendre.leggauss(n_azimuth)
        Phi = phi_o + half[:, None] * xa[None, :]
        P = np.broadcast_to(psi[:, None], Phi.shape)
        wphi = half[:, None] * wa[None, :]
    m = np.stack([np.sin(P) * np.cos(Phi), np.sin(P) * np.sin(Phi), np.cos(P)], -1)
    vals = np.asarray(f(m), float)
    return float(np.sum(vals * wphi * ring[:, None]))


def direction(theta_deg, phi_deg=0.0):
    th, ph = np.radians(theta_deg), np.radians(phi_deg)
    return np.array([np.sin(th) * np.cos(ph), np.sin(th) * np.sin(ph), np.cos(th)])


def normal_from_slope(s):
    """Microfacet normal of slope ``s = (-mx/mz, -my/mz)``."""
    s = np.asarray(s, float)
    m = np.concatenate([-s, np.ones(s.shape[:-1] + (1,))], -1)
    return m / np.linalg.norm(m, axis=-1, keepdims=True)


def slope_jacobian_fd(s, h=1e-6):
    """Solid angle per unit slope area, ``|dm/ds_x x dm/ds_y|``, by central differences."""
    s = np.asarray(s, float)
    ex = np.array([h, 0.0])
    ey = np.array([0.0, h])
    dx = (normal_from_slope(s + ex) - normal_from_slope(s - ex)) / (2 * h)
    dy = (normal_from_slope(s + ey) - normal_from_slope(s - ey)) / (2 * h)
    return np.linalg.norm(np.cross(dx, dy), axis=-1)


def slope_frame(model):
    """Mean slope ``(2,)`` and scale ``(2, 2)`` of ``model`` (GGX or Beckmann, scalar
    parameters) for :func:`prefilter.sphere.slope_warp`: its NDF spread over the square."""
    if isinstance(model, GGX):
        return np.zeros(2), np.diag([float(model.alpha_x), float(model.alpha_y)])
    return model.mean_slope, np.linalg.cholesky(model.slope_cov)


def reflect_warp(model, wo):
    """Chi-square bins for reflected visible normals of ``model`` seen from ``wo``: the
    (whitened) slope space of the half vector, restricted to the upper hemisphere and, for a
    tilted mean surface, to directions above it."""
    mu, scale = slope_frame(model)
    above = None
    if np.any(mu != 0.0):  # the lobe also vanishes below the mean surface
        above = np.array([-mu[0], -mu[1], 1.0]) / np.sqrt(1.0 + mu @ mu)
    return slope_warp(mu, scale, wo=wo, reflect=True, above=above)


def reflect_integral(f, model, wo):
    """Integral of ``f(wi (..., 3))`` over the whole sphere for a lobe of reflected normals of
    ``model`` seen from ``wo``: over half vectors ``h`` visible from ``wo`` (each ``wi`` is the
    reflection of one), ``d(omega_i) = 4 (wo.h) d(omega_h)``, in the slope warp of ``model``."""
    wo = np.asarray(wo, dtype=np.float64)

    def over_h(h):
        c = h @ wo
        return f(2.0 * c[..., None] * h - wo) * 4.0 * np.maximum(c, 0.0)

    # GGX's heavy tail reaches the square's edges, where the error falls only as the node
    # spacing there: 32 nodes per cell keep it below 2e-4 (1e-3 with 8)
    return warp_integral(over_h, slope_warp(*slope_frame(model), wo=wo), quad=32)
