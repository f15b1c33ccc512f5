"""The ``reference`` method's fused kernel (one Numba pass per row chunk) against its NumPy stages:
the same image to rounding, deterministic, independent of chunking and thread count."""

from __future__ import annotations

import numba
import numpy as np
import pytest

from prefilter.render.driver import with_settings
from prefilter.render.methods import RenderSettings
from prefilter.render.reference import fused_shader, render_reference
from prefilter.render.scene import load_scene
from prefilter.report.demo import showcase_scene

GAUSS = {"procedural": "gaussian", "size": 64, "seed": 1, "rms_slope": 0.3, "corr_length": 3}

# a normal-mapped anisotropic plane, a sphere with a height and a colour map, a normal-mapped
# plane seen from behind its normal (frame flip), under two quad lights
SPHERES = {
    "camera": {"origin": [0, 1.2, 3], "target": [0, 0.3, -1], "fov": 60, "width": 40,
               "height": 30},
    "objects": [
        {"type": "plane", "center": [0, 0, -2], "size": [8, 8], "uv_scale": [4, 4],
         "tangent": [1, 0, 0.3],
         "material": {"alpha_x": 0.03, "alpha_y": 0.06, "base_color": [0.3, 0.2, 0.1],
                      "f0": [0.9, 0.6, 0.5], "normal_map": GAUSS}},
        {"type": "sphere", "center": [0.8, 0.6, -1.5], "radius": 0.6, "uv_scale": [4, 2],
         "material": {"alpha": 0.3, "base_color": [0.2, 0.3, 0.6], "f0": 0.04,
                      "height_map": dict(GAUSS, seed=2),
                      "color_map": {"procedural": "noise", "size": 64, "seed": 3,
                                    "corr_length": 4, "sigma": 0.3}}},
        {"type": "plane", "center": [-1.2, 0.8, -1.5], "normal": [0.3, -0.3, -1],
         "size": [1, 1], "material": {"alpha": 0.1, "base_color": 0.5, "f0": 0.5,
                                      "normal_map": dict(GAUSS, seed=4)}}],
    "lights": [{"type": "quad", "radiance": [4, 3, 2],
                "vertices": [[-1.5, 0.3, -3], [1.5, 0.3, -3], [1.5, 2.0, -3],
                             [-1.5, 2.0, -3]]},
               {"type": "quad", "radiance": 1.0,
                "vertices": [[2, 3, -2], [2, 3, 0], [-2, 3, 0], [-2, 3, -2]]}]}


def _scenes():
    return {"showcase": load_scene(showcase_scene(1.0, 32, 20)), "spheres": load_scene(SPHERES)}


@pytest.mark.parametrize("name", ["showcase", "spheres"])
@pytest.mark.parametrize("spp, pairs, control", [(16, None, "ltc"), (8, 1, "ltc"),
                                                 (32, 4, "ltc"), (16, None, "none")])
def test_fused_matches_the_numpy_stages(name, spp, pairs, control):
    scene = _scenes()[name]
    st = RenderSettings(spp=spp, seed=3, params={"control": control})
    fused = render_reference(scene, st, pairs=pairs)
    staged = render_reference(scene, st, pairs=pairs, fused=False)
    assert fused.max() > 0.05
    rel = np.abs(fused - staged) / np.maximum(np.abs(staged), 1e-3 * np.abs(staged).max())
    assert rel.max() <= 1e-5, rel.max()


def test_fused_power_heuristic_matches_the_numpy_stages():
    scene = _scenes()["spheres"]
    st = RenderSettings(spp=8, seed=5)
    fused = render_reference(scene, st, heuristic="power")
    staged = render_reference(scene, st, heuristic="power", fused=False)
    rel = np.abs(fused - staged) / np.maximum(np.abs(staged), 1e-3 * np.abs(staged).max())
    assert rel.max() <= 1e-5, rel.max()


def test_fused_is_deterministic_across_chunks_and_threads():
    scene = _scenes()["spheres"]
    st = RenderSettings(spp=16, seed=7)
    a = render_reference(scene, st)
    assert a.tobytes() == render_reference(scene, st).tobytes()
    assert a.tobytes() == render_reference(scene, with_settings(st, chunk_samples=50)).tobytes()
    threads = numba.get_num_threads()
    try:
        numba.set_num_threads(1)
        one = render_reference(scene, st)
    finally:
        numba.set_num_threads(threads)
    assert a.tobytes() == one.tobytes()
    assert a.tobytes() != render_reference(scene, with_settings(st, seed=8)).tobytes()


def test_scenes_the_fused_kernel_does_not_take():
    scene = load_scene({**SPHERES, "lights": SPHERES["lights"]
                        + [{"type": "point", "position": [0, 2, 0], "intensity": 1.0}]})
    lights = scene.light_set()
    assert fused_shader(scene, lights, ()) is None
    assert fused_shader(scene, type(lights)(), ()) is None  # no quad light
    plain = _scenes()["spheres"]
    assert fused_shader(plain, plain.light_set(), ()) is not None
