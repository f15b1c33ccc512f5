"""Ground truth: supersampled pixel footprints and Monte Carlo integration over the lights.

Per pixel, ``spp`` stratified sub-pixel positions are traced with the G-buffer code and shaded
with full-resolution textures (level 0, bilinear). Each quad light is integrated with one light
sample (uniform on its area) and one BRDF sample (GGX visible normals or cosine, mixed), combined
with the balance heuristic (Veach 1997, eq. 9.4 / 9.13), using the true GGX BRDF with Schlick
Fresnel (:func:`prefilter.render.shading.brdf_cos`): no LTC. The estimator is unbiased, so images
converge to the exact one at ``O(spp^-1/2)``; ``docs/reference.md`` has the measured rates.

Random numbers come from one ``numpy.random.Generator`` per image row, spawned from
``SeedSequence(seed)``; rows are shaded in chunks for memory, so the image does not depend on the
chunk size or thread count.
"""

from __future__ import annotations

import numpy as np

from prefilter.microfacet import GGX, reflect
from prefilter.render.lights import LightSet, QuadLight, quad_light_pdf, quad_light_sample
from prefilter.render.shading import (
    brdf_cos,
    local_view,
    schlick,
    shade_delta_lights,
)
from prefilter.sphere.sampling import cosine_hemisphere, to_local, to_world

#: Random numbers per quad light per shading sample: light (2) + BRDF (3).
DIMS_PER_QUAD = 5


def specular_probability(wo, base_color, f0) -> np.ndarray:
    """Probability ``(N,)`` of sampling the GGX lobe rather than the cosine lobe.

    Proportional to a rough estimate of each lobe's reflectance (Fresnel at the view vs the
    diffuse albedo); any value in (0, 1] keeps the estimator unbiased, this one lowers variance.
    """
    s = np.mean(schlick(f0, wo[:, 2]), axis=-1)
    d = np.mean(base_color, axis=-1)
    tot = s + d
    return np.where(tot > 0.0, np.clip(s / np.where(tot > 0, tot, 1.0), 0.05, 1.0), 0.5)


def sample_brdf(wo, u, alpha_x, alpha_y, p_spec) -> np.ndarray:
    """Directions ``(N, 3)`` (shading frame) from the BRDF sampling mixture, uniforms ``u (N, 3)``.

    With probability ``p_spec``: reflect a GGX visible normal (Heitz 2018); otherwise a cosine
    sample. Density :func:`pdf_brdf`.
    """
    m = GGX(alpha_x, alpha_y).sample_vndf(wo, u[:, :2])
    spec = reflect(wo, m)
    diff = cosine_hemisphere(u[:, :2])
    return np.where((u[:, 2] < p_spec)[:, None], spec, diff)


def pdf_brdf(wo, wi, alpha_x, alpha_y, p_spec) -> np.ndarray:
    """Solid-angle density ``(N,)`` of :func:`sample_brdf`."""
    p_s = GGX(alpha_x, alpha_y).pdf_reflect(wo, wi)
    p_d = np.maximum(wi[:, 2], 0.0) / np.pi
    return p_spec * p_s + (1.0 - p_spec) * p_d


def estimate_quad(light: QuadLight, position, ts, bs, ns, wo, alpha_x, alpha_y, base_color, f0,
                  u) -> np.ndarray:
    """One-sample MIS estimate ``(N, 3)`` of the radiance reflected from one quad light.

    ``u (N, 5)``: 2 uniforms for the light sample, 3 for the BRDF sample. Balance heuristic with
    one sample per strategy: ``sum_k f(w_k) L / (p_light(w_k) + p_brdf(w_k))``.
    """
    p_spec = specular_probability(wo, base_color, f0)
    # Light sample.
    wl, pl = quad_light_sample(light, position, u[:, 0:2])
    wl_loc = to_local(wl, ts, bs, ns)
    wl_loc /= np.linalg.norm(wl_loc, axis=-1, keepdims=True)
    f = brdf_cos(wo, wl_loc, alpha_x, alpha_y, base_color, f0)
    den = pl + pdf_brdf(wo, wl_loc, alpha_x, alpha_y, p_spec)
    ok = (pl > 0.0) & (den > 0.0)
    est = np.where(ok[:, None], f / np.where(ok, den, 1.0)[:, None], 0.0)
    # BRDF sample.
    wb_loc = sample_brdf(wo, u[:, 2:5], alpha_x, alpha_y, p_spec)
    wb = to_world(wb_loc, ts, bs, ns)
    plb = quad_light_pdf(light, position, wb)
    f = brdf_cos(wo, wb_loc, alpha_x, alpha_y, base_color, f0)
    den = plb + pdf_brdf(wo, wb_loc, alpha_x, alpha_y, p_spec)
    ok = (plb > 0.0) & (den > 0.0)
    est += np.where(ok[:, None], f / np.where(ok, den, 1.0)[:, None], 0.0)
    return est * light.radiance


