"""Demo-report section: the roughness mip chains of ``prefilter bake roughness`` and their
far-field error on the built-in maps (:mod:`prefilter.studies.roughness`, docs/roughness.md)."""

from __future__ import annotations

import numpy as np

#: Base perceptual roughness of the section (docs/roughness.md has 0.3 and 0.6).
ROUGHNESS = 0.3
#: Levels shown as images and in the error table.
LEVELS = (2, 4, 6)


def _gray(a, lo: float, hi: float, size: int) -> np.ndarray:
    """``a (h, w)`` as a ``uint8`` grey image, ``lo -> 0``, ``hi -> 255``, enlarged to ``size``
    rows by pixel repetition (a level of ``2^k`` fewer texels keeps its blocks visible)."""
    g = np.clip((np.asarray(a, float) - lo) / max(hi - lo, 1e-12), 0.0, 1.0)
    rep = max(1, size // g.shape[0])
    return np.round(255 * np.kron(g, np.ones((rep, rep)))).astype(np.uint8)


def roughness_section(report, map_size: int = 256, seed: int = 0, log=print) -> list[dict]:
    """Add the section body to ``report``: per method, the baked perceptual roughness of the
    flakes map at :data:`LEVELS`, then the far-field error table of every method on every
    built-in map. Returns the table's rows
    (:func:`~prefilter.studies.roughness.roughness_error_table`).
    """
    from prefilter.roughness.bake import METHODS, bake_roughness
    from prefilter.studies.roughness import MAPS, roughness_error_table
    from prefilter.texture.procedural import normal_map

    alpha0 = ROUGHNESS * ROUGHNESS
    normals = normal_map("flakes", size=map_size, seed=seed)
    levels = [k for k in LEVELS if 2 ** k <= map_size]
    baked = {m: bake_roughness(normals, alpha0, m) for m in METHODS}
    hi = max(float(np.sqrt(baked[m][k]).max()) for m in METHODS for k in levels)
    for m in METHODS:
        report.add_image_row(
            f"`{m}`: perceptual roughness of the flakes map (black {ROUGHNESS:g}, white "
            f"{hi:.2f})",
            [(f"level {k} ({map_size >> k} x {map_size >> k})",
              _gray(np.sqrt(baked[m][k]), ROUGHNESS, hi, 64)) for k in levels], scale=2)
    rows = roughness_error_table(size=map_size, seed=seed, roughness=ROUGHNESS, levels=levels,
                                 maps=MAPS)
    log(f"roughness section: {len(rows)} rows, maps {map_size} x {map_size}")
    report.add_table(
        ["map", "method"] + [f"level {k} ({2 ** k} x {2 ** k} texels)" for k in levels],
        [[r["map"], r["method"]] + [f"{100 * r['rel_rmse'][k]:.1f} %" for k in levels]
         for r in rows],
        caption="Far-field relative RMSE against the supersampled reference (every level-0 "
        "texel shaded with its own normal, each block averaged), 18 view / light pairs, base "
        f"perceptual roughness {ROUGHNESS:g}. `none`: the plain mip chain (base roughness at "
        "every level), the error the methods remove. `python -m prefilter.studies.roughness "
        f"--size {map_size}` prints the same table.")
    return rows
