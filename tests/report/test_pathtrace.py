"""The path-tracing scenes and the demo report's section."""

from __future__ import annotations

import numpy as np
import pytest

from prefilter.render.lathe import lathe, smooth_profile
from prefilter.render.mesh import load_mesh
from prefilter.report.pathtrace import KETTLE_PROFILE, kettle_scene, sky_image, write_assets


def test_lathe_frame_is_right_handed_and_outward():
    """The body of revolution's faces wind outward, and the loader's tangent frame (from the
    UVs, MikkTSpace) is right-handed: ``t x b`` is the outward normal, ``t`` along ``+u``."""
    v, f, n, uv = lathe(smooth_profile(KETTLE_PROFILE, 16), segments=32)
    e = np.cross(v[f[:, 1]] - v[f[:, 0]], v[f[:, 2]] - v[f[:, 0]])
    c = v[f].mean(1)
    radial = c - np.array([0.0, 1.0, 0.0]) * c[:, 1:2]
    side = np.linalg.norm(radial, axis=-1) > 0.05  # faces on the sides (not the flat ends)
    assert np.all(np.sum(e[side] * radial[side], -1) > 0)
    assert np.allclose(np.linalg.norm(n, axis=-1), 1.0)


def test_assets_load_with_a_right_handed_frame(tmp_path):
    write_assets(tmp_path)
    m = load_mesh(tmp_path / "kettle.ply")
    assert m.uv is not None and np.all(m.tangents[:, 3] == 1.0)
    before = (tmp_path / "kettle.ply").stat().st_mtime_ns
    write_assets(tmp_path)  # unchanged files are left alone
    assert (tmp_path / "kettle.ply").stat().st_mtime_ns == before
    sky = sky_image(8)
    assert sky.shape == (8, 16, 3) and sky.min() > 0


def test_kettle_scene_loads(tmp_path):
    from prefilter.render.scene import load_scene

    write_assets(tmp_path)
    s = load_scene(kettle_scene(8, 6, 64), base_dir=tmp_path)
    assert [o.type for o in s.objects] == ["mesh", "plane"]
    assert sum(lt.type == "quad" for lt in s.lights) == 2


@pytest.mark.slow
def test_section_runs(tmp_path):
    from prefilter.report.demo import DemoSettings
    from prefilter.report.pathtrace import pathtrace_section
    from prefilter.report.report import Report

    r = Report("t")
    pathtrace_section(r, DemoSettings(section_width=16, section_height=12, section_spp=2), 0,
                      lambda *a: None)
    assert (r.write(tmp_path / "report")).is_file()
