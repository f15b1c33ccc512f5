"""Demo: a brushed-metal plane and a sphere under a quad light, ``ltc-aniso`` vs ``ltc`` vs
``reference`` (issue 4's rendering acceptance). ``run_demo`` returns RMSE and mean HDR-FLIP of
both LTC methods against the Monte Carlo reference and optionally writes the images (.npy)."""

from __future__ import annotations

from pathlib import Path

import numpy as np


def demo_scene(width: int = 200, height: int = 150) -> dict:
    """The scene as a dict (``docs/scenes.md``): plane brushed along x (rough across the
    brushing: ``alpha_x = 0.08``, ``alpha_y = 0.45``) and a sphere brushed along its latitudes
    (``alpha_x = 0.45`` along the tangent, ``0.06`` across), lit by one quad light."""
    return {
        "camera": {"origin": [0.0, 1.3, 4.6], "target": [0.2, 0.6, 0.0], "up": [0, 1, 0],
                   "fov": 50, "width": width, "height": height},
        "objects": [
            {"type": "plane", "center": [0, 0, 0], "normal": [0, 1, 0], "tangent": [1, 0, 0],
             "size": [8, 8],
             "material": {"alpha_x": 0.08, "alpha_y": 0.45, "base_color": 0.02,
                          "f0": [0.95, 0.93, 0.88]}},
            {"type": "sphere", "center": [0.9, 0.7, 0.3], "radius": 0.7, "pole": [0, 1, 0],
             "material": {"alpha_x": 0.45, "alpha_y": 0.06, "base_color": 0.02,
                          "f0": [0.95, 0.64, 0.54]}},
        ],
        "lights": [
            {"type": "quad", "vertices": [[-1.6, 1.2, -2.0], [-0.4, 1.2, -2.0],
                                          [-0.4, 2.4, -2.0], [-1.6, 2.4, -2.0]],
             "radiance": 6.0},
        ],
    }


def run_demo(out_dir=None, *, width: int = 200, height: int = 150, ref_spp: int = 64,
             seed: int = 0) -> dict:
    """Render the three methods and compare; returns ``{method: {"rmse", "flip"}}``."""
    from prefilter.render.metrics import flip, rmse
    from prefilter.render.driver import render
    from prefilter.render.scene import load_scene

    scene = load_scene(demo_scene(width, height))
    ref = render(scene, "reference", spp=ref_spp, seed=seed)
    out = {}
    images = {"reference": ref}
    for method in ("ltc-aniso", "ltc"):
        img = render(scene, method, spp=1, seed=seed)
        images[method] = img
        out[method] = {"rmse": float(rmse(img, ref)), "flip": float(flip(img, ref).mean)}
    if out_dir is not None:
        d = Path(out_dir)
        d.mkdir(parents=True, exist_ok=True)
        for k, v in images.items():
            np.save(d / f"demo_{k}.npy", v)
    return out
