"""Property-based tests of the renderer's building blocks (issue 10) and regression tests of the
boundary defects the fuzzing found in glints, leadr.envmap and validation.

Each regression test failed before its fix: a bare NumPy error, NaN output, an IndexError or a
RuntimeWarning instead of a :class:`PrefilterError` naming the parameter.
"""

import warnings

import numpy as np
import pytest
from hypothesis import example, given, settings
from hypothesis import strategies as st

from prefilter.validation import as_directions, as_float_array
from prefilter.errors import PrefilterError
from prefilter.leadr.envmap import EnvMap, sh9_irradiance, sh9_project
from prefilter.render.lights import QuadLight, quad_light_pdf, quad_light_sample

N = settings.default.max_examples


def expect_error(fn, *names):
    with pytest.raises(PrefilterError) as err:
        fn()
    for name in names:
        assert name in str(err.value), str(err.value)
    return str(err.value)


def direction(t_deg, p):
    t = np.radians(t_deg)
    return np.array([np.sin(t) * np.cos(p), np.sin(t) * np.sin(p), np.cos(t)])


unit = st.builds(direction, st.one_of(st.sampled_from([0.0, 89.9, 90.0, 180.0]),
                                      st.floats(0.0, 180.0)), st.floats(0.0, 2 * np.pi))


# -- glints: batch shapes and unit directions --------------------------------------------------


@pytest.fixture(scope="module")
def glint_surface():
    from prefilter.glints import surface
    from prefilter.texture import normal_map

    return surface(None, normal_map("gaussian", 16, 0))


def test_glints_batch_mismatch_names_the_arguments(glint_surface):
    from prefilter.glints import glint_brdf_cos, glint_ndf, sample_wi
    from prefilter.glints.sample import pdf_wi, sample_s_direct

    z3, z4 = np.zeros((3, 2)), np.zeros((4, 2))
    up3, up4 = np.tile([0.0, 0.0, 1.0], (3, 1)), np.tile([0.0, 0.0, 1.0], (4, 1))
    expect_error(lambda: glint_ndf(glint_surface, z3, 1.0, z4), "center", "s", "(3,)", "(4,)")
    expect_error(lambda: glint_brdf_cos(glint_surface, z3, 1.0, up3, up4), "wi", "(4,)")
    expect_error(lambda: glint_brdf_cos(glint_surface, z3, np.ones(4), up3, up3), "sigma_p")
    expect_error(lambda: sample_wi(glint_surface, z3, 0.1, up4), "wo", "(4,)")
    expect_error(lambda: pdf_wi(glint_surface, z3, 0.1, up3, up4), "wi", "(4,)")
    expect_error(lambda: sample_s_direct(glint_surface, z3, np.ones(4)), "sigma_p")
    expect_error(lambda: sample_wi(glint_surface, z3, -1.0, up3), "sigma_p")


def test_glint_brdf_rejects_non_unit_directions(glint_surface):
    from prefilter.glints import glint_brdf_cos, sample_wi

    c = [8.0, 8.0]
    expect_error(lambda: glint_brdf_cos(glint_surface, c, 1.0, [0, 0, 2.0], [0, 0, 1.0]), "wo",
                 "2.")
    expect_error(lambda: glint_brdf_cos(glint_surface, c, 1.0, [0, 0, 1.0], [0, 0, 0.0]), "wi")
    expect_error(lambda: sample_wi(glint_surface, c, 1.0, [0, 0, 0.5]), "wo")
    # lengths within the tolerance are renormalised: the same value as the unit vector
    a = glint_brdf_cos(glint_surface, c, 1.0, [0, 0, 1.0], [0.6, 0, 0.8])
    b = glint_brdf_cos(glint_surface, c, 1.0, [0, 0, 1.0 + 5e-4], [0.6, 0, 0.8])
    assert np.allclose(a, b, rtol=1e-12) and np.all(a > 0)


# -- leadr.envmap ------------------------------------------------------------------------------

ENV_CONST = EnvMap(np.full((8, 16, 3), 0.7))


def test_envmap_lookup_rejects_nan_and_bad_shapes():
    expect_error(lambda: ENV_CONST.lookup([np.nan, 0.0, 1.0]), "w", "NaN")
    expect_error(lambda: ENV_CONST.lookup([0.0, 0.0, 1.0], np.nan), "lod", "NaN")
    expect_error(lambda: ENV_CONST.lookup([0.0, 0.0, 1.0], "a"), "lod")
    expect_error(lambda: ENV_CONST.lookup([0.0, 0.0, 3.0]), "w", "unit")
    expect_error(lambda: ENV_CONST.lookup([0.0, 1.0]), "w", "(..., 3)")
    expect_error(lambda: ENV_CONST.lookup(np.tile([0.0, 0.0, 1.0], (3, 1)), np.zeros(4)), "lod",
                 "(3,)")


