// The WebGL2 renderer of the prefilter viewer: loads data/viewer.json and the exported tables,
// compiles the exported GLSL snippets with shaders/viewer.frag.glsl, draws one frame.
// No dependencies; see docs/viewer.md for the data formats.

import {GLINT_METHODS, bindGlintMode, loadGlintMode} from './glints.js';
import {LEADR_ENV_METHODS, bindLeadrEnv, leadrEnvUnits, loadLeadrEnv} from './leadr_env.js';

export const METHODS = ['ltc', 'ltc-multiscale', 'ltc-aniso', 'ltc-multiscale-aniso', 'leadr-point',
  'colormap-filtered', 'colormap-naive', ...LEADR_ENV_METHODS, ...GLINT_METHODS, 'colormap-lit'];

async function fetchOk(url, kind) {
  const r = await fetch(url);
  if (!r.ok) throw new Error(`${url}: HTTP ${r.status}`);
  return kind === 'json' ? r.json() : kind === 'text' ? r.text() : r.arrayBuffer();
}

function compile(gl, type, src) {
  const s = gl.createShader(type);
  gl.shaderSource(s, src);
  gl.compileShader(s);
  if (!gl.getShaderParameter(s, gl.COMPILE_STATUS)) {
    const log = gl.getShaderInfoLog(s);
    throw new Error('shader compile error: ' + log);
  }
  return s;
}

// float32 or float16 (raw IEEE half bits) RGBA data -> texture, NEAREST (read with texelFetch)
function texture2D(gl, w, h, buf, half, internal = null, format = gl.RGBA) {
  const t = gl.createTexture();
  gl.bindTexture(gl.TEXTURE_2D, t);
  gl.pixelStorei(gl.UNPACK_ALIGNMENT, 1);
  const ifmt = internal || (half ? gl.RGBA16F : gl.RGBA32F);
  const type = internal === gl.RGBA32I ? gl.INT : internal === gl.R32F ? gl.FLOAT
    : (half ? gl.HALF_FLOAT : gl.FLOAT);
  const data = internal === gl.RGBA32I ? new Int32Array(buf)
    : half ? new Uint16Array(buf) : new Float32Array(buf);
  gl.texImage2D(gl.TEXTURE_2D, 0, ifmt, w, h, 0, format, type, data);
  for (const [k, v] of [[gl.TEXTURE_MIN_FILTER, gl.NEAREST], [gl.TEXTURE_MAG_FILTER, gl.NEAREST],
                        [gl.TEXTURE_WRAP_S, gl.CLAMP_TO_EDGE], [gl.TEXTURE_WRAP_T, gl.CLAMP_TO_EDGE]])
    gl.texParameteri(gl.TEXTURE_2D, k, v);
  return t;
}

// the anisotropic table: LINEAR, CLAMP_TO_EDGE 3D textures, as ltc_aniso.glsl expects
function texture3D(gl, w, h, d, buf, half) {
  const t = gl.createTexture();
  gl.bindTexture(gl.TEXTURE_3D, t);
  gl.pixelStorei(gl.UNPACK_ALIGNMENT, 1);
  gl.texImage3D(gl.TEXTURE_3D, 0, half ? gl.RGBA16F : gl.RGBA32F, w, h, d, 0, gl.RGBA,
                half ? gl.HALF_FLOAT : gl.FLOAT, half ? new Uint16Array(buf) : new Float32Array(buf));
  for (const [k, v] of [[gl.TEXTURE_MIN_FILTER, gl.LINEAR], [gl.TEXTURE_MAG_FILTER, gl.LINEAR],
                        [gl.TEXTURE_WRAP_S, gl.CLAMP_TO_EDGE], [gl.TEXTURE_WRAP_T, gl.CLAMP_TO_EDGE],
                        [gl.TEXTURE_WRAP_R, gl.CLAMP_TO_EDGE]])
    gl.texParameteri(gl.TEXTURE_3D, k, v);
  return t;
}

function cross(a, b) { return [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]]; }
function norm(a) { const l = Math.hypot(a[0], a[1], a[2]); return [a[0] / l, a[1] / l, a[2] / l]; }

