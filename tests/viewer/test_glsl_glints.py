"""The glints GLSL (``prefilter.glints.gpu.glsl_source``) alone in WebGL2 against the Python it
mirrors, on a baked 64^2 flakes map uploaded by the page's own ``glints.js`` (float32 codes):
``glPointQuery`` against ``query.point_flat(interp="resample", bilinear=True)`` (resampled,
trilinear-clamped above the top level and at level 0 below it), ``glintNdf`` against
``brdf.glint_ndf`` (direct P-NDF below the finest level, ``fallback_truncation`` 4),
``glRangeQuery`` against ``query.range_multi`` on the resampling weights, and
``glintBrdfCos`` against ``brdf.glint_brdf_cos``."""

import shutil
from pathlib import Path

import numpy as np
import pytest

from prefilter.glints.brdf import glint_brdf_cos, glint_ndf
from prefilter.glints.gpu import GLSL_FILES, export_surface, glsl_source, write_gpu
from prefilter.glints.query import packed, point_flat, range_multi, weights

STATIC = Path(__file__).resolve().parents[2] / "src" / "prefilter" / "viewer" / "static"

_MAIN = """
uniform highp sampler2D uIn;
out vec4 o;
vec4 at(int k, int i) { return texelFetch(uIn, ivec2(8 * k + i, 0), 0); }
void main() {
    int k = int(gl_FragCoord.x);
    vec4 a = at(k, 0), b = at(k, 1), r = at(k, 2);
    vec2 c = a.xy;
    float sp = a.z;
    vec3 wo = at(k, 3).xyz, wi = at(k, 4).xyz, f0 = at(k, 5).xyz;
    o = vec4(glPointQuery(c, sp, b.xy), glintNdf(c, sp, b.xy),
             sp >= glSigmaMin ? glRangeQuery(c, sp, r.xy, r.zw) : 0.0,
             glintBrdfCos(c, sp, wo, wi, f0).g);
}
"""

# load glints.js, upload the exported map, draw `src` over n cases, read the float target back
# (after conftest.PROGRAM_JS, the ``program_js`` fixture)
_RUN = """
const [src, data, n, entry, done] = [arguments[0], arguments[1], arguments[2], arguments[3],
                                     arguments[arguments.length - 1]];
(async () => {
  const G = await import(new URL('glints.js', location.href).href);
  const c = document.createElement('canvas');
  const gl = c.getContext('webgl2');
  gl.getExtension('EXT_color_buffer_float');
  const head = '#version 300 es\\nprecision highp float;\\nprecision highp int;\\n' +
    'precision highp sampler2D;\\nprecision highp isampler2D;\\n' + G.GLINTS_HEAD;
  const p = fullScreenProgram(gl, head, src);
  const map = await G.fetchGlints(gl, new URL('./', location.href).href, entry);
  const u = (name, fn, ...args) => { const l = gl.getUniformLocation(p, name);
    if (l !== null) gl[fn](l, ...args); };
  const unit = G.bindGlints(gl, map, u, 1);
  const tex = (w, h, arr) => { const t = gl.createTexture();
    gl.bindTexture(gl.TEXTURE_2D, t);
    gl.texImage2D(gl.TEXTURE_2D, 0, gl.RGBA32F, w, h, 0, gl.RGBA, gl.FLOAT, arr);
    for (const k of [gl.TEXTURE_MIN_FILTER, gl.TEXTURE_MAG_FILTER])
      gl.texParameteri(gl.TEXTURE_2D, k, gl.NEAREST); return t; };
  gl.activeTexture(gl.TEXTURE0);
  tex(8 * n, 1, new Float32Array(data));
  u('uIn', 'uniform1i', 0);
  gl.activeTexture(gl.TEXTURE0 + unit);
  const out = tex(n, 1, null);
  const fb = gl.createFramebuffer();
  gl.bindFramebuffer(gl.FRAMEBUFFER, fb);
  gl.framebufferTexture2D(gl.FRAMEBUFFER, gl.COLOR_ATTACHMENT0, gl.TEXTURE_2D, out, 0);
  gl.viewport(0, 0, n, 1);
  gl.drawArrays(gl.TRIANGLES, 0, 3);
  const px = new Float32Array(4 * n);
  gl.readPixels(0, 0, n, 1, gl.RGBA, gl.FLOAT, px);
  return Array.from(px);
})().then(done, e => done('error: ' + (e && e.message || e)));
"""


