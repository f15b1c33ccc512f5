"""The exported data against its sources: table layouts and GLSL twins against the Python
lookups, the multi-scale nodes against the exact inverse of eq. 4, the atlas against box
averages, and the viewer folder's structure (no browser)."""

import json

import numpy as np
import pytest
from glsl_numpy import alpha_meso_twin, iso_glsl_twin

from prefilter.errors import PrefilterError
from prefilter.ltc import glsl as iso_glsl
from prefilter.ltc.table import GGXTable
from prefilter.multiscale import glsl as ms_glsl
from prefilter.multiscale.meso import alpha_meso_exact
from prefilter.render.scene import load_scene
from prefilter.viewer import default_scene, export_scene, viewer_scene


@pytest.fixture(scope="module")
def table():
    return GGXTable.load()


def _views(rng, n):
    theta = rng.uniform(0.0, 1.55, n)
    phi = rng.uniform(-np.pi, np.pi, n)
    return np.stack([np.sin(theta) * np.cos(phi), np.sin(theta) * np.sin(phi), np.cos(theta)], -1)


def test_iso_twin_matches_table_lookup(table):
    rng = np.random.default_rng(1)
    wo, alpha = _views(rng, 4000), rng.uniform(table.alpha_min, 1.0, 4000)
    M_ref, n_ref, f_ref = table.lookup(wo, alpha)
    params = iso_glsl.texture_params(table)
    M, n, f5 = iso_glsl_twin(iso_glsl.texture_layout(table, np.float32), params, wo, alpha)
    scale = np.abs(M_ref).max(axis=(-1, -2), keepdims=True)
    assert np.max(np.abs(M - M_ref) / scale) < 1e-5
    assert np.max(np.abs(n - n_ref)) < 1e-5 and np.max(np.abs(f5 - f_ref)) < 1e-5
    # half floats: 11-bit mantissas
    M16, n16, _ = iso_glsl_twin(iso_glsl.texture_layout(table, np.float16), params, wo, alpha)
    assert np.max(np.abs(M16 - M_ref) / scale) < 2e-3
    assert np.max(np.abs(n16 - n_ref)) < 2e-3


def test_iso_binary_layout(table, tmp_path):
    paths = iso_glsl.export_all(table, tmp_path)
    assert {p.name for p in paths} == {"ggx_iso_f32.bin", "ggx_iso_f16.bin",
                                       "ggx_iso_layout.json", "ltc_iso.glsl"}
    T, R = len(table.axis_t), len(table.axis_r)
    raw = np.fromfile(tmp_path / "ggx_iso_f32.bin", "<f4").reshape(3, R, T, 4)
    # texel (x = view index i, y = roughness index j) of texture k holds channels 4k..4k+3
    i, j = 17, 40
    chans = np.concatenate([raw[k, j, i] for k in range(3)])
    np.testing.assert_allclose(chans[:9], table.M[i, j].reshape(-1), rtol=1e-6, atol=1e-7)
    np.testing.assert_allclose(chans[9:11], [table.magnitude[i, j], table.fresnel[i, j]],
                               rtol=1e-6)
    half = np.fromfile(tmp_path / "ggx_iso_f16.bin", "<f2").reshape(3, R, T, 4)
    np.testing.assert_allclose(half[0, j, i], raw[0, j, i], rtol=1e-3, atol=1e-4)
    meta = json.loads((tmp_path / "ggx_iso_layout.json").read_text())
    assert meta["T"] == T and meta["R"] == R and meta["shape"] == [3, R, T, 4]
    src = (tmp_path / "ltc_iso.glsl").read_text()
    assert f"LTC_ISO_T = {T}" in src and "{T}" not in src and "{t_max" not in src


def test_iso_layout_rejects_nonuniform_axes(table):
    t = GGXTable(table.axis_t ** 1.5, table.axis_r, table.M, table.magnitude, table.fresnel)
    with pytest.raises(PrefilterError, match="uniform"):
        iso_glsl.texture_params(t)


def test_alpha_meso_nodes_match_exact_inverse():
    r = np.linspace(2.0 / 3.0, 1.0, 2001)
    got = alpha_meso_twin(ms_glsl.alpha_meso_nodes(), r)
    # float32 nodes, linear interpolation of a function with a log singularity at r = 1
    assert np.max(np.abs(got - alpha_meso_exact(r))) < 2e-4
    assert ms_glsl.alpha_meso_nodes().shape[1] == ms_glsl.ALPHA_MESO_WIDTH