// camera.Camera.basis(): right, true up, forward
export function cameraBasis(cam) {
  const f = norm([cam.target[0] - cam.origin[0], cam.target[1] - cam.origin[1], cam.target[2] - cam.origin[2]]);
  const r = norm(cross(f, cam.up));
  return {r, u: cross(r, f), f};
}

export class Viewer {
  constructor(canvas) {
    this.canvas = canvas;
    const gl = canvas.getContext('webgl2', {antialias: false, preserveDrawingBuffer: true});
    if (!gl) throw new Error('WebGL2 is not available');
    if (!gl.getExtension('EXT_color_buffer_float')) throw new Error('EXT_color_buffer_float is missing');
    this.floatLinear = !!gl.getExtension('OES_texture_float_linear');
    this.gl = gl;
    this.precision = 'f32';
    this.params = {methodLeft: 'ltc', methodRight: 'ltc', split: -1, exposure: 1.0, map: 'scene',
                   roughness: null, anisotropy: 0.0, lightOffset: [0, 0, 0], lightScale: 1.0};
  }

  async load(base = 'data/') {
    const gl = this.gl;
    const m = await fetchOk(base + 'viewer.json', 'json');
    this.manifest = m;
    this.scene = m.scene;
    this.camera = JSON.parse(JSON.stringify(m.scene.camera));
    const [iso, aniso, ms, leadr, cmap, vert, frag, leadrEnv, leadrEnvFrag] = await Promise.all([
      fetchOk(base + m.ltc_iso.glsl, 'text'), fetchOk(base + m.ltc_aniso.glsl, 'text'),
      fetchOk(base + m.alpha_meso.glsl, 'text'), fetchOk(base + m.leadr.glsl, 'text'),
      fetchOk(base + m.colormap.glsl, 'text'),
      fetchOk('shaders/viewer.vert.glsl', 'text'), fetchOk('shaders/viewer.frag.glsl', 'text'),
      fetchOk(base + m.leadr_env.glsl, 'text'), fetchOk('shaders/leadr_env.frag.glsl', 'text')]);
    const head = '#version 300 es\nprecision highp float;\nprecision highp int;\n' +
      'precision highp sampler2D;\nprecision highp sampler3D;\nprecision highp isampler2D;\n';
    const prog = gl.createProgram();
    gl.attachShader(prog, compile(gl, gl.VERTEX_SHADER, head + vert));
    gl.attachShader(prog, compile(gl, gl.FRAGMENT_SHADER, [head, iso, aniso, ms, leadr, leadrEnv, cmap,
      `#define METHOD_COLORMAP_LIT ${METHODS.indexOf('colormap-lit')}`, frag, leadrEnvFrag].join('\n')));
    gl.linkProgram(prog);
    if (!gl.getProgramParameter(prog, gl.LINK_STATUS)) throw new Error('link: ' + gl.getProgramInfoLog(prog));
    this.prog = prog;
    this.progUniforms = null;
    if (m.glints) this.glints = await loadGlintMode(this, base, compile, head, vert, [iso, aniso, ms, leadr, cmap], frag, METHODS);
    this.vao = gl.createVertexArray();
    this.tables = {};
    for (const p of ['f32', 'f16']) {
      const half = p === 'f16';
      const bi = await fetchOk(base + m.ltc_iso[p]);
      const ba = await fetchOk(base + m.ltc_aniso[p]);
      const es = half ? 2 : 4;
      const ni = m.ltc_iso.width * m.ltc_iso.height * 4 * es;
      const na = m.ltc_aniso.width * m.ltc_aniso.height * m.ltc_aniso.depth * 4 * es;
      this.tables[p] = {
        iso: [0, 1, 2].map(k => texture2D(gl, m.ltc_iso.width, m.ltc_iso.height, bi.slice(k * ni, (k + 1) * ni), half)),
        aniso: [0, 1, 2].map(k => texture3D(gl, m.ltc_aniso.width, m.ltc_aniso.height, m.ltc_aniso.depth, ba.slice(k * na, (k + 1) * na), half)),
      };
    }
    const am = await fetchOk(base + m.alpha_meso.f32);
    this.alphaMeso = texture2D(gl, m.alpha_meso.width, m.alpha_meso.height, am, false, gl.R32F, gl.RED);
    const at = await fetchOk(base + m.atlas.f32);
    this.atlas = texture2D(gl, m.atlas.width, m.atlas.height, at, false);
    const at16 = await fetchOk(base + m.atlas.f16);
    this.atlas16 = texture2D(gl, m.atlas.width, m.atlas.height, at16, true);
    // the colour-map table as the exported snippet expects it: LINEAR, its wrap mode along S
    const ct = await fetchOk(base + m.colormap.f32);
    this.colormapTable = texture2D(gl, m.colormap.width, m.colormap.height, ct, false);
    for (const [k, v] of [[gl.TEXTURE_MIN_FILTER, gl.LINEAR], [gl.TEXTURE_MAG_FILTER, gl.LINEAR],
                          [gl.TEXTURE_WRAP_S, gl[m.colormap.wrap_s]]])
      gl.texParameteri(gl.TEXTURE_2D, k, v);
    // the slope driver's pre-blurred stack (slope.glsl reads it with texelFetch)
    const cs = m.colormap.slope;
    this.colormapSlope = texture2D(gl, cs.width, cs.height, await fetchOk(base + cs.f32), false);
    this.leadrEnv = await loadLeadrEnv(gl, base, m.leadr_env, fetchOk);
    const lv = await fetchOk(base + m.atlas.levels);
    this.levels = texture2D(gl, m.atlas.n_levels, 1, lv, false, gl.RGBA32I, gl.RGBA_INTEGER);
    this.uniforms = {};
    const n = gl.getProgramParameter(prog, gl.ACTIVE_UNIFORMS);
    for (let i = 0; i < n; ++i) {
      const info = gl.getActiveUniform(prog, i);
      const name = info.name.replace(/\[0\]$/, '');
      this.uniforms[name] = gl.getUniformLocation(prog, info.name);
    }
    this.progUniforms = this.uniforms;
    return this;
  }

