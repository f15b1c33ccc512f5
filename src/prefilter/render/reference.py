"""Ground truth: supersampled pixel footprints and Monte Carlo integration over the lights.

Per pixel, ``spp`` stratified sub-pixel positions are traced with the G-buffer code and shaded
with full-resolution textures (level 0, bilinear). Each quad light is integrated with one light
sample (uniform on its area) and one BRDF sample (GGX visible normals or cosine, mixed), combined
with the balance heuristic (Veach 1997, eq. 9.4 / 9.13), using the true GGX BRDF with Schlick
Fresnel (:func:`prefilter.render.shading.brdf_cos`): no LTC. The estimator is unbiased, so images
converge to the exact one at ``O(spp^-1/2)``; ``docs/reference.md`` has the measured rates.

Textured quad lights (:class:`prefilter.render.lighttex.TexturedQuad`) are sampled the same way;
each sample's radiance is multiplied by the light texture at the sample's point on the light,
read at level 0 (bilinear, texel centres at ``(i + 0.5) / size``) with the texture coordinates of
:func:`prefilter.render.lighttex.texture_uv` (``p = v0 + u (v1 - v0) + v (v3 - v0)``, ``u`` along
columns): the same convention as the ``ltc`` method's prefiltered lookups. The densities do not
depend on the texture, so the estimator stays unbiased (only its variance grows with the
texture's contrast).

Random numbers come from one ``numpy.random.Generator`` per image row, spawned from
``SeedSequence(seed)``; rows are shaded in chunks for memory, so the image does not depend on the
chunk size or thread count.
"""

from __future__ import annotations

import math

import numpy as np

from prefilter.jit import njit_parallel, njit_serial, prange

from prefilter.microfacet import GGX, reflect
from prefilter.render.lights import (
    LightSet,
    QuadLight,
    quad_light_pdf,
    quad_light_sample,
    sample_quad_area,
)
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


def light_emission(light, points) -> np.ndarray:
    """Texture factor ``(N, 3)`` of a quad light at ``points (N, 3)`` on it: the level-0 bilinear
    texel of a :class:`~prefilter.render.lighttex.TexturedQuad` at its
    :func:`~prefilter.render.lighttex.texture_uv` (clamped to the light), ones for an untextured
    :class:`QuadLight`. A one-channel texture scales all three channels."""
    n = len(points)
    tex = getattr(light, "texture", None)
    if tex is None:
        return np.ones((n, 3))
    from prefilter.render.lighttex import texture_uv

    t = tex.lookup(texture_uv(light.vertices, points), 0.0)  # sigma 0: level 0, bilinear
    return t if t.shape[1] == 3 else np.repeat(t[:, :1], 3, axis=1)


def _geometry(light) -> QuadLight:
    """The untextured quad of ``light`` (its sampling densities ignore the texture)."""
    return light if isinstance(light, QuadLight) else QuadLight(light.vertices, light.radiance)


