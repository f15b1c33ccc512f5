"""Warps from the unit square to the sphere, and orthonormal frames.

All functions are vectorised: ``u`` has shape ``(..., 2)``, directions ``(..., 3)``.
"""

from __future__ import annotations

import numpy as np

from prefilter.validation import as_directions, as_float_array, as_uniform
from prefilter.errors import PrefilterError


def spherical_direction(theta, phi) -> np.ndarray:
    """Unit vector ``(..., 3)`` with polar angle ``theta`` from z and azimuth ``phi`` from x."""
    theta, phi = as_float_array(theta, "theta"), as_float_array(phi, "phi")
    try:
        theta, phi = np.broadcast_arrays(theta, phi)
    except ValueError:
        raise PrefilterError(f"theta, phi: shapes {theta.shape} and {phi.shape} do not "
                             "broadcast") from None
    st = np.sin(theta)
    return np.stack([st * np.cos(phi), st * np.sin(phi), np.cos(theta)], axis=-1)


def _concentric_disk(u: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Shirley-Chiu concentric map of ``u (..., 2)`` to the unit disk: returns (x, y)."""
    a = 2.0 * u[..., 0] - 1.0
    b = 2.0 * u[..., 1] - 1.0
    first = np.abs(a) > np.abs(b)
    with np.errstate(divide="ignore", invalid="ignore"):
        r = np.where(first, a, b)
        phi = np.where(first, (np.pi / 4) * b / a, np.pi / 2 - (np.pi / 4) * a / b)
    phi = np.where((a == 0) & (b == 0), 0.0, phi)
    return r * np.cos(phi), r * np.sin(phi)


def cosine_hemisphere(u) -> np.ndarray:
    """Cosine-weighted directions on the upper hemisphere, pdf ``z / pi`` (Malley's method)."""
    u = as_uniform(u, "u", last_dim=2)
    x, y = _concentric_disk(u)
    z = np.sqrt(np.maximum(0.0, 1.0 - x * x - y * y))
    return np.stack([x, y, z], axis=-1)


def cosine_hemisphere_pdf(w) -> np.ndarray:
    """Density of :func:`cosine_hemisphere` w.r.t. solid angle: ``max(0, w_z) / pi``."""
    return np.maximum(0.0, as_directions(w, "w")[..., 2]) / np.pi


def uniform_sphere(u) -> np.ndarray:
    """Uniform directions on the unit sphere, pdf ``1 / (4 pi)``."""
    u = as_uniform(u, "u", last_dim=2)
    z = 1.0 - 2.0 * u[..., 0]
    r = np.sqrt(np.maximum(0.0, 1.0 - z * z))
    phi = 2.0 * np.pi * u[..., 1]
    return np.stack([r * np.cos(phi), r * np.sin(phi), z], axis=-1)


def uniform_sphere_pdf(w) -> np.ndarray:
    """Density of :func:`uniform_sphere`, ``1 / (4 pi)``, shape ``(...)`` for ``w (..., 3)``."""
    return np.full(as_directions(w, "w").shape[:-1], 1.0 / (4.0 * np.pi))


def frame_from_normal(n) -> tuple[np.ndarray, np.ndarray]:
    """Tangent and bitangent ``(..., 3)`` completing unit normals ``n`` to a right-handed frame.

    Duff et al. 2017, "Building an orthonormal basis, revisited" (branchless, no singularity).
    """
    n = as_directions(n, "n")
    sign = np.where(n[..., 2] >= 0.0, 1.0, -1.0)
    a = -1.0 / (sign + n[..., 2])
    b = n[..., 0] * n[..., 1] * a
    t = np.stack([1.0 + sign * n[..., 0] ** 2 * a, sign * b, -sign * n[..., 0]], axis=-1)
    bt = np.stack([b, sign + n[..., 1] ** 2 * a, -n[..., 1]], axis=-1)
    return t, bt


def to_local(w, t, b, n) -> np.ndarray:
    """Coordinates of world vectors ``w`` in the frame ``(t, b, n)``, all ``(..., 3)``."""
    w, t, b, n = _frame_args(w, t, b, n)
    return np.stack([np.sum(w * t, -1), np.sum(w * b, -1), np.sum(w * n, -1)], axis=-1)


def to_world(w, t, b, n) -> np.ndarray:
    """World vectors from local coordinates ``w`` in the frame ``(t, b, n)``."""
    w, t, b, n = _frame_args(w, t, b, n)
    return w[..., 0:1] * t + w[..., 1:2] * b + w[..., 2:3] * n


def _frame_args(w, t, b, n):
    """Finite ``(..., 3)`` vectors (``w`` need not be unit: positions and vertices are fine)."""
    return tuple(as_float_array(x, name, ndim_min=1, last_dim=3)
                 for x, name in ((w, "w"), (t, "t"), (b, "b"), (n, "n")))
