"""NumPy twin of the ``ltc`` shader (:func:`prefilter.ltc.shading.shade_ltc`): the check the
fused kernels are tested against, and the shader for table-like stand-ins (any object with
``lookup(wo, alpha) -> (M, magnitude, fresnel)`` and ``alpha_min``)."""

from __future__ import annotations

import numpy as np

from prefilter.ltc.polygon import clamped_cosine_integral, clip_to_horizon, polygon_integral_minv
from prefilter.ltc.shading import scaled_inverse, spec_scale
from prefilter.render.lights import LightSet
from prefilter.render.shading import local_view, quad_local, shade_delta_lights


def shade_ltc_numpy(position, frame_t, frame_b, frame_n, view, alpha, base_color, f0,
                    lights: LightSet, table) -> np.ndarray:
    """NumPy implementation of :func:`prefilter.ltc.shading.shade_ltc`."""
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
    spec = spec_scale(f0, magnitude, fresnel)
    for ql in lights.quads:
        P = quad_local(ql, position, ts, bs, ns)
        front = (position - ql.vertices[0]) @ ql.normal > 0.0
        e_d = clamped_cosine_integral(P)
        # The light is cut at the shading horizon before the LTC transform: the kernel clips
        # M^-1 P in the cosine's space, which would keep the lobe's mass below the surface.
        e_s = polygon_integral_minv(M_inv, clip_to_horizon(P))
        rad = base_color * e_d[:, None] + spec * e_s[:, None]
        out += np.where(front[:, None], rad, 0.0) * ql.radiance
    return out
