"""The exported colour-map snippet (``prefilter.colormap.glsl.glsl_snippet``) alone in WebGL2 on
its baked table (RGBA32F, ``GL_LINEAR``, the snippet's wrap modes) against
:meth:`prefilter.colormap.table.ColormapTable.lookup`, for every edge rule.

The page's ``colormap-*`` modes (texture driver) are pixel-matched against
``prefilter.colormap.render`` in ``test_pixel_match.py``; this checks the snippet's other entry
points (``colormapTexture``, ``colormapHeight``) and every edge rule, which the modes do not
all reach."""

import numpy as np
import pytest

from prefilter.colormap.glsl import GLSL_WRAP, glsl_snippet
from prefilter.colormap.height import OWN_PARAMS, height_moments_approx, mean_visibility
from prefilter.colormap.table import prefilter_table

_MAIN = """
uniform highp sampler2D uIn;  // (mode, a, b, c): 0 filtered(mean a, sigma b); 1 texture at uv
                              // (a, b); 2 height(sigmaH a, lambdaO b, lambdaI c)
uniform highp sampler2D uMoments;
out vec4 o;
void main() {
    vec4 c = texelFetch(uIn, ivec2(8 * int(gl_FragCoord.x), 0), 0);
    vec3 r = c.x < 0.5 ? colormapFiltered(c.y, c.z)
           : c.x < 1.5 ? colormapTexture(uMoments, c.yz) : colormapHeight(c.y, c.z, c.w);
    o = vec4(r, 1.0);
}
"""


@pytest.mark.parametrize("edge", ["clamp", "mirror", "periodic"])
def test_colormap_snippet_in_webgl_matches_table_lookup(run_glsl, edge):
    rng = np.random.default_rng(7)
    # a smooth random colour map over [-1, 2]
    knots = rng.uniform(0, 1, (9, 3))
    x = np.linspace(0, 8, 64)
    cmap = np.stack([np.interp(x, np.arange(9), knots[:, c]) for c in range(3)], -1)
    table = prefilter_table(cmap, (-1.0, 2.0), sigma_max=0.5, size=64, edge=edge, n_sigma=16)
    meta = table.metadata()
    n = 300
    mean = rng.uniform(-4.0, 5.0, n)  # beyond the range on both sides: the edge rule
    sigma = rng.uniform(0.0, 0.6, n)  # beyond sigma_max: clamped to the last row
    # a (E[f], E[f^2]) texture read at texel centres (NEAREST): exact moments
    mt = np.zeros((8, 8, 4), np.float32)
    mt[..., 0] = rng.uniform(-1.0, 2.0, (8, 8))
    mt[..., 1] = mt[..., 0] ** 2 + rng.uniform(0.0, 0.2, (8, 8))
    ij = rng.integers(0, 8, (n, 2))
    sh, lo, li = rng.uniform(0.1, 1.0, n), rng.uniform(0, 3, n), rng.uniform(0, 3, n)
    data = np.zeros((3 * n, 8, 4), np.float32)
    data[:n, 0] = np.stack([np.zeros(n), mean, sigma, np.zeros(n)], -1)
    data[n:2 * n, 0] = np.stack([np.ones(n), (ij[:, 1] + 0.5) / 8, (ij[:, 0] + 0.5) / 8,
                                 np.zeros(n)], -1)
    data[2 * n:, 0] = np.stack([np.full(n, 2.0), sh, lo, li], -1)
    img = np.concatenate([table.table, np.ones(table.table.shape[:2] + (1,))], -1)
    wrap = GLSL_WRAP[edge].removeprefix("GL_")
    texs = [{"name": "uColormapTable", "w": table.n_mean, "h": table.n_sigma, "data": img,
             "filter": "LINEAR", "wrap_s": wrap, "wrap_t": "CLAMP_TO_EDGE"},
            {"name": "uMoments", "w": 8, "h": 8, "data": mt, "filter": "NEAREST",
             "wrap_s": "CLAMP_TO_EDGE", "wrap_t": "CLAMP_TO_EDGE"}]
    out = run_glsl(glsl_snippet(meta) + _MAIN, data, texs)[:, :3]
    d = data[:, 0].astype(np.float64)
    ref_f = table.lookup(d[:n, 1], d[:n, 2])
    m = mt[ij[:, 0], ij[:, 1]].astype(np.float64)
    ref_t = table.lookup(m[:, 0], np.sqrt(np.maximum(m[:, 1] - m[:, 0] ** 2, 0.0)))
    s, a, b = d[2 * n:, 1], d[2 * n:, 2], d[2 * n:, 3]
    mu, sd = height_moments_approx(a + b, s, OWN_PARAMS)
    ref_h = mean_visibility(a, b)[:, None] * table.lookup(mu, sd)
    errs = [np.abs(out[:n] - ref_f).max(), np.abs(out[n:2 * n] - ref_t).max(),
            np.abs(out[2 * n:] - ref_h).max()]
    print(f"{edge}: max abs error filtered {errs[0]:.2e} texture {errs[1]:.2e} "
          f"height {errs[2]:.2e}")
    # SwiftShader filters RGBA32F in float32 (measured ~5e-7); GPUs with 8-bit filter weights
    # would need ~2e-3
    assert max(errs) < 1e-4, errs
