"""Acceptance test of an LTC table against Monte Carlo integrals of the BRDF over quad lights.

Configurations are (view, roughness, quad) triples; the reference is an unbiased Monte Carlo
estimate of ``integral_P f(wo, wi) cos(theta_i) dwi`` by the renderer's multiple importance
sampling of the lobe and the light (:mod:`prefilter.render.estimator`). The functions are generic
in the lobe so other LTC tables can reuse them.
"""

from __future__ import annotations

import numpy as np

from prefilter.validation import as_float_array, as_positive_int, as_rng, as_upper_directions
from prefilter.errors import PrefilterError
from prefilter.sphere.polygon import clip_to_horizon  # noqa: F401  (re-exported for callers)

#: References below this value (cosine-weighted reflectance) are reported separately: their
#: relative error is dominated by the lobe's far tails and says little about shading quality.
REFERENCE_THRESHOLD = 1e-3

THETA_BINS_DEG = (0.0, 20.0, 40.0, 60.0, 75.0, 85.0)
ALPHA_BINS = (0.05, 0.1, 0.2, 0.4, 0.7, 1.0)
#: Bins of the fraction of the lobe's energy a quad catches (reference / albedo).
FRACTION_BINS = (0.0, 0.01, 0.03, 0.1, 0.3, 1.0)


def _orthonormal(n, rng, k):
    """Two unit vectors ``(k, 3)`` completing unit normals ``n (k, 3)``, randomly rotated."""
    a = np.where(np.abs(n[:, :1]) < 0.9, np.array([[1.0, 0, 0]]), np.array([[0, 1.0, 0]]))
    e1 = np.cross(n, a)
    e1 /= np.linalg.norm(e1, axis=-1, keepdims=True)
    e2 = np.cross(n, e1)
    g = rng.uniform(0, 2 * np.pi, (k, 1))
    return np.cos(g) * e1 + np.sin(g) * e2, -np.sin(g) * e1 + np.cos(g) * e2


def random_quads(n: int, rng, *, straddle: bool = False) -> np.ndarray:
    """``n`` random planar quads ``(n, 4, 3)`` facing the shading point at the origin.

    Centre at distance 1 in a random upper-hemisphere direction (uniform in solid angle; within 10
    degrees of the horizon when ``straddle``), half-sizes in [0.05, 0.6], plane tilted up to 60
    degrees from facing the origin, random in-plane rotation. Vertices are counter-clockwise seen
    from the origin (the front face). Non-straddling quads lie wholly above the horizon;
    straddling quads have vertices on both sides.
    """
    out = np.zeros((0, 4, 3))
    while len(out) < n:
        k = 2 * (n - len(out)) + 16
        phi = rng.uniform(0, 2 * np.pi, k)
        z = rng.uniform(-np.sin(np.radians(10)), np.sin(np.radians(10)), k) if straddle \
            else rng.uniform(0, 1, k)
        s = np.sqrt(1 - z * z)
        c = np.stack([s * np.cos(phi), s * np.sin(phi), z], -1)
        # facing normal -c, tilted by up to 60 degrees towards a random direction
        t1, _ = _orthonormal(-c, rng, k)
        tilt = np.radians(60) * np.sqrt(rng.random((k, 1)))
        nq = np.cos(tilt) * -c + np.sin(tilt) * t1
        e1, e2 = _orthonormal(nq, rng, k)
        h = rng.uniform(0.05, 0.6, (k, 2))
        a, b = e1 * h[:, :1], e2 * h[:, 1:]
        # e1 x e2 = nq (towards the origin): c-a-b, c+a-b, c+a+b, c-a+b is CCW seen from 0
        q = np.stack([c - a - b, c + a - b, c + a + b, c - a + b], 1)
        below = (q[..., 2] <= 0).sum(-1)
        keep = (below > 0) & (below < 4) if straddle else below == 0
        out = np.concatenate([out, q[keep]])
    return out[:n]


