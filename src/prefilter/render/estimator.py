"""Monte Carlo estimation of the radiance a lobe reflects from a quad light: one MIS estimator
fed by scrambled Sobol points.

Estimator (Veach 1997, eq. 9.13, one sample per strategy): a light sample ``w_l`` (uniform in the
solid angle of a rectangle, Urena et al. 2013, else on the quad's area:
:func:`prefilter.render.lights.light_sample`) and a lobe sample ``w_b``
(:meth:`prefilter.lobe.Lobe.sample`), combined with the balance heuristic
``f(w) L(w) / (p_light(w) + p_lobe(w))`` or the power heuristic
``f(w) L(w) p_s(w) / (p_light(w)^2 + p_lobe(w)^2)`` (Veach 1997, eq. 9.14, beta = 2):
:func:`mis_quad` for any :class:`~prefilter.lobe.Lobe` over arrays, :func:`material_mis_kernel`
for the material lobe of the renderer (:class:`MaterialLobe`) in Numba, tested equal to it.
The Numba path takes a control variate (:func:`ltc_control`): the GGX LTC fit of the specular
lobe, whose polygon integral is exact, subtracted from the lobe at every sample and added back
analytically.

Sample points (:func:`owen_sobol`): the first ``2^m`` points of the Sobol sequence (Joe and Kuo
direction numbers, :class:`scipy.stats.qmc.Sobol`), their order shuffled and their coordinates
nested-uniform (Owen) scrambled per pixel with the hash of Laine and Karras as in Burley 2020
("Practical hash-based Owen scrambling", JCGT 9(4), listings 1-3; the hash of
Vegdahl 2021). Each point stays uniform on
``[0, 1)^d`` (the estimator is unbiased) while each pixel's set keeps the Sobol stratification
(errors fall faster than ``n^-1/2`` for integrands of bounded variation). Every sample block
(sub-pixel position; the light sample of one quad light; its lobe sample) uses the first two
Sobol dimensions, a (0, 2)-sequence, with its own scramble ("padding", Burley 2020 section 4), and
aligned runs of ``2^k`` shuffled points are themselves nets, so the ``k`` light/lobe pairs shaded
at one sub-pixel position are stratified too (each strategy's ``k`` points in its own square).
"""

from __future__ import annotations

import functools

import numpy as np

from prefilter.jit import kernel_array, njit_inline, njit_parallel, njit_serial, prange, serial
from prefilter.lobe import Lobe, sample_weight
from prefilter.microfacet import GGX, reflect
from prefilter.microfacet.fresnel import schlick, schlick_jit
from prefilter.microfacet.ggx import ggx_d_jit, ggx_lambda_jit, ggx_sample_vndf_jit
from prefilter.microfacet.ltc import ltc_density, ltc_lookup
from prefilter.render.lights import (
    light_pdf,
    light_sample,
    quad_arrays,
    quad_constants,
    quad_pdf_jit,
    quad_sample_jit,
    quad_setup_jit,
)
from prefilter.render.shading import brdf_cos
from prefilter.sphere.polygon import clip_to_horizon_jit, polygon_integral_jit
from prefilter.sphere.sampling import cosine_hemisphere, to_local, to_world

#: Uniforms per quad light per sample: light point (2) and lobe direction (2).
DIMS_PER_QUAD = 4

#: MIS heuristics of :func:`mis_quad` and the kernel.
HEURISTICS = ("balance", "power")

_M32 = 0xFFFFFFFF


# ------------------------------------------------------------------------ scrambled Sobol points


@functools.lru_cache(maxsize=16)
def sobol_base(m: int, dims: int) -> np.ndarray:
    """The first ``2^m`` unscrambled Sobol points in ``dims`` dimensions as 32-bit integers
    ``(2^m, dims)`` int64 (point ``k`` is ``base[k] / 2^32``)."""
    from scipy.stats import qmc

    x = qmc.Sobol(dims, scramble=False, bits=32).random_base2(m)
    return np.ascontiguousarray(np.rint(x * 2.0**32).astype(np.int64))


@njit_inline
def hash32(x):
    """A 32-bit integer hash (Wellons' ``lowbias32``) of ``x``'s low 32 bits."""
    x &= 0xFFFFFFFF
    x ^= x >> 16
    x = (x * 0x7FEB352D) & 0xFFFFFFFF
    x ^= x >> 15
    x = (x * 0x846CA68B) & 0xFFFFFFFF
    x ^= x >> 16
    return x


