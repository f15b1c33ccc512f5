"""LEADR render method for point and directional lights (``leadr-point``).

Per G-buffer sample: the slope moments of the material's height map at the footprint's mip level
(the renderer's moments chain of the slopes, trilinear) give the mean slope and covariance
(:func:`prefilter.leadr.maps.shading_stats`); the micro roughness adds the Beckmann slope variance
``alpha^2 / 2`` per axis (GGX alpha taken as the Beckmann alpha). Shading is in the *geometric*
frame: the mesonormal is carried by the mean slope. Specular: the closed form of supplemental 3.3
with Schlick Fresnel; diffuse: the grid of Simplified Algorithm 3 with ``E(m) = <m, wi>``
(5 x 5). Quad and environment lights are rejected.
"""

from __future__ import annotations

import numpy as np

from prefilter.errors import PrefilterError
from prefilter.leadr.maps import shading_stats
from prefilter.leadr.shading import diffuse_directional, point_light, schlick

DIFFUSE_GRID = 5


def _local(w, t, b, n):
    return np.stack([np.sum(w * t, -1), np.sum(w * b, -1), np.sum(w * n, -1)], -1)


def leadr_stats(scene, g):
    """Mean slope ``(N, 2)`` and covariance ``(N, 2, 2)`` per hit sample, plus materials."""
    n = g.hit.size
    mean = np.zeros((n, 2))
    cov = np.zeros((n, 2, 2))
    base = np.zeros((n, 3))
    f0 = np.zeros((n, 3))
    for k in np.unique(g.object_id):
        m = g.object_id == k
        mat = scene.objects[int(k)].material
        if mat.height_map is not None:
            mom = mat.height_map.mip().lookup_footprint(g.uv[m], g.dudv[m])
        else:
            mom = np.zeros((int(m.sum()), 5))
        mu, c = shading_stats(mom, 0.0)
        c[:, 0, 0] += 0.5 * mat.alpha_x**2
        c[:, 1, 1] += 0.5 * mat.alpha_y**2
        mean[m], cov[m] = mu, c
        base[m] = mat.base_color
        f0[m] = mat.f0
    return mean, cov, base, f0


def shade_leadr_delta(scene, g, lights) -> np.ndarray:
    """Radiance ``(N, 3)`` of the hit samples ``g`` under point and directional lights."""
    flip = np.where(np.sum(g.view * g.normal, -1) < 0.0, -1.0, 1.0)[:, None]
    t, b, n = g.tangent, g.bitangent * flip, g.normal * flip
    mean, cov, base, f0 = leadr_stats(scene, g)
    wo = _local(g.view, t, b, n)
    wo /= np.linalg.norm(wo, axis=-1, keepdims=True)
    incoming = []
    for pl in lights.points:
        d = pl.position - g.position
        d2 = np.maximum(np.sum(d * d, -1), 1e-300)
        incoming.append((d / np.sqrt(d2)[:, None], pl.intensity / d2[:, None]))
    for dl in lights.directionals:
        incoming.append((np.broadcast_to(-dl.direction, g.position.shape), dl.irradiance))
    out = np.zeros((len(wo), 3))
    for w, e in incoming:
        wi = _local(w, t, b, n)
        wi /= np.linalg.norm(wi, axis=-1, keepdims=True)
        h = wo + wi
        h /= np.maximum(np.linalg.norm(h, axis=-1, keepdims=True), 1e-12)
        spec = point_light(wo, wi, mean, cov)[:, None] * schlick(f0, np.sum(h * wi, -1)[:, None])
        diff = base * diffuse_directional(wo, wi, mean, cov, DIFFUSE_GRID)[:, None]
        out += (spec + diff) * e
    return out


def render_leadr_point(scene, settings) -> np.ndarray:
    """The ``leadr-point`` method (point and directional lights only)."""
    from prefilter.render.pipeline import render_samples

    if any(light.type in ("quad", "environment") for light in scene.lights):
        raise PrefilterError("method 'leadr-point': expected only point and directional lights")
    lights = scene.light_set()
    return render_samples(scene, settings, lambda g, _u: shade_leadr_delta(scene, g, lights),
                          stratified=settings.spp > 1, desc="leadr-point")