@settings(max_examples=N)
@given(unit, st.one_of(st.sampled_from([-np.inf, -1.0, 0.0, 2.5, 3.0, 100.0, np.inf]),
                       st.floats(-5.0, 10.0)))
@example(np.array([0.0, 0.0, 1.0]), np.inf)  # the pole at the coarsest level
@example(np.array([0.0, 0.0, -1.0]), -np.inf)
def test_envmap_lookup_of_constant_map_is_the_constant(w, lod):
    # every level of a constant map averages to the constant (solid-angle weights sum to one)
    v = ENV_CONST.lookup(w, lod)
    assert v.shape == (3,)
    assert np.allclose(v, 0.7, rtol=1e-12)


def test_sh9_irradiance_rejects_bad_coefficients():
    n = [0.0, 0.0, 1.0]
    expect_error(lambda: sh9_irradiance(np.full((9, 3), np.nan), n), "coeffs", "NaN")
    expect_error(lambda: sh9_irradiance(np.zeros((8, 3)), n), "coeffs", "(8, 3)")
    expect_error(lambda: sh9_irradiance(np.zeros((9, 3, 1)), n), "coeffs")
    expect_error(lambda: sh9_irradiance(np.zeros((9, 3)), [0.0, np.nan, 1.0]), "n", "NaN")
    expect_error(lambda: sh9_irradiance(np.zeros((9, 3)), [0.0, 1.0]), "n", "(..., 3)")


@settings(max_examples=N)
@given(unit)
def test_sh9_irradiance_of_constant_radiance_is_pi_l(n):
    # E(n) = integral of L over the hemisphere = pi L (order 0 is exact; midpoint quadrature of
    # the projection on a 32 x 64 map: 1e-3)
    env = EnvMap(np.full((32, 64, 3), 2.0))
    c = sh9_project(env)
    e = sh9_irradiance(c, n)
    assert np.allclose(e, 2.0 * np.pi, rtol=2e-3)
    e1 = sh9_irradiance(c[:, 0], n)  # one channel as (9,)
    assert e1.shape == (1,) and np.allclose(e1, 2.0 * np.pi, rtol=2e-3)


@settings(max_examples=N)
@given(unit, unit)
@example(np.array([0.0, 0.0, 1.0]), direction(122.2, 0.0))  # the truncation's minimum (-0.040)
@example(direction(30.0, 1.0), direction(30.0, 1.0))  # towards the light: 17/16
def test_sh9_irradiance_of_a_directional_light_is_non_negative(d, n):
    from prefilter.leadr.envmap import sh9_directional

    c = sh9_directional(d[None], [[1.0]])
    e = sh9_irradiance(c, n)
    assert e.shape == (1,) and np.isfinite(e[0]) and e[0] >= 0.0
    if np.dot(n, d) > 1 - 1e-15:
        # sum_l A_l (2l + 1) / (4 pi) = (pi + 2 pi + 5 pi / 4) / (4 pi) towards the light
        assert e[0] == pytest.approx(17.0 / 16.0, rel=1e-5)


# -- validation ---------------------------------------------------------------------------------


@settings(max_examples=N)
@given(st.floats(1e150, 1e308), st.sampled_from([0, 1, 2]))
@example(1e308, 0)
def test_as_directions_of_huge_vectors_is_an_error_not_an_overflow(big, axis):
    v = np.zeros(3)
    v[axis] = big
    v[(axis + 1) % 3] = big
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # an overflow RuntimeWarning fails the test
        msg = expect_error(lambda: as_directions(v, "wo"), "wo", "unit vectors")
    assert "inf" not in msg or big * np.sqrt(2) > np.finfo(float).max


def test_as_float_array_of_huge_integers():
    expect_error(lambda: as_float_array([10**400, 1], "x"), "x", "finite")
    expect_error(lambda: as_float_array(-(10**400), "x"), "x", "finite")


# -- render package entry point and quad-light sampling ----------------------------------------


def test_render_is_exported_from_the_package():
    import prefilter.render as pr
    from prefilter.render import render
    from prefilter.render.driver import render as render_pipeline

    assert render is render_pipeline and "render" in pr.__all__