@njit_inline
def reverse32(x):
    """The 32 low bits of ``x`` in reverse order."""
    x = ((x >> 1) & 0x55555555) | ((x & 0x55555555) << 1)
    x = ((x >> 2) & 0x33333333) | ((x & 0x33333333) << 2)
    x = ((x >> 4) & 0x0F0F0F0F) | ((x & 0x0F0F0F0F) << 4)
    x = ((x >> 8) & 0x00FF00FF) | ((x & 0x00FF00FF) << 8)
    return ((x >> 16) & 0xFFFF) | ((x & 0xFFFF) << 16)


@njit_inline
def owen_scramble32(x, seed):
    """Nested uniform scramble of a 32-bit fixed-point number: bit ``k`` is flipped by a hash of
    the bits above it (Burley 2020, listing 3: a Laine-Karras-style permutation of the reversed
    bits, with the constants of Vegdahl 2021, "Building a better LK hash", whose low bits are
    uniform enough that pixel means of sharp features show no bias at 1024 points)."""
    x = reverse32(x)
    x ^= (x * 0x3D20ADEA) & 0xFFFFFFFF
    x = (x + seed) & 0xFFFFFFFF
    x = (x * ((seed >> 16) | 1)) & 0xFFFFFFFF
    x ^= (x * 0x05526C56) & 0xFFFFFFFF
    x ^= (x * 0x53A22864) & 0xFFFFFFFF
    return reverse32(x)


@njit_inline
def owen_sobol_pixel(key, pixel, seeds):
    """The scrambles of one pixel's set (see :func:`owen_sobol`): writes the coordinates'
    scramble seeds into ``seeds (dims,)`` and returns the shuffle's seed. ``key`` identifies the
    seed and the sample block."""
    s = hash32(key ^ hash32(pixel))
    for d in range(seeds.shape[0]):
        seeds[d] = hash32(s + 0x9E3779B9 * (d + 1))
    return hash32(s + 0x68E31DA4)


@njit_inline
def owen_sobol_index(j, shuffle, m):
    """Row of the Sobol table holding point ``j < 2^m`` of a pixel's set: the low ``m`` bits of
    a nested scramble of ``j`` (a permutation of ``[0, 2^m)``)."""
    return owen_scramble32(j, shuffle) & ((1 << m) - 1)


@njit_inline
def owen_sobol_coord(base, k, d, seeds):
    """Coordinate ``d`` of Sobol table row ``k``, scrambled by ``seeds[d]``, in ``[0, 1)``."""
    return owen_scramble32(base[k, d], seeds[d]) * (1.0 / 4294967296.0)


@njit_parallel
def owen_sobol_kernel(base, m, pixels, key, n, out):
    """``out[p, j]``: point ``j < n`` of pixel ``pixels[p]``'s scrambled set (see
    :func:`owen_sobol`); ``key`` identifies the seed and the sample block."""
    dims = out.shape[2]
    for p in prange(pixels.shape[0]):
        seeds = np.empty(dims, np.int64)
        shuffle = owen_sobol_pixel(key, pixels[p], seeds)
        for j in range(n):
            k = owen_sobol_index(j, shuffle, m)
            for d in range(dims):
                out[p, j, d] = owen_sobol_coord(base, k, d, seeds)


def owen_sobol(pixels, n: int, dims: int, seed: int, block: int) -> np.ndarray:
    """Uniforms ``(P, n, dims)``: for each pixel id of ``pixels (P,)`` (an image-wide index),
    ``n`` points of the ``dims``-dimensional Sobol sequence, shuffled and Owen scrambled by a
    hash of ``(seed, block, pixel)``.

    Each point is uniform on ``[0, 1)^dims``; the points of one pixel form a scrambled
    ``(t, m, s)``-net when ``n`` is a power of two (the first ``n`` of a shuffled net otherwise),
    and every aligned run of ``2^k`` of them is a net too. ``block`` numbers independent
    sample blocks (sub-pixel positions, each light): their scrambles are unrelated.
    """
    pixels = np.ascontiguousarray(pixels, dtype=np.int64).reshape(-1)
    m = max(0, int(np.ceil(np.log2(max(n, 1)))))
    base = sobol_base(m, dims)
    key = int(sobol_key(seed, block))
    out = np.empty((len(pixels), n, dims))
    serial(owen_sobol_kernel, len(pixels) * n)(base, m, pixels, key, n, out)
    return out


