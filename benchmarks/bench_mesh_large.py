"""Large meshes: load time, peak memory per triangle and the first G-buffer (Embree scene build)
for tessellated UV spheres of about 1M, 4M and 10M triangles (binary PLY with UVs).

``python benchmarks/bench_mesh_large.py [--triangles 1e6,4e6,1e7]``. Each size runs in a fresh
subprocess: the file is written first, then the peak resident memory above the process's level
before loading (``resource.getrusage`` high-water mark) is read after ``load_scene`` and after
one 256 x 256 G-buffer. The memory check of :func:`prefilter.render.mesh.load_mesh` assumes
:data:`prefilter.render.mesh.BYTES_PER_TRIANGLE` per triangle; the table shows the measured
figure beside it. No assertions (the machine is shared).
"""

from __future__ import annotations

import argparse
import json
import math
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent


def _rss() -> float:
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024.0


def child(n_triangles: int, tmp: str) -> dict:
    sys.path.insert(0, str(HERE.parent / "tests" / "render"))
    from mesh_assets import write_uv_sphere

    from prefilter.render import gbuffer, load_scene

    n_theta = max(4, int(math.sqrt(n_triangles / 4)))
    path = write_uv_sphere(Path(tmp) / "big.ply", n_theta, 2 * n_theta)
    file_bytes = path.stat().st_size
    camera = {"origin": [0.4, 0.8, 3], "target": [0, 0, 0], "fov": 45, "width": 256,
              "height": 256}
    import gc

    gc.collect()
    base = _rss()
    t0 = time.perf_counter()
    scene = load_scene({"camera": camera, "objects": [{"type": "mesh", "file": str(path)}]})
    t_load = time.perf_counter() - t0
    peak_load = _rss() - base
    tri = len(scene.objects[0].data.faces)
    t0 = time.perf_counter()
    gbuffer(scene)
    t_first = time.perf_counter() - t0
    return {"triangles": tri, "file_mb": file_bytes / 1e6, "load_s": t_load,
            "first_gbuffer_s": t_first, "peak_load_b_per_tri": peak_load / tri,
            "peak_b_per_tri": (_rss() - base) / tri}


def main() -> None:
    if len(sys.argv) > 1 and sys.argv[1] == "--child":
        print(json.dumps(child(int(float(sys.argv[2])), sys.argv[3])))
        return
    from prefilter.render.mesh import BYTES_PER_TRIANGLE

    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--triangles", default="1e6,4e6,1e7")
    args = p.parse_args()
    print(f"assumed by the loader's memory check: {BYTES_PER_TRIANGLE} B per triangle")
    print("| triangles | file (MB) | load (s) | first G-buffer 256^2 (s) | peak after load "
          "(B/triangle) | peak after G-buffer (B/triangle) |")
    print("|---|---|---|---|---|---|")
    for n in args.triangles.split(","):
        with tempfile.TemporaryDirectory() as tmp:
            out = subprocess.run([sys.executable, __file__, "--child", n, tmp], check=True,
                                 capture_output=True, text=True).stdout
        r = json.loads(out.strip().splitlines()[-1])
        print(f"| {r['triangles']:,} | {r['file_mb']:.0f} | {r['load_s']:.1f} | "
              f"{r['first_gbuffer_s']:.1f} | {r['peak_load_b_per_tri']:.0f} | "
              f"{r['peak_b_per_tri']:.0f} |", flush=True)


if __name__ == "__main__":
    main()
