"""GLSL export of LEADR shading under an environment map (``leadr-env``, ``leadr-irradiance``).

The snippet ``leadr_env.glsl`` holds the per-sample environment terms of
:func:`prefilter.leadr.render.shade_leadr_env` and
:func:`~prefilter.leadr.render.shade_leadr_irradiance` (``algorithm=full``) in float32, on top of
``leadr.glsl`` (:mod:`prefilter.leadr.glsl`: the statistics, Smith ``Lambda``, the 5 x 5
diffuse grid and ``G2 / G1``), which it follows:

- ``leadrEnvSpecular``: Algorithm 1 with self-shadowing on the ``N x N`` Gaussian grid
  (:func:`prefilter.leadr.kernels.env_specular_kernel`; ``N`` =
  :data:`~prefilter.leadr.render.ENV_GRID` or :data:`~prefilter.leadr.render.ENV_GRID_ROUGH`
  per footprint as :func:`~prefilter.leadr.render.specular_grid_size`), the artificial
  micronormal of supplemental 3.7, per-sample LOD ``log2(J cell / Omega_texel) / 2``
  (supplemental eqs. 1, 3) and trilinear reads of the lat-long environment (``leadrEnv``: an
  RGBA32F texture whose mip levels are :class:`prefilter.leadr.envmap.EnvMap`'s
  solid-angle-weighted levels, read with ``texelFetch``: wrap in phi, clamp in theta, as
  :mod:`prefilter.texture.fetch`);
- ``leadrEnvDiffuse``: Algorithm 3's grid on the exact irradiance map (``leadrIrradiance``: the
  node grid of :class:`prefilter.leadr.envmap.IrradianceMap`, read bilinearly as its ``lookup``)
  plus the self-shadowing loss :func:`prefilter.leadr.shading.diffuse_shadowing` (quadrature over
  the texels of the environment level with at most :data:`~prefilter.leadr.shading.SHADOW_ROWS`
  rows, twice that for footprints smoother than
  :data:`~prefilter.leadr.shading.SHADOW_FINE_SIGMA`), clamped at 0.

Grid nodes, weights and spacings are written in from
:func:`prefilter.leadr.shading.gaussian_grid` and the frame change from
:data:`prefilter.leadr.envmap.ENV_FROM_WORLD`, so the GPU integrates on the grids Python uses.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from prefilter.fileio import write_text_atomic

__all__ = ["env_textures", "export_all", "glsl_source"]

_GLSL = """\
// LEADR mapping under an environment map (Dupuy et al. 2013, Algorithms 1 and 3 with
// self-shadowing; supplemental 3.4-3.7): the environment terms of prefilter.leadr.render's
// shade_leadr_env / shade_leadr_irradiance (prefilter `leadr/glsl_env.py`). Needs leadr.glsl.
uniform highp sampler2D leadrEnv;         // lat-long radiance, mip level l = EnvMap.levels[l]
uniform highp sampler2D leadrIrradiance;  // IrradianceMap.values: R + 1 node rows, 2R columns
uniform int leadrEnvLevels;               // levels of leadrEnv; 0: no environment light
uniform float leadrEnvTexel;              // EnvMap.texel_solid_angle

const mat3 LEADR_ENV_FROM_WORLD = mat3({env_from_world});  // envmap.ENV_FROM_WORLD
const int LEADR_ENV_N = {n}, LEADR_ENV_N_ROUGH = {n_rough};  // render.ENV_GRID, ENV_GRID_ROUGH
const float LEADR_ROUGH_VAR = {rough_var:.9g};  // render.ROUGH_SIGMA^2
const float LEADR_ENV_P[{n}] = float[{n}]({p});
const float LEADR_ENV_W[{n}] = float[{n}]({w});
const float LEADR_ENV_P_ROUGH[{n_rough}] = float[{n_rough}]({p_rough});
const float LEADR_ENV_W_ROUGH[{n_rough}] = float[{n_rough}]({w_rough});
const float LEADR_ENV_H = {h:.9g}, LEADR_ENV_H_ROUGH = {h_rough:.9g};
const int LEADR_SHADOW_ROWS = {shadow_rows};               // shading.SHADOW_ROWS
const float LEADR_SHADOW_FINE_VAR = {shadow_fine_var:.9g};  // shading.SHADOW_FINE_SIGMA^2

