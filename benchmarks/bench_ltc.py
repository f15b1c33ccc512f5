"""Isotropic LTC throughput and its cost against Monte Carlo at equal error (``make bench``).

Prints, measured in this run:
1. polygon integrals per second for 1e6 shading points (random quads, M from the shipped table);
2. table lookups per second for 1e6 (view, roughness) pairs;
3. the cost of lookup + integral against Monte Carlo at equal error: for random configurations the
   LTC's relative error is measured against a high-sample MIS reference; the number of MIS samples
   whose standard error equals that error is derived from the measured per-sample variance, and
   Monte Carlo time per configuration is scaled to it. The Monte Carlo side is the vectorised
   NumPy MIS estimator of ``prefilter.ltc.validate`` (one configuration at a time), so the ratio
   compares this package's two paths, not the best possible Monte Carlo.
"""

from __future__ import annotations

import time

import numpy as np

from prefilter.ltc import GGXTable
from prefilter.sphere.polygon import clip_to_horizon, polygon_integral
from prefilter.ltc.validate import random_configurations, reference_quad_integral
from prefilter.microfacet import GGX


def best_of(fn, repeat=3):
    times = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return min(times)


def main(n_points: int = 1_000_000, n_configs: int = 200, n_ref: int = 100_000) -> None:
    table = GGXTable.load()
    rng = np.random.default_rng(1)
    cfg = random_configurations(n_points, rng)
    wo, alpha, quads = cfg["wo"], cfg["alpha"], cfg["quad"]

    table.lookup(wo[:10], alpha[:10])  # warm-up (imports, JIT)
    t_lookup = best_of(lambda: table.lookup(wo, alpha))
    M, mag, _ = table.lookup(wo, alpha)
    clipped = clip_to_horizon(quads)
    polygon_integral(M[:10], clipped[:10])
    t_int = best_of(lambda: polygon_integral(M, clipped))
    t_clip = best_of(lambda: clip_to_horizon(quads))
    print(f"table lookups:       {n_points / t_lookup / 1e6:6.2f} M/s ({t_lookup * 1e3:.0f} ms "
          f"for {n_points:.0e})")
    print(f"polygon integrals:   {n_points / t_int / 1e6:6.2f} M/s ({t_int * 1e3:.0f} ms "
          f"for {n_points:.0e}; horizon clipping {t_clip * 1e3:.0f} ms more)")

    # Equal-error comparison on a few configurations.
    small = random_configurations(n_configs, np.random.default_rng(2))
    Ms, ms, _ = table.lookup(small["wo"], small["alpha"])
    est = ms * polygon_integral(Ms, clip_to_horizon(small["quad"]))
    ref = np.zeros(n_configs)
    se = np.zeros(n_configs)
    t0 = time.perf_counter()
    for i in range(n_configs):
        ref[i], se[i] = reference_quad_integral(GGX(small["alpha"][i]), small["wo"][i],
                                                small["quad"][i], n_ref, np.random.default_rng(i))
    t_mc = (time.perf_counter() - t0) / n_configs  # per configuration at n_ref samples
    keep = ref > 1e-3
    rel_err = np.abs(est - ref)[keep] / ref[keep]
    # MIS samples needed for a standard error equal to the LTC's error: se scales as 1/sqrt(n).
    n_equal = n_ref * (se[keep] / np.maximum(rel_err * ref[keep], 1e-12)) ** 2
    n_med = float(np.median(n_equal))
    t_mc_equal = t_mc * n_med / n_ref
    t_ltc = (t_lookup + t_clip + t_int) / n_points
    print(f"LTC median relative error over {keep.sum()} configurations: {np.median(rel_err):.2%}")
    print(f"MIS samples for the same error (median): {n_med:.0f}")
    print(f"time per shading point: LTC {t_ltc * 1e9:.0f} ns, Monte Carlo at equal error "
          f"{t_mc_equal * 1e6:.1f} us  ->  ratio {t_mc_equal / t_ltc:.0f}x")


if __name__ == "__main__":
    main()
