"""Compare anisotropic LTC tables on issue 4's acceptance protocol and on lobe-centred quads
(docs/ltc-aniso.md, "What limits the p90").

    .venv/bin/python benchmarks/study_ltc_aniso.py [--configs 2000] [--samples 50000]
        [--lobe 500] [--lobe-samples 20000] [--cache refs.npz]
        [--repolish K OUT.npz] [--quad-polish OUT.npz] shipped path/to/table.npz ...

``shipped`` is the package table. **acceptance**: exactly the configurations and references of
``prefilter.studies.ltc_aniso.run_acceptance`` (seed 0: ``n`` anisotropic configurations, then
``n / 2`` isotropic ones), computed once and shared by all tables (``--cache`` keeps them
between runs). **lobe quads**: ``--lobe`` configurations drawn the same way (seed 5) with quads
centred on a direction reflected about a visible normal of the lobe, as highlights are (what the
acceptance's uniformly placed quads rarely test). Every table after the first also gets a
paired bootstrap (2000 resamples of the configurations) of its median and p90 difference to
the first table, with 95 % intervals.

Candidates built from the shipped table (written to ``OUT.npz``, then compared):
``--repolish K``: the bake's point-wise polish rerun with ``|p - q|^K`` (``bake.repolish``);
``--quad-polish``: every entry refitted on the acceptance metric (``bake.quad_polish``,
2 processes, 1024 + 256 reference samples, ~16 min on the loaded 2-core machine).
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from prefilter.ltc import AnisoGGXTable
from prefilter.studies.ltc_aniso import (estimates, format_statistics, random_aniso_configurations,
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
    ap.add_argument("--repolish", nargs=2, metavar=("K", "OUT"), default=None)
    ap.add_argument("--quad-polish", metavar="OUT", default=None)
    a = ap.parse_args()
    if a.repolish:
        from prefilter.ltc.aniso.bake import repolish

        repolish(AnisoGGXTable.load(), float(a.repolish[0])).save(a.repolish[1])
    if a.quad_polish:
        from prefilter.ltc.aniso.bake import QuadPolishSettings, quad_polish

        quad_polish(AnisoGGXTable.load(), QuadPolishSettings(lobe_samples=1024, light_samples=256,
                                                             processes=2)).save(a.quad_polish)
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
    first = {}
    rng = np.random.default_rng(0)
    for spec in a.tables:
        table = AnisoGGXTable.load(None if spec == "shipped" else spec)
        for name, cfg in sets.items():
            est = estimates(table, cfg)
            print(format_statistics(statistics(est, cfg["ref"], cfg), f"{spec}: {name}: "))
            ok = cfg["ref"] >= 1e-3
            err = np.abs(est[ok] / cfg["ref"][ok] - 1.0)
            if name not in first:
                first[name] = err
                continue
            idx = rng.integers(0, len(err), (2000, len(err)))
            for label, q in (("median", 50), ("p90", 90)):
                d = 100 * (np.percentile(err[idx], q, axis=1)
                           - np.percentile(first[name][idx], q, axis=1))
                print(f"  {label} - {a.tables[0]}'s: {d.mean():+.2f} pp, 95 % interval "
                      f"[{np.percentile(d, 2.5):+.2f}, {np.percentile(d, 97.5):+.2f}]")


if __name__ == "__main__":
    main()