int leadrMod(int a, int m) {{ int r = a % m; return r < 0 ? r + m : r; }}

// (u, v) = (phi / 2 pi, theta / pi) of a unit direction (envmap.latlong_uv)
vec2 leadrLatlong(vec3 w) {{
    float phi = atan(w.y, w.x);
    if (phi < 0.0) phi += 2.0 * LEADR_PI;
    return vec2(phi / (2.0 * LEADR_PI), acos(clamp(w.z, -1.0, 1.0)) / LEADR_PI);
}}

// bilinear read of level `level`, wrapped in u, clamped in v (texture.fetch.bilinear_add)
vec3 leadrEnvBilinear(int level, vec2 uv) {{
    ivec2 sz = textureSize(leadrEnv, level);
    float x = uv.x * float(sz.x) - 0.5, y = uv.y * float(sz.y) - 0.5;
    float x0 = floor(x), fx = x - x0;
    int j0 = leadrMod(int(x0), sz.x), j1 = (j0 + 1) % sz.x;
    y = clamp(y, 0.0, float(sz.y - 1));
    float y0 = min(floor(y), float(max(sz.y - 2, 0))), fy = y - y0;
    int i0 = int(y0), i1 = min(i0 + 1, sz.y - 1);
    vec3 a = texelFetch(leadrEnv, ivec2(j0, i0), level).rgb * (1.0 - fx)
        + texelFetch(leadrEnv, ivec2(j1, i0), level).rgb * fx;
    vec3 b = texelFetch(leadrEnv, ivec2(j0, i1), level).rgb * (1.0 - fx)
        + texelFetch(leadrEnv, ivec2(j1, i1), level).rgb * fx;
    return a * (1.0 - fy) + b * fy;
}}

// trilinear radiance in map direction w at `lod`, clamped to the chain (EnvMap.lookup)
vec3 leadrEnvLookup(vec3 w, float lod) {{
    vec2 uv = leadrLatlong(w);
    int n = leadrEnvLevels;
    lod = clamp(lod, 0.0, float(n - 1));
    int l0 = min(int(floor(lod)), max(n - 2, 0));
    float t = lod - float(l0);
    vec3 c = vec3(0.0);
    if (t < 1.0) c += (1.0 - t) * leadrEnvBilinear(l0, uv);
    if (t > 0.0) c += t * leadrEnvBilinear(l0 + 1, uv);
    return c;
}}

float leadrLargestVar(vec3 cov) {{
    return 0.5 * (cov.x + cov.y) + sqrt(0.25 * (cov.x - cov.y) * (cov.x - cov.y) + cov.z * cov.z);
}}

// the artificial micronormal (supplemental 3.7): normalize(n_bar - (n_bar.wo) eps wo)
vec3 leadrArtificial(vec3 wo, vec2 mu) {{
    vec3 nb = normalize(vec3(-mu, 1.0));
    vec3 t = nb - dot(nb, wo) * LEADR_ART_EPS * wo;
    return t / max(length(t), 1e-30);
}}

