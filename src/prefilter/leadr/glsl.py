"""GLSL export of LEADR shading under point and directional lights (the ``leadr-point`` method).

The snippet is the per-sample body of :func:`prefilter.leadr.render.shade_leadr_delta` in float32:
slope moments ``E[s_x], E[s_y], E[s_x^2], E[s_y^2], E[s_x s_y]`` (the height map's moment mip
chain, filtered over the footprint by the caller) -> mean slope and covariance
(:func:`prefilter.leadr.maps.shading_stats` plus the micro roughness ``alpha^2 / 2`` per axis),
then per light the closed-form rough specular of supplemental 3.3
(:func:`prefilter.leadr.shading.point_light`, exact Smith ``Lambda`` of Gaussian slopes) times
Schlick's Fresnel, plus ``base_color`` times the Gaussian-grid diffuse of Algorithm 3 for one
light: Simplified Algorithm 3 with ``E(m) = <m, wl>`` times ``G2 / G1``
(:func:`prefilter.leadr.shading.diffuse_directional` with ``shadowing=True``). ``LEADR_TAPS``
is :data:`prefilter.leadr.render.POINT_FOOTPRINT_TAPS` for the caller's box filter of the
moments (the viewer's ``footprintBox``). The grid nodes
and weights are written into the snippet from :func:`prefilter.leadr.shading.gaussian_grid`, so
the GPU integrates on the same grid as Python.

GLSL has no ``erfc``: ``leadrErfc`` is the Chebyshev-fitted ``t exp(-x^2 + P(t))``,
``t = 1 / (1 + x / 2)`` (fractional error below 1.2e-7 for every ``x >= 0``; Press et al.,
*Numerical Recipes*, section 6.2), kept in the factored form ``exp(-a^2) (1 / (a sqrt(pi)) -
exp(P(t)) t) / 2`` for ``Lambda`` so that nothing underflows before the product.
"""

from __future__ import annotations

from pathlib import Path

from prefilter.fileio import write_text_atomic

__all__ = ["ERFC_COEFFS", "export_all", "glsl_source"]

#: ``erfc(x) = t exp(-x^2 + sum_k c_k t^k)``, ``t = 1 / (1 + x / 2)``, ``x >= 0``.
ERFC_COEFFS = (-1.26551223, 1.00002368, 0.37409196, 0.09678418, -0.18628806, 0.27886807,
               -1.13520398, 1.48851587, -0.82215223, 0.17087277)