  mapNames() { return ['scene', 'none', ...this.manifest.maps.flatMap(x => x.names).filter(x => !x.startsWith('scene'))]; }

  _u(name, fn, ...args) { const l = this.uniforms[name]; if (l !== undefined && l !== null) this.gl[fn](l, ...args); }

  _bind(width, height) {
    const gl = this.gl, P = this.params, S = this.scene, m = this.manifest;
    const glints = this.glints && [P.methodLeft, P.methodRight].some(x => GLINT_METHODS.includes(x));
    this.uniforms = glints ? this.glints.uniforms : this.progUniforms;
    gl.useProgram(glints ? this.glints.prog : this.prog);
    const units = [['uAtlas', gl.TEXTURE_2D, this.atlas], ['uAtlas16', gl.TEXTURE_2D, this.atlas16],
                   ['uLevels', gl.TEXTURE_2D, this.levels],
                   ['uColormapTable', gl.TEXTURE_2D, this.colormapTable],
                   ['uCmSlopeStack', gl.TEXTURE_2D, this.colormapSlope],
                   ['alphaMesoNodes', gl.TEXTURE_2D, this.alphaMeso]];
    const t = this.tables[this.precision];
    for (let k = 0; k < 3; ++k) {
      units.push([`ltcIso${k}`, gl.TEXTURE_2D, t.iso[k]]);
      units.push([`ltcAniso${k}`, gl.TEXTURE_3D, t.aniso[k]]);
    }
    units.push(...leadrEnvUnits(gl, this.leadrEnv));
    units.forEach(([name, target, tex], i) => {
      gl.activeTexture(gl.TEXTURE0 + i);
      gl.bindTexture(target, tex);
      this._u(name, 'uniform1i', i);
    });
    if (glints) bindGlintMode(this, units.length);
    this._u('uAtlasWidth', 'uniform1i', m.atlas.width);
    const c = this.camera, b = cameraBasis(c);
    this._u('uCamO', 'uniform3fv', c.origin);
    this._u('uCamR', 'uniform3fv', b.r);
    this._u('uCamU', 'uniform3fv', b.u);
    this._u('uCamF', 'uniform3fv', b.f);
    this._u('uCamSy', 'uniform1f', 2.0 * Math.tan(c.fov * Math.PI / 360.0) / height);
    this._u('uSize', 'uniform2f', width, height);
    const objs = S.objects;
    this._u('uNumObjects', 'uniform1i', objs.length);
    const flat = (f) => objs.flatMap(f);
    this._u('uObjType', 'uniform1iv', objs.map(o => o.type));
    this._u('uObjC', 'uniform3fv', flat(o => o.center));
    this._u('uObjN', 'uniform3fv', flat(o => o.n));
    this._u('uObjT', 'uniform3fv', flat(o => o.t));
    this._u('uObjB', 'uniform3fv', flat(o => o.b));
    this._u('uObjP', 'uniform4fv', flat(o => [o.size[0], o.size[1], o.radius, 0]));
    this._u('uObjUV', 'uniform2fv', flat(o => o.uv_scale));
    this._u('uMatAlpha', 'uniform2fv', flat(o => this._alphas(o.material)));
    this._u('uMatBase', 'uniform3fv', flat(o => o.material.base_color));
    this._u('uMatF0', 'uniform3fv', flat(o => o.material.f0));
    this._u('uMatMap', 'uniform4iv', flat(o => {
      const k = this._mapIndex(o.material.map);
      if (k < 0) return [-1, 0, -1, 0];
      const mp = m.maps[k];
      return [mp.normals[0], mp.normals[1], mp.slopes[0], mp.slopes[1]];
    }));
    this._u('uMatColor', 'uniform4iv', flat(o => [...(o.material.color || [-1, 0, 0]), 0]));
    // leadr-point: the scene's height maps, or the chosen built-in's slope moments
    this._u('uMatHeight', 'uniform2iv', flat(o => {
      if (P.map === 'scene') return o.material.height || [-1, 0];
      const k = this._mapIndex(-1);
      return k < 0 ? [-1, 0] : m.maps[k].slopes;
    }));
    this._u('uMapsHalf', 'uniform1i', this.precision === 'f16' ? 1 : 0);
    this._u('uColormapChain', 'uniform2iv', m.colormap.chain);
    this._u('uColormapDriver', 'uniform1i', m.colormap.driver_code);
    this._u('uColormapLight', 'uniform4fv', m.colormap.light);
    bindLeadrEnv(this, this.leadrEnv);
    const quads = S.lights.map(q => this._light(q));
    this._u('uNumQuads', 'uniform1i', quads.length);
    if (quads.length) {
      this._u('uQuadV', 'uniform3fv', quads.flatMap(q => q.vertices.flat()));
      this._u('uQuadN', 'uniform3fv', quads.flatMap(q => q.normal));
      this._u('uQuadL', 'uniform3fv', quads.flatMap(q => q.radiance));
    }
    const pts = S.points || [], dirs = S.directionals || [];
    this._u('uNumPoints', 'uniform1i', pts.length);
    this._u('uNumDirs', 'uniform1i', dirs.length);
    if (pts.length) {
      this._u('uPointP', 'uniform3fv', pts.flatMap(p => p.position));
      this._u('uPointI', 'uniform3fv', pts.flatMap(p => p.intensity));
    }
    if (dirs.length) {
      this._u('uDirD', 'uniform3fv', dirs.flatMap(p => p.direction));
      this._u('uDirE', 'uniform3fv', dirs.flatMap(p => p.irradiance));
    }
    this._u('uMethodLeft', 'uniform1i', METHODS.indexOf(P.methodLeft));
    this._u('uMethodRight', 'uniform1i', METHODS.indexOf(P.methodRight));
    this._u('uSplit', 'uniform1f', P.split < 0 ? width + 1 : P.split * width);
    this._u('uExposure', 'uniform1f', P.exposure);
  }