def shade_reference(position, frame_t, frame_b, frame_n, view, alpha_x, alpha_y, base_color, f0,
                    lights: LightSet, u) -> np.ndarray:
    """Monte Carlo radiance ``(N, 3)`` at shading points, one MIS sample pair per quad light.

    Parameters
    ----------
    position, frame_t, frame_b, frame_n, view : (N, 3)
        Shading points, their (normal-mapped) shading frames and unit directions to the eye.
    alpha_x, alpha_y : (N,)
        GGX roughness along ``frame_t`` and ``frame_b``.
    base_color, f0 : (N, 3)
    lights : LightSet
    u : (N, Q, 5)
        Uniform random numbers, ``Q = len(lights.quads)``.

    Point and directional lights are evaluated exactly (no sampling).
    """
    position = np.asarray(position, dtype=np.float64)
    ts, bs, ns = (np.asarray(a, dtype=np.float64) for a in (frame_t, frame_b, frame_n))
    alpha_x = np.asarray(alpha_x, dtype=np.float64)
    alpha_y = np.asarray(alpha_y, dtype=np.float64)
    base_color = np.asarray(base_color, dtype=np.float64)
    f0 = np.asarray(f0, dtype=np.float64)
    wo = local_view(view, ts, bs, ns)
    out = shade_delta_lights(position, ts, bs, ns, wo, alpha_x, alpha_y, base_color, f0, lights)
    for q, ql in enumerate(lights.quads):
        out += estimate_quad(ql, position, ts, bs, ns, wo, alpha_x, alpha_y, base_color, f0,
                             u[:, q, :])
    return out


def stratified_offsets(spp: int, n: int, rng: np.random.Generator) -> np.ndarray:
    """Sub-pixel offsets ``(n, spp, 2)`` in ``[0, 1)^2``, stratified per pixel.

    A jittered ``k x k`` grid when ``spp = k^2``, otherwise Latin-hypercube (N-rooks) samples
    (each axis split into ``spp`` strata, one sample per stratum, y strata shuffled).
    """
    k = int(round(np.sqrt(spp)))
    if k * k == spp:
        i = np.arange(spp)
        base = np.stack([i % k, i // k], axis=-1).astype(np.float64)
        return (base[None] + rng.random((n, spp, 2))) / k
    sx = np.broadcast_to(np.arange(spp, dtype=np.float64), (n, spp))
    sy = rng.permuted(np.broadcast_to(np.arange(spp, dtype=np.float64), (n, spp)), axis=1)
    return (np.stack([sx, sy], axis=-1) + rng.random((n, spp, 2))) / spp


def render_reference(scene, settings) -> np.ndarray:
    """The ``reference`` method: ground truth for ``scene`` at ``settings.spp`` samples per pixel.

    Stratified sub-pixel positions (whole pixel footprint), level-0 bilinear textures, and per
    sample one MIS light/BRDF sample pair per quad light (:func:`shade_reference`). Returns
    ``(H, W, 3)`` linear radiance; deterministic for a given ``settings.seed``.
    """
    from prefilter.render.pipeline import render_samples, supported_lights, surface_attributes

    lights = supported_lights(scene, "reference")
    q = len(lights.quads)

    def shade(g, u):
        a = surface_attributes(scene, g, filtered=False)
        uq = u.reshape(len(u), q, DIMS_PER_QUAD) if q else np.zeros((len(g.hit), 0, 5))
        return shade_reference(g.position, a["t"], a["b"], a["n"], g.view, a["alpha_x"],
                               a["alpha_y"], a["base_color"], a["f0"], lights, uq)

    return render_samples(scene, settings, shade, random_dims=q * DIMS_PER_QUAD,
                          stratified=True, desc="reference")