def sobol_key(seed: int, block: int) -> int:
    """A 32-bit key of ``(seed, block)`` (SeedSequence mixing: no structure left between keys)."""
    return int(np.random.SeedSequence([int(seed), int(block)]).generate_state(1)[0])


# -------------------------------------------------------------------------- the material lobe


def specular_probability(wo, base_color, f0) -> np.ndarray:
    """Probability ``(N,)`` of sampling the GGX lobe rather than the cosine lobe.

    Proportional to a rough estimate of each lobe's reflectance (Fresnel at the view vs the
    diffuse albedo); any value in (0, 1] keeps the estimator unbiased, this one lowers variance.
    """
    s = np.mean(schlick(f0, wo[:, 2, None]), axis=-1)
    d = np.mean(base_color, axis=-1)
    tot = s + d
    return np.where(tot > 0.0, np.clip(s / np.where(tot > 0, tot, 1.0), 0.05, 1.0), 0.5)


def select_remap(u0, p):
    """Lobe choice by ``u0 < p`` and ``u0`` rescaled to ``[0, 1)`` within the chosen branch, so
    one uniform picks the lobe and still drives its sample (keeps 2-D stratification)."""
    first = u0 < p
    return first, np.where(first, u0 / np.where(p > 0, p, 1.0),
                           (u0 - p) / np.where(p < 1, 1.0 - p, 1.0))


def sample_brdf(wo, u, alpha_x, alpha_y, p_spec) -> np.ndarray:
    """Directions ``(N, 3)`` (shading frame) from the BRDF sampling mixture, uniforms ``u (N, 2)``.

    With probability ``p_spec`` (chosen by ``u[:, 0]``, :func:`select_remap`): reflect a GGX
    visible normal (Heitz 2018); otherwise a cosine sample. Density :func:`pdf_brdf`.
    """
    spec_first, u0 = select_remap(u[:, 0], p_spec)
    uu = np.stack([np.clip(u0, 0.0, 1.0 - 2.0**-53), u[:, 1]], axis=-1)
    m = GGX(alpha_x, alpha_y).sample_vndf(wo, uu)
    spec = reflect(wo, m)
    diff = cosine_hemisphere(uu)
    return np.where(spec_first[:, None], spec, diff)


def pdf_brdf(wo, wi, alpha_x, alpha_y, p_spec) -> np.ndarray:
    """Solid-angle density ``(N,)`` of :func:`sample_brdf`."""
    p_s = GGX(alpha_x, alpha_y).pdf_reflect(wo, wi)
    p_d = np.maximum(wi[:, 2], 0.0) / np.pi
    return p_spec * p_s + (1.0 - p_spec) * p_d


class MaterialLobe(Lobe):
    """The renderer's material as a lobe: Lambertian ``base_color`` plus GGX ``(alpha_x,
    alpha_y)`` with Schlick Fresnel ``f0`` (:func:`prefilter.render.shading.brdf_cos`), sampled
    by the mixture :func:`sample_brdf` (GGX with probability :func:`specular_probability`).

    Batched over ``N`` shading points: ``alpha_x, alpha_y (N,)``, ``base_color, f0 (N, 3)``,
    directions ``(N, 3)``; :meth:`eval` is rgb ``(N, 3)``.
    """

    def __init__(self, alpha_x, alpha_y, base_color, f0, p_spec):
        self.alpha_x, self.alpha_y = alpha_x, alpha_y
        self.base_color, self.f0, self.p_spec = base_color, f0, p_spec

    @classmethod
    def for_view(cls, wo, alpha_x, alpha_y, base_color, f0) -> "MaterialLobe":
        return cls(alpha_x, alpha_y, base_color, f0, specular_probability(wo, base_color, f0))

    def eval(self, wo, wi) -> np.ndarray:
        return brdf_cos(wo, wi, self.alpha_x, self.alpha_y, self.base_color, self.f0)

    def pdf(self, wo, wi) -> np.ndarray:
        return pdf_brdf(wo, wi, self.alpha_x, self.alpha_y, self.p_spec)

    def sample(self, wo, u):
        wi = sample_brdf(wo, u, self.alpha_x, self.alpha_y, self.p_spec)
        return wi, sample_weight(self.eval(wo, wi), self.pdf(wo, wi))