@pytest.fixture(scope="module")
def surf():
    from prefilter.viewer.glint_maps import glint_surface

    return glint_surface("flakes")


@pytest.fixture(scope="module")
def run_glints(browser, surf, tmp_path_factory, program_js):
    from prefilter.viewer import serve

    d = tmp_path_factory.mktemp("glints-glsl")
    (d / "index.html").write_text("<!doctype html><title>glints</title>")
    shutil.copy(STATIC / "glints.js", d / "glints.js")
    entry = write_gpu(export_surface(surf, codes="f32"), d)
    server, url = serve(d)
    browser.get(url + "index.html")
    browser.set_script_timeout(600)

    def run(src, data):
        data = np.asarray(data, np.float32)
        out = browser.execute_async_script(program_js + _RUN, src, data.reshape(-1).tolist(),
                                           data.shape[0], entry)
        if isinstance(out, str):
            raise AssertionError(out)
        return np.array(out, np.float64).reshape(data.shape[0], 4)

    yield run
    server.shutdown()
    server.server_close()


def _cases(surf, n, rng):
    """Footprints from below the finest level to above the top, half vectors on the slopes of
    texels inside them (where the NDF is not zero), and light directions reflecting them."""
    H, W = surf.shape
    sp = np.exp(rng.uniform(np.log(0.3), np.log(150.0), n))
    c = rng.uniform(0, 1, (n, 2)) * [W, H]
    t = np.floor(c + rng.normal(0, 1, (n, 2)) * np.minimum(sp, 8)[:, None]).astype(int)
    s_el = surf.normal_map[t[:, 1] % H, t[:, 0] % W, :2]
    q = s_el + rng.normal(0, 0.01, (n, 2))
    half = 0.01 * rng.uniform(0.3, 3, (n, 1))
    lo, hi = q - half, q + half * rng.uniform(0.5, 2, (n, 2))
    hz = np.sqrt(np.maximum(1 - np.sum(q * q, -1), 0.05))
    h = np.concatenate([q, hz[:, None]], -1)
    h /= np.linalg.norm(h, axis=-1, keepdims=True)
    wo = np.array([0.3, -0.2, 0.93])
    wo = np.broadcast_to(wo / np.linalg.norm(wo), (n, 3))
    wi = 2 * np.sum(wo * h, -1)[:, None] * h - wo
    wi[:, 2] = np.abs(wi[:, 2]) + 0.02
    wi /= np.linalg.norm(wi, axis=-1, keepdims=True)
    f0 = rng.uniform(0.05, 1, (n, 3))
    data = np.zeros((n, 8, 4), np.float32)
    data[:, 0, :2], data[:, 0, 2], data[:, 1, :2] = c, sp, q
    data[:, 2, :2], data[:, 2, 2:] = lo, hi
    data[:, 3, :3], data[:, 4, :3], data[:, 5, :3] = wo, wi, f0
    return data


def _close(gpu, ref, rtol):
    scale = max(np.max(np.abs(ref)), 1e-30)
    err = np.abs(gpu - ref) / np.maximum(np.abs(ref), 1e-3 * scale)
    return float(np.max(err))


def _tight(src):
    """The GLSL with room for 2 groups of at most 144 components in the per-group sums (the
    flakes map's largest rank): footprints spanning more groups flush and restart."""
    from prefilter.glints.gpu import SUM_SIZE, SUM_SLOTS

    return (src.replace(f"#define GLT_SLOTS {SUM_SLOTS}\n", "#define GLT_SLOTS 2\n")
            .replace(f"#define GLT_SUM_SIZE {SUM_SIZE}\n", "#define GLT_SUM_SIZE 144\n"))