def estimate_quad(light, position, ts, bs, ns, wo, alpha_x, alpha_y, base_color, f0,
                  u) -> np.ndarray:
    """One-sample MIS estimate ``(N, 3)`` of the radiance reflected from one quad light.

    ``light``: a :class:`QuadLight` or a textured quad (its radiance times
    :func:`light_emission` at each sample's point on the light). ``u (N, 5)``: 2 uniforms for the
    light sample, 3 for the BRDF sample. Balance heuristic with one sample per strategy (Veach
    1997, eq. 9.13): ``sum_k f(w_k) L(y_k) / (p_light(w_k) + p_brdf(w_k))``.
    """
    textured = getattr(light, "texture", None) is not None
    geo = _geometry(light)
    p_spec = specular_probability(wo, base_color, f0)
    # Light sample.
    wl, pl = quad_light_sample(geo, position, u[:, 0:2])
    wl_loc = to_local(wl, ts, bs, ns)
    wl_loc /= np.linalg.norm(wl_loc, axis=-1, keepdims=True)
    f = brdf_cos(wo, wl_loc, alpha_x, alpha_y, base_color, f0)
    den = pl + pdf_brdf(wo, wl_loc, alpha_x, alpha_y, p_spec)
    ok = (pl > 0.0) & (den > 0.0)
    est = np.where(ok[:, None], f / np.where(ok, den, 1.0)[:, None], 0.0)
    if textured:
        # the point quad_light_sample drew (same uniforms, same warp)
        est *= light_emission(light, sample_quad_area(geo.vertices, u[:, 0:2]))
    # BRDF sample.
    wb_loc = sample_brdf(wo, u[:, 2:5], alpha_x, alpha_y, p_spec)
    wb = to_world(wb_loc, ts, bs, ns)
    plb = quad_light_pdf(geo, position, wb)
    f = brdf_cos(wo, wb_loc, alpha_x, alpha_y, base_color, f0)
    den = plb + pdf_brdf(wo, wb_loc, alpha_x, alpha_y, p_spec)
    ok = (plb > 0.0) & (den > 0.0)
    eb = np.where(ok[:, None], f / np.where(ok, den, 1.0)[:, None], 0.0)
    if textured:
        n = geo.normal
        cos_l = wb @ n
        t = ((geo.vertices[0] - position) @ n) / np.where(ok, cos_l, 1.0)
        eb *= light_emission(light, position + np.where(ok, t, 0.0)[:, None] * wb)
    return (est + eb) * light.radiance


def shade_reference(position, frame_t, frame_b, frame_n, view, alpha_x, alpha_y, base_color, f0,
                    lights: LightSet, u, *, textured=(), kernel: bool = True) -> np.ndarray:
    """Monte Carlo radiance ``(N, 3)`` at shading points, one MIS sample pair per quad light.

    Parameters
    ----------
    position, frame_t, frame_b, frame_n, view : (N, 3)
        Shading points, their (normal-mapped) shading frames and unit directions to the eye.
    alpha_x, alpha_y : (N,)
        GGX roughness along ``frame_t`` and ``frame_b``.
    base_color, f0 : (N, 3)
    lights : LightSet
    u : (N, Q + T, 5)
        Uniform random numbers, ``Q = len(lights.quads)`` then ``T = len(textured)``.
    textured : sequence of TexturedQuad
        Textured quad lights (:func:`prefilter.render.lighttex.split_lights`).
    kernel : bool
        Use the Numba kernel (default) or the NumPy implementation (same numbers to rounding).

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
    est = estimate_quad_fast if kernel else estimate_quad
    for q, ql in enumerate(tuple(lights.quads) + tuple(textured)):
        out += est(ql, position, ts, bs, ns, wo, alpha_x, alpha_y, base_color, f0, u[:, q, :])
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
    sample one MIS light/BRDF sample pair per quad light, textured or not
    (:func:`shade_reference`). Returns ``(H, W, 3)`` linear radiance; deterministic for a given
    ``settings.seed``.
    """
    from prefilter.render.lighttex import split_lights
    from prefilter.render.pipeline import render_samples, surface_attributes

    lights, textured = split_lights(scene, "reference")
    q = len(lights.quads) + len(textured)

    def shade(g, u):
        a = surface_attributes(scene, g, filtered=False)
        uq = u.reshape(len(u), q, DIMS_PER_QUAD) if q else np.zeros((len(g.hit), 0, 5))
        return shade_reference(g.position, a["t"], a["b"], a["n"], g.view, a["alpha_x"],
                               a["alpha_y"], a["base_color"], a["f0"], lights, uq,
                               textured=textured)

    return render_samples(scene, settings, shade, random_dims=q * DIMS_PER_QUAD,
                          stratified=True, desc="reference")


# --------------------------------------------------------------------------------------------
# Numba kernel: the same estimator per sample, no temporaries (estimate_quad is its reference)
# --------------------------------------------------------------------------------------------


@njit_serial
def _lambda(ax, ay, x, y, z):
    a2 = ((ax * x) ** 2 + (ay * y) ** 2) / max(z * z, 1e-300)
    return a2 / (1.0 + math.sqrt(1.0 + a2)) / 2.0