class Lambert(Lobe):
    """A Lambertian lobe ``rho max(0, wi_z) / pi``, cosine sampled (weight ``rho``); ``rho``
    scalar or ``(N,)``."""

    def __init__(self, rho=1.0):
        self.rho = rho

    def eval(self, wo, wi) -> np.ndarray:
        return self.rho * np.maximum(np.asarray(wi)[..., 2], 0.0) / np.pi

    def pdf(self, wo, wi) -> np.ndarray:
        return np.maximum(np.asarray(wi)[..., 2], 0.0) / np.pi

    def sample(self, wo, u):
        wi = cosine_hemisphere(u)
        return wi, sample_weight(self.eval(wo, wi), self.pdf(wo, wi))

    def albedo(self, wo) -> np.ndarray:
        return np.broadcast_to(np.asarray(self.rho, dtype=np.float64), np.shape(wo)[:-1])


# ------------------------------------------------------------------------ the MIS estimator


def mis_weight(p_s, p_other, heuristic: str):
    """MIS weight divided by the sampling density: ``1 / (p_s + p_o)`` (balance) or
    ``p_s / (p_s^2 + p_o^2)`` (power); 0 where ``p_s = 0``."""
    if heuristic not in HEURISTICS:
        raise ValueError(f"heuristic: expected one of {HEURISTICS}, got {heuristic!r}")
    if heuristic == "balance":
        den = p_s + p_other
        num = np.ones_like(p_s)
    else:
        den = p_s * p_s + p_other * p_other
        num = p_s
    ok = (p_s > 0.0) & (den > 0.0)
    return np.where(ok, num / np.where(ok, den, 1.0), 0.0)


def mis_directions(lobe: Lobe, wo, wl, p_light, light_pdf_at, u_lobe, *,
                   heuristic: str = "balance"):
    """The two terms of one-sample-per-strategy MIS for any light, before its radiance.

    Parameters
    ----------
    lobe : Lobe
        Batched over ``N`` points (``eval (N,)`` or ``(N, C)``).
    wo : (N, 3)
        Views in the shading frame.
    wl : (N, 3)
        The light strategy's sampled directions (shading frame), with densities
        ``p_light (N,)`` (0 where the light does not emit).
    light_pdf_at : callable((N, 3) shading-frame directions) -> (N,)
        The light strategy's density at the lobe's samples.
    u_lobe : (N, 2)
        Uniforms of the lobe samples.

    Returns
    -------
    t_light : (N,) or (N, C)
        ``f(wl) w_light(wl) / p_light(wl)``: times the radiance from ``wl``, the light term.
    wb : (N, 3)
        The lobe's sampled directions.
    t_lobe : (N,) or (N, C)
        ``f(wb) w_lobe(wb) / p_lobe(wb)``, 0 where ``light_pdf_at(wb) = 0`` (no emission).
    """
    f_l = np.asarray(lobe.eval(wo, wl))
    w_l = mis_weight(p_light, lobe.pdf(wo, wl), heuristic)
    wb, _ = lobe.sample(wo, u_lobe)
    p_lb = light_pdf_at(wb)
    f_b = np.asarray(lobe.eval(wo, wb))
    w_b = np.where(p_lb > 0.0, mis_weight(lobe.pdf(wo, wb), p_lb, heuristic), 0.0)
    if f_l.ndim > 1:
        w_l, w_b = w_l[:, None], w_b[:, None]
    return f_l * w_l, wb, f_b * w_b


def mis_quad(lobe: Lobe, light, position, ts, bs, ns, wo, u, *, heuristic: str = "balance"):
    """:func:`mis_directions` for a quad light sampled by
    :func:`prefilter.render.lights.light_sample` (uniform in solid angle for rectangles, else on
    the area).

    Parameters
    ----------
    lobe : Lobe
        Any lobe, batched over the ``N`` shading points (``eval (N,)`` or ``(N, C)``).
    light : QuadLight
        The quad's geometry; its radiance is not applied.
    position, ts, bs, ns : (N, 3)
        Shading points and their shading frames.
    wo : (N, 3)
        View directions in the shading frame.
    u : (N, 4)
        Uniforms: light sample (2), lobe direction (2).

    Returns
    -------
    terms : (N, 2, C) or (N, 2)
        The light-sample and lobe-sample terms (sum them for the estimate).
    points : (N, 2, 3)
        Their points on the light (the shading point where a lobe sample misses the light), to
        read a light texture at.
    """
    wl, pl, pt_l = light_sample(light, position, u[:, 0:2])
    wl_loc = to_local(wl, ts, bs, ns)
    wl_loc /= np.linalg.norm(wl_loc, axis=-1, keepdims=True)
    hits = {}

    def pdf_at(w):
        p, hits["pt"] = light_pdf(light, position, to_world(w, ts, bs, ns))
        return p

    t_l, wb_loc, t_b = mis_directions(lobe, wo, wl_loc, pl, pdf_at, u[:, 2:4],
                                      heuristic=heuristic)
    return np.stack([t_l, t_b], axis=1), np.stack([pt_l, hits["pt"]], axis=1)


