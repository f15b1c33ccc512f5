"""GLSL lookup snippet for baked colour-map tables.

The snippet reads the baked table with one ``texture()`` call on a ``GL_LINEAR`` sampler (wrap
mode of the mean axis: :data:`GLSL_WRAP`); ``tests/colormap/test_glsl.py`` emulates that call in
float32 and checks it against :meth:`prefilter.colormap.table.ColormapTable.lookup`.
"""

from __future__ import annotations

from prefilter.errors import PrefilterError

__all__ = ["GLSL_WRAP", "glsl_snippet"]

#: OpenGL wrap mode of the mean axis for each edge rule (the sigma axis is always clamped).
GLSL_WRAP = {"clamp": "GL_CLAMP_TO_EDGE", "mirror": "GL_MIRRORED_REPEAT", "periodic": "GL_REPEAT"}

_SNIPPET = """\
// Filtered colour maps (Heitz, Nowrouzezahrai, Poulin, Neyret 2013), baked by
// `prefilter bake colormap`. Upload the table with row 0 of the file at t = 0, GL_LINEAR
// min/mag filters without mipmaps, wrap S = {wrap_s}, wrap T = GL_CLAMP_TO_EDGE.
uniform sampler2D uColormapTable; // rows: sigma = sigma_max * j / (n_sigma - 1); columns: mean
const vec2  kValueRange = vec2({lo}, {hi});
const float kSigmaMax   = {sigma_max};
const float kNSigma     = {n_sigma:.1f};

// <C, N(mean, sigma^2)> (eq. 10): one bilinear fetch.
vec3 colormapFiltered(float mean, float sigma) {{
    float u = (mean - kValueRange.x) / (kValueRange.y - kValueRange.x);
    float v = (clamp(sigma / kSigmaMax, 0.0, 1.0) * (kNSigma - 1.0) + 0.5) / kNSigma;
    return texture(uColormapTable, vec2(u, v)).rgb;
}}

// Tabulated driving function (section 4.2): a mipmapped texture of (E[f], E[f^2]).
vec3 colormapTexture(sampler2D moments, vec2 uv) {{
    vec2 m = texture(moments, uv).rg;
    return colormapFiltered(m.x, sqrt(max(m.y - m.x * m.x, 0.0)));
}}

// Procedural noise (section 4.2): the filtered noise value and its std per LOD (1D texture).
vec3 colormapNoise(float filteredNoise, sampler2D noiseStd, float lod, float nLevels) {{
    float s = texture(noiseStd, vec2((lod + 0.5) / nLevels, 0.5)).r;
    return colormapFiltered(filteredNoise, s);
}}

// Height-correlated colour (section 5.1, eqs. 13, 17, 18); lambdaO / lambdaI from eq. 3.
// Returns V_bar * <C_h, D_h> as eq. 14.
const vec4 kHeightFit = vec4({a_mu}, {b_mu}, {a_s}, {b_s}); // alpha/beta mu, sigma
vec3 colormapHeight(float sigmaH, float lambdaO, float lambdaI) {{
    float L = lambdaO + lambdaI;
    float mu = kHeightFit.x * sigmaH * log(kHeightFit.y * L + 1.0);
    float sd = sigmaH / (1.0 + kHeightFit.z * log(kHeightFit.w * L + 1.0));
    return (1.0 + lambdaO) / (1.0 + L) * colormapFiltered(mu, sd);
}}
"""


def _float_literal(x, digits: int = 9) -> str:
    """A GLSL float literal (GLSL ES has no implicit int -> float: ``2`` must be ``2.0``)."""
    text = f"{float(x):.{digits}g}"
    return text if any(c in text for c in ".eEn") else text + ".0"


def glsl_snippet(metadata: dict, height_params=None) -> str:
    """The GLSL lookup code for a baked table described by ``metadata``
    (:meth:`ColormapTable.metadata`); ``height_params`` defaults to our refit constants."""
    from prefilter.colormap.height import OWN_PARAMS

    try:
        lo, hi = metadata["value_range"]
        p = OWN_PARAMS if height_params is None else height_params
        f = _float_literal
        return _SNIPPET.format(wrap_s=GLSL_WRAP[metadata["edge"]], lo=f(lo), hi=f(hi),
                               sigma_max=f(metadata["sigma_max"]), n_sigma=metadata["n_sigma"],
                               a_mu=f(p[0], 6), b_mu=f(p[1], 6), a_s=f(p[2], 6),
                               b_s=f(p[3], 6))
    except (KeyError, TypeError, ValueError) as exc:
        raise PrefilterError(f"metadata: expected a colour-map table description, got {exc}") \
            from None
