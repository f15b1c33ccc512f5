"""Engine layouts of the anisotropic LTC table, the GLSL lookup and its Python twin.

Anisotropic-LTC paper, section 9 ("Storage", "Run time"). The 4D table becomes three RGBA 3D
textures of size ``W x H x D = T x F x (R * A)`` (theta fastest, then phi, then depth ``r * A +
a``), so the hardware interpolates trilinearly in (theta, phi, alpha) and the shader blends two
ratio slices by hand (6 fetches). Channels::

    tex0 = (m00, m01, m02, m10)   tex1 = (m11, m12, m20, m21)   tex2 = (m22, n, f5, 0)

with ``M`` the stored (aligned, unit third column) matrix, ``n`` the magnitude and ``f5`` the
Fresnel scalar. :data:`GLSL` folds the view with the symmetries, fetches, unfolds and inverts
``M`` (adjugate; the determinant cancels in the LTC integral), and :func:`glsl_twin` is the same
program line by line in NumPy, with GL's ``LINEAR`` filtering and ``CLAMP_TO_EDGE`` emulated (real
GPUs quantise the filter weights, typically to 8 bits; the twin does not).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from prefilter.fileio import atomic_path, save_json_atomic, save_npz_atomic
from prefilter.errors import PrefilterError

_CHANNELS = [(0, 0), (0, 1), (0, 2), (1, 0), (1, 1), (1, 2), (2, 0), (2, 1), (2, 2)]


def _uniform(c) -> bool:
    d = np.diff(c)
    return bool(np.allclose(d, d[0], rtol=1e-9, atol=1e-12))


def texture_params(table) -> dict:
    """The scalars the shader needs (grid sizes and the ranges of the uniform coordinates)."""
    c = table._coords
    if not all(_uniform(x) for x in c):
        raise PrefilterError("table axes: the texture layout needs nodes uniform in theta, phi, "
                             "sqrt(alpha) and sqrt(ratio)")
    T, F, A, R = table.shape
    return {"T": T, "F": F, "A": A, "R": R, "theta_max": float(c[0][-1]),
            "sqrt_alpha_min": float(c[2][0]), "sqrt_ratio_min": float(c[3][0])}


def texture_layout(table, dtype=np.float32) -> np.ndarray:
    """The three RGBA textures ``(3, D, H, W, 4)`` (``D = R * A``, ``H = F``, ``W = T``)."""
    T, F, A, R = table.shape
    ch = [table.M[..., i, j] for i, j in _CHANNELS] + [table.magnitude, table.fresnel,
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
    with atomic_path(g, suffix=".glsl") as tmp:
        tmp.write_text(glsl_source(table))
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


def _texture(tex, uvw):
    """GL ``texture()`` with LINEAR filtering and CLAMP_TO_EDGE: ``tex (D, H, W, 4)``."""
    D, H, W = tex.shape[:3]
    out = 0.0
    xs = []
    for k, size in enumerate((W, H, D)):
        x = uvw[..., k] * size - 0.5
        i0 = np.floor(x)
        t = x - i0
        i0 = i0.astype(np.intp)
        xs.append((np.clip(i0, 0, size - 1), np.clip(i0 + 1, 0, size - 1), t))
    for c in range(8):
        w = 1.0
        idx = []
        for k in range(3):
            lo, hi, t = xs[k]
            b = (c >> k) & 1
            idx.append(hi if b else lo)
            w = w * (t if b else 1.0 - t)
        out = out + w[..., None] * tex[idx[2], idx[1], idx[0]]
    return out


def glsl_twin(tex, params, wo, alpha_x, alpha_y):
    """:data:`GLSL`'s ``ltcAnisoLookup`` in NumPy, line by line (vectorised over ``(...)``).

    ``tex (3, D, H, W, 4)`` from :func:`texture_layout` (any float dtype; computed in float64),
    ``params`` from :func:`texture_params`. Returns ``(Minv (..., 3, 3), n, f5)``.
    """
    tex = np.asarray(tex, np.float64)
    T, F, A, R = (float(params[k]) for k in "TFAR")
    wo = np.asarray(wo, np.float64)
    ax, ay = np.broadcast_arrays(np.asarray(alpha_x, float), np.asarray(alpha_y, float))
    swp = ay > ax
    alpha = np.maximum(ax, ay)
    ratio = np.minimum(ax, ay) / alpha
    w = np.where(swp[..., None], wo[..., [1, 0, 2]], wo)
    s = np.stack([np.where(w[..., 0] < 0, -1.0, 1.0), np.where(w[..., 1] < 0, -1.0, 1.0)], -1)
    w = np.concatenate([np.abs(w[..., :2]), w[..., 2:]], -1)
    ft = np.clip(np.arccos(np.clip(w[..., 2], 0, 1)) / params["theta_max"], 0, 1) * (T - 1)
    fp = np.clip(np.arctan2(w[..., 1], w[..., 0]) / 1.5707963268, 0, 1) * (F - 1)
    fa = np.clip((np.sqrt(alpha) - params["sqrt_alpha_min"]) / (1 - params["sqrt_alpha_min"]),
                 0, 1) * (A - 1)
    fr = np.clip((np.sqrt(ratio) - params["sqrt_ratio_min"]) / (1 - params["sqrt_ratio_min"]),
                 0, 1) * (R - 1)
    r0 = np.minimum(np.floor(fr), R - 2)
    tr = (fr - r0)[..., None]
    u, v = (ft + 0.5) / T, (fp + 0.5) / F
    uvw_a = np.stack([u, v, (r0 * A + fa + 0.5) / (A * R)], -1)
    uvw_b = np.stack([u, v, ((r0 + 1) * A + fa + 0.5) / (A * R)], -1)
    t = [(1 - tr) * _texture(tex[k], uvw_a) + tr * _texture(tex[k], uvw_b) for k in range(3)]
    rows = np.stack([t[0][..., :3], np.stack([t[0][..., 3], t[1][..., 0], t[1][..., 1]], -1),
                     np.stack([t[1][..., 2], t[1][..., 3], t[2][..., 0]], -1)], -2)
    sv = np.concatenate([s, np.ones(s.shape[:-1] + (1,))], -1)
    rows = rows * sv[..., :, None] * sv[..., None, :]
    rows = np.where(swp[..., None, None], rows[..., [1, 0, 2], :][..., :, [1, 0, 2]], rows)
    M = rows
    c0, c1, c2 = M[..., :, 0], M[..., :, 1], M[..., :, 2]
    # adjugate, as in the shader: row i of det(M) M^-1 is (column i+1) x (column i+2)
    Minv = np.stack([np.cross(c1, c2), np.cross(c2, c0), np.cross(c0, c1)], -2)
    return Minv, t[2][..., 1], t[2][..., 2]


def load_layout(path) -> np.ndarray:
    """``tex`` from a ``ggx_aniso_f32.npz`` / ``_f16.npz`` file."""
    with np.load(path) as z:
        return z["tex"]


__all__ = ["GLSL", "export_all", "glsl_source", "glsl_twin", "load_layout", "texture_layout",
           "texture_params"]