def test_multiscale_glsl_has_fit_coefficients():
    from prefilter.multiscale import FIT_COEFFS

    src = ms_glsl.glsl_source()
    for c in FIT_COEFFS:
        assert f"{c:.9g}" in src


def test_export_folder(tmp_path):
    out = export_scene(default_scene(64, 48), tmp_path / "v", builtin_maps=False)
    for f in ("index.html", "main.js", "viewer.js", "shaders/viewer.frag.glsl",
              "data/viewer.json", "data/ltc_aniso.glsl", "data/ggx_aniso_f16.bin"):
        assert (out / f).is_file(), f
    m = json.loads((out / "data/viewer.json").read_text())
    assert m["scene"]["camera"]["width"] == 64 and len(m["scene"]["objects"]) == 2
    assert len(m["maps"]) == 1 and m["scene"]["objects"][0]["material"]["map"] == 0
    assert m["scene"]["objects"][1]["material"]["map"] == -1
    # the atlas holds the normal map's box-filtered mip chain: level 1 = 2x2 block means
    sc = load_scene(default_scene(64, 48))
    normals = sc.objects[0].material.normal_map.load()
    levels = np.fromfile(out / "data/levels_i32.bin", "<i4").reshape(-1, 4)
    atlas = np.fromfile(out / "data/atlas_f32.bin", "<f4").reshape(-1, 4)
    first = m["maps"][0]["normals"][0]
    off, h, w, stride = levels[first + 1]
    assert (h, w, stride) == (128, 128, 1)
    lv1 = atlas[off:off + h * w].reshape(h, w, 4)
    block = normals[2:4, 6:8].mean(axis=(0, 1))
    np.testing.assert_allclose(lv1[1, 3, :3], block, atol=1e-6)
    # slope moments (5 channels, 2 texels per texel): E[s_x] at level 0
    off, h, w, stride = levels[m["maps"][0]["slopes"][0]]
    assert stride == 2
    s0 = atlas[off:off + h * w * 2].reshape(h, w, 8)
    n = normals[5, 9]
    np.testing.assert_allclose(s0[5, 9, :2], -n[:2] / max(n[2], 0.05), rtol=1e-5, atol=1e-6)


@pytest.mark.parametrize("change, field", [
    (lambda d: d["lights"].append({**d["lights"][0], "texture": {"procedural": "noise",
                                                                  "size": 16}}), "lights[1]"),
    (lambda d: d["objects"].extend([d["objects"][1]] * 3), "objects"),
])
def test_unsupported_features_are_named(tmp_path, change, field):
    d = default_scene(32, 24)
    change(d)
    np.save(tmp_path / "env.npy", np.ones((8, 16, 3)))
    for light in d["lights"]:
        if light.get("image") == "ENV":
            light["image"] = str(tmp_path / "env.npy")
    with pytest.raises(PrefilterError, match=field.replace("[", r"\[").replace("]", r"\]")):
        export_scene(d, tmp_path / "x", builtin_maps=False)


def test_viewer_scene_frames_are_right_handed():
    vs = viewer_scene(load_scene(default_scene(32, 24)))
    for o in vs["objects"]:
        t, b, n = (np.array(o[k]) for k in "tbn")
        # planes: b = n x t, t x b = n; spheres store (pole, axis_x, axis_x x pole)
        if o["type"] == 0:
            np.testing.assert_allclose(np.cross(t, b), n, atol=1e-12)
        else:
            np.testing.assert_allclose(np.cross(t, n), b, atol=1e-12)


def test_footprint_bias_follows_the_method_defaults():
    from prefilter.multiscale.render import render_multiscale

    def f(scene, settings, *, lod_bias=1.5, lod_bias_start=None):
        pass

    def g(scene, settings, *, lod_bias=0.5, lod_bias_start=3):
        pass

    assert ms_glsl.footprint_bias(f) == (1.5, -1.0)
    assert ms_glsl.footprint_bias(g) == (0.5, 3.0)
    assert ms_glsl.footprint_bias(lambda scene, settings: None) == (0.0, -1.0)
    bias, start = ms_glsl.footprint_bias(render_multiscale)
    assert f"MS_LOD_BIAS = {bias!r}, MS_LOD_START = {start!r}" in ms_glsl.glsl_source()


