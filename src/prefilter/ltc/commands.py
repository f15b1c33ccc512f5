"""Command-line entry points for the isotropic GGX LTC table (a thin layer over the library).

``prefilter bake ltc-iso`` refits the table (:func:`prefilter.ltc.fit_iso.bake_table`);
``prefilter validate`` runs the quad-light acceptance test
(:func:`prefilter.ltc.validate.run_acceptance`).
"""

from __future__ import annotations

import time

import click

from prefilter.cliparams import SEED, OutputFile, scheduler_options


@click.command("ltc-iso")
@click.option("--res", default=64, show_default=True, type=click.IntRange(2, 1024),
              help="Table resolution along view angle and roughness.")
@click.option("--seed", default=0, show_default=True, type=SEED,
              help="Seed of the fixed stratified fitting samples.")
@click.option("--samples", "n_fit", default=32, show_default=True, type=click.IntRange(2, 512),
              help="Stratified samples per axis of each fitting sample set.")
@click.option("-o", "--out", type=OutputFile(), default=None,
              help="Output .npz (default: the user table, $PREFILTER_DATA/ggx_iso.npz or "
                   "~/.local/share/prefilter/ggx_iso.npz, which renders then use instead of "
                   "the table shipped with the package).")
@click.option("--objective", default="density", show_default=True,
              type=click.Choice(["density", "quads"]),
              help="density: fit |p - q|^power; quads: then refit each row on quad-light "
                   "integrals (the acceptance test's relative error, docs/ltc.md).")
@click.option("--power", default=1.0, show_default=True, type=click.FloatRange(0.1, 4.0),
              help="Exponent k of the density objective integral |p - q|^k.")
@click.option("--wait", is_flag=True,
              help="If another bake is writing the same output, wait for it (default: fail at "
                   "once, naming it).")
@scheduler_options
@click.option("--quiet", is_flag=True, help="No progress bar.")
def bake_ltc_iso(res, seed, n_fit, out, objective, power, wait, scheduler, workers, quiet):
    """Fit the isotropic GGX LTC table (resumable: rerun the same command after a kill).

    Each view angle's row is a task: --scheduler / --workers spread them over processes or a
    Dask cluster (docs/distributed.md), with the same bytes as one process."""
    from prefilter.ltc.fit_iso import FitSettings, bake_table, user_table_path

    settings = FitSettings(res_theta=res, res_alpha=res, n_fit=n_fit, seed=seed,
                           objective=objective, power=power)
    t0 = time.perf_counter()
    path = bake_table(out, settings, processes=workers or 1, scheduler=scheduler,
                      progress=not quiet, wait=wait)
    click.echo(f"wrote {path} ({res}x{res}) in {time.perf_counter() - t0:.1f} s")
    if out is None:
        click.echo(f"renders now use this user table instead of the shipped one; delete "
                   f"{user_table_path()} to go back")


@click.command("validate")
@click.option("--configs", default=2000, show_default=True, type=click.IntRange(1),
              help="Number of random (view, roughness, quad) configurations.")
@click.option("--samples", default=100_000, show_default=True, type=click.IntRange(2),
              help="Monte Carlo samples per configuration (half BRDF, half light).")
@click.option("--seed", default=0, show_default=True, type=SEED)
@click.option("--table", "table_path", type=click.Path(dir_okay=False), default=None,
              help="LTC table .npz (default: the user table if one was baked, else the "
                   "shipped one).")
@click.option("--json", "json_out", type=OutputFile(), default=None,
              help="Also write the statistics as JSON.")
@click.option("--quiet", is_flag=True, help="No progress bar.")
def validate(configs, samples, seed, table_path, json_out, quiet):
    """Compare the LTC table's quad-light integrals with Monte Carlo references."""
    from prefilter.fileio import save_json_atomic
    from prefilter.ltc.table import GGXTable
    from prefilter.ltc.validate import format_statistics, run_acceptance

    table = GGXTable.load(table_path)
    click.echo(f"LTC table: {table.path} ({table.source})")
    res = run_acceptance(table, configs, samples, seed, progress=not quiet)
    stats = res["stats"]
    stats["n_samples"] = samples
    stats["seed"] = seed
    stats["median_reference_relative_se"] = float(
        _median_rel_se(res["standard_error"], res["reference"]))
    click.echo(format_statistics(stats))
    click.echo(f"median relative standard error of the references: "
               f"{100 * stats['median_reference_relative_se']:.3f}%")
    if json_out:
        save_json_atomic(json_out, stats)


def _median_rel_se(se, ref):
    import numpy as np

    ok = ref > 0
    return np.median(se[ok] / ref[ok]) if ok.any() else float("nan")


@click.command("export-ltc")
@click.option("--preset", required=True, help="Engine layout (docs/ltc-export.md).",
              type=click.Choice(["ltc_code", "threejs", "babylon", "godot", "blender", "unity-hdrp",
                                 "unreal", "bevy", "compact"]))
@click.option("-o", "--out", "out_dir", required=True, type=click.Path(file_okay=False),
              help="Output directory (created if missing).")
@click.option("--table", "table_path", type=click.Path(dir_okay=False), default=None,
              help="LTC table .npz (default: the shipped table).")
@click.option("--measure", is_flag=True,
              help="compact: also measure the full table and both encodings with the "
                   "acceptance protocol of `prefilter validate` (writes compact_errors.json).")
@click.option("--configs", default=2000, show_default=True, type=click.IntRange(1),
              help="--measure: number of configurations.")
@click.option("--samples", default=100_000, show_default=True, type=click.IntRange(2),
              help="--measure: Monte Carlo samples per configuration.")
@click.option("--seed", default=0, show_default=True, type=int, help="--measure: seed.")
@click.option("--quiet", is_flag=True, help="No progress bar.")
def export_ltc(preset, out_dir, table_path, measure, configs, samples, seed, quiet):
    """Write the isotropic GGX LTC table in an engine's layout (docs/ltc-export.md)."""
    from pathlib import Path

    from prefilter.fileio import save_json_atomic
    from prefilter.ltc.export import export_preset
    from prefilter.ltc.table import as_table

    if measure and preset != "compact":
        raise click.UsageError("--measure applies to --preset compact")
    table = as_table(table_path)
    for path in export_preset(preset, out_dir, table):
        click.echo(f"wrote {path}")
    if measure:
        from prefilter.ltc.export.compact import compare_encodings

        def pct(x):
            return "-" if x is None else f"{100 * x:.2f}%"

        res = compare_encodings(table, configs, samples, seed, progress=not quiet)
        for name, r in res.items():
            for threshold, st in r["stats"].items():
                click.echo(f"{name:5s} {r['bytes']:7d} bytes  reference >= {threshold:g}: "
                           f"{st['count']:5d} configurations, median {pct(st['median'])}, "
                           f"p90 {pct(st['p90'])}, mean {pct(st['mean'])}")
        path = Path(out_dir) / "compact_errors.json"
        save_json_atomic(path, {"configs": configs, "samples": samples, "seed": seed,
                                "results": {k: {"bytes": v["bytes"],
                                                "stats": {str(t): s for t, s in
                                                          v["stats"].items()}}
                                            for k, v in res.items()}})
        click.echo(f"wrote {path}")
