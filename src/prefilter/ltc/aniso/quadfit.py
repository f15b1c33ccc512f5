"""Quad-light integrals as a fitting objective: the LTC of one lobe fitted to the relative error
of its polygon integrals over many quads (the metric of ``ltc validate``), and the vectorised
Monte Carlo references it is fitted to.

:func:`~prefilter.ltc.aniso.bake.quad_polish` refits every table entry with them.
"""

from __future__ import annotations

import numpy as np

from prefilter.errors import PrefilterError
from prefilter.sphere.polygon import clip_to_horizon, polygon_integral
from prefilter.ltc.validate import random_quads
from prefilter.microfacet import GGX, reflect
from prefilter.validation import as_rng


def acceptance_quads(k: int, rng, straddle_fraction: float = 0.2) -> np.ndarray:
    """``k`` quads ``(k, 4, 3)`` drawn like the acceptance's (``round(0.2 k)`` straddling)."""
    rng = as_rng(rng)
    ns = int(round(straddle_fraction * k))
    return np.concatenate([random_quads(ns, rng, straddle=True),
                           random_quads(k - ns, rng, straddle=False)])


def quad_references(wo, alpha_x: float, alpha_y: float, quads, n_lobe: int, n_light: int,
                    seed) -> np.ndarray:
    """MC ``integral_P GGX(ax, ay).eval(wo, wi) dwi`` over many convex quads -> ``(K,)``.

    The estimator of :func:`~prefilter.ltc.validate.reference_quad_integral` (balance heuristic,
    Veach 1997 eq. 9.15, visible-normal reflections + uniform area samples) vectorised over the
    quads: ``n_lobe`` lobe samples shared by all quads, ``n_light`` area samples per quad (two
    triangles chosen by area). ``wo (3,)``, ``quads (K, 4, 3)`` planar and convex.
    """
    from prefilter.validation import as_float_array, as_positive_int, as_upper_directions

    wo = as_upper_directions(wo, "wo")
    quads = as_float_array(quads, "quads", ndim_min=3, last_dim=3)
    n_lobe = as_positive_int(n_lobe, "n_lobe")
    n_light = as_positive_int(n_light, "n_light")
    rng = as_rng(seed, "seed")
    model = GGX(float(alpha_x), float(alpha_y))
    v0, v1, v2, v3 = (quads[:, i] for i in range(4))
    nrm = np.cross(v1 - v0, v2 - v0)
    nq = nrm / np.linalg.norm(nrm, axis=-1, keepdims=True)
    d = np.sum(nq * v0, -1)
    # hit test: (e_j x (p - v_j)) . n = p . (n x e_j) - v_j . (n x e_j) >= 0 for all edges
    g = np.cross(nq[:, None], np.roll(quads, -1, axis=1) - quads)
    gv = np.sum(g * quads, -1)
    tri = 0.5 * np.stack([np.linalg.norm(np.cross(v1 - v0, v2 - v0), axis=-1),
                          np.linalg.norm(np.cross(v2 - v0, v3 - v0), axis=-1)], -1)
    area = tri.sum(-1)

    def pdf_light(w):  # w (N, 3) -> (K, N), zero where the ray misses the quad
        cos = nq @ w.T
        ok = np.abs(cos) > 1e-12
        t = np.where(ok, d[:, None] / np.where(ok, cos, 1.0), -1.0)
        inside = (t > 0) & np.all(t[..., None] * np.einsum("ni,kji->knj", w, g)
                                  >= gv[:, None, :], axis=-1)
        return np.where(inside, t * t / (area[:, None] * np.maximum(np.abs(cos), 1e-300)), 0.0)

    wb = reflect(wo, model.sample_vndf(wo, rng.random((n_lobe, 2))))
    pb_b = model.pdf_reflect(wo, wb)
    f_b = model.eval(wo, wb)
    pl_b = pdf_light(wb)
    z_b = np.where(pl_b > 0, f_b / np.maximum(n_lobe * pb_b + n_light * pl_b, 1e-300), 0.0)
    u = rng.random((len(quads), n_light, 3))
    second = u[..., 2] * area[:, None] >= tri[:, :1]
    va = np.where(second[..., None], v2[:, None], v1[:, None])
    vb = np.where(second[..., None], v3[:, None], v2[:, None])
    su = np.sqrt(u[..., :1])
    pts = (1 - su) * v0[:, None] + su * (1 - u[..., 1:2]) * va + su * u[..., 1:2] * vb
    r = np.linalg.norm(pts, axis=-1)
    wl = pts / r[..., None]
    pl_l = r * r / (area[:, None] * np.maximum(np.abs(np.sum(wl * nq[:, None], -1)), 1e-300))
    z_l = model.eval(wo, wl) / np.maximum(n_lobe * model.pdf_reflect(wo, wl) + n_light * pl_l,
                                          1e-300)
    return z_b.sum(-1) + z_l.sum(-1)