// Algorithm 1 with G2 / G1 (kernels.env_specular_kernel): radiance towards wo of the rough
// specular layer, Schlick's f0 per channel; toMap: local frame -> map coordinates.
vec3 leadrEnvSpecular(vec3 wo, vec2 mu, vec3 cov, vec3 f0, mat3 toMap) {{
    bool rough = leadrLargestVar(cov) >= LEADR_ROUGH_VAR;
    int n = rough ? LEADR_ENV_N_ROUGH : LEADR_ENV_N;
    float hh = rough ? LEADR_ENV_H_ROUGH : LEADR_ENV_H;
    float sx = sqrt(cov.x), sy = sqrt(cov.y);
    float r = cov.z / (sx * sy), r_ = sqrt(max(1.0 - r * r, 0.0));
    float cell = hh * hh * sqrt(cov.x * cov.y - cov.z * cov.z);
    vec3 num = vec3(0.0), last = vec3(0.0);
    float den = 0.0;
    for (int k = 0; k <= LEADR_ENV_N_ROUGH * LEADR_ENV_N_ROUGH; ++k) {{
        if (k > n * n) break;
        vec3 m;
        float wt;
        bool grid = k < n * n;
        if (grid) {{
            int j = k / n, i = k % n;
            float pj = rough ? LEADR_ENV_P_ROUGH[j] : LEADR_ENV_P[j];
            float pi = rough ? LEADR_ENV_P_ROUGH[i] : LEADR_ENV_P[i];
            wt = rough ? LEADR_ENV_W_ROUGH[j] * LEADR_ENV_W_ROUGH[i]
                       : LEADR_ENV_W[j] * LEADR_ENV_W[i];
            m = normalize(vec3(-(mu.x + pj * sx), -(mu.y + (pj * r + pi * r_) * sy), 1.0));
        }} else {{
            m = leadrArtificial(wo, mu);
            wt = LEADR_ART_W;
        }}
        float d = dot(m, wo);
        float ws = wt * max(d, 0.0) / (grid ? m.z : 1.0);
        vec3 wi = 2.0 * d * m - wo;
        float jac = 4.0 * abs(d) * pow(abs(m.z), 3.0);
        float lod = 0.5 * log2(max(jac * cell, 1e-30) / leadrEnvTexel);
        float c = clamp(d, 0.0, 1.0);
        vec3 fr = f0 + (1.0 - f0) * pow(1.0 - c, 5.0);
        // the artificial micronormal stays unshadowed (it only keeps empty footprints lit)
        if (grid) fr *= leadrShadowing(wo, wi, mu, cov);
        last = fr * leadrEnvLookup(toMap * wi, lod);
        num += ws * last;
        den += ws;
    }}
    return den > 1e-30 ? num / den : last;
}}

// the irradiance map's bilinear lookup of a normal in map coordinates (IrradianceMap.lookup)
vec3 leadrIrradianceAt(vec3 n) {{
    ivec2 sz = textureSize(leadrIrradiance, 0);  // (2R, R + 1)
    int R = sz.y - 1, W = sz.x;
    n = normalize(n);
    float theta = acos(clamp(n.z, -1.0, 1.0)), phi = atan(n.y, n.x);
    if (phi < 0.0) phi += 2.0 * LEADR_PI;
    float y = theta * float(R) / LEADR_PI, x = phi * float(W) / (2.0 * LEADR_PI);
    float y0 = min(floor(y), float(R - 1)), x0 = floor(x);
    float fy = y - y0, fx = x - x0;
    int i0 = int(y0), j0 = leadrMod(int(x0), W), j1 = (j0 + 1) % W;
    vec3 top = texelFetch(leadrIrradiance, ivec2(j0, i0), 0).rgb * (1.0 - fx)
        + texelFetch(leadrIrradiance, ivec2(j1, i0), 0).rgb * fx;
    vec3 bot = texelFetch(leadrIrradiance, ivec2(j0, i0 + 1), 0).rgb * (1.0 - fx)
        + texelFetch(leadrIrradiance, ivec2(j1, i0 + 1), 0).rgb * fx;
    return top * (1.0 - fy) + bot * fy;
}}

