"""The ``ltc`` method: the fused kernel against the NumPy stages (G-buffer, footprint lookups,
the NumPy shader through the generic row driver), and its independence of the thread count."""

from __future__ import annotations

import numpy as np
import pytest
from ltc_numpy import shade_ltc_numpy

from prefilter.errors import TableFileError
from prefilter.render import load_scene
from prefilter.render.driver import render


def _table():
    from prefilter.ltc.table import GGXTable

    try:
        return GGXTable.load()
    except TableFileError as exc:  # the table is baked by another part of the project
        pytest.skip(f"no LTC table: {exc}")


def _textured_scene():
    gauss = {"procedural": "gaussian", "size": 64, "seed": 1, "rms_slope": 0.3, "corr_length": 3}
    return load_scene({
        "camera": {"origin": [0, 1.2, 3], "target": [0, 0.3, -1], "fov": 60, "width": 40,
                   "height": 30},
        "objects": [
            {"type": "plane", "center": [0, 0, -2], "size": [8, 8], "uv_scale": [4, 4],
             "tangent": [1, 0, 0.3],
             "material": {"alpha_x": 0.2, "alpha_y": 0.4, "base_color": [0.3, 0.2, 0.1],
                          "f0": [0.9, 0.6, 0.5], "normal_map": gauss}},
            {"type": "sphere", "center": [0.8, 0.6, -1.5], "radius": 0.6, "uv_scale": [4, 2],
             "material": {"alpha": 0.3, "base_color": [0.2, 0.3, 0.6], "f0": 0.04,
                          "height_map": dict(gauss, seed=2),
                          "color_map": {"procedural": "noise", "size": 64, "seed": 3,
                                        "corr_length": 4, "sigma": 0.3}}},
            # seen from behind its normal: the two-sided frame flip
            {"type": "plane", "center": [-1.2, 0.8, -1.5], "normal": [0.3, -0.3, -1],
             "size": [1, 1], "material": {"alpha": 0.1, "base_color": 0.5, "f0": 0.5}}],
        "lights": [{"type": "quad", "radiance": [4, 3, 2],
                    "vertices": [[-1.5, 0.3, -3], [1.5, 0.3, -3], [1.5, 2.0, -3],
                                 [-1.5, 2.0, -3]]},
                   {"type": "quad", "radiance": 1.0,
                    "vertices": [[2, 3, -2], [2, 3, 0], [-2, 3, 0], [-2, 3, -2]]}]})


def test_fused_ltc_method_matches_the_numpy_stages(monkeypatch):
    # The fused kernel against the NumPy G-buffer, MipChain.lookup_footprint and the NumPy
    # shader through the generic row driver (same sample positions, same shading model).
    import prefilter.render.driver as pl
    from gbuffer_numpy import intersect_numpy

    from prefilter.render.camera import rays_at
    from prefilter.render.methods import RenderSettings

    table = _table()
    s = _textured_scene()
    lights = s.light_set()

    def shade(g, _u):
        a = pl.surface_attributes(s, g, filtered=True)
        return shade_ltc_numpy(g.position, a["t"], a["b"], a["n"], g.view,
                               np.sqrt(a["alpha_x"] * a["alpha_y"]), a["base_color"], a["f0"],
                               lights, table)

    for spp, jitter in ((1, (0.0, 0.0)), (1, (0.3, -0.2)), (4, (0.0, 0.0))):
        got = render(s, "ltc", spp=spp, jitter=jitter, seed=2, table=table, chunk_samples=500)
        settings = RenderSettings(spp=spp, seed=2, jitter=jitter, progress=False,
                                  chunk_samples=1 << 18, table=table)
        with monkeypatch.context() as m:
            m.setattr(pl, "gbuffer_at", lambda sc, xy: intersect_numpy(sc, rays_at(sc.camera,
                                                                                    xy)))
            m.setattr(pl, "footprint_lookup", lambda ch, uv, dudv: ch.lookup_footprint(uv, dudv))
            want = pl.render_samples(s, settings, shade, stratified=spp > 1)
        g = intersect_numpy(s, rays_at(s.camera, np.stack(np.meshgrid(
            np.arange(40) + 0.5, np.arange(30) + 0.5), -1)))
        assert np.all(np.bincount(g.object_id[g.hit], minlength=3) > 10)  # all on screen
        back = np.sum(g.view * g.normal, -1) < 0
        assert np.all(back[g.object_id == 2])
        assert np.count_nonzero(want.sum(-1)) > 0.5 * want.shape[0] * want.shape[1]
        assert np.allclose(got, want, rtol=1e-6, atol=1e-7)  # float32 output


def test_ltc_image_does_not_depend_on_the_thread_count():
    import numba

    table = _table()
    s = _textured_scene()
    before = numba.get_num_threads()
    try:
        numba.set_num_threads(1)
        a = render(s, "ltc", spp=2, table=table)
        numba.set_num_threads(numba.config.NUMBA_NUM_THREADS)
        b = render(s, "ltc", spp=2, table=table)
    finally:
        numba.set_num_threads(before)
    assert a.tobytes() == b.tobytes()


def test_table_file_is_loaded_by_the_method(tmp_path):
    # RenderSettings.table may be a path: the ltc method loads it (render/ knows no LTC table)
    from prefilter.ltc.fit_iso import default_table_path
    from prefilter.ltc.table import as_table

    table = _table()
    s = _textured_scene()
    path = default_table_path()
    assert isinstance(as_table(str(path)), type(table))
    np.testing.assert_array_equal(render(s, "ltc", table=str(path)), render(s, "ltc", table=table))
    np.testing.assert_array_equal(render(s, "ltc-multiscale", table=path),
                                  render(s, "ltc-multiscale", table=table))
