"""The floor of a one-LTC-per-entry table on issue 4's acceptance protocol, and where the shipped
anisotropic table's error comes from (docs/ltc-aniso.md, "What limits the p90").

    .venv/bin/python benchmarks/study_ltc_oracle.py [--aniso 300] [--iso 200] [--train 192]
        [--test 48] [--seed 0] [--save results.npz] [--load results.npz] [--table FILE]

Configurations: a seeded subset of the acceptance's own (``ltc_aniso.run_acceptance``, seed 0: the
2000 anisotropic ones and the 1000 isotropic ones). Per configuration, ``--train`` training
quads and ``--test`` separate test quads drawn like the acceptance's (20 % straddling the
horizon), with vectorised MIS references (``quadfit.quad_references``; 4096 lobe + 1024 area
samples for training quads, 16384 + 4096 for test quads, i.e. ~1-2 % noise on test quads).
Models, all scored on the test quads by the acceptance's relative error (references >= 1e-3):

* ``table``: the shipped table (``lookup``: quadrilinear interpolation, symmetries, magnitude);
* ``table, exact n``: the table's M with the exact magnitude (separates the magnitude's share);
* ``entry fit``: the bake's own fit (``bake.fit_entries``: SW + L1 polish) at the exact (wo,
  alpha_x, alpha_y), exact magnitude: the table without interpolation;
* ``oracle l1`` / ``oracle l2``: the LTC and magnitude scale that minimise the acceptance metric
  itself on the training quads (``quadfit.fit_quad_ltc``, 9 parameters, started from the table's
  and the entry fit's matrices, the better kept), evaluated on the test quads: the best any
  table with one LTC per entry can do on this protocol;
* ``iso table`` (isotropic set only): the shipped 64 x 64 isotropic table.

The view clamp at 86 deg plays no part: acceptance views stop at 85 deg.
"""

from __future__ import annotations

import argparse
import json
import time

import numpy as np

from prefilter.ltc import AnisoGGXTable, GGXTable
from prefilter.ltc.aniso.fit import lobe_moments
from prefilter.ltc.aniso.quadfit import acceptance_quads, fit_quad_ltc, quad_references
from prefilter.sphere.polygon import clip_to_horizon, polygon_integral
from prefilter.ltc.validate import ALPHA_BINS, FRACTION_BINS, THETA_BINS_DEG
from prefilter.studies.ltc_aniso import random_aniso_configurations

RATIO_BINS = ALPHA_BINS  # 0.05-0.1 / 0.1-0.2 / 0.2-0.4 / 0.4-0.7 / 0.7-1, as ltc_aniso.statistics
THRESHOLD = 1e-3


def configurations(kind: str, n: int, seed: int) -> dict:
    """``n`` of the acceptance's configurations (``kind`` "aniso" or "iso"), seeded subset."""
    if kind == "aniso":
        cfg = random_aniso_configurations(2000, 0)
    else:
        cfg = random_aniso_configurations(1000, np.random.default_rng([0, 2]), isotropic=True)
    idx = np.sort(np.random.default_rng([seed, 11, kind == "iso"]).choice(
        len(cfg["wo"]), n, replace=False))
    return {k: v[idx] for k, v in cfg.items()} | {"index": idx}


def quads_and_references(cfg: dict, k_train: int, k_test: int, seed: int, tag: int) -> dict:
    n = len(cfg["wo"])
    out = {"train": np.zeros((n, k_train, 4, 3)), "test": np.zeros((n, k_test, 4, 3)),
           "ref_train": np.zeros((n, k_train)), "ref_test": np.zeros((n, k_test))}
    for i in range(n):
        args = (cfg["wo"][i], cfg["alpha_x"][i], cfg["alpha_y"][i])
        out["train"][i] = acceptance_quads(k_train, np.random.default_rng([seed, tag, 1, i]))
        out["test"][i] = acceptance_quads(k_test, np.random.default_rng([seed, tag, 2, i]))
        out["ref_train"][i] = quad_references(*args, out["train"][i], 4096, 1024,
                                              np.random.default_rng([seed, tag, 3, i]))
        out["ref_test"][i] = quad_references(*args, out["test"][i], 16384, 4096,
                                             np.random.default_rng([seed, tag, 4, i]))
    return out


def shade(M, mag, quads):
    """``mag * polygon_integral(M, clip(quads))`` for ``M (n, 3, 3)``, quads ``(n, k, 4, 3)``."""
    return np.asarray(mag)[:, None] * polygon_integral(M[:, None], clip_to_horizon(quads))


