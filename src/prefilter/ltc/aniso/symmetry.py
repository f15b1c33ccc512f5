"""Symmetries of the anisotropic GGX lobe and their action on LTC matrices.

Anisotropic-LTC paper, section 6 (eqs. 13-16; ``equations.md`` 3). With an orthogonal ``Q`` that
maps the lobe of one configuration onto another (``lobe'(w) = lobe(Q^T w)``), the LTC matrix maps
as ``M' = Q M Q^T``; conjugation keeps a matrix aligned because ``Q`` leaves the clamped cosine
invariant. The ``Q`` used here:

- ``S = diag(sx, sy, 1)`` (mirrors): the lobe at view azimuth ``-phi`` (``pi - phi``) is the mirror
  image of the lobe at ``phi`` under ``y -> -y`` (``x -> -x``), eq. 13;
- ``P`` swaps x and y: ``GGX(ax, ay)`` seen from azimuth ``phi`` is ``GGX(ay, ax)`` seen from
  ``pi/2 - phi``, mirrored by ``P`` (eqs. 14-15).
"""

from __future__ import annotations

import numpy as np

SWAP_XY = np.array([[0.0, 1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])


def mirror(M, sx, sy) -> np.ndarray:
    """``S M S`` with ``S = diag(sx, sy, 1)``, ``sx, sy in {-1, +1} (...)``; ``M (..., 3, 3)``.

    Entry ``(i, j)`` is multiplied by ``s_i s_j``, which is what the conjugation does.
    """
    M = np.asarray(M, dtype=np.float64)
    s = np.stack(np.broadcast_arrays(np.asarray(sx, float), np.asarray(sy, float),
                                     np.ones_like(np.asarray(sx, float))), -1)
    return M * s[..., :, None] * s[..., None, :]


def swap_xy(M) -> np.ndarray:
    """``P M P`` with ``P`` the x/y swap; ``M (..., 3, 3)``."""
    M = np.asarray(M, dtype=np.float64)
    return M[..., [1, 0, 2], :][..., :, [1, 0, 2]]


def canonical_view(wo, alpha_x, alpha_y):
    """Fold a configuration into the table's domain (eqs. 13 and 15).

    Returns ``(v, alpha, ratio, swap, sx, sy)``: ``v (..., 3)`` with ``v_x, v_y >= 0`` seen by
    ``GGX(alpha, alpha * ratio)`` (``alpha = max(ax, ay)``, ``ratio = min / max``), and the
    operations that map its LTC back: ``M = P^swap S M_table S P^swap`` (:func:`unfold`).
    """
    wo = np.asarray(wo, dtype=np.float64)
    ax, ay = np.broadcast_arrays(np.asarray(alpha_x, float), np.asarray(alpha_y, float))
    swap = ay > ax
    alpha = np.maximum(ax, ay)
    ratio = np.minimum(ax, ay) / alpha
    w = np.where(swap[..., None], wo[..., [1, 0, 2]], wo)
    sx = np.where(w[..., 0] < 0, -1.0, 1.0)
    sy = np.where(w[..., 1] < 0, -1.0, 1.0)
    v = np.stack([np.abs(w[..., 0]), np.abs(w[..., 1]), w[..., 2]], -1)
    return v, alpha, ratio, swap, sx, sy


def unfold(M_table, swap, sx, sy) -> np.ndarray:
    """``P^swap S M_table S P^swap``: the LTC of the original configuration (see above)."""
    M = mirror(M_table, sx, sy)
    return np.where(np.asarray(swap)[..., None, None], swap_xy(M), M)


def enforce(M, axis_theta, axis_phi, axis_ratio) -> np.ndarray:
    """Eq. 16 post-processing of a table ``M (T, F, A, R, 3, 3)`` of aligned matrices.

    - ``ratio = 1``: the entries at ``phi`` and ``pi/2 - phi`` are ``P``-images of each other;
      both are replaced by their average (requires a ``phi`` axis symmetric about ``pi/4``).
    - ``phi = 0`` (view in the xz plane, lobe symmetric under ``y -> -y``): ``M_xy, M_yx, M_yz,
      M_zy = 0``; ``phi = pi/2``: ``M_xy, M_yx, M_xz, M_zx = 0``.
    - ``theta = 0``: the lobe does not depend on ``phi`` and is symmetric under both mirrors: one
      diagonal matrix (the average over ``phi``) for every ``phi``.

    The third columns are renormalised to unit length afterwards.
    """
    M = np.array(M, dtype=np.float64, copy=True)
    th, ph, rr = (np.asarray(a, float) for a in (axis_theta, axis_phi, axis_ratio))
    if not np.allclose(ph + ph[::-1], np.pi / 2, atol=1e-12):
        raise ValueError("axis_phi must be symmetric about pi/4")
    iso = np.isclose(rr, 1.0)
    if iso.any():
        Mi = M[:, :, :, iso]
        M[:, :, :, iso] = 0.5 * (Mi + swap_xy(Mi[:, ::-1]))
    if np.isclose(ph[0], 0.0):
        for i, j in ((0, 1), (1, 0), (1, 2), (2, 1)):
            M[:, 0, ..., i, j] = 0.0
    if np.isclose(ph[-1], np.pi / 2):
        for i, j in ((0, 1), (1, 0), (0, 2), (2, 0)):
            M[:, -1, ..., i, j] = 0.0
    if np.isclose(th[0], 0.0):
        d = np.diagonal(M[0], axis1=-2, axis2=-1).mean(axis=0)  # (A, R, 3)
        M[0] = 0.0
        for k in range(3):
            M[0, ..., k, k] = d[None, ..., k]
    return M / np.linalg.norm(M[..., :, 2], axis=-1)[..., None, None]
