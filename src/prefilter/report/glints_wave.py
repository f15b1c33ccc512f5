"""Demo report section: glints under wave optics next to the geometric glints of the same surface.

A laptop-like scene: a large flat panel of isotropic height noise (0.25 um texels, 50 nm rms,
4-texel correlation) under a small point light, rendered with ``glints-wave`` (compressed RGB
diffraction NDF), ``glints-wave-direct`` (the same model uncompressed) and ``glints-direct``
(geometric P-NDF of the heightfield's normals): where the two optics agree (the glints' places)
and where colour appears (diffraction sparkles). docs/glints-wave.md.
"""

from __future__ import annotations

import time

import numpy as np

HEIGHTFIELD = "procedural:noise:128:0"


def laptop_scene(distance: float, normal_map_path: str, width: int, height: int) -> dict:
    """The measurement plane (:func:`prefilter.glints.render.measurement_scene`) as the panel,
    the heightfield in ``extras.glints_wave`` and its normals as the geometric normal map."""
    from prefilter.glints.render import measurement_scene

    sc = measurement_scene(distance, "gaussian", width=width, height=height)
    sc["objects"][0]["material"]["normal_map"] = {"path": normal_map_path}
    sc["extras"] = {"glints_wave": {"heightfield": HEIGHTFIELD}}
    return sc


def glints_wave_section(report, settings, seed: int, log, *, width: int = 64, height: int = 48,
                        distances=(0.5, 2.0)) -> None:
    from prefilter.glints.bake import cache_dir
    from prefilter.glints.wave.bake import as_heightfield_spec
    from prefilter.glints.wave.heightfield import normal_map
    from prefilter.render.driver import render
    from prefilter.render.metrics import flip
    from prefilter.render.scene import load_scene

    hf = as_heightfield_spec(HEIGHTFIELD)
    nm_path = cache_dir() / f"wave-normals-v2-{hf.digest[:16]}.npy"
    nm_path.parent.mkdir(parents=True, exist_ok=True)
    if not nm_path.exists():
        np.save(nm_path, 0.5 * normal_map(hf) + 0.5)  # stored as colours, as images are
    rows = []
    for d in distances:
        sc = load_scene(laptop_scene(d, str(nm_path), width, height))
        render(sc, "glints-wave", seed=seed, progress=True)  # bake (disk cache), compilation
        img, times = {}, {}
        for m in ("glints-wave", "glints-wave-direct", "glints-direct"):
            t0 = time.perf_counter()
            img[m] = render(sc, m, seed=seed)
            times[m] = time.perf_counter() - t0
        report.add_image_row(f"distance {d:g}", [(m, img[m]) for m in img], scale=4)
        wave, geo = img["glints-wave-direct"], img["glints-direct"]
        lum_ratio = float(wave.mean() / max(geo.mean(), 1e-300))
        # colour: chroma of the wave frame where it is lit
        lit = wave.sum(-1) > 1e-3 * wave.sum(-1).max()
        chroma = float(np.mean((wave.max(-1) - wave.min(-1))[lit] / wave.max(-1)[lit]))
        rows.append([f"{d:g}", float(flip(img["glints-wave"], wave).mean),
                     times["glints-wave"], times["glints-wave-direct"],
                     float(flip(wave, geo).mean), lum_ratio, chroma])
        log(f"glints-wave distance {d:g}: {times}")
    report.add_table(
        ["distance", "FLIP wave vs wave-direct", "glints-wave (s)", "glints-wave-direct (s)",
         "FLIP wave vs geometric", "mean radiance wave / geometric", "mean chroma (wave)"],
        rows, caption="One frame each at 1 spp, measured now (wall clock, this machine). The "
        "wave and geometric frames put the glints at the same places and carry the same energy; "
        "the wave frame's sparkles are coloured (chroma = (max - min) / max of RGB over lit "
        "pixels; 0 for grey). `benchmarks/bench_glints_wave.py` measures near / mid / far.")
