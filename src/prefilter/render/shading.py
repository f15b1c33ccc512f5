"""Per-sample shading over flat arrays of shading points: the material model and the LTC shader.

Material model (shared by every method): Lambertian diffuse with albedo ``base_color`` plus GGX
specular with roughness ``(alpha_x, alpha_y)`` along the shading tangent and bitangent and Schlick
Fresnel with reflectance ``f0`` (rgb) at normal incidence. Lights carry no visibility (no shadows).

Every function takes flat arrays: positions, frames and views ``(N, 3)``, roughness ``(N,)``,
colours ``(N, 3)``; it returns radiance ``(N, 3)``.

The view is clamped to the shading hemisphere (``wo_z >= VIEW_Z_MIN``, see :func:`local_view`)
because a normal map can tilt the shading normal away from a visible point; every method uses the
same clamp, so they converge to the same image.

:func:`shade_ltc` integrates quad lights in one fused Numba kernel per shading point
(:func:`prefilter.render.kernels.ltc_quads_kernel`); ``_shade_ltc_numpy`` is the NumPy
implementation it is tested against (and the path for table-like objects without table arrays).
"""

from __future__ import annotations

import numpy as np

from prefilter.ltc.polygon import clamped_cosine_integral, clip_to_horizon, polygon_integral_minv
from prefilter.microfacet import GGX, half_vector
from prefilter.render.lights import LightSet
from prefilter.sphere.sampling import to_local

#: Smallest cosine between the view and the shading normal (views below are clamped to it).
VIEW_Z_MIN = 1e-3


def schlick(f0, cos_theta) -> np.ndarray:
    """Schlick Fresnel ``F0 + (1 - F0)(1 - cos)^5`` for ``f0 (N, 3)`` and ``cos_theta (N,)``."""
    c = np.clip(np.asarray(cos_theta, dtype=np.float64), 0.0, 1.0)
    return f0 + (1.0 - f0) * ((1.0 - c) ** 5)[..., None]


def two_sided_frame(g):
    """Geometric frames ``t, b, n`` ``(N, 3)`` of hit samples ``g`` (a G-buffer selection),
    flipped to the viewer's side: a two-sided surface seen from behind shades with ``-b, -n``
    (``t`` kept, so the frame stays right-handed)."""
    flip = np.where(np.sum(g.view * g.normal, -1) < 0.0, -1.0, 1.0)[:, None]
    return g.tangent, g.bitangent * flip, g.normal * flip


def shading_frames(g):
    """:func:`two_sided_frame` of hit samples ``g`` and the unit view direction ``wo (N, 3)``
    in it."""
    t, b, n = two_sided_frame(g)
    wo = to_local(g.view, t, b, n)
    wo /= np.linalg.norm(wo, axis=-1, keepdims=True)
    return t, b, n, wo


def point_incoming(lights: LightSet, position) -> list:
    """``(w, E)`` per point and directional light of ``lights``: unit world directions to the
    light and irradiance at normal incidence (inverse-square falloff for points), both
    ``(N, 3)`` (directionals' are broadcast views), at ``position (N, 3)``."""
    incoming = []
    for pl in lights.points:
        d = pl.position - position
        d2 = np.maximum(np.sum(d * d, -1), 1e-300)
        incoming.append((d / np.sqrt(d2)[:, None], pl.intensity / d2[:, None]))
    for dl in lights.directionals:
        incoming.append((np.broadcast_to(-dl.direction, position.shape),
                         np.broadcast_to(dl.irradiance, position.shape)))
    return incoming


def shading_frame(frame_t, frame_b, frame_n, normal_ts=None):
    """Shading frame ``(t_s, b_s, n_s)``, each ``(N, 3)``, from a tangent-space normal.

    ``normal_ts (N, 3)`` (need not be unit: mip averages are shorter) is expressed in the geometric
    frame ``(t, b, n)``; the tangent is re-orthogonalised against the shading normal
    (Gram-Schmidt) so the anisotropy axes follow the surface's ``u`` direction, and the bitangent
    keeps the handedness of the geometric frame. ``None`` returns the geometric frame.
    """
    t = np.asarray(frame_t, dtype=np.float64)
    b = np.asarray(frame_b, dtype=np.float64)
    n = np.asarray(frame_n, dtype=np.float64)
    if normal_ts is None:
        return t, b, n
    m = np.asarray(normal_ts, dtype=np.float64)
    ns = m[..., 0:1] * t + m[..., 1:2] * b + m[..., 2:3] * n
    ln = np.linalg.norm(ns, axis=-1, keepdims=True)
    ns = np.where(ln > 1e-12, ns / np.maximum(ln, 1e-300), n)
    ts = t - np.sum(t * ns, axis=-1, keepdims=True) * ns
    lt = np.linalg.norm(ts, axis=-1, keepdims=True)
    # A shading normal along the tangent (never for sane maps): fall back to the bitangent side.
    alt = np.cross(b, ns)
    ts = np.where(lt > 1e-9, ts / np.maximum(lt, 1e-300), alt / np.linalg.norm(alt, axis=-1,
                                                                                keepdims=True))
    hand = np.where(np.sum(np.cross(n, t) * b, axis=-1, keepdims=True) >= 0.0, 1.0, -1.0)
    bs = hand * np.cross(ns, ts)
    return ts, bs, ns


