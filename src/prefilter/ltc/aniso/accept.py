"""Acceptance of the anisotropic table: quad-light integrals against Monte Carlo references.

Reuses :mod:`prefilter.ltc.validate` (random quads incl. horizon-straddling ones, horizon
clipping, the MIS reference estimator and the error statistics); only the roughness draw differs:
``alpha_x`` and ``alpha_y`` independent (or equal, for the comparison with the isotropic table).
"""

from __future__ import annotations

import numpy as np

from prefilter.validation import as_rng
from prefilter.ltc.polygon import clip_to_horizon
from prefilter.ltc.validate import (
    error_statistics,
    random_configurations,
    random_quads,
    reference_quad_integral,
)
from prefilter.errors import PrefilterError
from prefilter.microfacet import GGX, reflect


def random_aniso_configurations(n: int, seed, *, theta_deg=(0.0, 85.0), alpha=(0.05, 1.0),
                                straddle_fraction: float = 0.2, isotropic: bool = False) -> dict:
    """:func:`~prefilter.ltc.validate.random_configurations` with a second roughness.

    Returns a dict with ``wo`` (n, 3), ``alpha_x``, ``alpha_y`` (n,), ``quad`` (n, 4, 3) and
    ``straddle`` (n,); ``alpha_y`` is drawn uniformly in ``alpha`` (``= alpha_x`` if
    ``isotropic``).
    """
    rng = as_rng(seed, "seed")
    cfg = random_configurations(n, rng, theta_deg=theta_deg, alpha=alpha,
                                straddle_fraction=straddle_fraction)
    ax = cfg.pop("alpha")
    ay = ax.copy() if isotropic else rng.uniform(*alpha, n)
    return {**cfg, "alpha_x": ax, "alpha_y": ay}


def references(cfg: dict, n_samples: int, seed, *, progress: bool = False):
    """MC references ``(n,)`` and standard errors ``(n,)`` of ``GGX(ax, ay).eval`` over quads."""
    rng = as_rng(seed, "seed")
    n = len(cfg["wo"])
    ref, se = np.zeros(n), np.zeros(n)
    it = range(n)
    if progress:
        from tqdm import tqdm

        it = tqdm(it, desc="MC references", unit="config")
    for i in it:
        ref[i], se[i] = reference_quad_integral(GGX(cfg["alpha_x"][i], cfg["alpha_y"][i]),
                                                cfg["wo"][i], cfg["quad"][i], n_samples, rng)
    return ref, se


def estimates(table, cfg: dict) -> np.ndarray:
    """``magnitude * polygon_integral(M, clipped quad)`` from ``table.lookup`` -> ``(n,)``."""
    from prefilter.ltc.polygon import polygon_integral

    M, mag, _ = table.lookup(cfg["wo"], cfg["alpha_x"], cfg["alpha_y"])
    return mag * polygon_integral(M, clip_to_horizon(cfg["quad"]))


def statistics(est, ref, cfg: dict) -> dict:
    """:func:`~prefilter.ltc.validate.error_statistics` binned by view angle, by the larger
    roughness (``by_alpha``) and by the anisotropy ratio ``min / max`` (``by_ratio``)."""
    theta = np.arccos(np.clip(cfg["wo"][:, 2], -1, 1))
    ax, ay = cfg["alpha_x"], cfg["alpha_y"]
    amax = np.maximum(ax, ay)
    stats = error_statistics(est, ref, theta, amax)
    stats["by_ratio"] = error_statistics(est, ref, theta, np.minimum(ax, ay) / amax)["by_alpha"]
    return stats


def format_statistics(stats: dict, title: str = "") -> str:
    """Plain-text summary of :func:`statistics`."""

    def pct(x):
        return "   -  " if x is None else f"{100 * x:5.2f}%"

    lines = [f"{title}relative error over {stats['count']} configurations: median "
             f"{pct(stats['median'])}, p90 {pct(stats['p90'])}, mean {pct(stats['mean'])} "
             f"(excluded, reference < {stats['threshold']:g}: {stats['excluded']})"]
    for key, label in (("by_theta", "view angle (deg)"), ("by_alpha", "max roughness"),
                       ("by_ratio", "ratio min/max")):
        lines.append(f"  {label:18s} count  median     p90")
        for b in stats[key]:
            lines.append(f"    {b['lo']:5.2f}-{b['hi']:5.2f}    {b['count']:6d}  "
                         f"{pct(b['median'])}  {pct(b['p90'])}")
    return "\n".join(lines)


def run_acceptance(table, n_configs: int = 2000, n_samples: int = 50_000, seed=0, *,
                   iso_table=None, progress: bool = False) -> dict:
    """Issue 4's accuracy acceptance; returns ``{"aniso": stats, "isotropic": {...}}``.

    ``aniso``: ``n_configs`` configurations with independent roughnesses. ``isotropic``
    (``n_configs // 2`` configurations with ``alpha_x = alpha_y``, same references for both
    tables): statistics of this table and, if given, of the isotropic ``iso_table``.
    """
    cfg = random_aniso_configurations(n_configs, seed)
    ref, _ = references(cfg, n_samples, np.random.default_rng([seed, 1]), progress=progress)
    out = {"aniso": statistics(estimates(table, cfg), ref, cfg)}
    icfg = random_aniso_configurations(n_configs // 2, np.random.default_rng([seed, 2]),
                                       isotropic=True)
    iref, _ = references(icfg, n_samples, np.random.default_rng([seed, 3]), progress=progress)
    iso = {"aniso_table": statistics(estimates(table, icfg), iref, icfg)}
    if iso_table is not None:
        from prefilter.ltc.polygon import polygon_integral

        M, mag, _ = iso_table.lookup(icfg["wo"], np.clip(icfg["alpha_x"], iso_table.alpha_min, 1))
        est = mag * polygon_integral(M, clip_to_horizon(icfg["quad"]))
        iso["iso_table"] = statistics(est, iref, icfg)
    out["isotropic"] = iso
    return out


# --------------------------------------------------------------------------------------------
# The acceptance metric as a fitting objective: the one-LTC-per-entry floor ("oracle")
# --------------------------------------------------------------------------------------------


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
    from prefilter.ltc.polygon import polygon_integral

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
