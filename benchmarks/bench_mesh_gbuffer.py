"""Mesh G-buffer throughput: 512 x 512 primary rays (Mrays/s) on a tessellated UV sphere
(128 x 256 segments, 65k triangles; Embree picks the triangles, a Numba kernel computes the
float64 hits and ray-differential footprints) and on the analytic sphere (the Numba kernel), in
one run, and their ratio.

Best of 3 runs after a warm-up (JIT, Embree scene build); the mesh file is written to a
temporary directory by the tests' asset writer. No assertions (the machine is shared and noisy).
"""

from __future__ import annotations

import sys
import tempfile
import time
from pathlib import Path

from prefilter.render import gbuffer, load_scene

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests" / "render"))
from mesh_assets import write_uv_sphere  # noqa: E402

SIZE = 512
CAMERA = {"origin": [0.4, 0.8, 3], "target": [0, 0, 0], "fov": 45, "width": SIZE, "height": SIZE}


def best_of(scene, runs: int = 3) -> float:
    gbuffer(scene)  # warm-up
    best = float("inf")
    for _ in range(runs):
        t0 = time.perf_counter()
        gbuffer(scene)
        best = min(best, time.perf_counter() - t0)
    return best


def main() -> None:
    with tempfile.TemporaryDirectory() as tmp:
        path = write_uv_sphere(Path(tmp) / "sphere.ply", 128, 256)
        mesh = load_scene({"camera": CAMERA, "objects": [{"type": "mesh", "file": str(path)}]})
        analytic = load_scene({"camera": CAMERA, "objects": [{"type": "sphere", "radius": 1}]})
        n = SIZE * SIZE
        tm, ta = best_of(mesh), best_of(analytic)
        print(f"mesh (65k triangles): {n / tm / 1e6:.2f} Mrays/s ({tm * 1e3:.0f} ms)")
        print(f"analytic sphere:      {n / ta / 1e6:.2f} Mrays/s ({ta * 1e3:.0f} ms)")
        print(f"ratio analytic / mesh: {tm / ta:.1f}")


if __name__ == "__main__":
    main()
