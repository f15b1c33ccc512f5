"""Linearly transformed cosines (Heitz, Dupuy, Hill, Neubelt 2016, eqs. 1-3).

A distribution on the sphere obtained by transforming the clamped cosine ``Do(w) = max(0, w_z)/pi``
by a 3x3 matrix ``M``: ``D(w) = Do(w') |det M^-1| / |M^-1 w|^3`` with ``w' = M^-1 w / |M^-1 w|``.
"""

from __future__ import annotations

import numpy as np

from prefilter.validation import as_directions, as_float_array, as_uniform
from prefilter.errors import PrefilterError
from prefilter.sphere.sampling import cosine_hemisphere


def as_ltc_matrix(M, name: str = "M", *, max_cond: float = 1e8) -> np.ndarray:
    """Validated LTC matrices ``(..., 3, 3)``: finite and invertible (condition < ``max_cond``)."""
    M = as_float_array(M, name, ndim_min=2)
    if M.shape[-2:] != (3, 3):
        raise PrefilterError(f"{name}: expected shape (..., 3, 3), got {M.shape}")
    cond = np.linalg.cond(M.reshape(-1, 3, 3)) if M.size else np.zeros(0)
    if np.any(~np.isfinite(cond) | (cond > max_cond)):
        worst = float(np.nanmax(np.where(np.isfinite(cond), cond, np.inf)))
        raise PrefilterError(
            f"{name}: expected invertible matrices, got condition number {worst:.3g}")
    return M


class LTC:
    """A linearly transformed cosine with matrix ``M (..., 3, 3)`` (batched)."""

    def __init__(self, M):
        self.M = as_ltc_matrix(M)
        self.M_inv = np.linalg.inv(self.M)
        self.det_inv = np.abs(np.linalg.det(self.M_inv))

    def __repr__(self) -> str:
        return f"LTC(M={self.M!r})"

    def eval(self, w) -> np.ndarray:
        """Density ``D(w)`` w.r.t. solid angle for unit directions ``w (..., 3)``."""
        w = as_directions(w, "w")
        lw = np.einsum("...ij,...j->...i", self.M_inv, w)
        length = np.linalg.norm(lw, axis=-1)
        cos = np.maximum(0.0, lw[..., 2] / length)
        return cos / np.pi * self.det_inv / length**3

    pdf = eval  # sampling is exact, so the sampling density is the distribution itself

    def sample(self, u) -> np.ndarray:
        """Directions ``(..., 3)`` distributed as :meth:`eval`, from uniforms ``u (..., 2)``."""
        u = as_uniform(u, "u", last_dim=2)
        c = cosine_hemisphere(u)
        w = np.einsum("...ij,...j->...i", self.M, c)
        return w / np.linalg.norm(w, axis=-1, keepdims=True)
