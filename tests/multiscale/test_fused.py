"""The ``ltc-multiscale`` method's variants in the fused Numba shader.

References: the exact inverse of eq. 4 (bisection, ``alpha_meso_exact``), the NumPy functions
``alpha_meso`` / ``alpha_total`` of every variant, and the NumPy render path
(``multiscale_attributes`` + ``shade_ltc`` through the generic row driver), which stays the
general path of the methods; for the anisotropic taps also closed-form footprint means.
"""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

import prefilter.multiscale  # noqa: F401  (registers the methods)
from prefilter.errors import PrefilterError
from prefilter.ltc.table import GGXTable
from prefilter.multiscale import (alpha_meso, alpha_meso_exact, alpha_total,
                                  mean_resultant_length)
import prefilter.multiscale.render as msr
from prefilter.ltc.shading import shade_ltc
from prefilter.multiscale.kernels import _interp_uniform, multiscale_alpha
from prefilter.multiscale.render import (FOOTPRINTS, LOD_BIAS, LOD_BIAS_START, TAPS, TAPS_BELOW,
                                         TAPS_RATIO, meso_table, multiscale_attributes,
                                         multiscale_roughness)
from prefilter.multiscale.render import render_multiscale, taps_lookup
from prefilter.render import gbuffer, load_scene
from prefilter.render.driver import render, render_samples
from prefilter.render.methods import RenderSettings
from prefilter.texture.mip import MipChain, footprint_axes

#: ``footprint`` variant -> (alpha_meso variant, alpha_total variant)
VARIANTS = {name: v[:2] for name, v in FOOTPRINTS.items()}


def _kernel_alpha_meso(r):
    tab = meso_table()
    return np.array([_interp_uniform(np.sqrt(min(max(3 * (1 - x), 0.0), 1.0)), tab) for x in r])


def test_meso_table_reproduces_alpha_meso_and_the_exact_inverse():
    rng = np.random.default_rng(0)
    # uniform in r and log-spaced towards r = 1 (smooth footprints)
    r = np.concatenate([rng.uniform(2 / 3, 1.0, 3000), 1.0 - np.logspace(-9, -1, 2000)])
    got = _kernel_alpha_meso(r)
    want = alpha_meso(r)
    pos = want > 0
    assert np.max(np.abs(got[pos] - want[pos]) / want[pos]) < 1e-4
    # against the bisection: 1e-4 relative where alpha_meso >= 1.3e-3 (r <= 1 - 1e-5); nearer
    # r = 1 the linear interpolation of alpha ~ x / sqrt(log(1/x)) is absolutely tiny
    exact = alpha_meso_exact(r)
    far = r <= 1 - 1e-5
    assert np.max(np.abs(got[far] - exact[far]) / exact[far]) < 1e-4
    assert np.max(np.abs(got - exact)) < 1e-6
    assert _kernel_alpha_meso([1.0])[0] == 0.0 and abs(_kernel_alpha_meso([0.5])[0] - 1) < 1e-12


@pytest.mark.parametrize("meso,total", list(VARIANTS.values()))
def test_kernel_alpha_total_matches_the_numpy_variant(meso, total):
    rng = np.random.default_rng(1)
    r = np.concatenate([rng.uniform(0.6, 1.0, 400), 1.0 - np.logspace(-8, -1, 100), [1.0]])
    for a_mi in (0.0, 0.01, 0.03, 0.3, 0.9):
        obj = SimpleNamespace(material=SimpleNamespace(alpha_x=a_mi, alpha_y=a_mi))
        rows, tab = multiscale_roughness([obj], meso, total)
        got = np.array([multiscale_alpha(rows[0], x, tab) for x in r])
        want = alpha_total(a_mi, alpha_meso(np.minimum(r, 1.0), meso), total)
        tol = 1e-9
        if total == "mrl":
            # the closed form (lengths multiply) by bisection: the NumPy path's own round trip
            # through the table is 2 % off relative at a_mi = 0, r -> 1 (absolutely 6e-7)
            want = alpha_meso_exact(mean_resultant_length(a_mi) * np.clip(r, 2 / 3, 1))
            tol = 1e-6
        assert np.all(np.abs(got - want) <= 1e-4 * want + tol), (a_mi, meso, total)