# --------------------------------------------------------------- the material lobe in Numba


@njit_inline
def material_eval_pdf(wox, woy, woz, lam_o, wix, wiy, wiz, ax, ay, base, f0, p_spec):
    """:meth:`MaterialLobe.eval` (rgb) and :meth:`MaterialLobe.pdf`: ``(f_r, f_g, f_b, pdf)``
    (scalars, not an output array: stores to an array that may alias the inputs make the
    compiler reload them).
    ``lam_o``: Smith's ``Lambda`` of the view (per shading point, not per direction)."""
    hx, hy, hz = wox + wix, woy + wiy, woz + wiz
    hn = np.sqrt(hx * hx + hy * hy + hz * hz)
    if hn > 1e-12:
        hx, hy, hz = hx / hn, hy / hn, hz / hn
    else:
        hx, hy, hz = 0.0, 0.0, 1.0
    d = ggx_d_jit(ax, ay, hx, hy, hz) if hz > 0.0 else 0.0
    spec = 0.0
    if woz > 0.0 and wiz > 0.0:
        spec = d / (1.0 + lam_o + ggx_lambda_jit(ax, ay, wix, wiy, wiz)) / (4.0 * woz)
    c = min(max(wix * hx + wiy * hy + wiz * hz, 0.0), 1.0)
    cos_i = max(wiz, 0.0)
    d_cos = cos_i / np.pi
    # density of a reflected visible normal (GGX.pdf_reflect) and of the cosine lobe
    doth = wox * hx + woy * hy + woz * hz
    p_s = 0.0
    if doth > 1e-12 and woz > 0.0:
        p_s = (d * doth / (1.0 + lam_o) / woz) / (4.0 * doth)
    return (base[0] * d_cos + schlick_jit(f0[0], c) * spec,
            base[1] * d_cos + schlick_jit(f0[1], c) * spec,
            base[2] * d_cos + schlick_jit(f0[2], c) * spec,
            p_spec * p_s + (1.0 - p_spec) * d_cos)


@njit_inline
def mis_over(p_s, p_o, power):
    """:func:`mis_weight` for scalars."""
    if power:
        den = p_s * p_s + p_o * p_o
        return p_s / den if (p_s > 0.0 and den > 0.0) else 0.0
    den = p_s + p_o
    return 1.0 / den if (p_s > 0.0 and den > 0.0) else 0.0


@njit_inline
def specular_probability_jit(woz, base, f0):
    """:func:`specular_probability` of one shading point: ``woz`` the view's cosine,
    ``base, f0 (3,)``."""
    c0 = min(max(woz, 0.0), 1.0)
    s = 0.0
    dsum = 0.0
    for k in range(3):
        s += schlick_jit(f0[k], c0) / 3.0
        dsum += base[k] / 3.0
    tot = s + dsum
    return min(max(s / tot, 0.05), 1.0) if tot > 0.0 else 0.5


