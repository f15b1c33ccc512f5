"""Alignment of LTC matrices (anisotropic-LTC paper, section 5, eq. 11-12).

An LTC is unchanged when its matrix is multiplied on the right by a rotation about z or by a flip
of x and/or y (eq. 11): the clamped cosine is invariant under both. Interpolating matrices is only
meaningful between *aligned* representatives, the ones whose transformed cosine samples stay
closest to the original samples (eq. 12)::

    M' = argmin over M Rz(gamma) F of  mean_j | c_j - M' c_j / |M' c_j| |^2

Choice made here (documented in ``docs/ltc-aniso.md``): the paper searches the four flips
``F = diag(+-1, +-1, 1)``; two of them have determinant -1 and mirror ``M``. We first make
``det M > 0`` (multiplying by ``diag(1, -1, 1)`` when needed) and then search rotations only
(``diag(-1, -1, 1) = Rz(pi)`` is among them). Every aligned matrix therefore has a positive
determinant, so interpolating neighbours never crosses a singular matrix.
"""

from __future__ import annotations

import numpy as np

from prefilter.validation import as_positive_int
from prefilter.ltc.ltc import as_ltc_matrix
from prefilter.sphere.sampling import cosine_hemisphere

FLIP_Y = np.diag([1.0, -1.0, 1.0])


def rotation_z(gamma) -> np.ndarray:
    """Rotations ``(..., 3, 3)`` about z by angles ``gamma (...)`` (radians)."""
    g = np.asarray(gamma, dtype=np.float64)
    c, s = np.cos(g), np.sin(g)
    R = np.zeros(g.shape + (3, 3))
    R[..., 0, 0] = c
    R[..., 0, 1] = -s
    R[..., 1, 0] = s
    R[..., 1, 1] = c
    R[..., 2, 2] = 1.0
    return R


def cosine_points(n_side: int = 32) -> np.ndarray:
    """Deterministic cosine-distributed points ``(n_side^2, 3)`` (stratum centres, Malley)."""
    n_side = as_positive_int(n_side, "n_side", lo=2)
    x = (np.arange(n_side) + 0.5) / n_side
    u = np.stack(np.meshgrid(x, x, indexing="ij"), -1).reshape(-1, 2)
    return cosine_hemisphere(u)


def alignment_cost(M, c=None) -> np.ndarray:
    """Eq. 12's objective ``mean_j |c_j - M c_j / |M c_j||^2``; ``M (..., 3, 3)`` -> ``(...)``."""
    c = cosine_points() if c is None else np.asarray(c, dtype=np.float64)
    w = np.einsum("...ij,nj->...ni", np.asarray(M, dtype=np.float64), c)
    w /= np.linalg.norm(w, axis=-1, keepdims=True)
    return np.mean(np.sum((w - c) ** 2, axis=-1), axis=-1)


def _cost_rotated(M, gammas, c):
    """Cost of ``M Rz(gamma)`` for ``M (B, 3, 3)`` and ``gammas (B, G)`` -> ``(B, G)``."""
    # M Rz(g) c = M (Rz(g) c): rotate the (fixed) samples instead of the matrices
    cg, sg = np.cos(gammas)[..., None], np.sin(gammas)[..., None]
    rx = cg * c[:, 0] - sg * c[:, 1]
    ry = sg * c[:, 0] + cg * c[:, 1]
    rz = np.broadcast_to(c[:, 2], rx.shape)
    w = (M[:, None, :, 0, None] * rx[..., None, :] + M[:, None, :, 1, None] * ry[..., None, :]
         + M[:, None, :, 2, None] * rz[..., None, :])  # (B, G, 3, n)
    w /= np.linalg.norm(w, axis=-2, keepdims=True)
    d = sum((w[..., k, :] - c[:, k]) ** 2 for k in range(3))
    return d.mean(-1)


def align(M, *, n_side: int = 24, coarse: int = 72, chunk: int = 256) -> dict[str, np.ndarray]:
    """Aligned representatives of LTC matrices (eq. 12), with positive determinants.

    Linear search over ``gamma`` (``coarse`` angles), then two finer searches around the best
    angle (to about 0.0005 degrees), on ``n_side^2`` deterministic cosine points.

    Parameters
    ----------
    M : (..., 3, 3) invertible matrices.

    Returns
    -------
    dict with ``M`` (..., 3, 3) the aligned matrices ``M F Rz(gamma)`` (the LTCs are unchanged),
    ``gamma`` (...) and ``flipped`` (...) bool (``F = diag(1, -1, 1)`` was applied).
    """
    M = as_ltc_matrix(M)
    shape = M.shape[:-2]
    Mf = M.reshape(-1, 3, 3).copy()
    flipped = np.linalg.det(Mf) < 0
    Mf[flipped] = Mf[flipped] @ FLIP_Y
    c = cosine_points(n_side)
    gamma = np.zeros(len(Mf))
    for s in range(0, len(Mf), chunk):
        Mc = Mf[s:s + chunk]
        g = np.broadcast_to(np.linspace(0, 2 * np.pi, coarse, endpoint=False), (len(Mc), coarse))
        best = g[np.arange(len(Mc)), np.argmin(_cost_rotated(Mc, g, c), axis=1)]
        step = 2 * np.pi / coarse
        for _ in range(4):
            g = best[:, None] + np.linspace(-step, step, 21)
            best = g[np.arange(len(Mc)), np.argmin(_cost_rotated(Mc, g, c), axis=1)]
            step /= 10
        gamma[s:s + chunk] = np.mod(best, 2 * np.pi)
    out = Mf @ rotation_z(gamma)
    return {"M": out.reshape(M.shape), "gamma": gamma.reshape(shape),
            "flipped": flipped.reshape(shape)}
