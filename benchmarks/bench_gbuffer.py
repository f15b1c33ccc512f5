"""Primary-ray + G-buffer throughput (Mpixel/s) for a 1024 x 1024 view of a plane and a sphere.

Prints the best of 3 runs per scene; no assertions (the machine is shared and noisy).
"""

from __future__ import annotations

import time

from prefilter.render import gbuffer, load_scene

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
        best = float("inf")
        for _ in range(3):
            t0 = time.perf_counter()
            g = gbuffer(scene)
            best = min(best, time.perf_counter() - t0)
        mpix = SIZE * SIZE / best / 1e6
        print(f"{name:13s} {SIZE}x{SIZE}: {best * 1e3:7.1f} ms  {mpix:5.2f} Mpixel/s "
              f"(hit {g.hit.mean():.0%})")


if __name__ == "__main__":
    main()