def test_footprint_taps_follow_the_method_defaults():
    from prefilter.multiscale import render as ms_render

    def f(scene, settings, *, taps=3, taps_below=float("inf"), taps_ratio=2, taps_normalize=1):
        pass

    assert ms_glsl.footprint_taps(f) == (3, float("inf"), 2.0, True)
    assert ms_glsl.footprint_taps(lambda scene, settings: None) == (0, 4.0, 1.5, False)
    assert ms_glsl.footprint_taps(ms_render.render_multiscale) == (
        ms_render.TAPS, ms_render.TAPS_BELOW, ms_render.TAPS_RATIO, False)
    src = ms_glsl.glsl_source()
    assert f"const int MS_TAPS = {ms_render.TAPS};" in src
    assert (f"const float MS_TAPS_BELOW = {ms_render.TAPS_BELOW!r}, "
            f"MS_TAPS_RATIO = {ms_render.TAPS_RATIO!r};") in src
    assert "const bool MS_TAPS_NORM = false;" in src


def test_export_height_chains_for_leadr(tmp_path):
    """An object with a normal map and a height map keeps both (LTC modes read the normal map,
    leadr-point the height map's slope moments); the float16 atlas is the float32 one rounded."""
    from prefilter.viewer.match import scene

    d = scene("leadr", 32, 24)
    d["objects"][1]["material"]["normal_map"] = {"procedural": "flakes", "size": 32, "seed": 1}
    out = export_scene(d, tmp_path / "v", builtin_maps=False)
    assert (out / "data/leadr.glsl").read_text().count("leadrDelta") >= 1
    m = json.loads((out / "data/viewer.json").read_text())
    assert m["leadr"]["glsl"] == "leadr.glsl" and m["atlas"]["f16"] == "atlas_f16.bin"
    mats = [o["material"] for o in m["scene"]["objects"]]
    assert mats[1]["map"] >= 0 and m["maps"][mats[1]["map"]]["normals"][0] >= 0
    levels = np.fromfile(out / "data/levels_i32.bin", "<i4").reshape(-1, 4)
    atlas = np.fromfile(out / "data/atlas_f32.bin", "<f4").reshape(-1, 4)
    half = np.fromfile(out / "data/atlas_f16.bin", "<f2").reshape(-1, 4)
    np.testing.assert_allclose(half, atlas, rtol=1e-3, atol=1e-7)
    sc = load_scene(d)
    for o, mat in zip(sc.objects, mats):
        # level 0 of the height chain: the slopes' moments, E[s_x s_y] = s_x s_y per texel
        first, n = mat["height"]
        assert n == o.material.height_map.mip().n_levels
        off, h, w, stride = levels[first]
        slopes = o.material.height_map.load().slopes
        assert (h, w, stride) == (*slopes.shape[:2], 2)
        lv = atlas[off:off + h * w * 2].reshape(h, w, 8)
        np.testing.assert_allclose(lv[..., :2], slopes, rtol=1e-6, atol=1e-6)
        np.testing.assert_allclose(lv[..., 4], slopes[..., 0] * slopes[..., 1], rtol=1e-5,
                                   atol=1e-6)


def test_mesh_scene_is_refused_with_the_field(tmp_path):
    import trimesh

    from prefilter.viewer.export import viewer_scene

    quad = trimesh.Trimesh([[-1, 0, -1], [1, 0, -1], [1, 0, 1], [-1, 0, 1]], [[0, 2, 1], [0, 3, 2]],
                           visual=trimesh.visual.TextureVisuals(
                               uv=[[0, 0], [1, 0], [1, 1], [0, 1]]))
    quad.export(str(tmp_path / "q.obj"))
    scene = load_scene({
        "camera": {"origin": [0, 2, 3], "target": [0, 0, 0], "fov": 40, "width": 8,
                   "height": 6},
        "objects": [{"type": "mesh", "file": str(tmp_path / "q.obj")}],
        "lights": [{"type": "point", "position": [0, 2, 0], "intensity": 1.0}]})
    with pytest.raises(PrefilterError, match=r"objects\[0\]\.type: the viewer shows planes"):
        viewer_scene(scene)
