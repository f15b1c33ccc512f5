"""Indirect glints on the kettle scene: ``glints`` (compressed pyramid) against ``glints-direct``
(exact P-NDF of every footprint) on the same paths.

    python benchmarks/bench_indirect_glints.py              # 96 x 64, 16 spp, 128^2 map (~3 min)
    python benchmarks/bench_indirect_glints.py --map 64     # a smaller map (~40 s)

Both methods path-trace the scene with 2 vertices (camera -> floor or kettle -> light) from the
same seed: the floor is the same GGX lobe in both, so the paths that reach the kettle after the
floor's glossy bounce are the same, and there the kettle's glint lobe is queried with the
enlarged footprint (``prefilter.render.pathtrace``). The images keep the indirect light only
(light that reached the camera after 2 vertices). Reported:

* FLIP (HDR) of ``glints`` against ``glints-direct`` on those images (target <= 0.05);
* the time spent in the lobes at the second vertex (the indirect part: the kettle's glint lobe
  and the floor's GGX lobe, the same in both) and its ratio (target >= 10x), from the same run,
  and the glint lobe's share alone;
* both renders' total times.

The machine is shared: times are indicative, ratios come from one run. Glint maps are baked on
first use (64^2: ~15 s, 128^2: ~40 s on the loaded 2-core machine) and cached.
"""

from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path

import numpy as np

from prefilter.glints.indirect import render_glints_paths
from prefilter.render.methods import RenderSettings
from prefilter.render.metrics import flip
from prefilter.render.pathtrace import PathOptions, PathStats
from prefilter.render.scene import load_scene
from prefilter.report.pathtrace import kettle_scene, write_assets


def run(width: int, height: int, spp: int, map_size: int, seed: int = 0, out: str | None = None):
    directory = Path(tempfile.gettempdir()) / "prefilter-kettle"
    write_assets(directory)
    scene = load_scene(kettle_scene(width, height, map_size), base_dir=directory)
    settings = RenderSettings(spp=spp, seed=seed)
    res = {}
    for mode in ("compressed", "direct"):
        stats = PathStats()
        t0 = time.perf_counter()
        img = render_glints_paths(scene, settings, mode, mode, options=PathOptions(bounces=2),
                                  stats=stats, min_depth=1)
        res[mode] = (img, time.perf_counter() - t0, stats)
        if out:
            np.save(Path(out) / f"indirect-{mode}.npy", img)
    (a, ta, sa), (b, tb, sb) = res["compressed"], res["direct"]
    f = flip(a, b).mean
    ia, ib = sum(sa.lobe_seconds[1:]), sum(sb.lobe_seconds[1:])
    ga = sum(d.get("FootprintGlintLobe", 0.0) for d in sa.by_lobe[1:])
    gb = sum(d.get("FootprintGlintLobe", 0.0) for d in sb.by_lobe[1:])
    print(f"kettle {width} x {height}, {spp} spp, {map_size}^2 brushed map, 2 vertices, "
          "indirect light only")
    print(f"  FLIP glints vs glints-direct: {f:.4f}   (target <= 0.05)")
    print(f"  indirect part (lobes at vertex 2, {sa.vertices[1]} vertices): glints {ia:.2f} s, "
          f"glints-direct {ib:.2f} s, speed-up {ib / ia:.1f}x   (target >= 10x)")
    print(f"    of which the kettle's glint lobe: glints {ga:.2f} s, glints-direct {gb:.2f} s, "
          f"speed-up {gb / ga:.1f}x")
    print(f"  first vertex lobes: glints {sa.lobe_seconds[0]:.2f} s, glints-direct "
          f"{sb.lobe_seconds[0]:.2f} s")
    print(f"  whole render: glints {ta:.1f} s, glints-direct {tb:.1f} s ({tb / ta:.1f}x)")
    print(f"  image means: glints {a.mean():.4f}, glints-direct {b.mean():.4f}")
    return {"flip": f, "speedup": ib / ia, "speedup_glint": gb / ga, "t_glints": ta,
            "t_direct": tb}


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--width", type=int, default=96)
    p.add_argument("--height", type=int, default=64)
    p.add_argument("--spp", type=int, default=16)
    p.add_argument("--map", type=int, default=128, help="normal map size (texels)")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--out", default=None, help="directory for the two images (.npy)")
    a = p.parse_args(argv)
    run(a.width, a.height, a.spp, a.map, a.seed, a.out)


if __name__ == "__main__":
    main()