  // the roughness slider overrides every material: alpha_x = a (1 + k), alpha_y = a (1 - k)
  _alphas(mat) {
    const P = this.params;
    if (P.roughness === null) return [mat.alpha_x, mat.alpha_y];
    const c = (x) => Math.min(1, Math.max(0.001, x));
    return [c(P.roughness * (1 + P.anisotropy)), c(P.roughness * (1 - P.anisotropy))];
  }

  _mapIndex(sceneIndex) {
    const P = this.params;
    if (P.map === 'scene') return sceneIndex;
    if (P.map === 'none') return -1;
    return this.manifest.maps.findIndex(x => x.names.includes(P.map));
  }

  // light sliders: translate by lightOffset, scale about the centroid by lightScale
  _light(q) {
    const P = this.params;
    const c = [0, 1, 2].map(i => q.vertices.reduce((s, v) => s + v[i], 0) / 4);
    const vertices = q.vertices.map(v => [0, 1, 2].map(i => c[i] + P.lightScale * (v[i] - c[i]) + P.lightOffset[i]));
    return {vertices, normal: q.normal, radiance: q.radiance};
  }

  // draw to the canvas (sRGB display)
  draw() {
    const gl = this.gl, w = this.canvas.width, h = this.canvas.height;
    this._bind(w, h);
    this._u('uLinear', 'uniform1i', 0);
    gl.bindFramebuffer(gl.FRAMEBUFFER, null);
    gl.viewport(0, 0, w, h);
    gl.bindVertexArray(this.vao);
    gl.drawArrays(gl.TRIANGLES, 0, 3);
  }