def oracle(cfg, data, starts, mag, loss):
    """Per configuration, :func:`fit_quad_ltc` from each start; the lower training cost wins."""
    n = len(cfg["wo"])
    M = np.zeros((n, 3, 3))
    scale = np.ones(n)
    train_err = np.zeros(data["ref_train"].shape)
    for i in range(n):
        best = None
        for M0 in starts:
            r = fit_quad_ltc(data["train"][i], data["ref_train"][i], mag[i], M0[i], loss=loss)
            e = r["train_error"]
            cost = np.nanmean(e**2) if loss == "l2" else np.nanmean(e)
            if best is None or cost < best[0]:
                best = (cost, r)
        M[i], scale[i], train_err[i] = best[1]["M"], best[1]["scale"], best[1]["train_error"]
    return M, scale, train_err


def summary(err, ok):
    e = err[ok]
    if e.size == 0:
        return {"count": 0, "median": None, "p90": None}
    return {"count": int(e.size), "median": float(np.median(e)),
            "p90": float(np.percentile(e, 90)), "mean": float(e.mean())}


def binned(err, ok, x, edges):
    out = []
    for lo, hi in zip(edges[:-1], edges[1:]):
        m = (x >= lo) & ((x < hi) | ((hi == edges[-1]) & (x <= hi)))
        out.append({"lo": lo, "hi": hi, **summary(err, ok & m)})
    return out


def statistics(est, cfg, data, mag):
    """Pooled (configuration, test quad) relative errors, overall and binned."""
    ref = data["ref_test"]
    ok = ref >= THRESHOLD
    err = np.abs(est - ref) / np.where(ok, ref, 1.0)
    k = ref.shape[1]
    theta = np.repeat(np.degrees(np.arccos(cfg["wo"][:, 2]))[:, None], k, 1)
    ratio = np.repeat((np.minimum(cfg["alpha_x"], cfg["alpha_y"])
                       / np.maximum(cfg["alpha_x"], cfg["alpha_y"]))[:, None], k, 1)
    amax = np.repeat(np.maximum(cfg["alpha_x"], cfg["alpha_y"])[:, None], k, 1)
    frac = ref / np.asarray(mag)[:, None]
    return {**summary(err, ok), "excluded": int((~ok).sum()),
            "by_theta": binned(err, ok, theta, THETA_BINS_DEG),
            "by_ratio": binned(err, ok, ratio, RATIO_BINS),
            "by_alpha": binned(err, ok, amax, ALPHA_BINS),
            "by_fraction": binned(err, ok, frac, FRACTION_BINS)}, err, ok


def p90_carriers(err, ok, cfg, data, mag) -> dict:
    """Share of each bin among all pairs and among the pairs above the overall p90."""
    k = err.shape[1]
    top = ok & (err > np.percentile(err[ok], 90))
    theta = np.repeat(np.degrees(np.arccos(cfg["wo"][:, 2]))[:, None], k, 1)
    ratio = np.repeat((np.minimum(cfg["alpha_x"], cfg["alpha_y"])
                       / np.maximum(cfg["alpha_x"], cfg["alpha_y"]))[:, None], k, 1)
    frac = data["ref_test"] / np.asarray(mag)[:, None]
    z = data["test"][..., 2]
    straddle = (z.min(-1) <= 0) & (z.max(-1) > 0)
    out = {}
    for name, x, edges in (("theta", theta, THETA_BINS_DEG), ("ratio", ratio, RATIO_BINS),
                           ("fraction", frac, FRACTION_BINS)):
        rows = []
        for lo, hi in zip(edges[:-1], edges[1:]):
            m = (x >= lo) & ((x < hi) | ((hi == edges[-1]) & (x <= hi)))
            rows.append({"lo": lo, "hi": hi, "all": float((m & ok).sum() / ok.sum()),
                         "top": float((m & top).sum() / top.sum())})
        out[name] = rows
    out["straddle"] = {"all": float((straddle & ok).sum() / ok.sum()),
                       "top": float((straddle & top).sum() / top.sum())}
    return out


def pct(x):
    return "    -  " if x is None else f"{100 * x:6.2f}%"


