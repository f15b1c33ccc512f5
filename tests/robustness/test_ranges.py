"""Range validation at the boundary: scene magnitudes, slope covariances, glint footprint centres
and memory requests, each with a documented domain and a PrefilterError naming the field outside
it. No finite input may reach a kernel out of range (the reproductions that crashed the process
run in a subprocess, so a regression fails the test instead of killing the run)."""

from __future__ import annotations

import copy
import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from hypothesis import example, given, settings
from hypothesis import strategies as st

from prefilter.errors import PrefilterError
from prefilter.render import load_scene, render
from prefilter.render.scene import EXTENT_MAX, LIGHT_MAX, UV_SCALE_MAX
from prefilter.validation import (
    MEMORY_BUDGET_ENV,
    SLOPE_MAX,
    as_slope_covariance,
    check_memory,
    check_scalar,
    memory_budget,
)

N = settings.default.max_examples
SRC = str(Path(__file__).resolve().parents[2] / "src")

SCENE = {
    "camera": {"origin": [0, 1.2, 3], "target": [0, 0.3, 0], "fov": 40, "width": 8, "height": 6},
    "objects": [
        {"type": "plane", "size": 4, "material": {
            "alpha": 0.3, "normal_map": {"procedural": "gaussian", "size": 8, "seed": 1}}},
        {"type": "sphere", "center": [0, 0.5, 0], "radius": 0.5, "material": {
            "alpha": 0.2, "normal_map": {"procedural": "gaussian", "size": 8, "seed": 1}}},
    ],
    "lights": [{"type": "quad", "vertices": [[-1, 2, -1], [-1, 2, 1], [1, 2, 1], [1, 2, -1]],
                "radiance": 5},
               {"type": "point", "position": [0, 3, 0], "intensity": 2}],
}


def scene_with(path, value):
    """SCENE with the field at ``path`` (keys and indices) set to ``value``."""
    d = copy.deepcopy(SCENE)
    *keys, last = path
    x = d
    for k in keys:
        x = x[k]
    x[int(last) if isinstance(x, list) else last] = value
    return d


def field_name(path) -> str:
    out = ""
    for k in path:
        out += f"[{k}]" if isinstance(k, int) else (f".{k}" if out else k)
    return out


def run_python(code: str, env=None) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                          timeout=600, env={**os.environ, "PYTHONPATH": SRC, **(env or {})})


# -- scene magnitudes ------------------------------------------------------------------------------

# the reproductions: a crash, a ZeroDivisionError, unrelated messages or an error after the render
BAD_FIELDS = [
    (("objects", 1, "uv_scale"), [1e160, 1e160]),    # segfault in the footprint lookup kernel
    (("objects", 1, "uv_scale"), [1e180, 1e180]),    # ZeroDivisionError
    (("objects", 1, "uv_scale"), [1e20, 1e20]),      # "wi: expected unit vectors"
    (("objects", 0, "uv_scale"), 1e150),
    (("lights", 0, "radiance"), 1e308),              # "image: expected finite values", after
    (("lights", 1, "position"), [0, 1e300, 0]),      # "wi: expected unit vectors"
    (("camera", "origin"), [0, 1e300, 3]),           # "camera.up ... parallel"
    (("objects", 0, "material", "normal_map", "corr_length"), 1e9),  # "slopes: finite"
    (("objects", 1, "radius"), 10**400),             # OverflowError
    (("objects", 1, "center"), [0, 10**400, 0]),
    (("camera", "fov"), 10**400),
    (("objects", 1, "radius"), 1e300),
    (("objects", 0, "size"), [1e300, 1.0]),
    (("lights", 1, "intensity"), 1e200),
    (("lights", 0, "vertices", "2"), [1, 1e300, 1]),   # corners are named vertices.0 .. .3
    (("objects", 1, "material", "base_color"), 1e300),
]


@pytest.mark.parametrize("path,value", BAD_FIELDS, ids=[f"{field_name(p)}={v!s:.12}"
                                                        for p, v in BAD_FIELDS])