  // linear radiance at the scene camera's size (or width x height): Float32Array RGBA, row 0 at
  // the top (as the Python renderer's images)
  renderLinear(width = this.camera.width, height = this.camera.height) {
    const gl = this.gl;
    const tex = gl.createTexture();
    gl.bindTexture(gl.TEXTURE_2D, tex);
    gl.texImage2D(gl.TEXTURE_2D, 0, gl.RGBA32F, width, height, 0, gl.RGBA, gl.FLOAT, null);
    const fb = gl.createFramebuffer();
    gl.bindFramebuffer(gl.FRAMEBUFFER, fb);
    gl.framebufferTexture2D(gl.FRAMEBUFFER, gl.COLOR_ATTACHMENT0, gl.TEXTURE_2D, tex, 0);
    if (gl.checkFramebufferStatus(gl.FRAMEBUFFER) !== gl.FRAMEBUFFER_COMPLETE) throw new Error('float framebuffer incomplete');
    this._bind(width, height);
    this._u('uLinear', 'uniform1i', 1);
    gl.viewport(0, 0, width, height);
    gl.bindVertexArray(this.vao);
    gl.drawArrays(gl.TRIANGLES, 0, 3);
    const px = new Float32Array(width * height * 4);
    gl.readPixels(0, 0, width, height, gl.RGBA, gl.FLOAT, px);
    gl.bindFramebuffer(gl.FRAMEBUFFER, null);
    gl.deleteFramebuffer(fb);
    gl.deleteTexture(tex);
    const out = new Float32Array(px.length), row = width * 4;
    for (let y = 0; y < height; ++y) out.set(px.subarray((height - 1 - y) * row, (height - y) * row), y * row);
    return out;
  }

  // mean frame time (ms) of n synchronous draws to the canvas (readPixels of one pixel syncs)
  frameTime(n = 10) {
    const gl = this.gl, one = new Uint8Array(4);
    this.draw();
    gl.readPixels(0, 0, 1, 1, gl.RGBA, gl.UNSIGNED_BYTE, one);
    const t0 = performance.now();
    for (let i = 0; i < n; ++i) {
      this.draw();
      gl.readPixels(0, 0, 1, 1, gl.RGBA, gl.UNSIGNED_BYTE, one);
    }
    return (performance.now() - t0) / n;
  }
}

export function toBase64(f32) {
  const bytes = new Uint8Array(f32.buffer, f32.byteOffset, f32.byteLength);
  let s = '';
  for (let i = 0; i < bytes.length; i += 0x8000) s += String.fromCharCode.apply(null, bytes.subarray(i, i + 0x8000));
  return btoa(s);
}
