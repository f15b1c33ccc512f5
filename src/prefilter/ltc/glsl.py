"""Engine layout of the isotropic LTC table, its GLSL lookup, the GLSL polygon integral, and the
lookup's NumPy twin.

Heitz, Dupuy, Hill, Neubelt 2016, section 4 ("Implementation"): the ``(T, R)`` table over
``t = sqrt(1 - cos theta)`` and ``r = sqrt(alpha)`` becomes three RGBA 2D textures of size
``W x H = T x R`` (``t`` along x, ``r`` along y), with the channels of
:mod:`prefilter.ltc.aniso.export`::

    tex0 = (m00, m01, m02, m10)   tex1 = (m11, m12, m20, m21)   tex2 = (m22, n, f5, 0)

The shader interpolates bilinearly *by hand* (``texelFetch``, four taps per texture) so the result
is the table's bilinear interpolation in table space on every GPU, as
:meth:`prefilter.ltc.table.GGXTable.lookup` computes it (hardware filters quantise their weights).
:data:`GLSL` also holds the clipped polygon integral (eq. 11 with horizon clipping, the streaming
form of :func:`prefilter.sphere.polygon.clipped_edge_sum`) and the quad-light shading of
:func:`prefilter.ltc.shading.shade_ltc`, in float32.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from prefilter.fileio import atomic_path, save_json_atomic, write_text_atomic
from prefilter.errors import PrefilterError

__all__ = ["CHANNELS", "GLSL", "export_all", "glsl_source", "texture_layout", "texture_params",
           "uniform_nodes"]

#: The entries ``(row, column)`` of ``M`` in the order the texture channels hold them.
CHANNELS = [(0, 0), (0, 1), (0, 2), (1, 0), (1, 1), (1, 2), (2, 0), (2, 1), (2, 2)]


def uniform_nodes(c) -> bool:
    """Whether the table axis ``c`` is uniform (the GPU interpolates its index linearly)."""
    d = np.diff(c)
    return bool(np.allclose(d, d[0], rtol=1e-9, atol=1e-12))


def texture_params(table) -> dict:
    """Grid sizes and axis ranges the shader needs (axes must be uniform: ``t`` from 0)."""
    if not (uniform_nodes(table.axis_t) and uniform_nodes(table.axis_r) and table.axis_t[0] == 0.0):
        raise PrefilterError("table axes: the texture layout needs nodes uniform in "
                             "sqrt(1 - cos theta) (from 0) and sqrt(alpha)")
    return {"T": len(table.axis_t), "R": len(table.axis_r), "t_max": float(table.axis_t[-1]),
            "sqrt_alpha_min": float(table.axis_r[0])}


def texture_layout(table, dtype=np.float32) -> np.ndarray:
    """The three RGBA textures ``(3, H, W, 4)`` (``H = R`` rows of roughness, ``W = T``)."""
    ch = [table.M[..., i, j] for i, j in CHANNELS] + [table.magnitude, table.fresnel,
                                                       np.zeros(table.magnitude.shape)]
    x = np.stack(ch, -1).reshape(len(table.axis_t), len(table.axis_r), 3, 4)  # (T, R, 3, 4)
    return np.ascontiguousarray(x.transpose(2, 1, 0, 3)).astype(dtype)


GLSL = """\
// Isotropic GGX LTC (Heitz, Dupuy, Hill, Neubelt 2016; prefilter `ltc/glsl.py`).
// Textures: ltcIso0..2, T x R texels, RGBA = (m00 m01 m02 m10), (m11 m12 m20 m21), (m22 n f5 0),
// read with texelFetch (the bilinear interpolation is done here, in table space).
uniform highp sampler2D ltcIso0, ltcIso1, ltcIso2;
const int LTC_ISO_T = {T}, LTC_ISO_R = {R};
const float LTC_ISO_TMAX = {t_max:.9f}, LTC_ISO_SA_MIN = {sqrt_alpha_min:.9f};

void ltcIsoTaps(ivec2 p, out vec4 a, out vec4 b, out vec4 c) {{
    a = texelFetch(ltcIso0, p, 0); b = texelFetch(ltcIso1, p, 0); c = texelFetch(ltcIso2, p, 0);
}}

