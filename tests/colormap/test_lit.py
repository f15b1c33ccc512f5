"""Lit colour maps (``colormap-lit``): the general method against the paper's exact special
cases (Heitz and Neyret's closed form for a step colour map of heights, eq. 9's histogram for a
tabulated texture of few values), the render method against the unlit methods and against the
supersampled reference of the same lit shading, and bad input."""

import numpy as np
import pytest
from scipy.special import ndtr

from prefilter.colormap.height import filter_height, mean_visibility, smith_lambda_direction
from prefilter.colormap.lit import lit_colormap, render_colormap_lit
from prefilter.colormap.render import render_colormap_filtered
from prefilter.colormap.table import prefilter_table
from prefilter.errors import PrefilterError
from prefilter.render import gbuffer, load_scene, render
from prefilter.render.methods import RenderSettings, method_params
from prefilter.report.colormap_lit import (DRIVERS, TARGETS, driver_specs, lit_scene, measure,
                                           valid_mask)
from prefilter.studies.colormap import lab_rmse, scene_dict

LO, HI = np.array([0.1, 0.2, 0.8]), np.array([0.9, 0.6, 0.1])
SURF = {"procedural": "gaussian", "size": 64, "seed": 1, "rms_slope": 0.5, "corr_length": 3.0}


def _step_colors(h0, n=900, lo=-4.5, hi=4.5):
    x = lo + (np.arange(n) + 0.5) * (hi - lo) / n
    return np.where((x < h0)[:, None], LO, HI)


def _step_exact(h0, lam):
    """Heitz and Neyret 2012's closed form: under eq. 16, ``P_h(h) ~ Beta(1 + L, 1)``, so a step
    colour map at ``h0`` has ``<C, D_h> = C_hi + (C_lo - C_hi) P_h(h0)^(1 + L)``."""
    return HI + (LO - HI) * (ndtr(h0) ** (1.0 + lam))[..., None]


def _dirs(theta_deg, phi_deg=0.0):
    t, p = np.radians(theta_deg), np.radians(phi_deg)
    return np.stack([np.sin(t) * np.cos(p), np.sin(t) * np.sin(p), np.cos(t)], -1)


@pytest.mark.parametrize("h0", [-0.8, 0.0, 0.9])
def test_general_height_filter_matches_heitz_neyret_closed_form(h0):
    # eq. 4's special case (a sigmoid / step colour map of the heights of a Gaussian surface)
    # reached by the general method: Gaussian D_h (eqs. 17-18) and the pre-filtered table
    table = prefilter_table(_step_colors(h0), (-4.5, 4.5), 1.5, size=900)
    cov = 0.25 * np.eye(2)
    th_o = np.array([0.0, 40.0, 60.0, 75.0, 85.0])
    th_i = np.array([0.0, 30.0, 70.0, 80.0, 60.0])
    wo, wi = _dirs(th_o), _dirs(th_i, 140.0)
    lo, li = smith_lambda_direction(wo, cov), smith_lambda_direction(wi, cov)
    exact = mean_visibility(lo, li)[:, None] * _step_exact(h0, lo + li)
    got = filter_height(table, wo, wi, cov)
    # L = 0 (head-on): D_h is the height density itself, a Gaussian -> exact but for the table
    np.testing.assert_allclose(got[0], exact[0], atol=2e-3)
    assert np.max(np.abs(got - exact)) < 0.03, np.abs(got - exact).max()
    # the view-independent filter (D_h = p_h) is far off at grazing angles
    flat = mean_visibility(lo, li)[:, None] * _step_exact(h0, 0.0 * lo)
    assert np.max(np.abs(flat - exact)) > 4 * np.max(np.abs(got - exact))


def test_lit_height_render_far_away_is_the_closed_form(tmp_path):
    # a pixel covering the whole 64^2 surface: the lit filtered colour is E cos / pi times
    # eq. 14 with the closed-form inner product
    h0 = 0.3
    spec = {"driver": "height", "texture": SURF, "colors": _step_colors(h0, 128).tolist(),
            "range": [-4.5, 4.5], "sigma_max": 1.5}
    sd = scene_dict("plane", 60.0, 20000.0, 6, 6)
    light = np.array([0.5, 0.6, -0.3])
    sd["lights"] = [{"type": "directional", "direction": (-light).tolist(), "irradiance": 2.0}]
    sd["extras"] = {"colormap": spec}
    scene = load_scene(sd)
    img = render(scene, "colormap-lit")
    g = gbuffer(scene)
    m = valid_mask(scene)
    lit = lit_colormap(spec)
    t, b, n = g.tangent[m], g.bitangent[m], g.normal[m]
    loc = lambda w: np.stack([np.sum(w * t, -1), np.sum(w * b, -1), np.sum(w * n, -1)], -1)  # noqa: E731
    wo = loc(g.view[m])
    wi = loc(np.broadcast_to(light / np.linalg.norm(light), wo.shape))
    cov = lit.surface.slope_cov
    lo, li = smith_lambda_direction(wo, cov), smith_lambda_direction(wi, cov)
    expect = (2.0 * wi[:, 2] / np.pi * mean_visibility(lo, li))[:, None] * _step_exact(h0, lo + li)
    assert m.sum() > 10
    np.testing.assert_allclose(img[m], expect, atol=0.02 * expect.max())


