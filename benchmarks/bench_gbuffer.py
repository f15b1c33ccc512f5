"""Primary-ray + G-buffer throughput (Mpixel/s) for a 1024 x 1024 view of a plane and a sphere.

Prints the best of 3 runs per scene for the Numba path (``gbuffer``) and the NumPy path it
replaced (``intersect_numpy`` of ``generate_rays``, the tests' check), plus the
process CPU time of the Numba path; no assertions (the machine is shared and noisy).
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

from prefilter.render import gbuffer, load_scene
from prefilter.render.camera import generate_rays

# the NumPy twin the tests check the kernels against
sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests" / "render"))
from gbuffer_numpy import intersect_numpy  # noqa: E402

SIZE = 1024
CAMERA = {"origin": [0, 1.5, 4], "target": [0, 0, 0], "fov": 45, "width": SIZE, "height": SIZE}
SCENES = {
    "plane": [{"type": "plane", "size": [40, 40], "uv_scale": [40, 40]}],
    "sphere": [{"type": "sphere", "center": [0, 0.8, 0], "radius": 1.6}],
    "plane+sphere": [{"type": "plane", "size": [40, 40], "uv_scale": [40, 40]},
                     {"type": "sphere", "center": [0, 0.8, 0], "radius": 1.0}],
}


def main() -> None:
    for name, objects in SCENES.items():
        scene = load_scene({"camera": CAMERA, "objects": objects})
        g = gbuffer(scene)  # warm-up (and JIT)
        best, cpu = float("inf"), float("inf")
        for _ in range(3):
            c0, t0 = time.process_time(), time.perf_counter()
            g = gbuffer(scene)
            best = min(best, time.perf_counter() - t0)
            cpu = min(cpu, time.process_time() - c0)
        old = float("inf")
        for _ in range(2):
            t0 = time.perf_counter()
            intersect_numpy(scene, generate_rays(scene.camera))
            old = min(old, time.perf_counter() - t0)
        mpix = SIZE * SIZE / best / 1e6
        print(f"{name:13s} {SIZE}x{SIZE}: new {best * 1e3:6.1f} ms  {mpix:5.2f} Mpixel/s "
              f"(cpu {cpu * 1e3:6.1f} ms)   old {old * 1e3:6.1f} ms  "
              f"{SIZE * SIZE / old / 1e6:5.2f} Mpixel/s   (hit {g.hit.mean():.0%})")


if __name__ == "__main__":
    main()
