"""Acceptance of the anisotropic table: quad-light integrals against Monte Carlo references.

Reuses :mod:`prefilter.ltc.validate` (random quads incl. horizon-straddling ones, horizon
clipping, the MIS reference estimator and the error statistics); only the roughness draw differs:
``alpha_x`` and ``alpha_y`` independent (or equal, for the comparison with the isotropic table).
"""

from __future__ import annotations

import numpy as np

from prefilter.sphere.polygon import clip_to_horizon, polygon_integral
from prefilter.ltc.validate import error_statistics, random_configurations, reference_quad_integral
from prefilter.microfacet import GGX
from prefilter.validation import as_rng


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
    """The accuracy acceptance of the anisotropic table.

    Returns ``{"aniso": stats, "isotropic": {...}}``.

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
        M, mag, _ = iso_table.lookup(icfg["wo"], np.clip(icfg["alpha_x"], iso_table.alpha_min, 1))
        est = mag * polygon_integral(M, clip_to_horizon(icfg["quad"]))
        iso["iso_table"] = statistics(est, iref, icfg)
    out["isotropic"] = iso
    return out


#: Seed of the held-out accuracy check: no bake, polish or other acceptance draws from it.
HELDOUT_SEED = 2027
#: Only configurations whose reference reaches this value count in :func:`heldout_accuracy`
#: (quads that catch a visible part of the lobe; the published table's comparison set).
HELDOUT_THRESHOLD = 0.05


def heldout_configurations(n_configs: int = 4000, n_samples: int = 50_000,
                           seed: int = HELDOUT_SEED, *, screen_samples: int = 2000,
                           threshold: float = HELDOUT_THRESHOLD, progress: bool = False) -> dict:
    """Held-out configurations (:func:`random_aniso_configurations`) with independent MC
    references: ``cfg`` plus ``ref`` and ``se`` (n,), the reference and its standard error.

    A screening pass (``screen_samples`` per configuration) finds the configurations that can
    reach ``threshold``; only those (screened value >= ``threshold / 2``, i.e. more than ten
    screening standard errors below it for a lit quad) get the ``n_samples`` reference, from an
    independent stream. The others keep the screening estimate (``ref < threshold``, excluded
    by :func:`heldout_accuracy`).
    """
    cfg = random_aniso_configurations(n_configs, np.random.default_rng([seed, 0]))
    ref, se = references(cfg, screen_samples, np.random.default_rng([seed, 2]))
    lit = ref >= 0.5 * threshold
    sub = {k: v[lit] for k, v in cfg.items()}
    ref[lit], se[lit] = references(sub, n_samples, np.random.default_rng([seed, 1]),
                                   progress=progress)
    cfg["ref"], cfg["se"] = ref, se
    return cfg


def heldout_accuracy(table, cfg: dict, threshold: float = HELDOUT_THRESHOLD) -> dict:
    """Relative and absolute error of ``table`` on configurations with ``ref >= threshold``.

    ``cfg`` from :func:`heldout_configurations`. Returns ``count``, ``median`` and ``p90`` of
    ``|E / ref - 1|``, ``abs_p90`` of ``|E - ref|`` (cosine-weighted reflectance, Fresnel = 1),
    and ``mc_rel_se``, the median relative standard error of the references.
    """
    keep = cfg["ref"] >= threshold
    sub = {k: v[keep] for k, v in cfg.items()}
    est = estimates(table, sub)
    rel = np.abs(est / sub["ref"] - 1.0)
    return {"count": int(keep.sum()), "of": int(len(keep)), "threshold": threshold,
            "median": float(np.median(rel)), "p90": float(np.percentile(rel, 90)),
            "abs_p90": float(np.percentile(np.abs(est - sub["ref"]), 90)),
            "mc_rel_se": float(np.median(sub["se"] / sub["ref"]))}