def test_out_of_domain_scene_fields_are_named_at_load(path, value):
    with pytest.raises(PrefilterError) as err:
        load_scene(scene_with(path, value))
    assert str(err.value).startswith(field_name(path) + ":"), str(err.value)


def test_uv_scale_1e160_render_exits_2_in_one_line(tmp_path):
    # was a segfault (rc 139) in the footprint lookup kernel
    scene = tmp_path / "s.json"
    scene.write_text(json.dumps(scene_with(("objects", 1, "uv_scale"), [1e160, 1e160])))
    r = run_python("import sys; from prefilter.cli import main; sys.argv = ['prefilter', "
                   f"'render', {str(scene)!r}, '--quiet', '--out', {str(tmp_path / 'o.exr')!r}];"
                   " main()")
    assert r.returncode == 2, r.stderr[-2000:]
    assert "objects[1].uv_scale" in r.stderr


@settings(max_examples=N)
@given(st.sampled_from([("objects", 1, "uv_scale"), ("objects", 0, "center"),
                        ("camera", "origin"), ("lights", 1, "position"), ("lights", 0, "radiance"),
                        ("objects", 1, "radius"), ("lights", 1, "intensity")]),
       st.one_of(st.floats(allow_nan=False, allow_infinity=False),
                 st.integers(-10**400, 10**400), st.sampled_from([1e6, 1e12, 1e6 + 1, 1e-300])))
@example(("objects", 1, "uv_scale"), 1e160)
@example(("lights", 1, "position"), 10**400)
def test_scene_magnitudes_load_inside_the_domain_or_name_the_field(path, x):
    value = x if path[-1] in ("radius", "radiance", "intensity", "uv_scale") else [x, 1.0, 2.0]
    try:
        s = load_scene(scene_with(path, value))
    except PrefilterError as err:
        assert str(err).startswith(field_name(path) + ":"), str(err)
        return
    # accepted: every magnitude is inside the documented domain
    for obj in s.objects:
        assert np.all(np.abs(obj.center) <= EXTENT_MAX)
        assert np.all(np.abs(obj.uv_scale) <= UV_SCALE_MAX)
    for light in s.lights:
        for v in (getattr(light, "position", 0.0), getattr(light, "vertices", 0.0)):
            assert np.all(np.abs(v) <= EXTENT_MAX)
        for v in (getattr(light, "radiance", 0.0), getattr(light, "intensity", 0.0)):
            assert np.all((0.0 <= np.asarray(v)) & (np.asarray(v) <= LIGHT_MAX))
    assert np.all(np.abs(s.camera.origin) <= EXTENT_MAX)


def test_domain_edges_render_finite():
    # the largest accepted values render (a finite image), the smallest rejected ones do not load
    s = scene_with(("objects", 1, "uv_scale"), UV_SCALE_MAX)
    s["lights"][0]["radiance"] = LIGHT_MAX
    img = render(s, "ltc")
    assert np.all(np.isfinite(img))
    with pytest.raises(PrefilterError, match=r"^lights\[0\]\.radiance:"):
        load_scene(scene_with(("lights", 0, "radiance"), LIGHT_MAX * 1.0001))


def test_unit_vectors_of_huge_components_are_normalised():
    # |v|^2 overflowed: the normal became (0, 0, 0)
    s = load_scene(scene_with(("objects", 0, "normal"), [1e300, 1e300, 0]))
    assert np.allclose(s.objects[0].normal, [2**-0.5, 2**-0.5, 0.0])


# -- memory ----------------------------------------------------------------------------------------


@pytest.fixture
def budget_8g(monkeypatch):
    monkeypatch.setenv(MEMORY_BUDGET_ENV, "8G")


def test_render_refuses_a_trillion_samples_per_pixel(budget_8g):
    with pytest.raises(PrefilterError, match=r"^render: .* needs about .* PiB, more than the "
                                             r"memory budget of 8\.0 GiB"):
        render(SCENE, "ltc", spp=10**12)