def test_texture_filter_against_exact_histogram_eq9(tmp_path):
    # a tabulated texture of three values: its filtering distribution over a footprint covering
    # the texture is the histogram sum_j beta_j delta(v_j), and eq. 9 gives <C, D_f> exactly.
    # Blocks of 32 x 32 texels, so that the bilinear texture the reference samples blends values
    # only on 1/32 of its area
    rng = np.random.default_rng(4)
    values = np.array([-1.2, 0.3, 1.5])
    tex = np.kron(values[rng.choice(3, size=(4, 4), p=[0.25, 0.45, 0.3])], np.ones((32, 32)))
    beta = np.array([np.mean(tex == v) for v in values])
    np.save(tmp_path / "f.npy", tex)
    x = np.linspace(-4, 4, 256)
    nonlinear = np.stack([0.5 + 0.45 * np.sin(2.5 * x), 0.5 + 0.4 * np.tanh(3 * x),
                          np.exp(-x * x)], -1)
    linear = np.stack([0.5 + 0.1 * x, 0.5 - 0.05 * x, 0.6 + 0.0 * x], -1)
    sd = scene_dict("plane", 0.0, 20000.0, 6, 6)
    sd["lights"] = [{"type": "directional", "direction": [0, -1, 0], "irradiance": np.pi}]
    for colors, tol in ((linear, 2e-3), (nonlinear, None)):
        spec = {"driver": "texture", "texture": "f.npy", "colors": colors.tolist(),
                "range": [-4, 4], "sigma_max": 2.0}
        scene = load_scene({**sd, "extras": {"colormap": spec}}, base_dir=tmp_path)
        m = valid_mask(scene)
        table = lit_colormap(spec, base_dir=tmp_path).c0.table
        eq9 = np.sum(beta[:, None] * table.naive(values), 0)  # sum_j beta_j C(v_j)
        got = {f: render(scene, "colormap-lit", params={"filter": f}, spp=64 if f ==
                         "reference" else 1)[m] for f in ("filtered", "naive", "reference")}
        # the supersampled reference is eq. 9 (bilinear blends between texels aside; the mean
        # over pixels leaves out the sampling noise of 64 samples)
        assert np.max(np.abs(got["reference"].mean(0) - eq9)) < 0.03
        err = {f: np.max(np.abs(got[f] - eq9)) for f in ("filtered", "naive")}
        if tol is not None:  # an affine colour map: the Gaussian with the right mean is exact
            assert err["filtered"] < tol and err["naive"] < tol
        else:
            assert err["filtered"] < 0.5 * err["naive"], err


def test_lit_texture_is_the_unlit_colour_times_lambert():
    spec = driver_specs(64)["texture"]
    sd = scene_dict("plane", 50.0, 400.0, 10, 10)
    light = np.array([0.3, 0.9, 0.2])
    sd["lights"] = [{"type": "directional", "direction": (-light).tolist(), "irradiance": 2.5}]
    sd["extras"] = {"colormap": spec}
    scene = load_scene(sd)
    g = gbuffer(scene)
    cos = np.sum(light / np.linalg.norm(light) * g.normal, -1)
    unlit = render_colormap_filtered(scene, RenderSettings())
    lit = render_colormap_lit(scene, RenderSettings())
    np.testing.assert_allclose(lit, unlit * (2.5 * np.maximum(cos, 0) / np.pi)[..., None],
                               atol=1e-12)