def print_table(title, stats: dict):
    names = list(stats)
    print(f"===== {title}: relative error over (configuration, test quad) pairs")
    print(f"{'':22s}" + "".join(f"{n[:17]:>18s}" for n in names))
    print(f"{'all (median / p90)':22s}" + "".join(
        f"{pct(stats[n]['median'])} /{pct(stats[n]['p90'])}" for n in names))
    for key, label in (("by_theta", "view"), ("by_ratio", "ratio"), ("by_alpha", "alpha max"),
                       ("by_fraction", "ref/albedo")):
        for j, b in enumerate(stats[names[0]][key]):
            lab = f"{label} {b['lo']:g}-{b['hi']:g} ({b['count']})"
            print(f"{lab:22s}" + "".join(
                f"{pct(stats[n][key][j]['median'])} /{pct(stats[n][key][j]['p90'])}"
                for n in names))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--aniso", type=int, default=300)
    ap.add_argument("--iso", type=int, default=200)
    ap.add_argument("--train", type=int, default=192)
    ap.add_argument("--test", type=int, default=48)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--table", default=None, help="anisotropic table (default: shipped)")
    ap.add_argument("--save", default=None, help="write per-pair arrays to this .npz")
    ap.add_argument("--json", default=None, help="write the statistics to this file")
    a = ap.parse_args()
    from prefilter.ltc.aniso.bake import BakeSettings, fit_entries

    table = AnisoGGXTable.load(a.table)
    iso_table = GGXTable.load()
    all_stats, arrays = {}, {}
    for kind, n, tag in (("aniso", a.aniso, 1), ("iso", a.iso, 2)):
        if n <= 0:
            continue
        t0 = time.perf_counter()
        cfg = configurations(kind, n, a.seed)
        data = quads_and_references(cfg, a.train, a.test, a.seed, tag)
        t_ref = time.perf_counter() - t0
        wo, ax, ay = cfg["wo"], cfg["alpha_x"], cfg["alpha_y"]
        mag = lobe_moments(wo, ax, ay)["magnitude"]
        Mt, nt, _ = table.lookup(wo, ax, ay)
        t0 = time.perf_counter()
        Me = fit_entries(wo, ax, ay, BakeSettings())["M"]
        t_entry = time.perf_counter() - t0
        est = {"table": shade(Mt, nt, data["test"]),
               "table, exact n": shade(Mt, mag, data["test"]),
               "entry fit": shade(Me, mag, data["test"])}
        t0 = time.perf_counter()
        for loss in ("l1", "l2"):
            Mo, so, train_err = oracle(cfg, data, (Mt, Me), mag, loss)
            est[f"oracle {loss}"] = shade(Mo, mag * so, data["test"])
            ok = data["ref_train"] >= THRESHOLD
            print(f"{kind} oracle {loss}: in-sample (training quads) median "
                  f"{pct(np.median(train_err[ok]))}, p90 {pct(np.percentile(train_err[ok], 90))}")
        t_oracle = time.perf_counter() - t0
        if kind == "iso":
            Mi, ni, _ = iso_table.lookup(wo, np.clip(ax, iso_table.alpha_min, 1))
            est["iso table"] = shade(Mi, ni, data["test"])
        stats, errs = {}, {}
        for name, e in est.items():
            stats[name], errs[name], ok = statistics(e, cfg, data, mag)
        carriers = p90_carriers(errs["table"], ok, cfg, data, mag)
        all_stats[kind] = {"models": stats, "p90_carriers_table": carriers,
                           "configs": n, "train": a.train, "test": a.test,
                           "seconds": {"references": t_ref, "entry_fit": t_entry,
                                       "oracle": t_oracle}}
        print_table(f"{kind} ({n} configurations x {a.test} test quads)", stats)
        print(f"pairs above the table's p90 ({pct(stats['table']['p90'])}): share of all pairs "
              "-> share of the worst decile")
        for key in ("theta", "ratio", "fraction"):
            print(f"  {key:9s}" + "  ".join(f"{r['lo']:g}-{r['hi']:g}: {100 * r['all']:.0f}->"
                                          f"{100 * r['top']:.0f}%" for r in carriers[key]))
        s = carriers["straddle"]
        print(f"  straddling quads: {100 * s['all']:.0f} -> {100 * s['top']:.0f}%")
        print(f"times: references {t_ref:.0f} s, entry fit {t_entry:.0f} s, oracle "
              f"{t_oracle:.0f} s")
        arrays.update({f"{kind}_{k}": v for k, v in cfg.items()})
        arrays.update({f"{kind}_{k}": v for k, v in data.items() if k.startswith("ref")})
        arrays.update({f"{kind}_est_{k}": v for k, v in est.items()})
        arrays[f"{kind}_magnitude"] = mag
    if a.save:
        np.savez(a.save, **arrays)
    if a.json:
        with open(a.json, "w") as f:
            json.dump(all_stats, f, indent=1)


if __name__ == "__main__":
    main()
