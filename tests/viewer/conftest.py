"""The ``browser`` fixture: one headless Chromium per test module.

It FAILS when Debian's chromium / chromedriver are missing, unless PREFILTER_SKIP_BROWSER=1 (then
the browser tests are skipped with the reason).
"""

import os
import sys

import pytest

from prefilter.viewer.browser import CHROMEDRIVER, CHROMIUM

# the NumPy twins of the exported GLSL (tests/ltc/glsl_numpy.py) under --import-mode=importlib
_twins = os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), "ltc")
if _twins not in sys.path:
    sys.path.insert(0, _twins)


@pytest.fixture(scope="module")
def browser(tmp_path_factory):
    missing = [p for p in (CHROMIUM, CHROMEDRIVER) if not os.access(p, os.X_OK)]
    if missing:
        if os.environ.get("PREFILTER_SKIP_BROWSER") == "1":
            pytest.skip(f"PREFILTER_SKIP_BROWSER=1 and {', '.join(missing)} missing")
        pytest.fail(f"{', '.join(missing)} missing: install Debian's chromium and chromium-driver "
                    "(or set PREFILTER_SKIP_BROWSER=1 to skip the browser tests)")
    from prefilter.viewer.browser import chromium

    driver = chromium(tmp_path_factory.mktemp("chromium-profile"))
    yield driver
    driver.quit()


# -- the exported GLSL alone in WebGL2 ---------------------------------------------------------

#: JS defining ``fullScreenProgram(gl, head, src)``: the WebGL2 program of a full-screen triangle
#: and fragment shader ``src`` (both after ``head``), linked and in use; compile and link errors
#: thrown with the driver's log. Shared by the browser harnesses that run GLSL alone
#: (``run_glsl`` here, tests/viewer/test_glsl_polygon.py, tests/viewer/test_glsl_glints.py).
PROGRAM_JS = """
const fullScreenProgram = (gl, head, src) => {
  const sh = (t, s) => { const x = gl.createShader(t); gl.shaderSource(x, head + s);
    gl.compileShader(x); if (!gl.getShaderParameter(x, gl.COMPILE_STATUS))
    throw new Error(gl.getShaderInfoLog(x)); return x; };
  const p = gl.createProgram();
  gl.attachShader(p, sh(gl.VERTEX_SHADER, 'void main() { gl_Position = vec4(vec2[3](vec2(-1.0, ' +
    '-1.0), vec2(3.0, -1.0), vec2(-1.0, 3.0))[gl_VertexID], 0.0, 1.0); }'));
  gl.attachShader(p, sh(gl.FRAGMENT_SHADER, src));
  gl.linkProgram(p);
  if (!gl.getProgramParameter(p, gl.LINK_STATUS)) throw new Error(gl.getProgramInfoLog(p));
  gl.useProgram(p);
  return p;
};
"""


@pytest.fixture(scope="module")
def program_js():
    """:data:`PROGRAM_JS` for the test modules' own harnesses."""
    return PROGRAM_JS


_RUN = PROGRAM_JS + """
const [src, data, n, texs] = arguments;
const c = document.createElement('canvas');
const gl = c.getContext('webgl2');
gl.getExtension('EXT_color_buffer_float');
gl.getExtension('OES_texture_float_linear');  // LINEAR filtering of RGBA32F
const p = fullScreenProgram(gl, '#version 300 es\\nprecision highp float;\\n' +
  'precision highp int;\\nprecision highp sampler2D;\\n', src);
const tex = (w, h, arr, filter, ws, wt) => { const t = gl.createTexture();
  gl.bindTexture(gl.TEXTURE_2D, t);
  gl.texImage2D(gl.TEXTURE_2D, 0, gl.RGBA32F, w, h, 0, gl.RGBA, gl.FLOAT, arr);
  gl.texParameteri(gl.TEXTURE_2D, gl.TEXTURE_MIN_FILTER, gl[filter]);
  gl.texParameteri(gl.TEXTURE_2D, gl.TEXTURE_MAG_FILTER, gl[filter]);
  gl.texParameteri(gl.TEXTURE_2D, gl.TEXTURE_WRAP_S, gl[ws]);
  gl.texParameteri(gl.TEXTURE_2D, gl.TEXTURE_WRAP_T, gl[wt]); return t; };
gl.activeTexture(gl.TEXTURE0);
const inp = tex(8 * n, 1, new Float32Array(data), 'NEAREST', 'CLAMP_TO_EDGE', 'CLAMP_TO_EDGE');
gl.uniform1i(gl.getUniformLocation(p, 'uIn'), 0);
texs.forEach((t, i) => {
  gl.activeTexture(gl.TEXTURE1 + i);
  tex(t.w, t.h, new Float32Array(t.data), t.filter, t.wrap_s, t.wrap_t);
  gl.uniform1i(gl.getUniformLocation(p, t.name), 1 + i);
});
gl.activeTexture(gl.TEXTURE0 + 1 + texs.length);
const out = tex(n, 1, null, 'NEAREST', 'CLAMP_TO_EDGE', 'CLAMP_TO_EDGE');
const fb = gl.createFramebuffer();
gl.bindFramebuffer(gl.FRAMEBUFFER, fb);
gl.framebufferTexture2D(gl.FRAMEBUFFER, gl.COLOR_ATTACHMENT0, gl.TEXTURE_2D, out, 0);
gl.viewport(0, 0, n, 1);
gl.drawArrays(gl.TRIANGLES, 0, 3);
const px = new Float32Array(4 * n);
gl.readPixels(0, 0, n, 1, gl.RGBA, gl.FLOAT, px);
return Array.from(px);
"""


@pytest.fixture(scope="module")
def run_glsl(browser, tmp_path_factory):
    """``run(src, data (n, 8, 4), textures=()) -> (n, 4)``: a fragment shader ``src`` (reads
    case ``k`` as texels ``8k .. 8k + 7`` of ``uniform sampler2D uIn`` at ``gl_FragCoord.x = k``,
    writes ``out vec4 o``) drawn to an RGBA32F target of ``n x 1`` pixels in WebGL2.

    ``textures``: dicts ``name, w, h, data`` (RGBA float32) and ``filter`` (``LINEAR`` /
    ``NEAREST``), ``wrap_s``, ``wrap_t`` (WebGL names such as ``MIRRORED_REPEAT``)."""
    import numpy as np

    from prefilter.viewer import serve

    d = tmp_path_factory.mktemp("glsl-page")
    (d / "index.html").write_text("<!doctype html><title>glsl</title>")
    server, url = serve(d)
    browser.get(url + "index.html")

    def run(src, data, textures=()):
        data = np.asarray(data, np.float32)
        n = data.shape[0]
        texs = [dict(t, data=np.asarray(t["data"], np.float32).reshape(-1).tolist())
                for t in textures]
        out = browser.execute_script(_RUN, src, data.reshape(-1).tolist(), n, texs)
        return np.array(out, np.float64).reshape(n, 4)

    yield run
    server.shutdown()
    server.server_close()
