"""The material model every method shades with, over flat arrays of shading points.

Lambertian diffuse with albedo ``base_color`` plus GGX specular with roughness
``(alpha_x, alpha_y)`` along the shading tangent and bitangent and Schlick Fresnel with reflectance
``f0`` (rgb) at normal incidence. Lights carry no visibility (no shadows).

Every function takes flat arrays: positions, frames and views ``(N, 3)``, roughness ``(N,)``,
colours ``(N, 3)``; it returns radiance ``(N, 3)``.

The view is clamped to the shading hemisphere (``wo_z >= VIEW_Z_MIN``, see :func:`local_view`)
because a normal map can tilt the shading normal away from a visible point; every method uses the
same clamp, so they converge to the same image.
"""

from __future__ import annotations

import numpy as np

from prefilter.microfacet import GGX, half_vector
from prefilter.microfacet.fresnel import schlick
from prefilter.render.driver import two_sided_frame
from prefilter.render.lights import LightSet
from prefilter.sphere.sampling import to_local

#: Smallest cosine between the view and the shading normal (views below are clamped to it).
VIEW_Z_MIN = 1e-3


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
    fr = schlick(f0, np.sum(wi * h, axis=-1)[:, None])
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