@pytest.mark.parametrize("sums", ["default", "tight"])
def test_glints_glsl_matches_python(run_glints, surf, sums):
    rng = np.random.default_rng(3)
    n = 384
    data = _cases(surf, n, rng)
    src = glsl_source()
    if sums == "tight":
        assert int(np.asarray(packed(surf.gm)[3])[:, 0].max()) <= 144
        src = _tight(src)
        assert src != glsl_source()
    out = run_glints(src + _MAIN, data)
    d = data.astype(np.float64)
    c, sp, q = d[:, 0, :2], d[:, 0, 2], d[:, 1, :2]
    gm = surf.gm
    point = point_flat(gm, c, sp, q, interp="resample", bilinear=True)
    ndf = glint_ndf(surf, c, sp, q, fallback_truncation=4.0)
    brdf = glint_brdf_cos(surf, c, sp, d[:, 3, :3], d[:, 4, :3], d[:, 5, :3],
                          fallback_truncation=4.0)[:, 1]
    big = sp >= surf.sigma_min
    idx, w, _ = weights(gm, c[big], sp[big], interp="resample")
    rng_ = range_multi(gm, idx, w, d[big, 2, None, :2], d[big, 2, None, 2:])[:, 0]
    below = sp < surf.sigma_min
    # the cases exercise every path with non-zero values
    assert np.sum(below & (ndf > 0)) > 20 and np.sum(big & (ndf > 0)) > 100
    assert np.sum(sp > surf.gm.pyramid.sigma(surf.gm.pyramid.n_levels - 1)) > 5
    assert np.sum(rng_ > 0) > 50
    assert _close(out[:, 0], point, 1e-4) < 1e-4
    assert _close(out[:, 1], ndf, 1e-4) < 1e-4
    assert _close(out[big, 2], rng_, 1e-4) < 1e-4
    assert _close(out[:, 3], brdf, 1e-4) < 1e-4


_MULTI = """
uniform highp sampler2D uIn;
out vec4 o;
vec4 at(int k, int i) { return texelFetch(uIn, ivec2(8 * k + i, 0), 0); }
void main() {
    int k = int(gl_FragCoord.x);
    vec4 a = at(k, 0);
    vec4 rect[GLT_MAX_RECTS];
    for (int i = 0; i < 4; ++i) rect[i] = at(k, 2 + i);
    float mean[GLT_MAX_RECTS];
    glRangeMulti(a.xy, a.z, rect, 4, mean);
    o = vec4(mean[0], mean[1], mean[2], mean[3]);
}
"""


def test_glints_glsl_range_multi_matches_python(run_glints, surf):
    """``glRangeMulti`` (a quad light's patches in one walk over the taps) against
    ``range_multi`` with four rectangles per footprint, some crossing NDF blocks."""
    rng = np.random.default_rng(5)
    n = 128
    data = _cases(surf, n, rng)
    data[:, 0, 2] = np.maximum(data[:, 0, 2], surf.sigma_min * 1.01)
    q = data[:, 1, :2].astype(np.float64)
    half = 0.01 * rng.uniform(0.3, 3, (n, 4, 2))
    ctr = q[:, None, :] + rng.normal(0, 0.02, (n, 4, 2))
    lo, hi = ctr - half, ctr + half
    data[:, 2:6, :2], data[:, 2:6, 2:] = lo, hi
    out = run_glints(glsl_source() + _MULTI, data)
    d = data.astype(np.float64)
    idx, w, _ = weights(surf.gm, d[:, 0, :2], d[:, 0, 2], interp="resample")
    ref = range_multi(surf.gm, idx, w, d[:, 2:6, :2], d[:, 2:6, 2:])
    assert np.sum(ref > 0) > 100
    assert _close(out, ref, 1e-4) < 1e-4


def test_glsl_files_exist():
    from prefilter.glints.gpu import GLSL_DIR

    assert all((GLSL_DIR / f).is_file() for f in GLSL_FILES)
