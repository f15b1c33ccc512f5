"""NumPy twins of the exported GLSL lookups, line by line: the checks of the shaders' arithmetic
(the LTC tables' ``ltcIsoLookup`` and ``ltcAnisoLookup``, multi-scale's ``alphaMeso``)."""

import numpy as np

from prefilter.multiscale.meso import _A_NODES


def iso_glsl_twin(tex, params, wo, alpha):
    """``prefilter.ltc.glsl.GLSL``'s ``ltcIsoLookup`` in NumPy (float64), line by line,
    vectorised over ``(...)``.

    ``tex (3, R, T, 4)`` from ``texture_layout`` (any float dtype), ``params`` from
    ``texture_params``. Returns ``(M (..., 3, 3), n, f5)`` with ``M`` in the local frame (the
    shader goes on to its adjugate).
    """
    tex = np.asarray(tex, np.float64)
    T, R = int(params["T"]), int(params["R"])
    wo = np.asarray(wo, np.float64)
    sa_min = params["sqrt_alpha_min"]
    ft = np.clip(np.sqrt(np.maximum(0.0, 1.0 - wo[..., 2])) / params["t_max"], 0, 1) * (T - 1)
    sa = np.sqrt(np.clip(np.asarray(alpha, np.float64), sa_min * sa_min, 1.0))
    fr = np.clip((sa - sa_min) / (1.0 - sa_min), 0, 1) * (R - 1)
    i = np.minimum(np.floor(ft).astype(np.intp), T - 2)
    j = np.minimum(np.floor(fr).astype(np.intp), R - 2)
    a, b = (ft - i)[..., None, None], (fr - j)[..., None, None]
    t = np.moveaxis(tex, 0, -2)  # (R, T, 3, 4)
    x = ((1 - a) * (1 - b) * t[j, i] + a * (1 - b) * t[j, i + 1] + (1 - a) * b * t[j + 1, i]
         + a * b * t[j + 1, i + 1]).reshape(ft.shape + (12,))
    M = x[..., :9].reshape(ft.shape + (3, 3))
    rho = np.hypot(wo[..., 0], wo[..., 1])
    safe = np.where(rho > 0, rho, 1.0)
    c, s = np.where(rho > 0, wo[..., 0] / safe, 1.0), np.where(rho > 0, wo[..., 1] / safe, 0.0)
    Rz = np.zeros(ft.shape + (3, 3))
    Rz[..., 0, 0], Rz[..., 0, 1], Rz[..., 1, 0], Rz[..., 1, 1], Rz[..., 2, 2] = c, -s, s, c, 1
    return Rz @ M @ np.swapaxes(Rz, -1, -2), x[..., 9], x[..., 10]


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


def aniso_glsl_twin(tex, params, wo, alpha_x, alpha_y):
    """``prefilter.ltc.aniso.export.GLSL``'s ``ltcAnisoLookup`` in NumPy, line by line
    (vectorised over ``(...)``), GL's ``LINEAR`` filtering and ``CLAMP_TO_EDGE`` emulated (real
    GPUs quantise the filter weights, typically to 8 bits; the twin does not).

    ``tex (3, D, H, W, 4)`` from ``texture_layout`` (any float dtype; computed in float64),
    ``params`` from ``texture_params``. Returns ``(Minv (..., 3, 3), n, f5)``.
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


def alpha_meso_twin(nodes, r) -> np.ndarray:
    """``alphaMeso(r)`` of ``prefilter.multiscale.glsl.GLSL`` on ``nodes`` (from
    ``alpha_meso_nodes``), ``(...)``."""
    flat = np.asarray(nodes, np.float64).reshape(-1)
    n = len(_A_NODES)
    x = np.sqrt(np.clip(3.0 * (1.0 - np.asarray(r, np.float64)), 0.0, 1.0)) * (n - 1)
    k = np.minimum(np.floor(x).astype(np.intp), n - 2)
    return flat[k] + (x - k) * (flat[k + 1] - flat[k])


def load_layout(path) -> np.ndarray:
    """``tex`` from a ``ggx_aniso_f32.npz`` / ``_f16.npz`` file."""
    with np.load(path) as z:
        return z["tex"]