// wo: unit view in the shading frame (z = normal); alpha: GGX roughness (clamped to the table).
// Returns sign(det M) adj(M) (= |det M| M^-1, all the polygon integral needs), n and f5.
void ltcIsoLookup(vec3 wo, float alpha, out mat3 Minv, out float n, out float f5) {{
    float ft = clamp(sqrt(max(0.0, 1.0 - wo.z)) / LTC_ISO_TMAX, 0.0, 1.0)
               * float(LTC_ISO_T - 1);
    float sa = sqrt(clamp(alpha, LTC_ISO_SA_MIN * LTC_ISO_SA_MIN, 1.0));
    float fr = clamp((sa - LTC_ISO_SA_MIN) / (1.0 - LTC_ISO_SA_MIN), 0.0, 1.0)
               * float(LTC_ISO_R - 1);
    int i = min(int(floor(ft)), LTC_ISO_T - 2), j = min(int(floor(fr)), LTC_ISO_R - 2);
    float a = ft - float(i), b = fr - float(j);
    vec4 p0, p1, p2, q0, q1, q2, r0, r1, r2, s0, s1, s2;
    ltcIsoTaps(ivec2(i, j), p0, p1, p2);
    ltcIsoTaps(ivec2(i + 1, j), q0, q1, q2);
    ltcIsoTaps(ivec2(i, j + 1), r0, r1, r2);
    ltcIsoTaps(ivec2(i + 1, j + 1), s0, s1, s2);
    float w00 = (1.0 - a) * (1.0 - b), w10 = a * (1.0 - b), w01 = (1.0 - a) * b, w11 = a * b;
    vec4 t0 = w00 * p0 + w10 * q0 + w01 * r0 + w11 * s0;
    vec4 t1 = w00 * p1 + w10 * q1 + w01 * r1 + w11 * s1;
    vec4 t2 = w00 * p2 + w10 * q2 + w01 * r2 + w11 * s2;
    // M is tabulated in the view's azimuthal frame: M_local = Rz(phi) M Rz(phi)^T
    float rho = length(wo.xy);
    float c = rho > 0.0 ? wo.x / rho : 1.0, s = rho > 0.0 ? wo.y / rho : 0.0;
    mat3 R = mat3(c, s, 0.0, -s, c, 0.0, 0.0, 0.0, 1.0);  // column-major
    mat3 M = R * transpose(mat3(t0.xyz, vec3(t0.w, t1.xy), vec3(t1.zw, t2.x))) * transpose(R);
    mat3 adj = transpose(mat3(cross(M[1], M[2]), cross(M[2], M[0]), cross(M[0], M[1])));
    Minv = determinant(M) < 0.0 ? -adj : adj;
    n = t2.y; f5 = t2.z;
}}

// Arc a -> b times the z of its unit normal (scale-invariant; a, b need not be unit).
float ltcEdge(vec3 a, vec3 b) {{
    vec3 c = cross(a, b);
    float s = length(c);
    return s > 0.0 ? atan(s, dot(a, b)) * (c.z / s) : 0.0;
}}

// Integral of the clamped cosine over T P (eq. 11), the polygon P[0..n-1] clipped to z >= 0 after
// the transform T (one pass, exits joined to entries along the horizon); T = |det M| M^-1 gives
// the LTC integral. Zero for polygons through the origin or without area.
float ltcPolygon(mat3 T, vec3 P[5], int n) {{
    vec3 f = T * P[0], p = f, sum = f, N = vec3(0.0), e = vec3(0.0), g = vec3(0.0);
    float vmax = max(max(abs(f.x), abs(f.y)), abs(f.z)), acc = 0.0;
    bool hasExit = false, hasFirst = false;
    for (int j = 1; j <= 5; ++j) {{
        if (j > n) break;
        vec3 q = f;
        if (j < n) {{
            q = T * P[j]; sum += q; vmax = max(vmax, max(max(abs(q.x), abs(q.y)), abs(q.z)));
        }}
        N += cross(p, q);
        if (p.z >= 0.0) {{
            if (q.z >= 0.0) {{
                acc += ltcEdge(p, q);
            }} else {{
                e = vec3(mix(p.xy, q.xy, p.z / (p.z - q.z)), 0.0);
                acc += ltcEdge(p, e); hasExit = true;
            }}
        }} else if (q.z >= 0.0) {{
            vec3 i = vec3(mix(p.xy, q.xy, p.z / (p.z - q.z)), 0.0);
            if (hasExit) {{ acc += ltcEdge(e, i); hasExit = false; }}
            else {{ g = i; hasFirst = true; }}
            acc += ltcEdge(i, q);
        }}
        p = q;
    }}
    if (hasExit && hasFirst) acc += ltcEdge(e, g);
    float nn = length(N);
    // float32 tolerances of the float64 tests in prefilter.sphere.polygon
    if (nn <= 1e-6 * float(n) * vmax * vmax || abs(dot(N, sum)) <= 1e-6 * float(n) * nn * vmax)
        return 0.0;
    return max(0.0, -sign(determinant(T)) * acc * 0.15915494309);
}}