#: Objectives of :func:`fit_quad_ltc`: least squares of the relative error ("l2") or a smooth
#: L1 of it ("l1": ``scipy``'s ``soft_l1`` with a 1 % knee).
QUAD_LOSSES = {"l2": ("linear", 1.0), "l1": ("soft_l1", 0.01)}


def _quad_estimates(x, clipped, magnitude):
    M = np.append(x[:8], 1.0).reshape(3, 3)
    scale = np.exp(x[8]) if len(x) > 8 else 1.0
    return magnitude * scale * polygon_integral(M, clipped)


def fit_quad_ltc(quads, reference, magnitude: float, M0, *, loss: str = "l2",
                 threshold: float = 1e-3, max_nfev: int = 400, fit_scale: bool = True) -> dict:
    """The LTC (and magnitude scale) that best fits quad-light integrals of one lobe.

    Minimises the acceptance metric itself, the relative error
    ``magnitude * s * polygon_integral(M, clip_to_horizon(P_k)) / r_k - 1`` over training quads
    ``P_k`` with references ``r_k >= threshold`` (:data:`QUAD_LOSSES`), by
    ``scipy.optimize.least_squares`` (trust region, finite differences) over the 8 free entries
    of ``M`` (``M_22 = 1``) and ``log s`` (``s = 1`` fixed unless ``fit_scale``), started from
    ``M0``.

    Parameters
    ----------
    quads : (K, 4, 3) training quads. reference : (K,) their MC integrals.
    magnitude : the lobe's ``n``. M0 : (3, 3) start (``M0[2, 2] > 0``).

    Returns
    -------
    dict with ``M`` (3, 3) (unit third column, ``det > 0``), ``scale`` (``s``), ``train_error``
    (K,) relative errors on the kept training quads (NaN elsewhere) and ``start_error`` (K,)
    those of ``M0``.
    """
    from scipy.optimize import least_squares

    from prefilter.validation import as_float_array

    if loss not in QUAD_LOSSES:
        raise PrefilterError(f"loss: expected one of {sorted(QUAD_LOSSES)}, got {loss!r}")
    M0 = as_float_array(M0, "M0")
    if M0.shape != (3, 3) or not M0[2, 2] > 0:
        raise PrefilterError(f"M0: expected a (3, 3) matrix with M0[2, 2] > 0, got {M0}")
    clipped = clip_to_horizon(quads)
    ref = np.asarray(reference, float)
    keep = ref >= threshold
    if not keep.any():
        raise PrefilterError(f"reference: expected some values >= {threshold}, got none")
    ck, rk = clipped[keep], ref[keep]

    def residual(x):
        try:
            return _quad_estimates(x, ck, magnitude) / rk - 1.0
        except PrefilterError:  # a singular trial matrix: steer the trust region away
            return np.full(len(rk), 1e3)

    x0 = (M0 / M0[2, 2]).reshape(-1)[:8]
    if fit_scale:
        x0 = np.append(x0, 0.0)
    kind, f_scale = QUAD_LOSSES[loss]
    res = least_squares(residual, x0, loss=kind, f_scale=f_scale, method="trf",
                        x_scale="jac", diff_step=1e-6, max_nfev=max_nfev)
    x = res.x  # trust-region steps are only accepted when they lower the cost
    M = np.append(x[:8], 1.0).reshape(3, 3)
    M /= np.linalg.norm(M[:, 2])
    if np.linalg.det(M) < 0:  # the same LTC (the cosine is even in y), stored with det > 0
        M = M * np.array([1.0, -1.0, 1.0])

    def errors(xx):
        e = np.full(len(ref), np.nan)
        e[keep] = np.abs(residual(xx))
        return e

    return {"M": M, "scale": float(np.exp(x[8])) if fit_scale else 1.0, "train_error": errors(x),
            "start_error": errors(x0)}
