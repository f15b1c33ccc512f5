"""Compare isotropic LTC tables as in docs/ltc.md ("Grazing views"): the acceptance protocol,
quads centred on the lobe (highlights), and the demo plane's mean bias against `reference`.

    python benchmarks/study_ltc_iso.py [--configs 2000 --samples 100000] [--lobe 500]
        [--lobe-samples 20000] [--demo-spp 256] shipped aniso path/to/table.npz ...

`shipped` is the package table, `aniso` the anisotropic table at ratio 1. References are computed
once per run and shared by all tables (same seeds as in docs/ltc.md: acceptance 0, lobe quads 5).
"""

from __future__ import annotations

import argparse

import numpy as np

from prefilter.ltc.fit_iso import _quads_around
from prefilter.ltc.polygon import clip_to_horizon, polygon_integral
from prefilter.ltc.table import GGXTable
from prefilter.ltc.validate import (error_statistics, format_statistics, random_configurations,
                                    reference_quad_integral)
from prefilter.microfacet import GGX, reflect


class AnisoAsIso:
    """The anisotropic table at alpha_x = alpha_y, with the isotropic table's `lookup`."""

    def __init__(self):
        from prefilter.ltc.aniso.table import AnisoGGXTable

        self.table = AnisoGGXTable.load()

    def lookup(self, wo, alpha):
        return self.table.lookup(wo, alpha, alpha)


def get_table(spec: str):
    if spec == "aniso":
        return AnisoAsIso()
    return GGXTable.load(None if spec == "shipped" else spec)


def references(cfg, n_samples: int, rng) -> np.ndarray:
    ref = np.zeros(len(cfg["alpha"]))
    for i in range(len(ref)):
        ref[i] = reference_quad_integral(GGX(cfg["alpha"][i]), cfg["wo"][i], cfg["quad"][i],
                                         n_samples, rng)[0]
    return ref


def acceptance_set(n: int, n_samples: int, seed: int = 0) -> dict:
    """The configurations and references of `run_acceptance` (same generator sequence)."""
    rng = np.random.default_rng(seed)
    cfg = random_configurations(n, rng)
    cfg["ref"] = references(cfg, n_samples, rng)
    return cfg


def lobe_set(n: int, n_samples: int, seed: int = 5) -> dict:
    """Quads centred on a direction reflected about a visible normal of the lobe."""
    rng = np.random.default_rng(seed)
    cfg = random_configurations(n, rng)
    c = reflect(cfg["wo"], GGX(cfg["alpha"]).sample_vndf(cfg["wo"], rng.random((n, 2))))
    c[:, 2] = np.maximum(c[:, 2], 0.02)
    c /= np.linalg.norm(c, axis=-1, keepdims=True)
    cfg["quad"] = _quads_around(c, rng)
    cfg["ref"] = references(cfg, n_samples, rng)
    return cfg


def evaluate(table, cfg) -> dict:
    M, mag, _ = table.lookup(cfg["wo"], cfg["alpha"])
    est = mag * polygon_integral(M, clip_to_horizon(cfg["quad"]))
    theta = np.arccos(np.clip(cfg["wo"][:, 2], -1, 1))
    return error_statistics(est, cfg["ref"], theta, cfg["alpha"], albedo=mag)


def demo_bias(specs, spp: int = 256) -> dict:
    """Mean of `ltc` (or `ltc-aniso`) on the flat showcase plane at alpha 0.3 against
    `reference` with `spp` samples per pixel."""
    from prefilter.report.demo import showcase_scene
    from prefilter.render.pipeline import render

    scene = showcase_scene(1.0, 96, 60, alpha=0.3)
    scene["objects"][0]["material"].pop("normal_map", None)
    ref = render(scene, "reference", spp=spp, seed=0).mean()
    out = {}
    for spec in specs:
        if spec == "aniso":
            img = render(scene, "ltc-aniso")
        else:
            img = render(scene, "ltc", table=None if spec == "shipped" else GGXTable.load(spec))
        out[spec] = img.mean() / ref - 1.0
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("tables", nargs="+")
    ap.add_argument("--configs", type=int, default=2000)
    ap.add_argument("--samples", type=int, default=100_000)
    ap.add_argument("--lobe", type=int, default=500)
    ap.add_argument("--lobe-samples", type=int, default=20_000)
    ap.add_argument("--demo-spp", type=int, default=256)
    a = ap.parse_args()
    sets = {"acceptance": acceptance_set(a.configs, a.samples),
            "lobe quads": lobe_set(a.lobe, a.lobe_samples)}
    bias = demo_bias(a.tables, a.demo_spp) if a.demo_spp > 0 else {}
    for spec in a.tables:
        table = get_table(spec)
        for name, cfg in sets.items():
            print(f"===== {spec}: {name}")
            print(format_statistics(evaluate(table, cfg)))
        if spec in bias:
            print(f"===== {spec}: demo plane mean bias {100 * bias[spec]:+.1f} %")


if __name__ == "__main__":
    main()