def random_configurations(
    n: int,
    seed,
    *,
    theta_deg: tuple[float, float] = (0.0, 85.0),
    alpha: tuple[float, float] = (0.05, 1.0),
    straddle_fraction: float = 0.2,
) -> dict[str, np.ndarray]:
    """``n`` random (view, roughness, quad) configurations for the acceptance test.

    View angles uniform in ``theta_deg`` (degrees) with uniform azimuth, roughness uniform in
    ``alpha``, quads from :func:`random_quads` (the first ``round(straddle_fraction n)`` straddle
    the horizon, then the order is shuffled).

    Returns
    -------
    dict with ``wo`` (n, 3), ``alpha`` (n,), ``quad`` (n, 4, 3), ``straddle`` (n,) bool.
    """
    n = as_positive_int(n, "n")
    rng = as_rng(seed, "seed")
    if not 0.0 <= straddle_fraction <= 1.0:
        raise PrefilterError(f"straddle_fraction: expected a number in [0, 1], got "
                             f"{straddle_fraction}")
    theta = np.radians(rng.uniform(*theta_deg, n))
    phi = rng.uniform(0, 2 * np.pi, n)
    wo = np.stack([np.sin(theta) * np.cos(phi), np.sin(theta) * np.sin(phi), np.cos(theta)], -1)
    a = rng.uniform(*alpha, n)
    ns = int(round(straddle_fraction * n))
    quads = np.concatenate([random_quads(ns, rng, straddle=True),
                            random_quads(n - ns, rng, straddle=False)])
    straddle = np.arange(n) < ns
    perm = rng.permutation(n)
    return {"wo": wo, "alpha": a, "quad": quads[perm], "straddle": straddle[perm]}


def reference_quad_integral(model, wo, quad, n_samples: int, rng) -> tuple[float, float]:
    """Monte Carlo ``integral over the quad of model.eval(wo, wi) dwi``, with standard error.

    The renderer's MIS estimator (:func:`prefilter.render.estimator.mis_quad`: balance heuristic
    between the lobe's samples and uniform area samples of the quad), ``n_samples // 2`` pairs.
    Parts of the quad below the horizon contribute nothing (``eval`` is zero there).

    Parameters
    ----------
    model : a :class:`~prefilter.lobe.Lobe` (a microfacet model) with scalar parameters.
    wo : (3,) view above the surface.
    quad : (4, 3) corners of a planar convex quad (either winding), shading point at the origin.
    n_samples : total number of samples (>= 2).

    Returns
    -------
    (estimate, standard_error)
    """
    from prefilter.render.estimator import mis_quad
    from prefilter.render.lights import QuadLight

    wo = as_upper_directions(wo, "wo")
    quad = as_float_array(quad, "quad", ndim_min=2, last_dim=3)
    n = as_positive_int(n_samples, "n_samples", lo=2) // 2
    rng = as_rng(rng)
    light = QuadLight(quad, np.ones(3))
    if abs(float(light.normal @ light.vertices[0])) < 1e-12:
        raise PrefilterError("quad: expected a quad whose plane misses the shading point")
    if light.normal @ light.vertices[0] > 0.0:  # facing away: the same quad seen from its front
        light = QuadLight(quad[::-1], np.ones(3))
    frame = np.broadcast_to(np.eye(3)[:, None, :], (3, n, 3))  # t, b, n of the local frame
    terms, _ = mis_quad(model, light, np.zeros((n, 3)), *frame, np.broadcast_to(wo, (n, 3)),
                        rng.random((n, 4)))
    z = terms.sum(axis=1)
    return float(z.mean()), float(z.std(ddof=1) / np.sqrt(n))