@njit_serial
def _ggx_d(ax, ay, x, y, z):
    if z <= 0.0:
        return 0.0
    t = (x / ax) ** 2 + (y / ay) ** 2 + z * z
    return 1.0 / (math.pi * ax * ay * t * t)


@njit_serial
def _brdf_pdf(wox, woy, woz, wix, wiy, wiz, ax, ay, base, f0, p_spec, f_out):
    """Writes the cosine-weighted BRDF (rgb) into ``f_out``; returns the mixture pdf."""
    hx, hy, hz = wox + wix, woy + wiy, woz + wiz
    hn = math.sqrt(hx * hx + hy * hy + hz * hz)
    if hn > 1e-12:
        hx, hy, hz = hx / hn, hy / hn, hz / hn
    else:
        hx, hy, hz = 0.0, 0.0, 1.0
    lam_o = _lambda(ax, ay, wox, woy, woz)
    d = _ggx_d(ax, ay, hx, hy, hz)
    spec = 0.0
    if woz > 0.0 and wiz > 0.0:
        spec = d / (1.0 + lam_o + _lambda(ax, ay, wix, wiy, wiz)) / (4.0 * woz)
    c = min(max(wix * hx + wiy * hy + wiz * hz, 0.0), 1.0)
    c5 = (1.0 - c) ** 5
    cos_i = max(wiz, 0.0)
    for k in range(3):
        f_out[k] = base[k] / math.pi * cos_i + (f0[k] + (1.0 - f0[k]) * c5) * spec
    # Density of a reflected visible normal (pdf_reflect) and of the cosine lobe.
    doth = wox * hx + woy * hy + woz * hz
    p_s = 0.0
    if doth > 1e-12 and woz > 0.0:
        p_s = (d * doth / (1.0 + lam_o) / woz) / (4.0 * doth)
    return p_spec * p_s + (1.0 - p_spec) * cos_i / math.pi


