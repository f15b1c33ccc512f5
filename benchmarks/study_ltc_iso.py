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

from prefilter.ltc.fit_iso import ProbeSettings, _quads_around, refine_entry, view_from_t
from prefilter.sphere.polygon import clip_to_horizon, polygon_integral
from prefilter.ltc.table import GGXTable
from prefilter.ltc.validate import (error_statistics, format_statistics, random_configurations,
                                    reference_quad_integral)
from prefilter.microfacet import GGX, reflect
from prefilter.validation import as_positive_int


class AnisoAsIso:
    """The anisotropic table at alpha_x = alpha_y, with the isotropic table's `lookup`."""

    def __init__(self):
        from prefilter.ltc.aniso.table import AnisoGGXTable

        self.table = AnisoGGXTable.load()

    def lookup(self, wo, alpha):
        return self.table.lookup(wo, alpha, alpha)


def probe_refit_study(n_configs: int = 200, settings: ProbeSettings | None = None, *,
                      n_samples: int = 20_000, table=None) -> dict:
    """Quad-light errors of the table vs. the probe refit at each configuration's exact entry.

    The first ``n_configs`` acceptance configurations (``validate.random_configurations``, seed 0)
    are evaluated with ``table.lookup`` (default: the shipped table) and with
    ``fit_iso.refine_entry`` started from the table's matrix at the configuration's exact view angle
    and roughness (probes from ``settings.seed``, never the acceptance seed). References:
    ``validate.reference_quad_integral`` with ``n_samples`` samples (seed 123).

    Returns dict with ``table`` and ``refined`` (``validate.error_statistics`` of each) and the
    mean probe objective before and after the refit (``objective_start``, ``objective_end``).
    """
    settings = settings or ProbeSettings()
    table = table or GGXTable.load()
    cfg = random_configurations(as_positive_int(n_configs, "n_configs"), 0)
    rng = np.random.default_rng(123)
    rows = []
    for wo, alpha, quad in zip(cfg["wo"], cfg["alpha"], cfg["quad"]):
        phi = np.arctan2(wo[1], wo[0])
        c, s = np.cos(phi), np.sin(phi)
        R = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
        q = clip_to_horizon(quad @ R)  # the view's azimuthal frame
        M0, n, _ = table.lookup_canonical(wo[2], alpha)
        n = float(n)
        fit = refine_entry(view_from_t(np.sqrt(1.0 - wo[2])), alpha, M0, n, settings)
        ref, _ = reference_quad_integral(GGX(alpha), wo, quad, n_samples, rng)
        rows.append((np.arccos(wo[2]), alpha, n, ref, n * polygon_integral(M0, q),
                     n * polygon_integral(fit["M"], q), fit["error_start"], fit["error"]))
    th, a, n, ref, e0, e1, o0, o1 = np.array(rows).T
    return {"table": error_statistics(e0, ref, th, a, albedo=n),
            "refined": error_statistics(e1, ref, th, a, albedo=n),
            "objective_start": float(o0.mean()), "objective_end": float(o1.mean())}


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
    from prefilter.render.driver import render

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