def test_view_and_light_dependence():
    # heights: lighting from near the horizon shows the tops (the colour changes, not only the
    # brightness); texture colours do not depend on the light
    specs = driver_specs(64)
    specs["height"] = {**specs["height"], "colors": _step_colors(0.0, 128).tolist()}
    out = {}
    for name in ("texture", "height"):
        for elev in (80.0, 15.0):
            sd = scene_dict("plane", 0.0, 2000.0, 6, 6)
            e = np.radians(elev)
            sd["lights"] = [{"type": "directional", "irradiance": 1.0,
                             "direction": [-np.cos(e), -np.sin(e), 0.0]}]
            sd["extras"] = {"colormap": specs[name]}
            img = render(load_scene(sd), "colormap-lit")
            out[name, elev] = img[3, 3] / img[3, 3].sum()  # chromaticity
    assert np.allclose(out["texture", 80.0], out["texture", 15.0], atol=1e-6)
    assert np.abs(out["height", 80.0] - out["height", 15.0]).max() > 0.02


@pytest.mark.parametrize("rig", ["sun", pytest.param("quad", marks=pytest.mark.slow),
                                 pytest.param("env", marks=pytest.mark.slow)])
def test_every_driver_converges_to_the_reference_far_away(tmp_path, rig):
    # small images and 16 x 16 reference samples; benchmarks/bench_colormap_lit.py measures
    # the full 32 x 32 table
    rows = measure((("plane", 70.0, 1500.0, "far"),), DRIVERS, (rig,), size=10, n_ref=16,
                   tex_size=128)
    for r in rows:
        assert r["pixels"] > 30
        assert r["ratio"] <= TARGETS[r["driver"]], r


def test_quad_and_environment_lights_converge():
    rows = measure((("plane", 70.0, 1500.0, "far"),), ("height",), ("quad", "env"), size=8,
                   n_ref=12, tex_size=128)
    for r in rows:
        assert r["ratio"] <= TARGETS[r["driver"]], r


def test_near_footprints_filtered_close_to_reference(tmp_path):
    # magnified footprints: filtered, naive and reference agree (no spurious blur)
    scene = lit_scene("plane", 0.0, 40.0, 10, driver_specs(64)["height"], "sun", tmp_path)
    m = valid_mask(scene)
    f = render(scene, "colormap-lit")
    n = render(scene, "colormap-lit", params={"filter": "naive"})
    r = render(scene, "colormap-lit", params={"filter": "reference"}, spp=64)
    assert lab_rmse(f, r, m) <= 1.05 * lab_rmse(n, r, m) + 0.5


def test_registry_and_params():
    assert method_params("colormap-lit") == {"filter": ("filtered", "naive", "reference")}
    with pytest.raises(PrefilterError, match="filter"):
        render(load_scene({**scene_dict("plane", 0.0, 40.0, 4, 4),
                           "extras": {"colormap": driver_specs(64)["texture"]}}),
               "colormap-lit", params={"filter": "box"})


def _bad(spec, match, tmp_path=None, lights=None):
    sd = scene_dict("plane", 0.0, 40.0, 4, 4)
    sd["lights"] = lights or [{"type": "directional", "direction": [0, -1, 0],
                               "irradiance": 1.0}]
    if spec is not None:
        sd["extras"] = {"colormap": spec}
    with pytest.raises(PrefilterError, match=match):
        render(load_scene(sd, base_dir=tmp_path or "."), "colormap-lit")


def test_bad_input(tmp_path):
    specs = driver_specs(64)
    slope, height = specs["slope"], specs["height"]
    _bad(None, r"extras\.colormap")
    _bad({**slope, "colors": [[0.1, 0.2, 0.3]] * 4}, r"extras\.colormap\.colors")
    _bad({**slope, "extent": -1}, r"extras\.colormap\.extent")
    _bad({**slope, "size": 1}, r"extras\.colormap\.size")
    _bad({**slope, "range": [0, 1]}, r"extras\.colormap\.range")
    _bad({"driver": "gradient"}, r"extras\.colormap\.driver")
    _bad({**specs["linear"], "mode": "max"}, r"extras\.colormap\.mode")
    _bad({**specs["linear"], "kappa": [1, 2]}, r"extras\.colormap\.kappa")
    _bad({**specs["linear"], "height": {**height, "driver": "noise"}},
         r"extras\.colormap\.height\.driver")
    _bad({**specs["linear"], "slope": {**slope, "texture": {**SURF, "seed": 9}}},
         r"extras\.colormap\.slope\.texture")
    _bad({"driver": "combine", "mode": "product"}, r"extras\.colormap\.c0")
    _bad({**specs["product"], "weights": 1}, r"extras\.colormap\.weights")
    np.save(tmp_path / "t.npy", np.ones((4, 4, 3)))
    _bad(specs["texture"], r"lights\[0\]", tmp_path,
         [{"type": "quad", "vertices": [[-1, 3, -1], [1, 3, -1], [1, 3, 1], [-1, 3, 1]],
           "radiance": 1.0, "texture": "t.npy"}])