def _scene(alpha_plane: float = 0.03) -> dict:
    gauss = {"procedural": "gaussian", "size": 64, "seed": 1, "rms_slope": 0.3, "corr_length": 3}
    return {
        "camera": {"origin": [0, 1.2, 3], "target": [0, 0.3, -1], "fov": 60, "width": 40,
                   "height": 30},
        "objects": [
            {"type": "plane", "center": [0, 0, -2], "size": [8, 8], "uv_scale": [4, 4],
             "tangent": [1, 0, 0.3],
             "material": {"alpha_x": alpha_plane, "alpha_y": 2 * alpha_plane,
                          "base_color": [0.3, 0.2, 0.1], "f0": [0.9, 0.6, 0.5],
                          "normal_map": gauss}},
            {"type": "sphere", "center": [0.8, 0.6, -1.5], "radius": 0.6, "uv_scale": [4, 2],
             "material": {"alpha": 0.3, "base_color": [0.2, 0.3, 0.6], "f0": 0.04,
                          "height_map": dict(gauss, seed=2),
                          "color_map": {"procedural": "noise", "size": 64, "seed": 3,
                                        "corr_length": 4, "sigma": 0.3}}},
            # seen from behind its normal (frame flip), a normal map too
            {"type": "plane", "center": [-1.2, 0.8, -1.5], "normal": [0.3, -0.3, -1],
             "size": [1, 1], "material": {"alpha": 0.1, "base_color": 0.5, "f0": 0.5,
                                          "normal_map": dict(gauss, seed=4)}}],
        "lights": [{"type": "quad", "radiance": [4, 3, 2],
                    "vertices": [[-1.5, 0.3, -3], [1.5, 0.3, -3], [1.5, 2.0, -3],
                                 [-1.5, 2.0, -3]]},
                   {"type": "quad", "radiance": 1.0,
                    "vertices": [[2, 3, -2], [2, 3, 0], [-2, 3, 0], [-2, 3, -2]]}]}


def _table():
    try:
        return GGXTable.load()
    except Exception:  # noqa: BLE001  (no shipped table: a toy one exercises the same code)
        t = np.linspace(0.0, 0.99, 8)
        r = np.linspace(0.1, 1.0, 8)
        M = np.zeros((8, 8, 3, 3))
        M[..., 0, 0] = M[..., 1, 1] = (r**2)[None, :]
        M[..., 2, 2] = 1.0
        M[..., 0, 2] = 0.2 * t[:, None]
        return GGXTable(t, r, M, np.ones((8, 8)), 0.1 * np.ones((8, 8)))


def _numpy_path(sc, settings, meso, total, lod_bias=0.0, lod_bias_start=None, taps=0):
    lights = sc.light_set()

    def shade(g, _u):
        a = multiscale_attributes(sc, g, meso=meso, total=total, lod_bias=lod_bias,
                                  lod_bias_start=lod_bias_start, taps=taps)
        return shade_ltc(g.position, a["t"], a["b"], a["n"], g.view, a["alpha"],
                         a["base_color"], a["f0"], lights, settings.table)

    return render_samples(sc, settings, shade, stratified=settings.spp > 1)


def _no_numpy_driver(*_a, **_k):
    raise AssertionError("the generic row driver ran: the fused path was not taken")


@pytest.mark.parametrize("name", list(VARIANTS))
def test_fused_images_match_the_numpy_path(name, monkeypatch):
    meso, total = VARIANTS[name]
    # the default variant reads the normal map with its ramped LOD bias and its anisotropic
    # taps (TAPS_BELOW and TAPS_RATIO are multiscale_attributes' defaults too)
    bias = (LOD_BIAS, LOD_BIAS_START, TAPS) if name == "fit" else (0.0, None, 0)
    table = _table()
    sc = load_scene(_scene())
    for spp, jitter in ((1, (0.0, 0.0)), (2, (0.3, -0.2))):
        with monkeypatch.context() as m:
            m.setattr(msr, "render_samples", _no_numpy_driver)
            got = render(sc, "ltc-multiscale", spp=spp, jitter=jitter, seed=2, table=table,
                         chunk_samples=700, params={"footprint": name})
        want = _numpy_path(sc, RenderSettings(spp=spp, seed=2, jitter=jitter, table=table),
                           meso, total, *bias)
        assert np.count_nonzero(want.sum(-1)) > 0.5 * want.shape[0] * want.shape[1]
        rel = np.abs(got - want) / np.maximum(np.abs(want), 1e-3 * want.max())
        assert rel.max() < 1e-4, (name, spp, rel.max())
    # the roughness really changes the image (not the ltc method's)
    naive = render(sc, "ltc", spp=2, jitter=(0.3, -0.2), seed=2, table=table)
    assert np.abs(naive - got).max() > 1e-2 * got.max()


