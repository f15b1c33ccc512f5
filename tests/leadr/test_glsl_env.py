"""The exported environment snippet carries Python's grids and frame change; its textures are
the environment's mip levels and irradiance nodes (the page's pixel match is in
tests/viewer/test_pixel_match.py)."""

import numpy as np

from prefilter.leadr import glsl_env
from prefilter.leadr.envmap import EnvMap, IrradianceMap, procedural_env
from prefilter.leadr.render import ENV_GRID, ENV_GRID_ROUGH
from prefilter.leadr.shading import gaussian_grid


def test_snippet_holds_the_python_grids():
    src = glsl_env.glsl_source()
    for n in (ENV_GRID, ENV_GRID_ROUGH):
        p, w, h = gaussian_grid(n)
        assert f"{p[0]:.9g}" in src and f"{w[n // 2]:.9g}" in src and f"{h:.9g}" in src
    # mat3 is column-major: the first column of ENV_FROM_WORLD is (0, -1, 0)
    assert "mat3(0.0, -1.0, 0.0, 0.0, 0.0, 1.0, 1.0, 0.0, 0.0)" in src


def test_env_textures_are_the_levels_and_the_irradiance_nodes():
    env = EnvMap(procedural_env(16))
    tex = glsl_env.env_textures(env)
    assert tex["present"] and len(tex["levels"]) == len(env.levels)
    for a, b in zip(tex["levels"], env.levels):
        np.testing.assert_allclose(a[..., :3], b, rtol=1e-6)
        assert a.dtype == np.float32 and np.all(a[..., 3] == 1)
    np.testing.assert_allclose(tex["irradiance"][..., :3], IrradianceMap(env).values, rtol=1e-6)
    assert tex["texel"] == env.texel_solid_angle
    assert not glsl_env.env_textures(None)["present"]
