"""``prefilter bake ltc-aniso``: bake the anisotropic GGX LTC table (thin layer over
:func:`prefilter.ltc.aniso.bake.bake_table`)."""

from __future__ import annotations

import time

import click

from prefilter.cliparams import SEED, OutputDir, OutputFile


@click.command("ltc-aniso")
@click.option("--res", default=8, show_default=True, type=click.IntRange(2, 64),
              help="Resolution of each of the four axes (theta, phi, alpha, ratio).")
@click.option("--steps", default=300, show_default=True, type=click.IntRange(0),
              help="Gradient steps of the sliced-Wasserstein fit (0: none; needs --init).")
@click.option("--polish-steps", default=100, show_default=True, type=click.IntRange(0),
              help="Steps of the point-wise L1 polish after the SW fit (0: none).")
@click.option("--polish-samples", default=256, show_default=True, type=click.IntRange(2),
              help="Samples per entry and polish step.")
@click.option("--polish-check", default=2048, show_default=True, type=click.IntRange(2),
              help="Monte Carlo samples of the L1 check that keeps a polish only if it helps.")
@click.option("--neighbours", is_flag=True,
              help="With --init: start each entry from the best (lowest L1 distance) of its "
                   "own fit and its grid neighbours' fits.")
@click.option("--init", "init", type=click.Path(exists=True, dir_okay=False), default=None,
              help="Warm start: a baked table whose fits start every entry (default: the "
                   "identity). With --steps 0 only the polish runs from them.")
@click.option("--chunk", default=512, show_default=True, type=click.IntRange(1),
              help="Entries fitted together as one tensor program (and per checkpoint).")
@click.option("--seed", default=0, show_default=True, type=SEED)
@click.option("-o", "--out", type=OutputFile(), default=None,
              help="Output .npz (default: the user table, $PREFILTER_DATA/ggx_aniso.npz or "
                   "~/.local/share/prefilter/ggx_aniso.npz, which renders then use instead of "
                   "the table shipped with the package).")
@click.option("--export", "export_dir", type=OutputDir(), default=None,
              help="Also write the float32 / half-float texture layouts and GLSL here.")
@click.option("--wait", is_flag=True,
              help="If another bake is writing the same output, wait for it (default: fail at "
                   "once, naming it).")
@click.option("--quiet", is_flag=True, help="No progress bar.")
def bake_ltc_aniso(res, steps, polish_steps, polish_samples, polish_check, neighbours, init,
                   chunk, seed, out, export_dir, wait, quiet):
    """Fit the anisotropic GGX LTC table (resumable: rerun the same command after a kill)."""
    from dataclasses import replace

    from prefilter.ltc.aniso.bake import BakeSettings, bake_table
    from prefilter.ltc.aniso.fit import SWSettings
    from prefilter.ltc.aniso.table import user_table_path

    settings = BakeSettings(res_theta=res, res_phi=res, res_alpha=res, res_ratio=res,
                            chunk=chunk, polish_steps=polish_steps,
                            polish_samples=polish_samples, polish_check=polish_check,
                            init=str(init or ""), init_neighbours=neighbours,
                            sw=replace(SWSettings(), steps=steps, seed=seed))
    t0 = time.perf_counter()
    path = bake_table(out, settings, progress=not quiet, wait=wait)
    click.echo(f"wrote {path} ({res}^4) in {time.perf_counter() - t0:.1f} s")
    if out is None:
        click.echo(f"renders now use this user table instead of the shipped one; delete "
                   f"{user_table_path()} to go back")
    if export_dir:
        from prefilter.ltc.aniso.export import export_all
        from prefilter.ltc.aniso.table import AnisoGGXTable

        for f in export_all(AnisoGGXTable.load(path), export_dir):
            click.echo(f"wrote {f}")
