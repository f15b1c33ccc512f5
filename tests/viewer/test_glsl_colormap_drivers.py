"""The colour-map drivers' GLSL (``prefilter.colormap.glsl_drivers``: ``shaders/noise.glsl``,
``height.glsl``, ``slope.glsl``) alone in WebGL2 against their Python twins: the noise std per
area LOD (``NoiseStd`` interpolated in variance, as ``kernels._noise_kernel``), Smith ``Lambda``
and the footprint's height filtering (``height.filter_height_footprint``) from the deep shadow
to full light, and the slope filtering (``slope.filter_slope``, ``SlopeColormapTable.naive``)
for views down to grazing and anisotropic covariances."""

import numpy as np

from prefilter.colormap.glsl import glsl_snippet
from prefilter.colormap.glsl_drivers import driver_glsl, slope_texture
from prefilter.colormap.height import filter_height_footprint, smith_lambda_direction
from prefilter.colormap.slope import filter_slope, slope_prefilter_table
from prefilter.colormap.table import prefilter_table
from prefilter.colormap.texture import NoiseStd

_MAIN = """
uniform highp sampler2D uIn;
out vec4 o;
void main() {
    int k = 8 * int(gl_FragCoord.x);
    vec4 a = texelFetch(uIn, ivec2(k, 0), 0), b = texelFetch(uIn, ivec2(k + 1, 0), 0);
    vec4 c = texelFetch(uIn, ivec2(k + 2, 0), 0);
    vec3 r;
    if (a.x < 0.5) r = vec3(colormapNoiseSigma(a.y), 0.0, 0.0);
    else if (a.x < 1.5) r = vec3(colormapLambda(b.xyz), 0.0, 0.0);
    else if (a.x < 2.5) r = colormapHeightFootprint(a.y, a.z, b.x, b.y);
    else if (a.x < 3.5) r = colormapSlope(b.xyz, c.xy, vec3(c.z, c.w, a.y));
    else r = colormapSlopeNaive(c.xy);
    o = vec4(r, 1.0);
}
"""


def test_driver_glsl_in_webgl_matches_python(run_glsl):
    rng = np.random.default_rng(3)
    knots = rng.uniform(0, 1, (9, 3))
    cmap = np.stack([np.interp(np.linspace(0, 8, 64), np.arange(9), knots[:, c])
                     for c in range(3)], -1)
    table = prefilter_table(cmap, (-3.0, 3.0), sigma_max=1.5, size=64)
    slope_map = rng.uniform(0, 1, (16, 16, 3))
    stable = slope_prefilter_table(slope_map, extent=1.0, sigma_max=0.5, n_levels=8)
    noise = NoiseStd.from_procedural(64, 3.0, 1.0)
    cov = np.array([[0.09, 0.02], [0.02, 0.04]])

    class Driver:  # what driver_glsl reads of a ColormapDriver
        noise_std = noise
        slope_cov = cov

    n = 200
    data = np.zeros((5 * n, 8, 4))
    lod = rng.uniform(-1.0, 9.0, n)
    data[:n, 0, :2] = np.stack([np.zeros(n), lod], -1)
    th, ph = np.arccos(rng.uniform(0.02, 1.0, n)), rng.uniform(0, 2 * np.pi, n)
    w = np.stack([np.sin(th) * np.cos(ph), np.sin(th) * np.sin(ph), np.cos(th)], -1)
    data[n:2 * n, 0, 0] = 1.0
    data[n:2 * n, 1, :3] = w
    mean, var = rng.uniform(-2.5, 2.5, n), rng.uniform(0.0, 1.2, n)
    lo, li = np.exp(rng.uniform(-10, 3, n)), np.exp(rng.uniform(-10, 4, n))
    data[2 * n:3 * n, 0, :3] = np.stack([np.full(n, 2.0), mean, var], -1)
    data[2 * n:3 * n, 1, :2] = np.stack([lo, li], -1)
    mu = rng.uniform(-0.6, 0.6, (n, 2))
    sxx, syy = rng.uniform(0.001, 0.15, n), rng.uniform(0.001, 0.15, n)
    sxy = rng.uniform(-0.9, 0.9, n) * np.sqrt(sxx * syy)
    for k, rows in ((3.0, slice(3 * n, 4 * n)), (4.0, slice(4 * n, 5 * n))):
        data[rows, 0, :2] = np.stack([np.full(n, k), sxy], -1)
        data[rows, 1, :3] = w
        data[rows, 2] = np.stack([mu[:, 0], mu[:, 1], sxx, syy], -1)
    img = np.concatenate([table.table, np.ones(table.table.shape[:2] + (1,))], -1)
    stack = slope_texture(stable)
    texs = [{"name": "uColormapTable", "w": table.n_mean, "h": table.n_sigma, "data": img,
             "filter": "LINEAR", "wrap_s": "CLAMP_TO_EDGE", "wrap_t": "CLAMP_TO_EDGE"},
            {"name": "uCmSlopeStack", "w": stack.shape[1], "h": stack.shape[0], "data": stack,
             "filter": "NEAREST", "wrap_s": "CLAMP_TO_EDGE", "wrap_t": "CLAMP_TO_EDGE"}]
    src = glsl_snippet(table.metadata()) + driver_glsl(Driver, stable) + _MAIN
    out = run_glsl(src, data, texs)[:, :3]
    d = data.astype(np.float32).astype(np.float64)  # the inputs the GPU saw
    ref_noise = np.sqrt(np.interp(np.clip(d[:n, 0, 1], 0, noise.variance.size - 1),
                                  np.arange(noise.variance.size), noise.variance))
    ref_lam = smith_lambda_direction(d[n:2 * n, 1, :3], cov)
    h = d[2 * n:3 * n]
    ref_h = filter_height_footprint(table, h[:, 0, 1], np.sqrt(h[:, 0, 2]), h[:, 1, 0], h[:, 1, 1])
    s = d[3 * n:4 * n]
    c = np.stack([np.stack([s[:, 2, 2], s[:, 0, 1]], -1), np.stack([s[:, 0, 1], s[:, 2, 3]], -1)],
                 -2)
    ref_s = filter_slope(stable, s[:, 1, :3], s[:, 2, :2], c)
    ref_naive = stable.naive(d[4 * n:, 2, :2])
    errs = {"noise": np.abs(out[:n, 0] - ref_noise).max() / ref_noise.max(),
            "lambda": np.max(np.abs(out[n:2 * n, 0] - ref_lam) / np.maximum(ref_lam, 1e-3)),
            "height": np.abs(out[2 * n:3 * n] - ref_h).max(),
            "slope": np.abs(out[3 * n:4 * n] - ref_s).max(),
            "slope-naive": np.abs(out[4 * n:] - ref_naive).max()}
    print({k: f"{v:.2e}" for k, v in errs.items()})
    assert max(errs.values()) < 1e-4, errs