// Sutherland-Hodgman of the quad P against z >= 0, padded to 5 vertices with the last one
// (all zero when nothing is above).
void ltcClipHorizon(vec3 P[5], out vec3 C[5]) {{
    int count = 0;
    for (int k = 0; k < 5; ++k) C[k] = vec3(0.0);
    for (int i = 0; i < 4; ++i) {{
        vec3 a = P[i == 0 ? 3 : i - 1], b = P[i];
        if ((a.z >= 0.0) != (b.z >= 0.0)) {{
            C[count++] = vec3(mix(a.xy, b.xy, a.z / (a.z - b.z)), 0.0);
        }}
        if (b.z >= 0.0) C[count++] = b;
    }}
    for (int k = 1; k < 5; ++k) if (k >= count && count > 0) C[k] = C[count - 1];
}}

// Radiance of one quad light (corners Q, emission normal qn, radiance L) at position pos with
// shading frame (t, b, n): base E(P) + spec E(M^-1 P), the light cut at the shading horizon
// before the LTC transform (prefilter.ltc.shading.shade_ltc); one-sided lights.
vec3 ltcQuad(vec3 Q[4], vec3 qn, vec3 L, vec3 pos, vec3 t, vec3 b, vec3 n, mat3 Minv,
             vec3 base, vec3 spec) {{
    if (dot(pos - Q[0], qn) <= 0.0) return vec3(0.0);
    vec3 P[5], C[5];
    for (int k = 0; k < 4; ++k) {{
        vec3 d = Q[k] - pos; P[k] = vec3(dot(d, t), dot(d, b), dot(d, n));
    }}
    P[4] = P[3];
    float ed = ltcPolygon(mat3(1.0), P, 4);
    ltcClipHorizon(P, C);
    float es = ltcPolygon(Minv, C, 5);
    return (base * ed + spec * es) * L;
}}
"""


def glsl_source(table) -> str:
    """:data:`GLSL` with the table's constants filled in."""
    return GLSL.format(**texture_params(table))


def export_all(table, out_dir) -> list[Path]:
    """Write ``ggx_iso_f32.bin`` / ``ggx_iso_f16.bin`` (raw little-endian :func:`texture_layout`,
    shape ``(3, R, T, 4)``), ``ggx_iso_layout.json`` and ``ltc_iso.glsl``; returns the paths."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    params = texture_params(table)
    paths = []
    for name, dt in (("f32", "<f4"), ("f16", "<f2")):
        b = out / f"ggx_iso_{name}.bin"
        with atomic_path(b, suffix=".bin") as tmp:
            tmp.write_bytes(texture_layout(table, np.dtype(dt)).tobytes())
        paths.append(b)
    meta = {**params, "shape": [3, params["R"], params["T"], 4],
            "channels": ["m00 m01 m02 m10", "m11 m12 m20 m21", "m22 magnitude fresnel 0"],
            "x": "sqrt(1 - cos theta) = t_max * i / (T - 1)",
            "y": "sqrt(alpha) = sqrt_alpha_min + (1 - sqrt_alpha_min) * j / (R - 1)",
            "filter": "NEAREST (texelFetch; bilinear in the shader)"}
    save_json_atomic(out / "ggx_iso_layout.json", meta)
    g = out / "ltc_iso.glsl"
    write_text_atomic(g, glsl_source(table))
    return paths + [out / "ggx_iso_layout.json", g]
