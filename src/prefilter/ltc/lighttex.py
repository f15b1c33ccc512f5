"""Textured quad lights under an LTC lobe (Heitz et al. 2016, section 5.3 "Textured lights").

The integral of an LTC lobe ``D`` times a textured radiance ``L`` over the light polygon ``P`` is
split as ``integral_P D L ~= E(M^-1 P) * L_avg``: the untextured polygon integral times the
``D``-weighted average of the texture over the polygon. ``L_avg`` is approximated by one lookup in
the light's prefiltered texture (:class:`prefilter.render.lighttex.LightTexture`): in the lobe's
cosine space (``M^-1`` applied to the polygon) the cosine is centred on ``z``, so the lookup point
is the orthogonal projection of the origin onto the transformed light plane, and the filter width
grows with the distance ``d`` of that plane: a clamped cosine seen on a plane at distance ``d`` has
irradiance density ``d^2 / (d^2 + rho^2)^2``, half of it within ``rho = d``; the Gaussian with the
same half-mass radius has ``sigma = d / sqrt(2 ln 2) = 0.85 d``. (The paper pads the texture with
a blurred border; the light's pyramid normalises its convolution to the light instead.)
"""

from __future__ import annotations

import numpy as np

from prefilter.sphere.polygon import clamped_cosine_integral, clip_to_horizon, polygon_integral_minv
from prefilter.ltc.shading import scaled_inverse, shade_ltc, spec_scale
from prefilter.render.lighttex import texture_uv
from prefilter.render.shading import local_view, quad_local

__all__ = ["SIGMA_PER_DISTANCE", "light_texture_lookup_point", "shade_ltc_textured",
           "shade_textured_quads"]

#: Gaussian sigma per plane distance of the clamped cosine's footprint (same half-mass radius).
SIGMA_PER_DISTANCE = 1.0 / np.sqrt(2.0 * np.log(2.0))

def light_texture_lookup_point(M_inv, P) -> tuple[np.ndarray, np.ndarray]:
    """Where and how wide to read the light texture for an LTC lobe (Heitz et al. 2016, 5.3).

    Parameters
    ----------
    M_inv : (N, 3, 3) the lobe's inverse matrix (any positive scale).
    P : (N, 4, 3) the light's corners in the shading frame (unclipped).

    Returns
    -------
    uv : (N, 2) texture coordinates of the orthogonal projection of the origin onto the light
        plane in cosine space; ``width`` : (N,) the Gaussian sigma in units of ``sqrt(area)``
        of the transformed light (``0.85 d / sqrt(A)``).
    """
    Q = np.matmul(P, np.swapaxes(M_inv, -1, -2))
    nrm = np.cross(Q[:, 1] - Q[:, 0], Q[:, 3] - Q[:, 0])
    a2 = np.maximum(np.sum(nrm * nrm, -1), 1e-300)
    h = np.sum(nrm * Q[:, 0], -1)
    foot = (h / a2)[:, None] * nrm
    d = np.abs(h) / np.sqrt(a2)
    return texture_uv(Q, foot), SIGMA_PER_DISTANCE * d / a2 ** 0.25


def _rgb(x: np.ndarray) -> np.ndarray:
    return x if x.shape[1] == 3 else np.broadcast_to(x[:, :1], (x.shape[0], 3))


def shade_textured_quads(position, ts, bs, ns, wo, M_inv, spec, base_color,
                         quads) -> np.ndarray:
    """Radiance ``(N, 3)`` from textured quads: diffuse ``base_color E(P) T(uv_d)`` plus specular
    ``spec_scale E(M^-1 P) T(uv_s)`` (Heitz et al. 2016, section 5.3).

    ``wo`` (N, 3) is the local view (unused but for the front test's symmetry with
    :func:`prefilter.ltc.shading.shade_ltc`); ``M_inv`` (N, 3, 3) from the LTC table,
    ``spec`` (N, 3) the Fresnel-weighted magnitude (:func:`prefilter.ltc.shading.spec_scale`).
    """
    out = np.zeros((len(position), 3))
    eye = np.broadcast_to(np.eye(3), M_inv.shape)
    for ql in quads:
        P = quad_local(ql, position, ts, bs, ns)
        front = (position - ql.vertices[0]) @ ql.normal > 0.0
        h, w = ql.texture.shape[:2]
        texels = np.sqrt(h * w)
        uv_d, wd = light_texture_lookup_point(eye, P)
        uv_s, wsp = light_texture_lookup_point(M_inv, P)
        t_d = _rgb(ql.texture.lookup(uv_d, wd * texels))
        t_s = _rgb(ql.texture.lookup(uv_s, wsp * texels))
        e_d = clamped_cosine_integral(P)
        e_s = polygon_integral_minv(M_inv, clip_to_horizon(P))
        rad = base_color * (e_d[:, None] * t_d) + spec * (e_s[:, None] * t_s)
        out += np.where(front[:, None], rad, 0.0) * ql.radiance
    return out


def shade_ltc_textured(position, ts, bs, ns, view, alpha, base_color, f0, lights, textured,
                       table) -> np.ndarray:
    """:func:`prefilter.ltc.shading.shade_ltc` for ``lights`` plus the textured quads
    ``textured`` with the same isotropic table lookup."""
    out = shade_ltc(position, ts, bs, ns, view, alpha, base_color, f0, lights, table)
    if not textured:
        return out
    wo = local_view(view, ts, bs, ns)
    M, magnitude, fresnel = table.lookup(wo, np.clip(alpha, table.alpha_min, 1.0))
    return out + shade_textured_quads(position, ts, bs, ns, wo, scaled_inverse(M),
                                      spec_scale(f0, magnitude, fresnel),
                                      base_color, textured)