def quad(size, height, tilt):
    """A square of side ``size`` at ``y = height`` lit downwards, tilted by ``tilt`` radians about
    x (tilt = pi / 2: its plane contains the shading point's horizon)."""
    c, s = np.cos(tilt), np.sin(tilt)
    corners = np.array([[-1, 0, -1], [1, 0, -1], [1, 0, 1], [-1, 0, 1]], float) * size / 2
    rot = np.array([[1, 0, 0], [0, c, -s], [0, s, c]])
    return corners @ rot.T + [0.0, height, 0.0]


@settings(max_examples=N)
@given(st.one_of(st.sampled_from([1e-6, 1.0, 1e4]), st.floats(1e-3, 10.0)),
       st.one_of(st.sampled_from([0.0, -1.0, 1e-9]), st.floats(-2.0, 2.0)),
       st.one_of(st.sampled_from([0.0, np.pi / 2, np.pi]), st.floats(0.0, np.pi)),
       st.integers(0, 2**32 - 1))
@example(1.0, 0.0, np.pi / 2, 0)  # the light's plane through the shading point
def test_quad_light_sample_pdf_finite_and_consistent(size, height, tilt, seed):
    v = quad(size, height, tilt)
    try:
        light = QuadLight(v, [1.0, 1.0, 1.0])
    except PrefilterError:
        return  # degenerate quads are rejected when built
    rng = np.random.default_rng(seed)
    x = rng.uniform(-1, 1, (64, 3)) * [1, 0, 1]
    wi, pdf = quad_light_sample(light, x, rng.random((64, 2)))
    assert np.all(np.isfinite(wi)) and np.all(np.isfinite(pdf)) and np.all(pdf >= 0)
    ok = pdf > 0
    assert np.allclose(np.linalg.norm(wi[ok], axis=-1), 1.0)
    p2 = quad_light_pdf(light, x, wi)
    assert np.all(np.isfinite(p2)) and np.all(p2 >= 0)
    # the pdf of a sampled direction is the sampler's density (points hit the quad's front)
    good = ok & (pdf < 1e12)
    assert np.allclose(p2[good], pdf[good], rtol=1e-6)


RENDER_SCENE = {
    "camera": {"origin": [0, 1.2, 3], "target": [0, 0.3, 0], "fov": 40, "width": 4, "height": 3},
    "objects": [{"type": "plane", "size": 4.0}],
    "lights": [{"type": "quad", "vertices": [[1, 2, -1], [1, 2, 1], [-1, 2, 1], [-1, 2, -1]],
                "radiance": 1.0}]}


@pytest.mark.parametrize("kwargs, name", [
    ({"spp": 0}, "spp"), ({"spp": 2.0}, "spp"), ({"seed": -1}, "seed"), ({"seed": 1.5}, "seed"),
    ({"jitter": (np.nan, 0.0)}, "jitter"), ({"jitter": 1.0}, "jitter"),
    ({"chunk_samples": 0}, "chunk_samples"), ({"method": None}, "method"),
    ({"method": "LTC"}, "method"),
    # a table of the wrong type reached the shader: AttributeError 'str' has no 'lookup'
    ({"table": "ggx.npz"}, "table"), ({"table": 3}, "table"),
])
def test_render_arguments_are_validated(kwargs, name):
    from prefilter.render import render

    kw = dict(kwargs)
    method = kw.pop("method", "ltc")
    for m in ([method] if "method" in kwargs else ["ltc", "ltc-multiscale"]):
        expect_error(lambda m=m: render(RENDER_SCENE, m, **kw), name)


@pytest.mark.parametrize("scale", [1e-6, 1e-3, 1.0, 1e4])
def test_quad_light_validity_does_not_depend_on_scene_units(scale):
    # was: an absolute area threshold of 1e-12 rejected a valid 1e-6 x 1e-6 quad
    from prefilter.render.lights import QuadLight

    square = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0.0]])
    light = QuadLight(square * scale + [0, 0, 2], 1.0)
    np.testing.assert_allclose(light.normal, [0, 0, 1], atol=1e-12)
    with pytest.raises(PrefilterError, match="area > 0"):
        QuadLight(np.array([[0, 0, 0], [1, 0, 0], [2, 0, 0], [3, 0, 0.0]]) * scale, 1.0)
    with pytest.raises(PrefilterError, match="coplanar"):
        QuadLight((square + np.array([[0, 0, 0]] * 3 + [[0, 0, 1e-3]])) * scale, 1.0)
