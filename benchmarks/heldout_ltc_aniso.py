"""Held-out accuracy of anisotropic LTC tables (docs/ltc-aniso.md, "Held-out accuracy").

    .venv/bin/python benchmarks/heldout_ltc_aniso.py [--configs 4000] [--samples 50000]
        [--cache refs.npz] [shipped] [path/to/table.npz ...]

Configurations drawn from ``prefilter.studies.ltc_aniso.HELDOUT_SEED`` (no bake or polish uses
it), independent Monte Carlo references (50 000 MIS samples each); over the configurations with
reference >= 0.05: median and p90 relative error and p90 absolute error per table, and the
paired difference to the first table with a bootstrap 95 % interval. ``--cache`` keeps the
references between runs (they take most of the time). ``shipped`` is the package's table (not a
user table).
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from prefilter.ltc import AnisoGGXTable
from prefilter.ltc.aniso.table import shipped_table_path
from prefilter.studies.ltc_aniso import (HELDOUT_SEED, HELDOUT_THRESHOLD, estimates,
                                         heldout_accuracy, heldout_configurations)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("tables", nargs="*", default=["shipped"])
    ap.add_argument("--configs", type=int, default=4000)
    ap.add_argument("--samples", type=int, default=50_000)
    ap.add_argument("--cache", default=None, help="npz holding the references between runs")
    a = ap.parse_args()
    key = f"{HELDOUT_SEED}_{a.configs}_{a.samples}"
    cache = Path(a.cache) if a.cache else None
    if cache is not None and cache.is_file() and str(np.load(cache)["key"]) == key:
        raw = np.load(cache)
        cfg = {k: raw[k] for k in raw.files if k != "key"}
    else:
        cfg = heldout_configurations(a.configs, a.samples, progress=True)
        if cache is not None:
            np.savez(cache, key=key, **cfg)
    first = None
    rng = np.random.default_rng(0)
    for spec in a.tables:
        table = AnisoGGXTable.load(shipped_table_path() if spec == "shipped" else spec)
        s = heldout_accuracy(table, cfg)
        print(f"{spec}: {s['count']} of {s['of']} configurations with reference >= "
              f"{s['threshold']:g}: median {100 * s['median']:.2f} %, p90 {100 * s['p90']:.2f} %, "
              f"absolute p90 {s['abs_p90']:.4f} (MC relative standard error, median: "
              f"{100 * s['mc_rel_se']:.2f} %)")
        keep = cfg["ref"] >= HELDOUT_THRESHOLD
        sub = {k: v[keep] for k, v in cfg.items()}
        est = estimates(table, sub)
        err = np.stack([np.abs(est / sub["ref"] - 1.0), np.abs(est - sub["ref"])])
        if first is None:
            first = err
            continue
        idx = rng.integers(0, err.shape[1], (2000, err.shape[1]))
        for label, row, q, unit in (("median", 0, 50, "pp"), ("p90", 0, 90, "pp"),
                                    ("absolute p90", 1, 90, "")):
            scale = 100 if unit else 1
            d = scale * (np.percentile(err[row][idx], q, axis=1)
                         - np.percentile(first[row][idx], q, axis=1))
            print(f"  {label} - {a.tables[0]}'s: {d.mean():+.4f} {unit}, 95 % interval "
                  f"[{np.percentile(d, 2.5):+.4f}, {np.percentile(d, 97.5):+.4f}]")


if __name__ == "__main__":
    main()