def error_statistics(estimate, reference, theta, alpha, *,
                     threshold: float = REFERENCE_THRESHOLD, albedo=None) -> dict:
    """Relative-error summary of ``estimate`` vs ``reference`` (all ``(n,)``).

    Configurations with ``reference < threshold`` are excluded from the relative statistics and
    summarised by their absolute error. Returns a JSON-serialisable dict: ``median``, ``p90``,
    ``mean``, ``count``, ``excluded``, ``excluded_max_abs``, and per-bin ``by_theta`` /
    ``by_alpha`` lists of ``{lo, hi, count, median, p90}`` (theta in degrees); with ``albedo``
    (n,) also ``by_fraction``, binned by the fraction ``reference / albedo`` of the lobe's energy
    that the quad catches.
    """
    est = np.asarray(estimate, float)
    ref = np.asarray(reference, float)
    theta = np.asarray(theta, float)
    alpha = np.asarray(alpha, float)
    keep = ref >= threshold
    rel = np.abs(est - ref) / np.where(keep, ref, 1.0)

    def summary(mask):
        r = rel[mask & keep]
        if r.size == 0:
            return {"count": 0, "median": None, "p90": None}
        return {"count": int(r.size), "median": float(np.median(r)),
                "p90": float(np.percentile(r, 90))}

    def binned(x, edges):
        out = []
        for lo, hi in zip(edges[:-1], edges[1:]):
            m = (x >= lo) & ((x < hi) | (hi == edges[-1]) & (x <= hi))
            out.append({"lo": lo, "hi": hi, **summary(m)})
        return out

    all_ = summary(np.ones_like(keep))
    extra = {}
    if albedo is not None:
        frac = ref / np.maximum(np.asarray(albedo, float), 1e-300)
        extra["by_fraction"] = binned(frac, FRACTION_BINS)
    return {
        **all_,
        **extra,
        "mean": float(rel[keep].mean()) if keep.any() else None,
        "threshold": threshold,
        "excluded": int((~keep).sum()),
        "excluded_max_abs": float(np.abs(est - ref)[~keep].max()) if (~keep).any() else 0.0,
        "by_theta": binned(np.degrees(theta), THETA_BINS_DEG),
        "by_alpha": binned(alpha, ALPHA_BINS),
    }


def format_statistics(stats: dict) -> str:
    """A plain-text table of :func:`error_statistics` output."""

    def pct(x):
        return "   -  " if x is None else f"{100 * x:5.2f}%"

    lines = [
        f"relative error over {stats['count']} configurations (reference >= "
        f"{stats['threshold']:g}): median {pct(stats['median'])}, p90 {pct(stats['p90'])}, "
        f"mean {pct(stats['mean'])}",
        f"excluded (reference < {stats['threshold']:g}): {stats['excluded']}, max abs error "
        f"{stats['excluded_max_abs']:.3g}",
        "view angle (deg)   count  median     p90",
    ]
    for b in stats["by_theta"]:
        lines.append(f"  {b['lo']:5.1f}-{b['hi']:5.1f}   {b['count']:6d}  {pct(b['median'])}  "
                     f"{pct(b['p90'])}")
    lines.append("roughness alpha   count  median     p90")
    for b in stats["by_alpha"]:
        lines.append(f"  {b['lo']:5.2f}-{b['hi']:5.2f}   {b['count']:6d}  {pct(b['median'])}  "
                     f"{pct(b['p90'])}")
    if "by_fraction" in stats:
        lines.append("reference/albedo  count  median     p90")
        for b in stats["by_fraction"]:
            lines.append(f"  {b['lo']:5.2f}-{b['hi']:5.2f}   {b['count']:6d}  {pct(b['median'])}  "
                         f"{pct(b['p90'])}")
    return "\n".join(lines)


def run_acceptance(table, n_configs: int = 2000, n_samples: int = 100_000, seed=0, *,
                   progress: bool = False) -> dict:
    """Compare ``magnitude * polygon_integral(M, quad)`` from ``table.lookup`` with MC references.

    Returns a dict with the per-configuration arrays (``estimate``, ``reference``,
    ``standard_error``, ``theta``, ``alpha``, ``straddle``) and ``stats``
    (:func:`error_statistics`).
    """
    from prefilter.sphere.polygon import polygon_integral
    from prefilter.microfacet import GGX

    rng = as_rng(seed, "seed")
    cfg = random_configurations(n_configs, rng)
    M, mag, _ = table.lookup(cfg["wo"], cfg["alpha"])
    est = mag * polygon_integral(M, clip_to_horizon(cfg["quad"]))
    ref = np.zeros(n_configs)
    se = np.zeros(n_configs)
    it = range(n_configs)
    if progress:
        from tqdm import tqdm

        it = tqdm(it, desc="MC references", unit="config")
    for i in it:
        ref[i], se[i] = reference_quad_integral(GGX(cfg["alpha"][i]), cfg["wo"][i],
                                                cfg["quad"][i], n_samples, rng)
    theta = np.arccos(np.clip(cfg["wo"][:, 2], -1, 1))
    return {"estimate": est, "reference": ref, "standard_error": se, "theta": theta,
            "alpha": cfg["alpha"], "straddle": cfg["straddle"],
            "stats": error_statistics(est, ref, theta, cfg["alpha"], albedo=mag)}