// Simplified Algorithm 3 on the irradiance map (shading.diffuse_irradiance, albedo 1)
vec3 leadrIrradianceGrid(vec3 wo, vec2 mu, vec3 cov, mat3 toMap) {{
    float sx = sqrt(cov.x), sy = sqrt(cov.y);
    float r = cov.z / (sx * sy), r_ = sqrt(max(1.0 - r * r, 0.0));
    vec3 num = vec3(0.0);
    float den = 0.0;
    for (int j = 0; j < LEADR_GRID; ++j) {{
        float x = mu.x + LEADR_P[j] * sx;
        for (int k = 0; k < LEADR_GRID; ++k) {{
            float y = mu.y + (LEADR_P[j] * r + LEADR_P[k] * r_) * sy;
            vec3 m = normalize(vec3(-x, -y, 1.0));
            float ws = LEADR_W[j] * LEADR_W[k] * max(dot(m, wo), 0.0) / m.z;
            num += ws * leadrIrradianceAt(toMap * m);
            den += ws;
        }}
    }}
    vec3 t = leadrArtificial(wo, mu);
    float wa = LEADR_ART_W * max(dot(t, wo), 0.0);
    vec3 ra = leadrIrradianceAt(toMap * t);
    num += wa * ra;
    den += wa;
    return (den > 1e-30 ? num / den : ra) / LEADR_PI;
}}

// what self-shadowing removes from the diffuse layer (<= 0; kernels.diffuse_shadow_kernel):
// -(1 / pi) sum W S sum_d L_d Omega_d <m, d>+ (1 - G2 / G1) / sum W S over the texels d of the
// environment level with at most LEADR_SHADOW_ROWS rows (twice that for smooth footprints)
vec3 leadrDiffuseShadowing(vec3 wo, vec2 mu, vec3 cov, mat3 toMap) {{
    int rows = leadrLargestVar(cov) < LEADR_SHADOW_FINE_VAR ? 2 * LEADR_SHADOW_ROWS
                                                             : LEADR_SHADOW_ROWS;
    int lev = leadrEnvLevels - 1;
    for (int l = 0; l < 32; ++l) {{
        if (l >= leadrEnvLevels) break;
        if (textureSize(leadrEnv, l).y <= rows) {{ lev = l; break; }}
    }}
    ivec2 sz = textureSize(leadrEnv, lev);
    float sx = sqrt(cov.x), sy = sqrt(cov.y);
    float r = cov.z / (sx * sy), r_ = sqrt(max(1.0 - r * r, 0.0));
    vec3 gm[LEADR_GRID * LEADR_GRID];
    float gw[LEADR_GRID * LEADR_GRID];
    float den = 0.0, steep = 0.0;
    for (int j = 0; j < LEADR_GRID; ++j) {{
        for (int i = 0; i < LEADR_GRID; ++i) {{
            float x = mu.x + LEADR_P[j] * sx, y = mu.y + (LEADR_P[j] * r + LEADR_P[i] * r_) * sy;
            vec3 m = normalize(vec3(-x, -y, 1.0));
            int k = j * LEADR_GRID + i;
            gm[k] = m;
            gw[k] = LEADR_W[j] * LEADR_W[i] * max(dot(m, wo), 0.0) / m.z;
            den += gw[k];
            steep = max(steep, sqrt(x * x + y * y));
        }}
    }}
    float lo;
    bool finiteO = leadrLambda(wo, mu, cov, lo);
    mat3 toLocal = transpose(toMap);
    float dphi = 2.0 * LEADR_PI / float(sz.x);
    vec3 num = vec3(0.0);
    for (int i = 0; i < 4 * LEADR_SHADOW_ROWS; ++i) {{
        if (i >= sz.y) break;
        float t0 = float(i) * LEADR_PI / float(sz.y), t1 = float(i + 1) * LEADR_PI / float(sz.y);
        float theta = 0.5 * (t0 + t1), st = sin(theta), ct = cos(theta);
        float omega = (cos(t0) - cos(t1)) * dphi;
        for (int jj = 0; jj < 8 * LEADR_SHADOW_ROWS; ++jj) {{
            if (jj >= sz.x) break;
            float phi = (float(jj) + 0.5) * dphi;
            vec3 d = toLocal * vec3(st * cos(phi), st * sin(phi), ct);
            float lost;
            if (d.z <= 0.0) {{
                // blocked by the height field itself, but only the grid's steepest
                // micronormals see below the horizon
                if (-d.z >= steep * length(d.xy)) continue;
                lost = 1.0;
            }} else {{
                float li;
                if (!leadrLambda(d, mu, cov, li)) lost = 1.0;
                else lost = finiteO ? 1.0 - 1.0 / (1.0 + li / (1.0 + lo)) : 0.0;
                if (lost <= 0.0) continue;
            }}
            float acc = 0.0;
            for (int g = 0; g < LEADR_GRID * LEADR_GRID; ++g)
                acc += gw[g] * max(dot(gm[g], d), 0.0);
            if (acc > 0.0)
                num += acc * lost * omega * texelFetch(leadrEnv, ivec2(jj, i), lev).rgb;
        }}
    }}
    return den > 1e-30 ? -num / (den * LEADR_PI) : vec3(0.0);
}}