@pytest.mark.parametrize("start", [None, 2.0])
def test_fused_lod_bias_matches_the_numpy_path(start):
    from prefilter.multiscale.render import render_multiscale

    table = _table()
    sc = load_scene(_scene())
    st = RenderSettings(table=table)
    got = render_multiscale(sc, st, lod_bias=1.0, lod_bias_start=start, taps=0)
    assert np.abs(render_multiscale(sc, st, lod_bias=0.0, lod_bias_start=None, taps=0)
                  - got).max() > 1e-3 * got.max()
    lights = sc.light_set()

    def shade(g, _u):
        a = multiscale_attributes(sc, g, lod_bias=1.0, lod_bias_start=start)
        return shade_ltc(g.position, a["t"], a["b"], a["n"], g.view, a["alpha"],
                         a["base_color"], a["f0"], lights, table)

    want = render_samples(sc, st, shade, stratified=False)
    rel = np.abs(got - want) / np.maximum(np.abs(want), 1e-3 * want.max())
    assert rel.max() < 1e-4


def test_ramped_lod_bias_leaves_small_footprints_alone():
    from prefilter.multiscale.render import render_multiscale
    from prefilter.texture.mip import footprint_axes

    table = _table()
    sc = load_scene(_scene())
    st = RenderSettings(table=table)
    plain = render_multiscale(sc, st, lod_bias=0.0, lod_bias_start=None, taps=0)
    ramped = render_multiscale(sc, st, lod_bias=1.0, lod_bias_start=2.0, taps=0)
    const = render_multiscale(sc, st, lod_bias=1.0, lod_bias_start=None, taps=0)
    # the big plane's footprints (object 0) in texels of its 64^2 normal map
    from prefilter.render import gbuffer

    gb = gbuffer(sc)
    major = footprint_axes(gb.dudv, (64, 64))[0]
    on_plane = gb.hit & (gb.object_id == 0)
    small = on_plane & (major < 3.9)
    large = on_plane & (major > 8.1)
    assert small.sum() > 20 and large.sum() > 20
    np.testing.assert_array_equal(ramped[small], plain[small])
    np.testing.assert_allclose(ramped[large], const[large], rtol=1e-6, atol=1e-7)


# -- anisotropic taps (``taps=``): compiled in the fused shader, ``taps_lookup`` its NumPy twin --
# References: closed-form footprint means of a striped normal map (a footprint one texel wide
# along the stripes sees one stripe: length 1; the isotropic level of its major axis averages
# four stripes: ``cos theta``), the NumPy twin, and the untapped kernel on the footprints the
# option must leave alone (bit for bit).

def _stripes(theta: float, size: int = 16, along_u: bool = True) -> np.ndarray:
    # rows (constant v) alternate between two unit normals tilted by +-theta
    s, c = np.sin(theta), np.cos(theta)
    sign = np.where(np.arange(size) % 2 == 0, 1.0, -1.0)
    n = np.zeros((size, size, 3))
    n[..., 0] = s * sign[:, None]
    n[..., 2] = c
    return n if along_u else n.transpose(1, 0, 2)


@pytest.mark.parametrize("along_u", [True, False])
def test_taps_along_the_stripes_see_one_stripe(along_u):
    theta, size = 0.6, 16
    chain = MipChain(_stripes(theta, size, along_u))
    # texel centres, footprint 3.5 texels along the stripes and 1 across them
    i = np.arange(8)
    uv = np.stack([(i + 0.5) / size, (2 * i + 0.5) / size], -1)
    d = np.zeros((8, 2, 2))
    major, minor = 3.5 / size, 1.0 / size
    if along_u:
        d[:, 0, 0], d[:, 1, 1] = major, minor
    else:
        uv = uv[:, ::-1]
        d[:, 1, 0], d[:, 0, 1] = major, minor
    got = taps_lookup(chain, uv, d, taps=4)
    # the footprint covers one stripe: its mean normal is that stripe's unit normal
    want = _stripes(theta, size, along_u)[(uv[:, 1] * size).astype(int),
                                          (uv[:, 0] * size).astype(int)]
    np.testing.assert_allclose(got, want, atol=1e-12)
    # without taps: the major axis' level (log2 3.5) mixes the stripes, r -> cos theta
    iso = taps_lookup(chain, uv, d, taps=0)
    r = np.linalg.norm(iso, axis=-1)
    assert np.all(r < 1.0 - 0.5 * (1.0 - np.cos(theta)))
    # footprints at or above `below` texels are read as without taps
    big = d * (4.0 / 3.5)
    np.testing.assert_array_equal(taps_lookup(chain, uv, big, taps=4),
                                  taps_lookup(chain, uv, big, taps=0))


