"""Engine layouts of the anisotropic LTC table and the GLSL lookup.

Anisotropic-LTC paper, section 9 ("Storage", "Run time"). The 4D table becomes three RGBA 3D
textures of size ``W x H x D = T x F x (R * A)`` (theta fastest, then phi, then depth ``r * A +
a``), so the hardware interpolates trilinearly in (theta, phi, alpha) and the shader blends two
ratio slices by hand (6 fetches). Channels::

    tex0 = (m00, m01, m02, m10)   tex1 = (m11, m12, m20, m21)   tex2 = (m22, n, f5, 0)

with ``M`` the stored (aligned, unit third column) matrix, ``n`` the magnitude and ``f5`` the
Fresnel scalar. :data:`GLSL` folds the view with the symmetries, fetches, unfolds and inverts
``M`` (adjugate; the determinant cancels in the LTC integral); the tests check it through the
same program line by line in NumPy (``tests/ltc/glsl_numpy.py``).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from prefilter.fileio import atomic_path, save_json_atomic, save_npz_atomic, write_text_atomic
from prefilter.errors import PrefilterError
from prefilter.ltc.glsl import CHANNELS, uniform_nodes

def texture_params(table) -> dict:
    """The scalars the shader needs (grid sizes and the ranges of the uniform coordinates)."""
    c = table._coords
    if not all(uniform_nodes(x) for x in c):
        raise PrefilterError("table axes: the texture layout needs nodes uniform in theta, phi, "
                             "sqrt(alpha) and sqrt(ratio)")
    T, F, A, R = table.shape
    return {"T": T, "F": F, "A": A, "R": R, "theta_max": float(c[0][-1]),
            "sqrt_alpha_min": float(c[2][0]), "sqrt_ratio_min": float(c[3][0])}


def texture_layout(table, dtype=np.float32) -> np.ndarray:
    """The three RGBA textures ``(3, D, H, W, 4)`` (``D = R * A``, ``H = F``, ``W = T``)."""
    T, F, A, R = table.shape
    ch = [table.M[..., i, j] for i, j in CHANNELS] + [table.magnitude, table.fresnel,
                                                       np.zeros(table.shape)]
    x = np.stack(ch, -1)  # (T, F, A, R, 12)
    x = x.transpose(3, 2, 1, 0, 4).reshape(R * A, F, T, 3, 4)  # depth = r * A + a
    return np.ascontiguousarray(x.transpose(3, 0, 1, 2, 4)).astype(dtype)


def export_all(table, out_dir) -> list[Path]:
    """Write ``ggx_aniso_f32.npz`` / ``ggx_aniso_f16.npz`` (key ``tex``, shape ``(3, D, H, W,
    4)``), the raw little-endian ``.bin`` of both, ``ggx_aniso_layout.json`` and
    ``ltc_aniso.glsl``; returns the paths."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    params = texture_params(table)
    paths = []
    for name, dt in (("f32", "<f4"), ("f16", "<f2")):
        tex = texture_layout(table, np.dtype(dt))
        p = out / f"ggx_aniso_{name}.npz"
        save_npz_atomic(p, tex=tex)
        b = out / f"ggx_aniso_{name}.bin"
        with atomic_path(b, suffix=".bin") as tmp:
            tmp.write_bytes(tex.tobytes())
        paths += [p, b]
    meta = {**params, "shape": list(texture_layout(table).shape),
            "channels": ["m00 m01 m02 m10", "m11 m12 m20 m21", "m22 magnitude fresnel 0"],
            "depth_index": "ratio_index * A + alpha_index", "filter": "LINEAR, CLAMP_TO_EDGE"}
    save_json_atomic(out / "ggx_aniso_layout.json", meta)
    g = out / "ltc_aniso.glsl"
    write_text_atomic(g, glsl_source(table))
    return paths + [out / "ggx_aniso_layout.json", g]