@njit_parallel
def _estimate_quad_kernel(pos, ts, bs, ns, wo, ax, ay, base, f0, verts, normal, area, u, out, hit):
    """``out[i, 0]`` / ``out[i, 1]``: the light- and BRDF-sample terms (rgb, untextured);
    ``hit[i, 0]`` / ``hit[i, 1]``: their points on the light (for the light texture)."""
    n = pos.shape[0]
    tri1 = 0.5 * math.sqrt(
        ((verts[1, 1] - verts[0, 1]) * (verts[2, 2] - verts[0, 2])
         - (verts[1, 2] - verts[0, 2]) * (verts[2, 1] - verts[0, 1])) ** 2
        + ((verts[1, 2] - verts[0, 2]) * (verts[2, 0] - verts[0, 0])
           - (verts[1, 0] - verts[0, 0]) * (verts[2, 2] - verts[0, 2])) ** 2
        + ((verts[1, 0] - verts[0, 0]) * (verts[2, 1] - verts[0, 1])
           - (verts[1, 1] - verts[0, 1]) * (verts[2, 0] - verts[0, 0])) ** 2)
    p1 = tri1 / area
    for i in prange(n):
        f = np.empty(3)
        wox, woy, woz = wo[i, 0], wo[i, 1], wo[i, 2]
        axi, ayi = ax[i], ay[i]
        # Lobe selection probability (specular_probability).
        c5 = (1.0 - min(max(woz, 0.0), 1.0)) ** 5
        s = 0.0
        dsum = 0.0
        for k in range(3):
            s += (f0[i, k] + (1.0 - f0[i, k]) * c5) / 3.0
            dsum += base[i, k] / 3.0
        tot = s + dsum
        p_spec = min(max(s / tot, 0.05), 1.0) if tot > 0.0 else 0.5
        acc0 = 0.0
        acc1 = 0.0
        acc2 = 0.0
        # -- light sample: uniform on the area (sample_quad_area) --
        u0 = u[i, 0]
        if u0 < p1:
            u0 = u0 / p1
            b_i, c_i = 1, 2
        else:
            u0 = (u0 - p1) / (1.0 - p1) if p1 < 1.0 else 0.0
            b_i, c_i = 2, 3
        u0 = min(max(u0, 0.0), 1.0)
        su = math.sqrt(u0)
        b0 = 1.0 - su
        b1 = u[i, 1] * su
        b2 = 1.0 - b0 - b1
        dx = verts[0, 0] + b1 * (verts[c_i, 0] - verts[0, 0]) + b2 * (verts[b_i, 0] - verts[0, 0])
        dy = verts[0, 1] + b1 * (verts[c_i, 1] - verts[0, 1]) + b2 * (verts[b_i, 1] - verts[0, 1])
        dz = verts[0, 2] + b1 * (verts[c_i, 2] - verts[0, 2]) + b2 * (verts[b_i, 2] - verts[0, 2])
        hit[i, 0, 0], hit[i, 0, 1], hit[i, 0, 2] = dx, dy, dz
        dx -= pos[i, 0]
        dy -= pos[i, 1]
        dz -= pos[i, 2]
        dist2 = dx * dx + dy * dy + dz * dz
        dist = math.sqrt(dist2)
        if dist > 1e-12:
            dx, dy, dz = dx / dist, dy / dist, dz / dist
            cos_l = -(dx * normal[0] + dy * normal[1] + dz * normal[2])
            if cos_l > 1e-12:
                pl = dist2 / (area * cos_l)
                lx = dx * ts[i, 0] + dy * ts[i, 1] + dz * ts[i, 2]
                ly = dx * bs[i, 0] + dy * bs[i, 1] + dz * bs[i, 2]
                lz = dx * ns[i, 0] + dy * ns[i, 1] + dz * ns[i, 2]
                ln = math.sqrt(lx * lx + ly * ly + lz * lz)
                lx, ly, lz = lx / ln, ly / ln, lz / ln
                pb = _brdf_pdf(wox, woy, woz, lx, ly, lz, axi, ayi, base[i], f0[i], p_spec, f)
                den = pl + pb
                if den > 0.0:
                    acc0 += f[0] / den
                    acc1 += f[1] / den
                    acc2 += f[2] / den
        out[i, 0, 0] = acc0
        out[i, 0, 1] = acc1
        out[i, 0, 2] = acc2
        acc0 = 0.0
        acc1 = 0.0
        acc2 = 0.0
        hit[i, 1, 0], hit[i, 1, 1], hit[i, 1, 2] = pos[i, 0], pos[i, 1], pos[i, 2]
        # -- BRDF sample: GGX visible normal (Heitz 2018) reflected, or cosine --
        if u[i, 4] < p_spec:
            vx, vy, vz = axi * wox, ayi * woy, woz
            vn = math.sqrt(vx * vx + vy * vy + vz * vz)
            vx, vy, vz = vx / vn, vy / vn, vz / vn
            lensq = vx * vx + vy * vy
            if lensq > 1e-14:
                inv = 1.0 / math.sqrt(lensq)
                t1x, t1y, t1z = -vy * inv, vx * inv, 0.0
            else:
                t1x, t1y, t1z = 1.0, 0.0, 0.0
            t2x = vy * t1z - vz * t1y
            t2y = vz * t1x - vx * t1z
            t2z = vx * t1y - vy * t1x
            r = math.sqrt(u[i, 2])
            phi = 2.0 * math.pi * u[i, 3]
            q1 = r * math.cos(phi)
            q2 = r * math.sin(phi)
            sw = 0.5 * (1.0 + vz)
            q2 = (1.0 - sw) * math.sqrt(max(0.0, 1.0 - q1 * q1)) + sw * q2
            q3 = math.sqrt(max(0.0, 1.0 - q1 * q1 - q2 * q2))
            mx = axi * (q1 * t1x + q2 * t2x + q3 * vx)
            my = ayi * (q1 * t1y + q2 * t2y + q3 * vy)
            mz = max(1e-12, q1 * t1z + q2 * t2z + q3 * vz)
            mn = math.sqrt(mx * mx + my * my + mz * mz)
            mx, my, mz = mx / mn, my / mn, mz / mn
            dot = wox * mx + woy * my + woz * mz
            bx, by, bz = 2.0 * dot * mx - wox, 2.0 * dot * my - woy, 2.0 * dot * mz - woz
        else:
            # Shirley-Chiu concentric disk lifted to the hemisphere (cosine_hemisphere).
            a = 2.0 * u[i, 2] - 1.0
            b = 2.0 * u[i, 3] - 1.0
            if a == 0.0 and b == 0.0:
                rr, ph = 0.0, 0.0
            elif abs(a) > abs(b):
                rr, ph = a, (math.pi / 4.0) * b / a
            else:
                rr, ph = b, math.pi / 2.0 - (math.pi / 4.0) * a / b
            bx, by = rr * math.cos(ph), rr * math.sin(ph)
            bz = math.sqrt(max(0.0, 1.0 - bx * bx - by * by))
        # World direction and its hit on the front of the quad (quad_light_pdf).
        wx = bx * ts[i, 0] + by * bs[i, 0] + bz * ns[i, 0]
        wy = bx * ts[i, 1] + by * bs[i, 1] + bz * ns[i, 1]
        wz = bx * ts[i, 2] + by * bs[i, 2] + bz * ns[i, 2]
        cos_l = -(wx * normal[0] + wy * normal[1] + wz * normal[2])
        if cos_l > 1e-12:
            t = ((verts[0, 0] - pos[i, 0]) * normal[0] + (verts[0, 1] - pos[i, 1]) * normal[1]
                 + (verts[0, 2] - pos[i, 2]) * normal[2]) / (-cos_l)
            if t > 0.0:
                hx = pos[i, 0] + t * wx
                hy = pos[i, 1] + t * wy
                hz = pos[i, 2] + t * wz
                inside = True
                for k in range(4):
                    k1 = (k + 1) % 4
                    ex = verts[k1, 0] - verts[k, 0]
                    ey = verts[k1, 1] - verts[k, 1]
                    ez = verts[k1, 2] - verts[k, 2]
                    px = hx - verts[k, 0]
                    py = hy - verts[k, 1]
                    pz = hz - verts[k, 2]
                    cr = ((ey * pz - ez * py) * normal[0] + (ez * px - ex * pz) * normal[1]
                          + (ex * py - ey * px) * normal[2])
                    if cr < 0.0:
                        inside = False
                if inside:
                    hit[i, 1, 0], hit[i, 1, 1], hit[i, 1, 2] = hx, hy, hz
                    plb = t * t / (area * cos_l)
                    pb = _brdf_pdf(wox, woy, woz, bx, by, bz, axi, ayi, base[i], f0[i], p_spec,
                                   f)
                    den = plb + pb
                    if den > 0.0:
                        acc0 += f[0] / den
                        acc1 += f[1] / den
                        acc2 += f[2] / den
        out[i, 1, 0] = acc0
        out[i, 1, 1] = acc1
        out[i, 1, 2] = acc2


def estimate_quad_fast(light, position, ts, bs, ns, wo, alpha_x, alpha_y, base_color, f0,
                       u) -> np.ndarray:
    """:func:`estimate_quad` as a Numba kernel (same random numbers, same estimate to rounding);
    the light texture, if any, is read afterwards at the two samples' points on the light."""
    n = len(position)
    geo = _geometry(light)

    def c(a, shape):
        return np.ascontiguousarray(np.broadcast_to(np.asarray(a, dtype=np.float64), shape))

    out = np.empty((n, 2, 3))
    hit = np.empty((n, 2, 3))
    _estimate_quad_kernel(c(position, (n, 3)), c(ts, (n, 3)), c(bs, (n, 3)), c(ns, (n, 3)),
                          c(wo, (n, 3)), c(alpha_x, (n,)), c(alpha_y, (n,)),
                          c(base_color, (n, 3)), c(f0, (n, 3)), geo.vertices, geo.normal,
                          float(geo.area), c(u, (n, 5)), out, hit)
    if getattr(light, "texture", None) is None:
        est = out[:, 0] + out[:, 1]
    else:
        est = (out[:, 0] * light_emission(light, hit[:, 0])
               + out[:, 1] * light_emission(light, hit[:, 1]))
    return est * light.radiance
