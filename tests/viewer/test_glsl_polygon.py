"""The exported GLSL snippets run in WebGL2 against the Python they mirror: the polygon integral
(``prefilter.ltc.glsl``: ``ltcPolygon``, ``ltcClipHorizon``) against
``prefilter.sphere.polygon.polygon_integral_minv`` / ``clip_to_horizon`` over random transforms
(mirrored ones included) and quads crossing the horizon; the anisotropic lookup
(``ltc_aniso.glsl`` with its 3D textures, float32 and float16) against ``AnisoGGXTable.lookup``."""

import numpy as np
import pytest

from prefilter.ltc import glsl as iso_glsl
from prefilter.sphere.polygon import clip_to_horizon, polygon_integral, polygon_integral_minv
from prefilter.ltc.table import GGXTable
from prefilter.viewer import serve

# after conftest.PROGRAM_JS (the ``program_js`` fixture)
_RUN = """
const [src, data, n] = arguments;
const c = document.createElement('canvas');
const gl = c.getContext('webgl2');
gl.getExtension('EXT_color_buffer_float');
const p = fullScreenProgram(gl, '#version 300 es\\nprecision highp float;\\n' +
  'precision highp int;\\n', src);
const tex = (w, arr) => { const t = gl.createTexture(); gl.bindTexture(gl.TEXTURE_2D, t);
  gl.texImage2D(gl.TEXTURE_2D, 0, gl.RGBA32F, w, 1, 0, gl.RGBA, gl.FLOAT, arr);
  gl.texParameteri(gl.TEXTURE_2D, gl.TEXTURE_MIN_FILTER, gl.NEAREST);
  gl.texParameteri(gl.TEXTURE_2D, gl.TEXTURE_MAG_FILTER, gl.NEAREST); return t; };
const inp = tex(8 * n, new Float32Array(data));
const out = tex(n, null);
const fb = gl.createFramebuffer();
gl.bindFramebuffer(gl.FRAMEBUFFER, fb);
gl.framebufferTexture2D(gl.FRAMEBUFFER, gl.COLOR_ATTACHMENT0, gl.TEXTURE_2D, out, 0);
gl.useProgram(p);
gl.activeTexture(gl.TEXTURE0); gl.bindTexture(gl.TEXTURE_2D, inp);
gl.uniform1i(gl.getUniformLocation(p, 'uIn'), 0);
gl.viewport(0, 0, n, 1);
gl.drawArrays(gl.TRIANGLES, 0, 3);
const px = new Float32Array(4 * n);
gl.readPixels(0, 0, n, 1, gl.RGBA, gl.FLOAT, px);
return Array.from(px);
"""

_LINKED = "'precision highp int;\\n', src);\n"  # the line of _RUN after the program is in use
assert _LINKED in _RUN

_MAIN = """
uniform highp sampler2D uIn;  // per case: 3 texels of matrix rows, 4 texels of quad corners
out vec4 o;
void main() {
    int k = int(gl_FragCoord.x) * 8;
    vec4 a = texelFetch(uIn, ivec2(k, 0), 0), b = texelFetch(uIn, ivec2(k + 1, 0), 0);
    vec4 c = texelFetch(uIn, ivec2(k + 2, 0), 0);
    mat3 T = transpose(mat3(a.xyz, b.xyz, c.xyz));
    vec3 P[5], C[5];
    for (int i = 0; i < 4; ++i) P[i] = texelFetch(uIn, ivec2(k + 3 + i, 0), 0).xyz;
    P[4] = P[3];
    ltcClipHorizon(P, C);
    o = vec4(ltcPolygon(T, C, 5), ltcPolygon(mat3(1.0), P, 4), 0.0, 1.0);
}
"""


@pytest.fixture(scope="module")
def page(browser, tmp_path_factory):
    d = tmp_path_factory.mktemp("glsl")
    (d / "index.html").write_text("<!doctype html><title>glsl</title>")
    server, url = serve(d)
    browser.get(url + "index.html")
    yield browser
    server.shutdown()
    server.server_close()


