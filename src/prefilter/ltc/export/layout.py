"""The isotropic GGX table resampled to the 64 x 64 grid engines read, as inverse-matrix texels.

Heitz, Dupuy, Hill, Neubelt 2016, section 4 and the reference code (``selfshadow/ltc_code``,
``fitLTC.cpp`` ``packTab`` and the ``ltc_quad.fs`` shader): engines index the table with

    uv = (r, sqrt(1 - cos theta)) * (N - 1) / N + 0.5 / N,      r = sqrt(alpha), N = 64

(hardware bilinear filtering, texel centres at ``(i + 0.5) / N``, so node ``i`` sits at
``r = i / (N - 1)``), and store the inverse matrix divided by its middle entry,
``M^-1 / (M^-1)_11``, whose four free entries go to ``ltc_1`` as
``((M^-1)_00, (M^-1)_20, (M^-1)_02, (M^-1)_22)`` (row, column) so that the shader's
``mat3(vec3(t.x, 0, t.y), vec3(0, 1, 0), vec3(t.z, 0, t.w))`` (column-major) is ``M^-1``.
``ltc_2 = (n, f5, 0, sphere)``: magnitude, Fresnel term (Hill 2016: ``F0 n + (1 - F0) f5`` is
:func:`prefilter.ltc.schlick_scale`) and the reference code's clipped-sphere form factor table.
The view is along ``+x`` in the matrix's frame (the shader's ``T1 = normalize(V - N (V.N))``), as
in :class:`prefilter.ltc.table.GGXTable`.
"""

from __future__ import annotations

import numpy as np

from prefilter.errors import PrefilterError

__all__ = ["ENGINE_SIZE", "VIEW_AXES", "engine_nodes", "inverse_texels", "ltc_code_textures",
           "resample", "sphere_form_factor"]

#: Texels per side of every engine table (three.js, Babylon.js, Blender, the reference code).
ENGINE_SIZE = 64


def engine_nodes(size: int = ENGINE_SIZE) -> np.ndarray:
    """Texel-centre coordinates ``(size,)`` in table units: ``i / (size - 1)``, ``0 .. 1``."""
    return np.arange(size, dtype=np.float64) / (size - 1)


#: Row parametrisations: ``v`` as a function of the view's ``cos theta``.
VIEW_AXES = ("sqrt", "theta")


def resample(table, size: int = ENGINE_SIZE, view: str = "sqrt"):
    """The table at the engine nodes, by the table's own bilinear lookup.

    Rows are ``v = j / (size - 1)`` with ``v = sqrt(1 - cos theta)`` (``view="sqrt"``, the
    reference code's axis) or ``v = theta / (pi / 2)`` (``view="theta"``), columns
    ``r = sqrt(alpha) = i / (size - 1)``; nodes outside the table's range take its clamped
    values (roughness below ``alpha_min`` uses the first column, views beyond ``theta_max`` the
    last row), as :meth:`GGXTable.lookup` does.

    Returns
    -------
    M : (size, size, 3, 3) forward matrices (view along +x), magnitude, fresnel : (size, size)
    """
    if size < 2:
        raise PrefilterError(f"size: expected >= 2, got {size}")
    if view not in VIEW_AXES:
        raise PrefilterError(f"view: expected one of {', '.join(VIEW_AXES)}, got {view!r}")
    x = engine_nodes(size)
    cos_theta = 1.0 - x * x if view == "sqrt" else np.cos(0.5 * np.pi * x)
    # grazing nodes clamp to the last row (as the lookup would); wo_z = 0 itself is degenerate
    wo_z = np.maximum(cos_theta, np.cos(table.theta_max))
    wo_z = np.broadcast_to(wo_z[:, None], (size, size))
    alpha = np.broadcast_to((x * x)[None, :], (size, size))
    M, n, f5 = table.lookup_canonical(wo_z, alpha)
    return M, n, f5


def inverse_texels(M) -> np.ndarray:
    """``(..., 4)`` texels ``((M^-1)_00, (M^-1)_20, (M^-1)_02, (M^-1)_22)`` of ``M^-1 / (M^-1)_11``.

    ``M (..., 3, 3)`` of the isotropic form ``[[a, 0, b], [0, c, 0], [d, 0, e]]``; the polygon
    integral only depends on ``M^-1`` up to a positive factor, and ``(M^-1)_11 = 1 / c > 0``.
    """
    Minv = np.linalg.inv(np.asarray(M, dtype=np.float64))
    Minv = Minv / Minv[..., 1:2, 1:2]
    return np.stack([Minv[..., 0, 0], Minv[..., 2, 0], Minv[..., 0, 2], Minv[..., 2, 2]], -1)


def sphere_form_factor(size: int = ENGINE_SIZE, n_nodes: int = 256) -> np.ndarray:
    """The reference code's sphere table ``(size, size)``: row ``j`` (``len = j / (size - 1)``),
    column ``i`` (``z = 2 i / (size - 1) - 1``).

    A spherical cap of half-angle ``sigma`` (``sin^2 sigma = len``) around a direction at
    ``cos omega = z`` from the normal: its horizon-clipped projected solid angle divided by the
    unclipped ``pi len`` (Heitz, Hill 2017, "Real-time line- and disk-light shading", the
    ``ltc_2.w`` lookup of the reference code); ``max(z, 0)`` for ``len = 0``. Integrated here in
    the cap's polar angle ``t`` (Gauss-Legendre, ``n_nodes``) with the azimuthal integral of
    ``max(0, A - B cos phi)`` in closed form (``A = cos t cos omega``, ``B = sin t sin omega``).
    """
    x = engine_nodes(size)
    z = (2.0 * x - 1.0)[None, :, None]
    length = x[:, None, None]
    sigma = np.arcsin(np.sqrt(length))
    g, w = np.polynomial.legendre.leggauss(n_nodes)
    t = 0.5 * sigma * (g + 1.0)  # (rows, 1, nodes)
    sin_omega = np.sqrt(np.maximum(0.0, 1.0 - z * z))
    A = np.cos(t) * z
    B = np.sin(t) * sin_omega
    with np.errstate(divide="ignore", invalid="ignore"):
        phi0 = np.arccos(np.clip(A / np.where(B > 0, B, 1.0), -1.0, 1.0))
    partial = 2.0 * ((np.pi - phi0) * A + B * np.sin(phi0))
    azimuthal = np.where(A >= B, 2.0 * np.pi * A, np.where(A <= -B, 0.0, partial))
    integral = 0.5 * sigma[..., 0] * np.sum(w * azimuthal * np.sin(t), axis=-1)
    with np.errstate(divide="ignore", invalid="ignore"):
        value = integral / (np.pi * length[..., 0])
    return np.where(length[..., 0] > 0, value, np.maximum(z[..., 0], 0.0))


def ltc_code_textures(table, size: int = ENGINE_SIZE):
    """``ltc_1, ltc_2``, each ``(size, size, 4)`` float64, rows ``v``, columns ``r``.

    ``ltc_1``: :func:`inverse_texels`; ``ltc_2 = (n, f5, 0, sphere)``
    (:func:`sphere_form_factor`). The layout every preset derives from.
    """
    M, n, f5 = resample(table, size)
    ltc_1 = inverse_texels(M)
    ltc_2 = np.stack([n, f5, np.zeros_like(n), sphere_form_factor(size)], -1)
    return ltc_1, ltc_2
