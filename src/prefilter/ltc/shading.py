"""The ``ltc`` shader over flat arrays of shading points: quad lights integrated by linearly
transformed cosines (Heitz et al. 2016, eqs. 10-11), point and directional lights by the material
model (:mod:`prefilter.render.shading`).

:func:`shade_ltc` integrates quad lights in one fused Numba kernel per shading point
(:func:`prefilter.ltc.kernels.ltc_quads_kernel`; its NumPy twin is a check in
``tests/ltc/ltc_numpy.py``).
"""

from __future__ import annotations

import numpy as np

from prefilter.jit import kernel_array
from prefilter.errors import PrefilterError
from prefilter.ltc.table import schlick_scale
from prefilter.render.lights import LightSet
from prefilter.render.shading import VIEW_Z_MIN, local_view, shade_delta_lights

__all__ = ["TABLE_ARRAYS", "scaled_inverse", "shade_ltc", "spec_scale"]

#: The arrays of a :class:`prefilter.ltc.table.GGXTable` the compiled shaders read.
TABLE_ARRAYS = ("axis_t", "axis_r", "M", "magnitude", "fresnel")


def spec_scale(f0, magnitude, fresnel) -> np.ndarray:
    """Specular weight ``(N, 3)`` of the LTC lobes for reflectances ``f0 (N, 3)`` and the
    table's ``magnitude, fresnel (N,)`` (:func:`prefilter.ltc.table.schlick_scale`)."""
    return schlick_scale(magnitude[:, None], fresnel[:, None], f0)


def scaled_inverse(M) -> np.ndarray:
    """``|det M| M^-1`` for ``M (N, 3, 3)`` by cross products of the columns (no LAPACK call).

    Rows of the adjugate are ``c1 x c2, c2 x c0, c0 x c1``; the polygon integral only needs
    ``M^-1`` up to a positive factor (:func:`prefilter.sphere.polygon.polygon_integral_minv`).
    """
    c0, c1, c2 = M[..., :, 0], M[..., :, 1], M[..., :, 2]
    adj = np.stack([np.cross(c1, c2), np.cross(c2, c0), np.cross(c0, c1)], axis=-2)
    det = np.sum(c0 * adj[..., 0, :], axis=-1)
    return adj * np.where(det < 0.0, -1.0, 1.0)[..., None, None]


def shade_ltc(position, frame_t, frame_b, frame_n, view, alpha, base_color, f0,
              lights: LightSet, table) -> np.ndarray:
    """Radiance ``(N, 3)`` with quad lights integrated by LTCs (Heitz et al. 2016, eqs. 10-11).

    Parameters
    ----------
    position, frame_t, frame_b, frame_n : (N, 3)
        Shading points and their shading frame (already normal-mapped, see
        :func:`prefilter.render.driver.shading_frame`).
    view : (N, 3)
        Unit directions towards the eye.
    alpha : (N,)
        Isotropic GGX roughness (the table is isotropic).
    base_color, f0 : (N, 3)
        Diffuse albedo and Schlick reflectance.
    lights : LightSet
    table : prefilter.ltc.GGXTable

    Diffuse is ``base_color * E(P)`` (the clamped-cosine integral, M = I); specular is
    ``(f0 (n - f5) + f5) E(M^-1 P)`` with ``(M, n, f5)`` from the table. Polygons are clipped at
    the shading horizon. Point and directional lights use the true BRDF.
    """
    from prefilter.jit import serial
    from prefilter.ltc.kernels import ltc_quads_kernel

    position = np.asarray(position, dtype=np.float64)
    ts, bs, ns = (np.asarray(a, dtype=np.float64) for a in (frame_t, frame_b, frame_n))
    alpha = np.asarray(alpha, dtype=np.float64)
    base_color = np.asarray(base_color, dtype=np.float64)
    f0 = np.asarray(f0, dtype=np.float64)
    if lights.points or lights.directionals:
        wo = local_view(view, ts, bs, ns)
        out = shade_delta_lights(position, ts, bs, ns, wo, alpha, alpha, base_color, f0, lights)
    else:
        out = np.zeros((len(position), 3))
    if not lights.quads:
        return out
    if not all(hasattr(table, k) for k in TABLE_ARRAYS):
        raise PrefilterError(f"table: expected an isotropic LTC table with the arrays "
                             f"{', '.join(TABLE_ARRAYS)}, got {type(table).__name__}")
    n = len(position)

    def c3(a):
        return kernel_array(a, (n, 3), np.float64)

    status = np.zeros(n, np.uint8)
    # Roughness below the table's range uses its smoothest row (the kernel clamps alpha to
    # [alpha_min, 1], documented in docs/reference.md); the light is cut at the shading horizon
    # before the LTC transform, as in the NumPy path.
    serial(ltc_quads_kernel, n)(c3(position), c3(ts), c3(bs), c3(ns), c3(view),
                     kernel_array(alpha, (n,), np.float64),
                     c3(base_color), c3(f0),
                     np.ascontiguousarray([q.vertices for q in lights.quads], dtype=np.float64),
                     np.ascontiguousarray([q.normal for q in lights.quads], dtype=np.float64),
                     np.ascontiguousarray([q.radiance for q in lights.quads], dtype=np.float64),
                     np.ascontiguousarray(table.axis_t, dtype=np.float64),
                     np.ascontiguousarray(table.axis_r, dtype=np.float64),
                     np.ascontiguousarray(table.M, dtype=np.float64),
                     np.ascontiguousarray(table.magnitude, dtype=np.float64),
                     np.ascontiguousarray(table.fresnel, dtype=np.float64), VIEW_Z_MIN, out,
                     status)
    if status.any():
        k = int(np.flatnonzero(status)[0])
        raise PrefilterError(f"M_inv: expected invertible matrices, got a singular LTC matrix "
                             f"at shading point {k}")
    return out