def test_render_refuses_a_16384_square_image(budget_8g):
    s = copy.deepcopy(SCENE)
    s["camera"].update(width=16384, height=16384)
    with pytest.raises(PrefilterError, match=r"needs about .* GiB, more than the memory budget"):
        render(s, "ltc")


def test_procedural_maps_refuse_absurd_sizes(budget_8g):
    from prefilter.texture import height_map, normal_map
    from prefilter.texture.procedural import noise

    for fn in (lambda: normal_map("gaussian", 99999999), lambda: height_map("brushed", 10**6),
               lambda: noise(10**7)):
        with pytest.raises(PrefilterError, match=r"^size: .*more than the memory budget"):
            fn()


def test_colormap_table_refuses_a_tiny_value_range(budget_8g):
    # `bake colormap --range 0 1e-12`: the widest Gaussian spans 2.5e11 value ranges
    from prefilter.colormap import gaussian_operator, prefilter_table

    with pytest.raises(PrefilterError, match=r"^sigma_max: .*more than the memory budget"):
        prefilter_table(np.linspace(0, 1, 24).reshape(8, 3), (0.0, 1e-12), size=16)
    with pytest.raises(PrefilterError, match=r"^sigma: .*more than the memory budget"):
        gaussian_operator(8, 1e300)


def test_glints_bake_of_an_absurd_procedural_map_is_refused(tmp_path, budget_8g):
    r = run_python("import sys; from prefilter.cli import main; sys.argv = ['prefilter', "
                   "'bake', 'glints', 'procedural:gaussian:99999999', '-o', "
                   f"{str(tmp_path / 'g.npz')!r}]; main()", env={MEMORY_BUDGET_ENV: "8G"})
    assert r.returncode == 2, r.stderr[-2000:]
    assert "memory budget" in r.stderr and "Traceback" not in r.stderr


@pytest.mark.parametrize("text,nbytes", [("8G", 8 << 30), ("512M", 512 << 20), ("1000", 1000),
                                         ("1.5GiB", 3 << 29), ("2t", 2 << 40)])
def test_memory_budget_from_the_environment(monkeypatch, text, nbytes):
    monkeypatch.setenv(MEMORY_BUDGET_ENV, text)
    assert memory_budget() == nbytes
    assert check_memory(nbytes, "x") == nbytes
    with pytest.raises(PrefilterError, match=r"^x: needs about"):
        check_memory(nbytes + 1, "x")


@pytest.mark.parametrize("text", ["lots", "-1G", "0", "nan", "G"])
def test_bad_memory_budget_names_the_variable(monkeypatch, text):
    monkeypatch.setenv(MEMORY_BUDGET_ENV, text)
    with pytest.raises(PrefilterError, match=f"^{MEMORY_BUDGET_ENV}:"):
        check_memory(1, "x")


def test_default_memory_budget_is_a_fraction_of_the_machine(monkeypatch):
    monkeypatch.delenv(MEMORY_BUDGET_ENV, raising=False)
    total = os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES")
    assert 0 < memory_budget() < total


# -- slope covariances -----------------------------------------------------------------------------


def test_env_specular_of_a_huge_covariance_is_an_error_not_a_segfault():
    # the determinant inf - inf = NaN passed the definiteness check
    r = run_python(
        "import numpy as np\n"
        "from prefilter import leadr\n"
        "from prefilter.errors import PrefilterError\n"
        "env = leadr.EnvMap(leadr.procedural_env(8))\n"
        "try:\n"
        "    leadr.env_specular(env, [0, 0, 1.0], np.zeros(2), np.full((2, 2), 1e300), 3)\n"
        "except PrefilterError as e:\n"
        "    print('error:', e)\n")
    assert r.returncode == 0, r.stderr[-2000:]
    assert r.stdout.startswith("error: slope_cov:"), r.stdout


cov_entry = st.one_of(st.floats(-1e308, 1e308), st.sampled_from([1e-300, SLOPE_MAX**2, 1e13]))