def _cases(rng, n):
    # quads around the z axis, tilted so that most cross the horizon
    centre = np.stack([rng.normal(0, 0.6, n), rng.normal(0, 0.6, n), rng.uniform(-0.3, 1.0, n)],
                      -1)
    u = rng.normal(size=(n, 3))
    v = np.cross(u, rng.normal(size=(n, 3)))
    u *= rng.uniform(0.2, 0.8, (n, 1)) / np.linalg.norm(u, axis=-1, keepdims=True)
    v *= rng.uniform(0.2, 0.8, (n, 1)) / np.linalg.norm(v, axis=-1, keepdims=True)
    quads = centre[:, None] + np.stack([-u - v, u - v, u + v, -u + v], 1)
    T = np.eye(3) + rng.normal(0, 0.5, (n, 3, 3))
    T[: n // 4, 0] *= -1.0  # mirrored transforms (negative determinant)
    return T, quads


def test_polygon_integral_matches_python(page, program_js):
    rng = np.random.default_rng(3)
    n = 256
    T, quads = _cases(rng, n)
    data = np.zeros((n, 8, 4), np.float32)
    data[:, :3, :3] = T
    data[:, 3:7, :3] = quads
    src = iso_glsl.glsl_source(GGXTable.load()) + _MAIN
    out = np.array(page.execute_script(program_js + _RUN, src, data.reshape(-1).tolist(), n))
    out = out.reshape(n, 4)
    clipped = clip_to_horizon(quads)
    ref_s = polygon_integral_minv(T, clipped)
    ref_d = polygon_integral_minv(np.broadcast_to(np.eye(3), T.shape), quads)
    crossing = (quads[..., 2].min(-1) < 0) & (quads[..., 2].max(-1) > 0)
    assert crossing.sum() > n // 4 and (ref_s > 1e-3).sum() > n // 4
    print("max abs error spec %.2e diffuse %.2e" % (np.abs(out[:, 0] - ref_s).max(),
                                                   np.abs(out[:, 1] - ref_d).max()))
    np.testing.assert_allclose(out[:, 0], ref_s, rtol=1e-4, atol=1e-5)
    np.testing.assert_allclose(out[:, 1], ref_d, rtol=1e-4, atol=1e-5)


_ANISO_MAIN = """
uniform highp sampler2D uIn;  // per case: (wo, 0), (alpha_x, alpha_y, 0, 0)
out vec4 o;
void main() {
    int k = int(gl_FragCoord.x);
    vec3 wo = texelFetch(uIn, ivec2(8 * k, 0), 0).xyz;
    vec2 a = texelFetch(uIn, ivec2(8 * k + 1, 0), 0).xy;
    mat3 Minv; float n, f5;
    ltcAnisoLookup(wo, a.x, a.y, Minv, n, f5);
    // the integral over a fixed quad (one number that depends on the whole of Minv)
    vec3 P[5] = vec3[5](vec3(-0.2, 0.3, 0.5), vec3(0.5, 0.4, 0.4), vec3(0.4, -0.3, 0.6),
                        vec3(-0.3, -0.2, 0.5), vec3(-0.3, -0.2, 0.5));
    o = vec4(n, f5, n * ltcPolygon(Minv, P, 4), 1.0);
}
"""


@pytest.mark.parametrize("precision", ["f32", "f16"])
def test_aniso_lookup_in_webgl_matches_table(page, program_js, precision):
    """The exported ``ltc_aniso.glsl`` with its 3D textures (hardware LINEAR filtering) against
    ``AnisoGGXTable.lookup``: magnitude and the LTC integral over a quad."""
    from prefilter.ltc.aniso.export import glsl_source, texture_layout
    from prefilter.ltc.aniso.table import AnisoGGXTable

    table = AnisoGGXTable.load()
    rng = np.random.default_rng(5)
    n = 256
    t, p = np.radians(rng.uniform(0, 85, n)), rng.uniform(-np.pi, np.pi, n)
    wo = np.stack([np.sin(t) * np.cos(p), np.sin(t) * np.sin(p), np.cos(t)], -1)
    ax, ay = rng.uniform(0.05, 1, n), rng.uniform(0.05, 1, n)
    data = np.zeros((n, 8, 4), np.float32)
    data[:, 0, :3], data[:, 1, 0], data[:, 1, 1] = wo, ax, ay
    tex = texture_layout(table, np.float16 if precision == "f16" else np.float32)
    src = ("precision highp sampler3D;\n" + glsl_source(table)
           + iso_glsl.glsl_source(GGXTable.load()) + _ANISO_MAIN)
    run = program_js + _RUN.replace(_LINKED, _LINKED + """
gl.getExtension('OES_texture_float_linear');  // LINEAR filtering of RGBA32F
const [D, H, W] = arguments[3];
const half = arguments[5];
for (let k = 0; k < 3; ++k) {
  const t3 = gl.createTexture();
  gl.activeTexture(gl.TEXTURE1 + k); gl.bindTexture(gl.TEXTURE_3D, t3);
  const raw = arguments[4][k];
  gl.texImage3D(gl.TEXTURE_3D, 0, half ? gl.RGBA16F : gl.RGBA32F, W, H, D, 0, gl.RGBA,
                half ? gl.HALF_FLOAT : gl.FLOAT,
                half ? new Uint16Array(raw) : new Float32Array(raw));
  for (const [a, b] of [[gl.TEXTURE_MIN_FILTER, gl.LINEAR], [gl.TEXTURE_MAG_FILTER, gl.LINEAR],
       [gl.TEXTURE_WRAP_S, gl.CLAMP_TO_EDGE], [gl.TEXTURE_WRAP_T, gl.CLAMP_TO_EDGE],
       [gl.TEXTURE_WRAP_R, gl.CLAMP_TO_EDGE]]) gl.texParameteri(gl.TEXTURE_3D, a, b);
  gl.uniform1i(gl.getUniformLocation(p, 'ltcAniso' + k), 1 + k);
}""")
    raw = [(tex[k].view(np.uint16) if precision == "f16" else tex[k]).reshape(-1).tolist()
           for k in range(3)]
    out = np.array(page.execute_script(run, src, data.reshape(-1).tolist(), n,
                                       list(tex.shape[1:4]), raw, precision == "f16"))
    out = out.reshape(n, 4)
    M, mag, fres = table.lookup(wo, ax, ay)
    P = np.array([[-0.2, 0.3, 0.5], [0.5, 0.4, 0.4], [0.4, -0.3, 0.6], [-0.3, -0.2, 0.5]])
    ref = mag * polygon_integral(M, P)
    tol = 2e-3 if precision == "f16" else 5e-4
    print(f"{precision}: max |n| error {np.abs(out[:, 0] - mag).max():.2e}, max integral error "
          f"{np.abs(out[:, 2] - ref).max():.2e} (max {ref.max():.3g})")
    np.testing.assert_allclose(out[:, 0], mag, atol=tol)
    np.testing.assert_allclose(out[:, 1], fres, atol=tol)
    np.testing.assert_allclose(out[:, 2], ref, atol=tol * max(1.0, ref.max()), rtol=tol)
