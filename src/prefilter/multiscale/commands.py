"""``prefilter multiscale-fit``: rerun the eq. 6 convolution and the eq. 7 refits (Tao et al. 2021).

Prints the paper's eq. 5 error against the exact inverse of eq. 4, the coefficients and errors of
eq. 7 (paper), eq. 7's form refitted, our form (:data:`prefilter.multiscale.FIT_COEFFS`) and mean
resultant length matching, all against the maximum-likelihood alphas of a Monte Carlo grid.
"""

from __future__ import annotations

import json

import click
import numpy as np

from prefilter.cliparams import SEED, OutputFile


def fit_report(n_grid: int = 32, samples: int = 1 << 17, seed: int = 0) -> dict:
    """Everything ``multiscale-fit`` prints, as a JSON-able dict (grid uniform in sqrt(alpha)
    from 0.01 to 1, as the LTC table's roughness axis)."""
    from prefilter.multiscale.convolution import (
        convolution_grid,
        fit_polynomial,
        grid_errors,
    )
    from prefilter.multiscale.meso import alpha_meso, alpha_meso_exact

    r = np.linspace(2.0 / 3.0, 1.0, 20001)
    exact = alpha_meso_exact(r)
    err = alpha_meso(r, "paper") - exact
    keep = exact >= 0.12
    eq5 = {"max_abs": float(np.abs(err).max()), "r_at_max_abs": float(r[np.abs(err).argmax()]),
           "max_rel_alpha_ge_0.12": float(np.max(np.abs(err[keep]) / exact[keep])),
           "max_abs_table_vs_exact": float(np.abs(alpha_meso(r) - exact).max())}
    axis = np.linspace(0.1, 1.0, n_grid) ** 2
    grid = convolution_grid(axis, axis, samples, seed)

    def clean(d):
        return {k: (v.tolist() if isinstance(v, np.ndarray) else v) for k, v in d.items()}

    return {
        "eq5": eq5,
        "grid": {"n": n_grid, "samples": samples, "seed": seed,
                 "max_below_horizon": float(grid["below"].max())},
        "eq7_paper": clean(grid_errors(grid, "paper")),
        "eq7_refit": clean(fit_polynomial(grid, "paper")),
        "ours_refit": clean(fit_polynomial(grid, "ours")),
        "ours_shipped": clean(grid_errors(grid, "fit")),
        "mrl": clean(grid_errors(grid, "mrl")),
    }


@click.command("multiscale-fit",
               short_help="Check eq. 5, refit eq. 7 of multi-scale LTC (Monte Carlo).")
@click.option("--grid", "n_grid", default=32, show_default=True, type=click.IntRange(2, 1024),
              help="Grid nodes per axis.")
@click.option("--samples", default=1 << 17, show_default=True, type=click.IntRange(1),
              help="Monte Carlo samples/node.")
@click.option("--seed", type=SEED, default=0, show_default=True)
@click.option("--out", type=OutputFile(), default=None, help="Write JSON here.")
def multiscale_fit(n_grid, samples, seed, out):
    """Verify eq. 5 and refit eq. 7 of multi-scale LTC (Tao et al. 2021) by Monte Carlo."""
    rep = fit_report(n_grid, samples, seed)
    if out:
        from prefilter.fileio import save_json_atomic

        save_json_atomic(out, rep)
    click.echo(json.dumps(rep, indent=1))