def test_normalised_taps_between_two_stripes_are_unit():
    theta, size = 0.6, 16
    chain = MipChain(_stripes(theta, size))
    # on the boundary between two stripes: bilinear blends of +-theta average to cos theta,
    # the surface there is the blend's direction, a unit normal (0, 0, 1)
    uv = np.stack([(np.arange(6) + 0.5) / size, (np.arange(6) * 2 + 1.0) / size], -1)
    d = np.zeros((6, 2, 2))
    d[:, 0, 0], d[:, 1, 1] = 3.0 / size, 0.5 / size
    got = taps_lookup(chain, uv, d, taps=4, normalize=True)
    np.testing.assert_allclose(got, np.tile([0.0, 0.0, 1.0], (6, 1)), atol=1e-12)
    plain = taps_lookup(chain, uv, d, taps=4)
    np.testing.assert_allclose(plain, np.tile([0.0, 0.0, np.cos(theta)], (6, 1)), atol=1e-12)


def _numpy_path_kw(sc, settings, **kw):
    lights = sc.light_set()

    def shade(g, _u):
        a = multiscale_attributes(sc, g, **kw)
        return shade_ltc(g.position, a["t"], a["b"], a["n"], g.view, a["alpha"],
                         a["base_color"], a["f0"], lights, settings.table)

    return render_samples(sc, settings, shade, stratified=settings.spp > 1)


@pytest.mark.parametrize("bias,normalize", [((2.0, 2.0), False), ((0.0, None), False),
                                            ((1.0, None), False), ((2.0, 2.0), True)])
def test_fused_taps_match_the_numpy_twin(bias, normalize, monkeypatch):
    table = _table()
    sc = load_scene(_scene())
    st = RenderSettings(table=table, spp=2, jitter=(0.3, -0.2), seed=2)
    kw = {"lod_bias": bias[0], "lod_bias_start": bias[1], "taps": 4, "taps_below": 6.0,
          "taps_normalize": normalize}
    with monkeypatch.context() as m:
        m.setattr(msr, "render_samples", lambda *_a, **_k: (_ for _ in ()).throw(
            AssertionError("the generic row driver ran: the fused path was not taken")))
        got = render_multiscale(sc, st, **kw)
    want = _numpy_path_kw(sc, st, **kw)
    rel = np.abs(got - want) / np.maximum(np.abs(want), 1e-3 * want.max())
    assert rel.max() < 1e-4, rel.max()
    # the taps change the image where they apply
    plain = render_multiscale(sc, st, lod_bias=bias[0], lod_bias_start=bias[1], taps=0)
    assert np.abs(plain - got).max() > 1e-2 * got.max()


def test_taps_leave_large_and_round_footprints_bit_identical():
    table = _table()
    sc = load_scene(_scene())
    st = RenderSettings(table=table)
    plain = render_multiscale(sc, st, taps=0)
    tapped = render_multiscale(sc, st, taps=4, taps_below=4.0, taps_ratio=1.5)
    gb = gbuffer(sc)
    # the normal-mapped planes' footprints (both maps 64^2); the sphere has a height map
    major, minor, _ = footprint_axes(gb.dudv, (64, 64))
    mapped = gb.hit & (gb.object_id != 1)
    untouched = gb.hit & ~(mapped & (major < 4.0) & (major > 1.5 * minor))
    touched = gb.hit & ~untouched
    assert untouched.sum() > 50 and touched.sum() > 50
    np.testing.assert_array_equal(tapped[untouched], plain[untouched])
    assert np.abs(tapped[touched] - plain[touched]).max() > 0.0
    # taps_below = 0 or one tap at most: the untapped image, bit for bit
    np.testing.assert_array_equal(render_multiscale(sc, st, taps=4, taps_below=0.0), plain)
    np.testing.assert_array_equal(render_multiscale(sc, st, taps=1), plain)


@pytest.mark.parametrize("kw", [{"taps": -1}, {"taps": 2.5}, {"taps": 4, "taps_ratio": 0.5},
                                {"taps": 4, "taps_below": float("nan")},
                                {"taps": 4, "taps_below": "x"}])
def test_bad_tap_options_are_rejected(kw):
    sc = load_scene(_scene())
    with pytest.raises(PrefilterError):
        render_multiscale(sc, RenderSettings(table=_table()), **kw)


def test_registered_taps_defaults_are_the_attribute_defaults():
    import inspect

    sig = inspect.signature(multiscale_attributes).parameters
    assert (sig["taps_below"].default, sig["taps_ratio"].default) == (TAPS_BELOW, TAPS_RATIO)
    assert TAPS >= 2