@njit_inline
def ltc_control(wox, woy, woz, ax, ay, f0, axis_t, axis_r, tab_m, tab_mag, tab_fres, mm, cvar):
    """The control variate of :func:`material_mis_pair` at one shading point: the isotropic GGX
    LTC table's fit of the specular lobe, ``g (rgb) D_M`` (Heitz et al. 2016; Schlick through the
    table's ``(n, f5)``: ``g = f0 (n - f5) + f5``), for ``alpha = sqrt(ax ay)``. Writes
    ``cvar (13,)``: the LTC in ``cvar[:10]`` (:func:`prefilter.microfacet.ltc.ltc_lookup`,
    scratch ``mm``) and ``g`` in ``cvar[10:13]``, zeros (no control variate) where the table does
    not fit the lobe: ``alpha`` below its range, anisotropy beyond 2:1, or a singular matrix.
    Returns whether ``g`` is not zero. Any ``g`` leaves the estimate unbiased (its exact
    integral is added back, :func:`ltc_control_integral`); a close one removes most of the
    variance of the light's edges crossing the lobe."""
    for c in range(3):
        cvar[10 + c] = 0.0
    alpha = np.sqrt(ax * ay)
    if alpha < axis_r[0] * axis_r[0] or max(ax, ay) > 2.0 * min(ax, ay):
        return False
    ok, mag, fres = ltc_lookup(wox, woy, woz, alpha, axis_t, axis_r, tab_m, tab_mag, tab_fres,
                               mm, cvar)
    if not ok:
        return False
    for c in range(3):
        cvar[10 + c] = f0[c] * (mag - fres) + fres
    return cvar[10] != 0.0 or cvar[11] != 0.0 or cvar[12] != 0.0


@njit_inline
def ltc_control_integral(px, py, pz, ts, bs, ns, verts, cvar, P, C):
    """``int D_M`` over the quad ``verts (4, 3)`` seen from ``(px, py, pz)`` (frame ``ts, bs,
    ns``), cut at the shading horizon first as the estimator is (its samples below it count 0):
    the exact integral of the control variate's lobe (:func:`ltc_control`; one-sided, Heitz et
    al. 2016, eq. 11). Scratch ``P (4, 3)``, ``C (5, 3)``."""
    for v in range(4):
        dx, dy, dz = verts[v, 0] - px, verts[v, 1] - py, verts[v, 2] - pz
        P[v, 0] = dx * ts[0] + dy * ts[1] + dz * ts[2]
        P[v, 1] = dx * bs[0] + dy * bs[1] + dz * bs[2]
        P[v, 2] = dx * ns[0] + dy * ns[1] + dz * ns[2]
    clip_to_horizon_jit(P, 4, C)
    return polygon_integral_jit(cvar, C, 5)


