"""Methods render mesh scenes through the G-buffer: a 2-triangle quad as the analytic plane, a
tessellated sphere close to the analytic sphere."""

from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("trimesh")
pytest.importorskip("embreex")

from mesh_assets import write_quad, write_uv_sphere  # noqa: E402

from prefilter.render import load_scene, render  # noqa: E402

LIGHTS = [{"type": "quad", "vertices": [[-1, 2.5, -1], [1, 2.5, -1], [1, 2.5, 1], [-1, 2.5, 1]],
           "radiance": 5}]
NMAP = {"alpha": 0.2, "base_color": 0.3, "normal_map": {"procedural": "gaussian", "size": 128}}
PLAIN = {"alpha": 0.3, "base_color": 0.3, "f0": 0.9}


def scene(obj, cam):
    return load_scene({"camera": cam, "objects": [obj], "lights": LIGHTS})


@pytest.mark.parametrize("method, spp", [("ltc", 1), ("reference", 4)])
def test_quad_mesh_renders_as_the_analytic_plane(tmp_path, method, spp):
    """Same image as the analytic plane to float32 rounding (the mesh runs the staged path,
    the plane the fused kernel; they agree to rounding)."""
    cam = {"origin": [0.3, 1.5, 3], "target": [0, 0, 0], "fov": 40, "width": 48, "height": 32}
    quad = write_quad(tmp_path / "quad.obj")
    a = render(scene({"type": "plane", "size": [4, 4], "material": NMAP}, cam), method, spp=spp)
    b = render(scene({"type": "mesh", "file": str(quad), "material": NMAP}, cam), method,
               spp=spp)
    assert a.mean() > 0.05
    np.testing.assert_allclose(b, a, rtol=1e-5, atol=1e-6)


@pytest.mark.parametrize("method, spp", [("ltc", 1), ("reference", 16)])
@pytest.mark.parametrize("material", ["plain", "normal_map"])
def test_tessellated_sphere_renders_close_to_the_analytic_sphere(tmp_path, method, spp,
                                                                 material):
    """A 128 x 256 UV sphere (65k triangles) within 1 % relative RMSE of the analytic sphere
    (measured: ltc 0.02 % plain, 0.2 % with a normal map; reference 0.5 %, mostly the Monte
    Carlo noise of different hit points at 16 spp)."""
    cam = {"origin": [0.4, 0.8, 3], "target": [0, 0, 0], "fov": 40, "width": 96, "height": 96}
    mat = PLAIN if material == "plain" else NMAP
    sphere = write_uv_sphere(tmp_path / "s.ply", 128, 256)
    a = render(scene({"type": "sphere", "radius": 1.0, "material": mat}, cam), method, spp=spp)
    b = render(scene({"type": "mesh", "file": str(sphere), "material": mat}, cam), method,
               spp=spp)
    rel = np.sqrt(np.mean((a - b) ** 2) / np.mean(a**2))
    assert rel < 0.01, rel
