"""Compare anisotropic LTC tables on issue 4's acceptance protocol and on lobe-centred quads
(docs/ltc-aniso.md, "What limits the p90").

    .venv/bin/python benchmarks/study_ltc_aniso.py [--configs 2000] [--samples 50000]
        [--lobe 500] [--lobe-samples 20000] [--cache refs.npz] shipped path/to/table.npz ...

``shipped`` is the package table. **acceptance**: exactly the configurations and references of
``prefilter.ltc.aniso.accept.run_acceptance`` (seed 0: ``n`` anisotropic configurations, then
``n / 2`` isotropic ones), computed once and shared by all tables (``--cache`` keeps them
between runs). **lobe quads**: ``--lobe`` configurations drawn the same way (seed 5) with quads
centred on a direction reflected about a visible normal of the lobe, as highlights are (what the
acceptance's uniformly placed quads rarely test).
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from prefilter.ltc import AnisoGGXTable
from prefilter.ltc.aniso.accept import (estimates, format_statistics, random_aniso_configurations,
                                        references, statistics)
from prefilter.ltc.fit_iso import _quads_around
from prefilter.microfacet import GGX, reflect


def acceptance_sets(n: int, n_samples: int, seed: int = 0) -> dict:
    """The two configuration sets of ``run_acceptance`` with their references (same seeds)."""
    cfg = random_aniso_configurations(n, seed)
    cfg["ref"] = references(cfg, n_samples, np.random.default_rng([seed, 1]))[0]
    icfg = random_aniso_configurations(n // 2, np.random.default_rng([seed, 2]), isotropic=True)
    icfg["ref"] = references(icfg, n_samples, np.random.default_rng([seed, 3]))[0]
    return {"acceptance": cfg, "acceptance, isotropic": icfg}


def lobe_set(n: int, n_samples: int, seed: int = 5) -> dict:
    """Configurations whose quads are centred on a reflection about a visible normal."""
    rng = np.random.default_rng(seed)
    cfg = random_aniso_configurations(n, rng)
    m = GGX(cfg["alpha_x"], cfg["alpha_y"]).sample_vndf(cfg["wo"], rng.random((n, 2)))
    c = reflect(cfg["wo"], m)
    c[:, 2] = np.maximum(c[:, 2], 0.02)  # grazing lobes reflect below the horizon too
    c /= np.linalg.norm(c, axis=-1, keepdims=True)
    cfg["quad"] = _quads_around(c, rng)
    cfg["ref"] = references(cfg, n_samples, rng)[0]
    return cfg


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("tables", nargs="+")
    ap.add_argument("--configs", type=int, default=2000)
    ap.add_argument("--samples", type=int, default=50_000)
    ap.add_argument("--lobe", type=int, default=500)
    ap.add_argument("--lobe-samples", type=int, default=20_000)
    ap.add_argument("--cache", default=None, help="npz holding the references between runs")
    a = ap.parse_args()
    key = f"{a.configs}_{a.samples}_{a.lobe}_{a.lobe_samples}"
    cache = Path(a.cache) if a.cache else None
    if cache is not None and cache.is_file() and str(np.load(cache)["key"]) == key:
        raw = np.load(cache)
        names = [str(s) for s in raw["names"]]
        sets = {name: {k.split("/", 1)[1]: raw[k] for k in raw.files
                       if k.startswith(f"{j}/")} for j, name in enumerate(names)}
    else:
        sets = acceptance_sets(a.configs, a.samples)
        if a.lobe > 0:
            sets["lobe quads"] = lobe_set(a.lobe, a.lobe_samples)
        if cache is not None:
            flat = {f"{j}/{k}": v for j, cfg in enumerate(sets.values()) for k, v in cfg.items()}
            np.savez(cache, key=key, names=np.array(list(sets)), **flat)
    for spec in a.tables:
        table = AnisoGGXTable.load(None if spec == "shipped" else spec)
        for name, cfg in sets.items():
            print(format_statistics(statistics(estimates(table, cfg), cfg["ref"], cfg),
                                    f"{spec}: {name}: "))


if __name__ == "__main__":
    main()
