"""The ``ltc-aniso`` render method: quad lights integrated with the anisotropic LTC table.

Same pipeline as the ``ltc`` method (:func:`prefilter.ltc.render.render_ltc`) with the
lookup of :class:`~prefilter.ltc.aniso.table.AnisoGGXTable` in the shading frame (x = tangent),
so ``alpha_x`` and ``alpha_y`` are used as they are (``ltc`` uses their geometric mean).
Textured quad lights get the prefiltered light-texture lookup of the ``ltc`` method
(:func:`prefilter.ltc.lighttex.shade_textured_quads`, Heitz et al. 2016, section 5.3) with
this lobe's ``M^-1``.
"""

from __future__ import annotations

import numpy as np

from prefilter.ltc.lighttex import shade_textured_quads
from prefilter.sphere.polygon import clamped_cosine_integral, clip_to_horizon, polygon_integral_minv
from prefilter.ltc.shading import scaled_inverse, spec_scale
from prefilter.render.driver import render_samples, surface_attributes
from prefilter.render.lighttex import split_lights
from prefilter.render.shading import local_view, quad_local, shade_delta_lights


def shade_ltc_aniso(position, frame_t, frame_b, frame_n, view, alpha_x, alpha_y, base_color, f0,
                    lights, table, textured=()) -> np.ndarray:
    """Radiance ``(N, 3)``: diffuse ``base_color E(P)`` + specular ``(f0 (n - f5) + f5)
    E(M^-1 P)`` with ``(M, n, f5) = table.lookup(wo, alpha_x, alpha_y)`` (anisotropic-LTC paper,
    section 9; Hill and Heitz 2016 for Fresnel). Point and directional lights use the BRDF.

    ``textured``: :class:`~prefilter.render.lighttex.TexturedQuad` lights, each polygon integral
    times the light texture averaged under the lobe (Heitz et al. 2016, section 5.3).
    """
    position = np.asarray(position, dtype=np.float64)
    ts, bs, ns = (np.asarray(a, dtype=np.float64) for a in (frame_t, frame_b, frame_n))
    ax, ay = np.asarray(alpha_x, float), np.asarray(alpha_y, float)
    base_color, f0 = np.asarray(base_color, float), np.asarray(f0, float)
    wo = local_view(view, ts, bs, ns)
    out = shade_delta_lights(position, ts, bs, ns, wo, ax, ay, base_color, f0, lights)
    if not (lights.quads or textured):
        return out
    # grazing or back-facing views (normal mapping) are looked up just above the horizon
    wo_t = wo.copy()
    wo_t[:, 2] = np.maximum(wo_t[:, 2], 1e-4)
    wo_t /= np.linalg.norm(wo_t, axis=-1, keepdims=True)
    M, magnitude, fresnel = table.lookup(wo_t, np.clip(ax, 1e-4, 1), np.clip(ay, 1e-4, 1))
    M_inv = scaled_inverse(M)
    spec = np.where((wo[:, 2] > 0)[:, None],
                    spec_scale(f0, magnitude, fresnel), 0.0)
    for ql in lights.quads:
        P = quad_local(ql, position, ts, bs, ns)
        front = (position - ql.vertices[0]) @ ql.normal > 0.0
        rad = base_color * clamped_cosine_integral(P)[:, None] \
            + spec * polygon_integral_minv(M_inv, clip_to_horizon(P))[:, None]
        out += np.where(front[:, None], rad, 0.0) * ql.radiance
    if textured:
        out += shade_textured_quads(position, ts, bs, ns, wo, M_inv, spec, base_color, textured)
    return out


def render_ltc_aniso(scene, settings) -> np.ndarray:
    """The ``ltc-aniso`` method (registered in :mod:`prefilter.ltc.aniso`)."""
    from prefilter.ltc.aniso.table import AnisoGGXTable

    lights, textured = split_lights(scene, "ltc-aniso")
    table = settings.table if isinstance(settings.table, AnisoGGXTable) else AnisoGGXTable.load()

    def shade(g, _u):
        a = surface_attributes(scene, g)
        return shade_ltc_aniso(g.position, a["t"], a["b"], a["n"], g.view, a["alpha_x"],
                               a["alpha_y"], a["base_color"], a["f0"], lights, table, textured)

    return render_samples(scene, settings, shade, stratified=settings.spp > 1, desc="ltc-aniso")