# Called, not inlined: inlined into the fused reference kernel it nearly doubled that kernel's
# compile time for no measurable speed.
@njit_serial
def material_mis_pair(px, py, pz, ts, bs, ns, wox, woy, woz, lam_o, ax, ay, base, f0, p_spec,
                      verts, normal, area, p1, d_plane, rect, sr, u0, u1, u2, u3, power, cvar):
    """One light/lobe sample pair of :func:`mis_quad` for :class:`MaterialLobe` at the shading
    point ``(px, py, pz)`` with frame ``ts, bs, ns (3,)``, view ``wo`` in that frame, its Smith
    ``lam_o`` and the lobe choice probability ``p_spec`` (:func:`specular_probability_jit`); the
    quad light ``verts (4, 3)``, ``normal (3,)``, ``area``, ``rect`` with
    :func:`prefilter.render.lights.quad_constants` ``p1, d_plane`` and the point's sampling state
    ``sr`` (:func:`prefilter.render.lights.quad_setup_jit`); uniforms ``u0, u1`` (light sample),
    ``u2, u3`` (lobe direction). Control variate ``cvar (13,)`` (:func:`ltc_control`): its
    ``g (rgb) D_M(w)`` is subtracted from the lobe at both samples (``g = 0``: none).

    Returns 12 scalars: the light-sample term (rgb, before the light's radiance; 0 where the
    sample adds nothing), the lobe-sample term (rgb), and their points on the light (the shading
    point where the lobe's ray misses it).
    """
    tl0 = tl1 = tl2 = tb0 = tb1 = tb2 = 0.0
    g0, g1, g2 = cvar[10], cvar[11], cvar[12]
    # -- light sample (lights.light_sample) --
    dx, dy, dz, pl, lx, ly, lz = quad_sample_jit(px, py, pz, verts, normal, area, p1, rect, sr,
                                                 u0, u1)
    if pl > 0.0:
        wx = dx * ts[0] + dy * ts[1] + dz * ts[2]
        wy = dx * bs[0] + dy * bs[1] + dz * bs[2]
        wz = dx * ns[0] + dy * ns[1] + dz * ns[2]
        wn = np.sqrt(wx * wx + wy * wy + wz * wz)
        wx, wy, wz = wx / wn, wy / wn, wz / wn
        if wz > 0.0:  # below the shading horizon the lobe is 0
            f_r, f_g, f_b, pb = material_eval_pdf(wox, woy, woz, lam_o, wx, wy, wz, ax, ay, base,
                                                  f0, p_spec)
            if g0 != 0.0 or g1 != 0.0 or g2 != 0.0:
                dm = ltc_density(cvar, wx, wy, wz)
                f_r, f_g, f_b = f_r - g0 * dm, f_g - g1 * dm, f_b - g2 * dm
            w = mis_over(pl, pb, power)
            tl0, tl1, tl2 = f_r * w, f_g * w, f_b * w
    # -- lobe sample: GGX visible normal reflected, or cosine (sample_brdf) --
    if u2 < p_spec:
        ua = min(u2 / p_spec, 1.0 - 2.0**-53)
        mx, my, mz = ggx_sample_vndf_jit(ax, ay, wox, woy, woz, ua, u3)
        dot = wox * mx + woy * my + woz * mz
        bx, by, bz = 2.0 * dot * mx - wox, 2.0 * dot * my - woy, 2.0 * dot * mz - woz
    else:
        ua = min((u2 - p_spec) / (1.0 - p_spec), 1.0 - 2.0**-53)
        bx, by, bz = cosine_hemisphere_jit(ua, u3)
    # world direction and its hit on the front of the quad (lights.light_pdf)
    wx = bx * ts[0] + by * bs[0] + bz * ns[0]
    wy = bx * ts[1] + by * bs[1] + bz * ns[1]
    wz = bx * ts[2] + by * bs[2] + bz * ns[2]
    plb, hx, hy, hz = quad_pdf_jit(px, py, pz, wx, wy, wz, verts, normal, area, d_plane, sr)
    if plb > 0.0 and bz > 0.0:
        f_r, f_g, f_b, pb = material_eval_pdf(wox, woy, woz, lam_o, bx, by, bz, ax, ay, base, f0,
                                              p_spec)
        if g0 != 0.0 or g1 != 0.0 or g2 != 0.0:
            dm = ltc_density(cvar, bx, by, bz)
            f_r, f_g, f_b = f_r - g0 * dm, f_g - g1 * dm, f_b - g2 * dm
        w = mis_over(pb, plb, power)
        tb0, tb1, tb2 = f_r * w, f_g * w, f_b * w
    return tl0, tl1, tl2, tb0, tb1, tb2, lx, ly, lz, hx, hy, hz


@njit_parallel
def material_mis_kernel(pos, ts, bs, ns, wo, ax, ay, base, f0, verts, normal, area, rect,
                        is_rect, u, power, keep, cv, axis_t, axis_r, tab_m, tab_mag, tab_fres,
                        acc, out, hit):
    """:func:`mis_quad` for :class:`MaterialLobe` over ``K`` sample pairs per shading point
    (:func:`material_mis_pair` each).

    ``u (N, K, 4)``; writes ``acc[i]`` (rgb), the sum of all terms of point ``i``, and with
    ``keep`` also ``out[i, k, s]`` (rgb) and ``hit[i, k, s]`` (point on the light) for the
    light (``s = 0``) and lobe (``s = 1``) samples of pair ``k``. With ``cv``, the LTC table
    ``axis_t, axis_r, tab_m, tab_mag, tab_fres`` is the control variate (:func:`ltc_control`)
    and ``acc`` holds ``K`` times its integral besides the terms.
    """
    n = pos.shape[0]
    npairs = u.shape[1]
    p1, d_plane = quad_constants(verts, normal, area)
    for i in prange(n):
        p_spec = specular_probability_jit(wo[i, 2], base[i], f0[i])
        lam_o = ggx_lambda_jit(ax[i], ay[i], wo[i, 0], wo[i, 1], wo[i, 2])
        sr = quad_setup_jit(pos[i, 0], pos[i, 1], pos[i, 2], rect, is_rect)
        cvar = np.zeros(13)
        for k in range(3):
            acc[i, k] = 0.0
        if cv and ltc_control(wo[i, 0], wo[i, 1], wo[i, 2], ax[i], ay[i], f0[i], axis_t, axis_r,
                              tab_m, tab_mag, tab_fres, np.empty(9), cvar):
            e = npairs * ltc_control_integral(pos[i, 0], pos[i, 1], pos[i, 2], ts[i], bs[i],
                                              ns[i], verts, cvar, np.empty((4, 3)),
                                              np.empty((5, 3)))
            for k in range(3):
                acc[i, k] = cvar[10 + k] * e
        for j in range(npairs):
            r = material_mis_pair(pos[i, 0], pos[i, 1], pos[i, 2], ts[i], bs[i], ns[i], wo[i, 0],
                                  wo[i, 1], wo[i, 2], lam_o, ax[i], ay[i], base[i], f0[i],
                                  p_spec, verts, normal, area, p1, d_plane, rect, sr, u[i, j, 0],
                                  u[i, j, 1], u[i, j, 2], u[i, j, 3], power, cvar)
            for k in range(3):
                acc[i, k] += r[k]
                acc[i, k] += r[3 + k]
            if keep:
                for q in range(2):
                    for k in range(3):
                        out[i, j, q, k] = r[3 * q + k]
                        hit[i, j, q, k] = r[6 + 3 * q + k]