GLSL = """\
// Anisotropic GGX LTC lookup (Kt, Dupuy, Heitz; prefilter `ltc/aniso/export.py`).
// wo: view in the tangent frame (x = tangent, z = normal), wo.z > 0; ax, ay: GGX roughness.
// Returns M^-1 (up to a positive factor) for the LTC polygon integral, the magnitude n and the
// Fresnel scalar f5: shade = (F0 * (n - f5) + f5) * ltcIntegral(Minv, polygon).
// GLSL ES 3.00 has no default precision for sampler3D.
precision highp sampler3D;
uniform sampler3D ltcAniso0, ltcAniso1, ltcAniso2;  // LINEAR, CLAMP_TO_EDGE
const float LTC_T = {T}.0, LTC_F = {F}.0, LTC_A = {A}.0, LTC_R = {R}.0;
const float LTC_THETA_MAX = {theta_max:.9f};
const float LTC_SA_MIN = {sqrt_alpha_min:.9f}, LTC_SR_MIN = {sqrt_ratio_min:.9f};

void ltcAnisoFetch(vec3 uvw, out vec4 t0, out vec4 t1, out vec4 t2) {{
    t0 = texture(ltcAniso0, uvw); t1 = texture(ltcAniso1, uvw); t2 = texture(ltcAniso2, uvw);
}}

void ltcAnisoLookup(vec3 wo, float ax, float ay, out mat3 Minv, out float n, out float f5) {{
    // roughness symmetry (eq. 15): table holds alpha_x >= alpha_y; swapping is a mirror x <-> y
    bool swp = ay > ax;
    float alpha = max(ax, ay), ratio = min(ax, ay) / alpha;
    vec3 w = swp ? wo.yxz : wo;
    // azimuthal symmetry (eq. 13): fold into phi in [0, pi/2]
    vec2 s = vec2(w.x < 0.0 ? -1.0 : 1.0, w.y < 0.0 ? -1.0 : 1.0);
    w.xy = abs(w.xy);
    float ft = clamp(acos(clamp(w.z, 0.0, 1.0)) / LTC_THETA_MAX, 0.0, 1.0) * (LTC_T - 1.0);
    float fp = clamp(atan(w.y, w.x) / 1.5707963268, 0.0, 1.0) * (LTC_F - 1.0);
    float fa = clamp((sqrt(alpha) - LTC_SA_MIN) / (1.0 - LTC_SA_MIN), 0.0, 1.0) * (LTC_A - 1.0);
    float fr = clamp((sqrt(ratio) - LTC_SR_MIN) / (1.0 - LTC_SR_MIN), 0.0, 1.0) * (LTC_R - 1.0);
    float r0 = min(floor(fr), LTC_R - 2.0), tr = fr - r0;
    vec2 uv = (vec2(ft, fp) + 0.5) / vec2(LTC_T, LTC_F);
    vec4 a0, a1, a2, b0, b1, b2;
    ltcAnisoFetch(vec3(uv, (r0 * LTC_A + fa + 0.5) / (LTC_A * LTC_R)), a0, a1, a2);
    ltcAnisoFetch(vec3(uv, ((r0 + 1.0) * LTC_A + fa + 0.5) / (LTC_A * LTC_R)), b0, b1, b2);
    vec4 t0 = mix(a0, b0, tr), t1 = mix(a1, b1, tr), t2 = mix(a2, b2, tr);
    // rows of M, then unfold: M <- S M S (mirror), then P M P (swap)
    vec3 r0v = vec3(t0.x, t0.y, t0.z), r1v = vec3(t0.w, t1.x, t1.y), r2v = vec3(t1.z, t1.w, t2.x);
    vec3 sv = vec3(s, 1.0);
    r0v *= sv.x * sv; r1v *= sv.y * sv; r2v *= sv;
    if (swp) {{ vec3 tmp = r0v.yxz; r0v = r1v.yxz; r1v = tmp; r2v = r2v.yxz; }}
    mat3 M = transpose(mat3(r0v, r1v, r2v));  // GLSL matrices are column-major
    // run-time inversion (section 7): adjugate; det M > 0 for every stored and blended M
    Minv = transpose(mat3(cross(M[1], M[2]), cross(M[2], M[0]), cross(M[0], M[1])));
    n = t2.y; f5 = t2.z;
}}
"""


def glsl_source(table) -> str:
    """:data:`GLSL` with the table's constants filled in."""
    return GLSL.format(**texture_params(table))


__all__ = ["GLSL", "export_all", "glsl_source", "texture_layout",
           "texture_params"]