@settings(max_examples=N)
@given(cov_entry, cov_entry, cov_entry, st.floats(-1e300, 1e300))
@example(1e300, 1e300, 1e300, 0.0)
@example(1e-300, 1e-300, 0.0, 0.0)
def test_slope_covariances_accepted_have_finite_positive_determinants(a, b, c, m):
    from prefilter.leadr import point_light

    cov = np.array([[a, c], [c, b]])
    try:
        out = as_slope_covariance(cov, "slope_cov")
    except PrefilterError as err:
        assert str(err).startswith("slope_cov:")
    else:
        det = out[0, 0] * out[1, 1] - out[0, 1] ** 2
        assert np.isfinite(det) and det > 0
    wo = [0.0, 0.6, 0.8]
    try:
        v = point_light(wo, wo, (m, 0.0), cov)
    except PrefilterError as err:
        assert str(err).split(":")[0] in ("slope_cov", "mean_slope")
    else:
        assert np.isfinite(v) and v >= 0


# -- glint footprint centres -----------------------------------------------------------------------


@pytest.fixture(scope="module")
def glints_map(tmp_path_factory):
    from prefilter.glints.bake import bake
    from prefilter.glints.store import load

    # an analytic periodic normal map (as the glints property tests)
    x = np.arange(16) + 0.5
    sx, sy = np.meshgrid(0.2 * np.sin(2 * np.pi * x / 16), 0.2 * np.cos(2 * np.pi * x / 16))
    nm = np.stack([sx, sy, np.sqrt(1 - sx * sx - sy * sy)], -1)
    out = tmp_path_factory.mktemp("glints_ranges") / "wavy.npz"
    bake(nm, out, rank=4, ndf_res=16, block=8, support=0.5, cell=16, converge=0.0,
         progress=False)
    return load(out)


@pytest.mark.parametrize("cx", [9.3e18, 1e19, -1e19, 2.0**70 + 3.0, 1e300, -1e308])
def test_far_centres_are_the_tiled_footprint(glints_map, cx):
    # int64 texel indices overflowed: negative values and values up to 6e58
    from prefilter.glints import point, range_mean, sample_s

    size = glints_map.pyramid.width
    near = float(np.mod(cx, size))
    for sp in (0.7, 3.0):
        assert point(glints_map, [cx, 5.0], sp, [0.1, 0.1]) == point(
            glints_map, [near, 5.0], sp, [0.1, 0.1])
        assert range_mean(glints_map, [5.0, cx], sp, [0, 0], [0.2, 0.2]) == range_mean(
            glints_map, [5.0, near], sp, [0, 0], [0.2, 0.2])
        s_far, p_far = sample_s(glints_map, [cx, cx], sp, 3)
        s_near, p_near = sample_s(glints_map, [near, near], sp, 3)
        assert np.array_equal(s_far, s_near) and p_far == p_near


@settings(max_examples=N)
@given(st.floats(-1e308, 1e308), st.floats(-1e308, 1e308), st.floats(0.0, 40.0))
def test_queries_at_any_finite_centre_are_finite_and_bounded(glints_map, cx, cy, sp):
    from prefilter.glints import point, range_mean

    p = point(glints_map, [cx, cy], sp, [0.1, -0.1])
    r = range_mean(glints_map, [cx, cy], sp, [-0.2, -0.2], [0.2, 0.2])
    # a density of s on the support [-0.5, 0.5]^2 of the map: never the 6e58 of an overflow
    assert np.isfinite(p) and np.isfinite(r) and abs(p) < 1e3 and abs(r) < 1e3


# -- scalars ---------------------------------------------------------------------------------------


@settings(max_examples=N)
@given(st.one_of(st.floats(), st.integers(-10**400, 10**400), st.text(max_size=4), st.none(),
                 st.complex_numbers(), st.booleans(), st.lists(st.floats(), max_size=2)))
@example("0.5")
@example(10**400)
@example(np.array([0.1, 0.2]))
def test_check_scalar_returns_a_number_in_range_or_names_the_argument(x):
    try:
        v = check_scalar(x, "sigma", lo=0.0, hi=10.0)
    except PrefilterError as err:
        assert str(err).startswith("sigma: expected a number"), str(err)
    else:
        assert type(v) is float and 0.0 <= v <= 10.0