// the environment's diffuse layer (albedo 1): Algorithm 3 on the irradiance map with the
// self-shadowing loss, clamped at 0 (render._diffuse_env + diffuse_shadowing)
vec3 leadrEnvDiffuse(vec3 wo, vec2 mu, vec3 cov, mat3 toMap) {{
    return max(leadrIrradianceGrid(wo, mu, cov, toMap) + leadrDiffuseShadowing(wo, mu, cov, toMap),
               0.0);
}}
"""


def _float(v) -> str:
    s = f"{float(v):.9g}"
    return s if any(ch in s for ch in ".en") else s + ".0"


def _floats(x) -> str:
    return ", ".join(_float(v) for v in np.ravel(x))


def glsl_source() -> str:
    """The GLSL snippet ``leadr_env.glsl`` (included after ``leadr.glsl``)."""
    from prefilter.leadr.envmap import ENV_FROM_WORLD
    from prefilter.leadr.render import ENV_GRID, ENV_GRID_ROUGH, ROUGH_SIGMA
    from prefilter.leadr.shading import SHADOW_FINE_SIGMA, SHADOW_ROWS, gaussian_grid

    p, w, h = gaussian_grid(ENV_GRID)
    pr, wr, hr = gaussian_grid(ENV_GRID_ROUGH)
    # GLSL's mat3 constructor is column-major: the transpose's rows are the columns
    return _GLSL.format(env_from_world=_floats(np.asarray(ENV_FROM_WORLD).T),
                        n=ENV_GRID, n_rough=ENV_GRID_ROUGH, rough_var=ROUGH_SIGMA**2,
                        p=_floats(p), w=_floats(w), p_rough=_floats(pr), w_rough=_floats(wr),
                        h=h, h_rough=hr, shadow_rows=SHADOW_ROWS,
                        shadow_fine_var=SHADOW_FINE_SIGMA**2)


def env_textures(env) -> dict:
    """The textures the snippet reads for an :class:`~prefilter.leadr.envmap.EnvMap` ``env``
    (``None``: no environment): ``levels``, the radiance levels ``(h, w, 4)`` float32 (alpha 1),
    ``irradiance``, the :class:`~prefilter.leadr.envmap.IrradianceMap` nodes ``(R + 1, 2R, 4)``,
    and ``texel``, :attr:`~prefilter.leadr.envmap.EnvMap.texel_solid_angle`."""
    from prefilter.leadr.envmap import IrradianceMap

    def rgba(a):
        return np.concatenate([a, np.ones(a.shape[:2] + (1,))], -1).astype(np.float32)

    if env is None:
        z = np.zeros((1, 2, 4), np.float32)
        return {"levels": [z], "irradiance": np.zeros((2, 2, 4), np.float32), "texel": 1.0,
                "present": False}
    return {"levels": [rgba(a) for a in env.levels],
            "irradiance": rgba(IrradianceMap(env).values), "texel": float(env.texel_solid_angle),
            "present": True}


def export_all(out_dir) -> list[Path]:
    """Write ``leadr_env.glsl`` (:func:`glsl_source`) to ``out_dir``; returns the paths."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    g = out / "leadr_env.glsl"
    write_text_atomic(g, glsl_source())
    return [g]