def local_view(view, ts, bs, ns) -> np.ndarray:
    """View direction ``(N, 3)`` in the shading frame, clamped to ``z >= VIEW_Z_MIN``.

    ``view`` points from the surface towards the eye.
    """
    wo = to_local(view, ts, bs, ns)
    wo[:, 2] = np.maximum(wo[:, 2], VIEW_Z_MIN)
    return wo / np.linalg.norm(wo, axis=-1, keepdims=True)


def brdf_cos(wo, wi, alpha_x, alpha_y, base_color, f0) -> np.ndarray:
    """Cosine-weighted BRDF ``f(wo, wi) max(0, wi_z)``, rgb ``(N, 3)``, in the shading frame.

    ``base_color / pi * wi_z + F_schlick(wi.h) D(h) G2(wo, wi) / (4 wo_z)``: the GGX term of
    Walter et al. 2007 (eq. 20) with height-correlated Smith masking (Heitz 2014, eq. 99).
    Zero for ``wi`` below the shading horizon.
    """
    wo = np.asarray(wo, dtype=np.float64)
    wi = np.asarray(wi, dtype=np.float64)
    up = wi[:, 2] > 0.0
    spec = GGX(alpha_x, alpha_y).eval(wo, wi)
    h = half_vector(wo, wi)
    fr = schlick(f0, np.sum(wi * h, axis=-1))
    diff = base_color / np.pi * np.where(up, wi[:, 2], 0.0)[:, None]
    return diff + fr * spec[:, None]


def shade_delta_lights(position, ts, bs, ns, wo, alpha_x, alpha_y, base_color, f0,
                       lights: LightSet) -> np.ndarray:
    """Radiance ``(N, 3)`` from point and directional lights: the BRDF evaluated directly."""
    out = np.zeros((len(position), 3))
    for w, e in point_incoming(lights, position):
        out += brdf_cos(wo, to_local(w, ts, bs, ns), alpha_x, alpha_y, base_color, f0) * e
    return out


def quad_local(light, position, ts, bs, ns) -> np.ndarray:
    """Corners ``(N, 4, 3)`` of a quad light relative to each shading point, in its frame."""
    d = light.vertices[None, :, :] - position[:, None, :]
    return np.matmul(d, np.stack([ts, bs, ns], axis=-1))


def scaled_inverse(M) -> np.ndarray:
    """``|det M| M^-1`` for ``M (N, 3, 3)`` by cross products of the columns (no LAPACK call).

    Rows of the adjugate are ``c1 x c2, c2 x c0, c0 x c1``; the polygon integral only needs
    ``M^-1`` up to a positive factor (:func:`prefilter.ltc.polygon_integral_minv`).
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
        :func:`shading_frame`).
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
    from prefilter.errors import PrefilterError
    from prefilter.render.kernels import ltc_quads_kernel, serial

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
    if not all(hasattr(table, k) for k in ("axis_t", "axis_r", "M", "magnitude", "fresnel")):
        # a table-like object without the GGXTable arrays (test stand-ins): the NumPy path
        return _shade_ltc_numpy(position, ts, bs, ns, view, alpha, base_color, f0, lights, table)
    n = len(position)

    def c3(a):
        return np.ascontiguousarray(np.broadcast_to(a, (n, 3)), dtype=np.float64)

    status = np.zeros(n, np.uint8)
    # Roughness below the table's range uses its smoothest row (the kernel clamps alpha to
    # [alpha_min, 1], documented in docs/reference.md); the light is cut at the shading horizon
    # before the LTC transform, as in the NumPy path.
    serial(ltc_quads_kernel, n)(c3(position), c3(ts), c3(bs), c3(ns), c3(view),
                     np.ascontiguousarray(np.broadcast_to(alpha, (n,)), dtype=np.float64),
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


def _shade_ltc_numpy(position, frame_t, frame_b, frame_n, view, alpha, base_color, f0,
              lights: LightSet, table) -> np.ndarray:
    """NumPy implementation of :func:`shade_ltc` (cross-checks the fused kernel in the tests)."""
    position = np.asarray(position, dtype=np.float64)
    ts, bs, ns = (np.asarray(a, dtype=np.float64) for a in (frame_t, frame_b, frame_n))
    alpha = np.asarray(alpha, dtype=np.float64)
    base_color = np.asarray(base_color, dtype=np.float64)
    f0 = np.asarray(f0, dtype=np.float64)
    wo = local_view(view, ts, bs, ns)
    out = shade_delta_lights(position, ts, bs, ns, wo, alpha, alpha, base_color, f0, lights)
    if not lights.quads:
        return out
    # Roughness below the table's range uses its smoothest row (documented in docs/reference.md).
    M, magnitude, fresnel = table.lookup(wo, np.clip(alpha, table.alpha_min, 1.0))
    M_inv = scaled_inverse(M)
    spec_scale = f0 * (magnitude - fresnel)[:, None] + fresnel[:, None]
    for ql in lights.quads:
        P = quad_local(ql, position, ts, bs, ns)
        front = (position - ql.vertices[0]) @ ql.normal > 0.0
        e_d = clamped_cosine_integral(P)
        # The light is cut at the shading horizon before the LTC transform: the kernel clips
        # M^-1 P in the cosine's space, which would keep the lobe's mass below the surface.
        e_s = polygon_integral_minv(M_inv, clip_to_horizon(P))
        rad = base_color * e_d[:, None] + spec_scale * e_s[:, None]
        out += np.where(front[:, None], rad, 0.0) * ql.radiance
    return out