@njit_inline
def cosine_hemisphere_jit(u1, u2):
    """:func:`prefilter.sphere.sampling.cosine_hemisphere` for one pair of uniforms:
    Shirley-Chiu concentric disk lifted to the hemisphere."""
    a = 2.0 * u1 - 1.0
    b = 2.0 * u2 - 1.0
    if a == 0.0 and b == 0.0:
        r, ph = 0.0, 0.0
    elif abs(a) > abs(b):
        r, ph = a, (np.pi / 4.0) * b / a
    else:
        r, ph = b, np.pi / 2.0 - (np.pi / 4.0) * a / b
    x, y = r * np.cos(ph), r * np.sin(ph)
    return x, y, np.sqrt(max(0.0, 1.0 - x * x - y * y))


def material_mis(light, position, ts, bs, ns, wo, alpha_x, alpha_y, base_color, f0, u, *,
                 heuristic: str = "balance", keep: bool = True, control=None):
    """:func:`mis_quad` of :class:`MaterialLobe` by :func:`material_mis_kernel` for ``K``
    sample pairs per point: ``u (N, K, 4)`` -> ``total (N, 3)`` (the sum of all terms) and,
    with ``keep``, ``terms (N, K, 2, 3)``, ``points (N, K, 2, 3)`` (same numbers as
    :func:`mis_quad` to rounding; ``None`` without ``keep``).

    ``control``: ``None``, or the LTC table arrays (:func:`control_arrays`) of the control
    variate (:func:`ltc_control`; then ``total`` includes ``K`` times its integral and the terms
    are of the difference: not with ``keep``)."""
    if heuristic not in HEURISTICS:
        raise ValueError(f"heuristic: expected one of {HEURISTICS}, got {heuristic!r}")
    if control is not None and keep:
        raise ValueError("control: a control variate needs keep=False (the terms are of the "
                         "difference, so a light texture cannot weigh them)")
    n, k = u.shape[0], u.shape[1]

    def c(a, shape):
        return kernel_array(a, shape, np.float64)

    total = np.empty((n, 3))
    shape = (n, k, 2, 3) if keep else (1, 1, 2, 3)
    terms = np.empty(shape)
    points = np.empty(shape)
    serial(material_mis_kernel, n * k)(
        c(position, (n, 3)), c(ts, (n, 3)), c(bs, (n, 3)), c(ns, (n, 3)), c(wo, (n, 3)),
        c(alpha_x, (n,)), c(alpha_y, (n,)), c(base_color, (n, 3)), c(f0, (n, 3)),
        *quad_arrays(light), c(u, (n, k, DIMS_PER_QUAD)), heuristic == "power", keep,
        control is not None, *(NO_CONTROL if control is None else control), total, terms, points)
    return (total, terms, points) if keep else (total, None, None)


#: Table arrays standing for "no control variate" (same types as :func:`control_arrays`).
NO_CONTROL = (np.zeros(2), np.zeros(2), np.zeros((2, 2, 3, 3)), np.zeros((2, 2)),
              np.zeros((2, 2)))


def control_arrays(table) -> tuple:
    """The arrays of an isotropic GGX LTC table (``axis_t, axis_r, M, magnitude, fresnel`` of
    :class:`prefilter.ltc.table.GGXTable`) as the kernels take them (contiguous float64)."""
    return tuple(np.ascontiguousarray(getattr(table, a), dtype=np.float64)
                 for a in ("axis_t", "axis_r", "M", "magnitude", "fresnel"))
