"""The exported LEADR snippet (``prefilter.leadr.glsl``) alone in WebGL2 against the Python it
mirrors: ``leadrStats`` + ``leadrSpecular`` + ``leadrDiffuse`` + ``leadrDelta`` against
:func:`prefilter.leadr.maps.shading_stats`, :func:`prefilter.leadr.shading.point_light`
(closed form, exact Smith Lambda), ``schlick`` and ``diffuse_directional`` (5 x 5 grid; in
``leadrDelta`` with ``shadowing=True``, Smith ``G2 / G1``) on random moments, roughnesses and
directions (lights below the surface included); the page's ``leadr-point`` against
``prefilter.render``."""

import numpy as np
from scipy import special

from prefilter.leadr import glsl as leadr_glsl
from prefilter.leadr.maps import shading_stats
from prefilter.leadr.shading import diffuse_directional, point_light, schlick

_MAIN = """
uniform highp sampler2D uIn;  // wo, wi, moments, (E[sx sy], alpha_x, alpha_y), base, f0
out vec4 o;
vec4 at(int k, int i) { return texelFetch(uIn, ivec2(8 * k + i, 0), 0); }
void main() {
    int k = int(gl_FragCoord.x);
    vec3 wo = at(k, 0).xyz, wi = at(k, 1).xyz;
    vec4 e = at(k, 3);
    vec2 mu; vec3 cov;
    leadrStats(at(k, 2), e.x, e.yz, mu, cov);
    vec3 L = leadrDelta(wo, wi, mu, cov, at(k, 4).rgb, at(k, 5).rgb);
    o = vec4(leadrSpecular(wo, wi, mu, cov), leadrDiffuse(wo, wi, mu, cov), L.r, L.b);
}
"""


def _dirs(rng, n, zmin):
    z = rng.uniform(zmin, 1.0, n)
    phi = rng.uniform(-np.pi, np.pi, n)
    s = np.sqrt(1.0 - z * z)
    return np.stack([s * np.cos(phi), s * np.sin(phi), z], -1)


def test_erfcx_fit_against_scipy():
    x = np.linspace(0.0, 30.0, 300_001)
    t = 1.0 / (1.0 + 0.5 * x)
    c = leadr_glsl.ERFC_COEFFS
    fit = t * np.exp(sum(ck * t**k for k, ck in enumerate(c)))
    assert np.max(np.abs(fit / special.erfcx(x) - 1.0)) < 1.2e-7


def test_leadr_snippet_in_webgl_matches_python(run_glsl):
    rng = np.random.default_rng(11)
    n = 512
    wo = _dirs(rng, n, 0.05)
    wi = _dirs(rng, n, -0.3)  # some lights below the geometric surface
    mean = rng.uniform(-0.5, 0.5, (n, 2))
    # footprint covariances from none to wide, correlations up to +-0.95
    sx, sy = rng.uniform(0.0, 0.4, n), rng.uniform(0.0, 0.4, n)
    r = rng.uniform(-0.95, 0.95, n)
    mom = np.stack([mean[:, 0], mean[:, 1], sx**2 + mean[:, 0] ** 2, sy**2 + mean[:, 1] ** 2,
                    r * sx * sy + mean[:, 0] * mean[:, 1]], -1).astype(np.float32)
    alpha = rng.uniform(0.03, 0.8, (n, 2)).astype(np.float32)
    base, f0 = rng.uniform(0, 1, (n, 3)), rng.uniform(0, 1, (n, 3))
    data = np.zeros((n, 8, 4), np.float32)
    data[:, 0, :3], data[:, 1, :3], data[:, 2] = wo, wi, mom[:, :4]
    data[:, 3, 0], data[:, 3, 1:3] = mom[:, 4], alpha
    data[:, 4, :3], data[:, 5, :3] = base, f0
    out = run_glsl(leadr_glsl.glsl_source() + _MAIN, data)
    # the reference from the float32 inputs the GPU sees
    d = data.astype(np.float64)
    wo, wi, base, f0 = d[:, 0, :3], d[:, 1, :3], d[:, 4, :3], d[:, 5, :3]
    mu, cov = shading_stats(np.concatenate([d[:, 2], d[:, 3, :1]], -1), 0.0)
    cov[:, 0, 0] += 0.5 * d[:, 3, 1] ** 2
    cov[:, 1, 1] += 0.5 * d[:, 3, 2] ** 2
    spec = point_light(wo, wi, mu, cov)
    diff = diffuse_directional(wo, wi, mu, cov, 5)
    # leadrDelta's diffuse is Algorithm 3 for one light: with G2 / G1 (leadr-point's shading)
    diff_sh = diffuse_directional(wo, wi, mu, cov, 5, shadowing=True)
    # the shadowing must matter on these inputs, or the check below could not see it missing
    assert np.mean(np.abs(diff_sh - diff)) > 0.01 * np.mean(diff)
    h = wo + wi
    h /= np.linalg.norm(h, axis=-1, keepdims=True)
    L = spec[:, None] * schlick(f0, np.sum(h * wi, -1)[:, None]) + base * diff_sh[:, None]
    lit = spec > 1e-3
    assert lit.sum() > n // 4 and (wi[:, 2] < 0).sum() > n // 10
    print(f"max rel error spec {np.max(np.abs(out[lit, 0] / spec[lit] - 1)):.2e}, "
          f"diffuse {np.max(np.abs(out[:, 1] - diff)):.2e}, "
          f"delta {np.max(np.abs(out[:, 2:] - L[:, [0, 2]]) / (1 + L[:, [0, 2]])):.2e}")
    np.testing.assert_allclose(out[:, 0], spec, rtol=2e-4, atol=1e-6)
    np.testing.assert_allclose(out[:, 1], diff, rtol=1e-4, atol=1e-6)
    np.testing.assert_allclose(out[:, 2:], L[:, [0, 2]], rtol=2e-4, atol=1e-6)


def test_page_renders_leadr_point_with_box_filter_and_shadowing(browser):
    """The page's ``leadr-point`` (``footprintBox`` + ``leadrDelta``) against
    ``prefilter.render`` on the ``leadr`` scene and on ``leadr-grazing`` (low lights, mostly
    diffuse): relative RMSE <= 1 % for float32 and float16 moment maps, while the old one-tap
    shading and the unshadowed diffuse each differ from the Python image by > 5x that (so a page
    missing either would fail)."""
    from prefilter.leadr import render as lr
    from prefilter.render.driver import render
    from prefilter.viewer import pixel_match
    from prefilter.viewer.match import scene

    rows = pixel_match(scenes=("leadr", "leadr-grazing"), methods=("leadr-point",),
                       driver=browser, width=96, height=72)
    assert len(rows) == 4
    for r in rows:
        assert r["covered"] > 0.3 * 96 * 72
        assert r["rel_rmse"] <= 0.01, r
    sc = scene("leadr-grazing", 96, 72)
    ref = render(sc, "leadr-point")
    rel = lambda a: np.sqrt(np.mean((a - ref) ** 2)) / np.sqrt(np.mean(ref**2))  # noqa: E731
    saved = lr.POINT_FOOTPRINT_TAPS, lr.POINT_SHADOWING
    try:
        lr.POINT_FOOTPRINT_TAPS = 1
        one_tap = render(sc, "leadr-point")
        lr.POINT_FOOTPRINT_TAPS, lr.POINT_SHADOWING = saved[0], False
        unshadowed = render(sc, "leadr-point")
    finally:
        lr.POINT_FOOTPRINT_TAPS, lr.POINT_SHADOWING = saved
    assert rel(one_tap) > 0.05 and rel(unshadowed) > 0.05