_GLSL = """\
// LEADR mapping under point and directional lights (Dupuy, Heitz, Iehl, Poulin, Neyret,
// Ostromoukhov 2013; supplemental 3.3 and Simplified Algorithm 3), the body of
// prefilter.leadr.render.shade_leadr_delta (prefilter `leadr/glsl.py`). Local frame: z = the
// geometric normal.
const int LEADR_GRID = {n};
const float LEADR_P[{n}] = float[{n}]({nodes});
const float LEADR_W[{n}] = float[{n}]({weights});
const float LEADR_BASE_R2 = {base_r2:.9g};  // leadr.maps.MIN_BASE_ROUGHNESS^2
const float LEADR_ART_EPS = {eps:.9g}, LEADR_ART_W = {art_w:.9g};  // supplemental 3.7
const float LEADR_PI = 3.14159265358979;
// the caller's box filter of the moments: up to LEADR_TAPS^2 trilinear taps over the pixel
// footprint (leadr.render.FOOTPRINT_TAPS, footprint_moments)
const int LEADR_TAPS = {taps};

// Slope moments (A = E[sx], E[sy], E[sx^2], E[sy^2]; exy = E[sx sy]) and GGX alphas taken as
// Beckmann alphas -> mean slope and covariance (xx, yy, xy) (leadr.maps.shading_stats, eq. 8).
void leadrStats(vec4 A, float exy, vec2 alpha, out vec2 mu, out vec3 cov) {{
    mu = A.xy;
    float cxx = max(A.z - mu.x * mu.x, 0.0), cyy = max(A.w - mu.y * mu.y, 0.0);
    float bound = sqrt(cxx * cyy);
    cov = vec3(cxx + LEADR_BASE_R2 + 0.5 * alpha.x * alpha.x,
               cyy + LEADR_BASE_R2 + 0.5 * alpha.y * alpha.y,
               clamp(exy - mu.x * mu.y, -bound, bound));
}}

// exp(x^2) erfc(x) for x >= 0 (Numerical Recipes' Chebyshev fit, fractional error < 1.2e-7)
float leadrErfcx(float x) {{
    float t = 1.0 / (1.0 + 0.5 * x);
    return t * exp({poly});
}}

// Smith Lambda of non-centred Gaussian slopes (supplemental 3.2, exact form); false where it is
// infinite (w sees only the back of the mean surface).
bool leadrLambda(vec3 w, vec2 mu, vec3 cov, out float lam) {{
    float d = w.z - mu.x * w.x - mu.y * w.y;
    float s = sqrt(max(cov.x * w.x * w.x + 2.0 * cov.z * w.x * w.y + cov.y * w.y * w.y, 0.0));
    lam = 0.0;
    if (!(s > 0.0)) return d > 0.0;
    float a = d / (1.41421356 * s);
    if (!(a > 0.0)) return false;
    lam = max(0.5 * exp(-a * a) * (1.0 / (a * 1.77245385) - leadrErfcx(a)), 0.0);
    return true;
}}

// Rough specular per unit light radiance from wi, F = 1 (supplemental 3.3, leadr.point_light):
// (n.g / n.o) D(h) / (4 (1 + Lambda(wo) + Lambda(wi))) with the mean-surface area n.o.
float leadrSpecular(vec3 wo, vec3 wi, vec2 mu, vec3 cov) {{
    vec3 h = wo + wi;
    float hn = length(h);
    if (hn > 1e-12) h /= hn;
    if (!(h.z > 1e-12)) return 0.0;
    float dx = -h.x / h.z - mu.x, dy = -h.y / h.z - mu.y;
    float det = cov.x * cov.y - cov.z * cov.z;
    float q = (cov.y * dx * dx - 2.0 * cov.z * dx * dy + cov.x * dy * dy) / det;
    float h2 = h.z * h.z;
    float D = exp(-0.5 * q) / (2.0 * LEADR_PI * sqrt(det) * h2 * h2);
    float area = wo.z - mu.x * wo.x - mu.y * wo.y, lo, li;
    if (!(area > 0.0) || !leadrLambda(wo, mu, cov, lo) || !leadrLambda(wi, mu, cov, li))
        return 0.0;
    return D / (4.0 * area * (1.0 + lo + li));
}}

// Rough diffuse microfacets (albedo 1) lit from wl with unit radiance: the LEADR_GRID^2 Gaussian
// grid of Simplified Algorithm 3 plus the artificial micronormal (leadr.diffuse_directional).
float leadrDiffuse(vec3 wo, vec3 wl, vec2 mu, vec3 cov) {{
    float sx = sqrt(cov.x), sy = sqrt(cov.y);
    float r = cov.z / (sx * sy), r_ = sqrt(max(1.0 - r * r, 0.0));
    float num = 0.0, den = 0.0;
    for (int j = 0; j < LEADR_GRID; ++j) {{
        float x = mu.x + LEADR_P[j] * sx;
        for (int k = 0; k < LEADR_GRID; ++k) {{
            float y = mu.y + (LEADR_P[j] * r + LEADR_P[k] * r_) * sy;
            vec3 m = normalize(vec3(-x, -y, 1.0));
            float ws = LEADR_W[j] * LEADR_W[k] * max(dot(m, wo), 0.0) / m.z;
            num += ws * max(dot(m, wl), 0.0);
            den += ws;
        }}
    }}
    vec3 nb = normalize(vec3(-mu, 1.0));
    vec3 t = nb - dot(nb, wo) * LEADR_ART_EPS * wo;
    t /= max(length(t), 1e-30);
    float wa = LEADR_ART_W * max(dot(t, wo), 0.0), ra = max(dot(t, wl), 0.0);
    num += wa * ra;
    den += wa;
    return (den > 0.0 ? num / den : ra) / LEADR_PI;
}}

// Self-shadowing of the diffuse light from wi (leadr.shading.shadowing_ratio; supplemental 3.3,
// Algorithm 2): G2 / G1 = 1 / (1 + Lambda(wi) / (1 + Lambda(wo))); 1 when the mesosurface faces
// away from wo (Lambda(wo) infinite: never black), 0 for wi below it or below the geometric plane.
float leadrShadowing(vec3 wo, vec3 wi, vec2 mu, vec3 cov) {{
    float lo, li;
    if (!(wi.z > 0.0) || !leadrLambda(wi, mu, cov, li)) return 0.0;
    if (!leadrLambda(wo, mu, cov, lo)) return 1.0;
    return 1.0 / (1.0 + li / (1.0 + lo));
}}

// Radiance towards wo per unit irradiance from wi (point light: I / d^2; directional: E):
// specular times Schlick's Fresnel at the half vector, plus base * the shadowed diffuse
// (Algorithm 3 for one light).
vec3 leadrDelta(vec3 wo, vec3 wi, vec2 mu, vec3 cov, vec3 base, vec3 f0) {{
    float c = clamp(dot(normalize(wo + wi), wi), 0.0, 1.0);
    vec3 F = f0 + (1.0 - f0) * pow(1.0 - c, 5.0);
    return leadrSpecular(wo, wi, mu, cov) * F
        + base * (leadrDiffuse(wo, wi, mu, cov) * leadrShadowing(wo, wi, mu, cov));
}}
"""


def _float(v) -> str:
    s = f"{float(v):.9g}"
    return s if any(ch in s for ch in ".en") else s + ".0"  # GLSL: no int -> float in arrays


def _floats(x) -> str:
    return ", ".join(_float(v) for v in x)


def glsl_source(n: int | None = None) -> str:
    """The GLSL snippet (``leadr.glsl``) with the ``n x n`` grid of
    :func:`prefilter.leadr.shading.gaussian_grid` (default: ``render.DIFFUSE_GRID``, as
    ``leadr-point``)."""
    from prefilter.leadr.maps import MIN_BASE_ROUGHNESS
    from prefilter.leadr.render import DIFFUSE_GRID, POINT_FOOTPRINT_TAPS
    from prefilter.leadr.shading import ARTIFICIAL_EPS, ARTIFICIAL_WEIGHT, gaussian_grid

    p, w, _ = gaussian_grid(DIFFUSE_GRID if n is None else n)
    c = ERFC_COEFFS
    poly = f"{c[-1]:.9g}"
    for k in c[-2:0:-1]:
        poly = f"{k:.9g} + t * ({poly})"
    poly = f"{c[0]:.9g} + t * ({poly})"
    return _GLSL.format(n=len(p), nodes=_floats(p), weights=_floats(w), taps=POINT_FOOTPRINT_TAPS,
                        base_r2=MIN_BASE_ROUGHNESS**2, eps=ARTIFICIAL_EPS,
                        art_w=ARTIFICIAL_WEIGHT, poly=poly)


def export_all(out_dir) -> list[Path]:
    """Write ``leadr.glsl`` (:func:`glsl_source`) to ``out_dir``; returns the paths."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    g = out / "leadr.glsl"
    write_text_atomic(g, glsl_source())
    return [g]
