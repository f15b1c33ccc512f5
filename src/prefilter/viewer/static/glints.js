// The viewer's `glints` mode: a baked glints map as WebGL2 2D array textures
// (prefilter.glints.gpu.export_gpu / write_gpu), the uniforms of the glints GLSL
// (prefilter/glints/glsl), and the mode's own program (viewer.frag.glsl with GLINTS defined and
// shaders/glints.frag.glsl after it). See docs/viewer.md, "Glints".

// texture name -> sampler uniform, in the order of glints_textures.glsl's GL_TEX_* indices
export const GLINT_TEXTURES = [['fa', 'glFa'], ['fb', 'glFb'], ['pa', 'glPa'], ['pb', 'glPb'],
  ['c', 'glC'], ['w', 'glW'], ['meta', 'glMeta'], ['index', 'glIndex'], ['cell', 'glCell'],
  ['elements', 'glElements']];
export const GLINT_CODES = ['f32', 'f16', 'u8'];

function formatOf(gl, fmt) {
  switch (fmt) {
    case 'R32F': return [gl.R32F, gl.RED, gl.FLOAT, Float32Array];
    case 'R16F': return [gl.R16F, gl.RED, gl.HALF_FLOAT, Uint16Array];
    case 'R8': return [gl.R8, gl.RED, gl.UNSIGNED_BYTE, Uint8Array];
    case 'R32I': return [gl.R32I, gl.RED_INTEGER, gl.INT, Int32Array];
    case 'RGBA32I': return [gl.RGBA32I, gl.RGBA_INTEGER, gl.INT, Int32Array];
    case 'RGBA32F': return [gl.RGBA32F, gl.RGBA, gl.FLOAT, Float32Array];
    case 'RGBA16F': return [gl.RGBA16F, gl.RGBA, gl.HALF_FLOAT, Uint16Array];
    case 'RGBA8': return [gl.RGBA8, gl.RGBA, gl.UNSIGNED_BYTE, Uint8Array];
  }
  throw new Error(`glints texture format ${fmt} unknown`);
}

function arrayTexture(gl, fmt, shape, buf) {
  const [ifmt, format, type, Arr] = formatOf(gl, fmt);
  const [w, h, layers] = shape;
  const lim = [['MAX_TEXTURE_SIZE', Math.max(w, h)], ['MAX_ARRAY_TEXTURE_LAYERS', layers]];
  for (const [name, need] of lim) {
    const have = gl.getParameter(gl[name]);
    if (need > have) throw new Error(`glints texture needs ${name} >= ${need}, this browser has ${have}`);
  }
  const t = gl.createTexture();
  gl.bindTexture(gl.TEXTURE_2D_ARRAY, t);
  gl.pixelStorei(gl.UNPACK_ALIGNMENT, 1);
  gl.texImage3D(gl.TEXTURE_2D_ARRAY, 0, ifmt, w, h, layers, 0, format, type,
                buf ? new Arr(buf) : new Arr(w * h * layers * (format === gl.RED || format === gl.RED_INTEGER ? 1 : 4)));
  for (const [k, v] of [[gl.TEXTURE_MIN_FILTER, gl.NEAREST], [gl.TEXTURE_MAG_FILTER, gl.NEAREST],
                        [gl.TEXTURE_WRAP_S, gl.CLAMP_TO_EDGE], [gl.TEXTURE_WRAP_T, gl.CLAMP_TO_EDGE]])
    gl.texParameteri(gl.TEXTURE_2D_ARRAY, k, v);
  return t;
}

// entry: write_gpu's manifest entry; buffers: name -> ArrayBuffer of its file
export function glintTextures(gl, entry, buffers) {
  const tex = {};
  for (const [name] of GLINT_TEXTURES) {
    const f = entry.files[name];
    // a map without its normal map has no elements: a 1-texel stand-in (never read)
    tex[name] = f ? arrayTexture(gl, f.format, f.shape, buffers[name])
      : arrayTexture(gl, 'RGBA32F', [1, 1, 1], null);
  }
  return {entry, tex};
}

export async function fetchGlints(gl, base, entry) {
  const buffers = {};
  await Promise.all(Object.entries(entry.files).map(async ([name, f]) => {
    const r = await fetch(base + f.file);
    if (!r.ok) throw new Error(`${base + f.file}: HTTP ${r.status}`);
    buffers[name] = await r.arrayBuffer();
  }));
  return glintTextures(gl, entry, buffers);
}

// bind a map's textures from texture unit `unit0` on and set its uniforms;
// u(name, fn, ...args) sets a uniform if the program has it
export function bindGlints(gl, map, u, unit0) {
  const e = map.entry;
  GLINT_TEXTURES.forEach(([name, uni], i) => {
    gl.activeTexture(gl.TEXTURE0 + unit0 + i);
    gl.bindTexture(gl.TEXTURE_2D_ARRAY, map.tex[name]);
    u(uni, 'uniform1i', unit0 + i);
  });
  const dims = GLINT_TEXTURES.flatMap(([name]) => {
    const f = e.files[name];
    return f ? [f.shape[0], f.shape[1]] : [1, 1];
  });
  u('glDims', 'uniform2iv', dims);
  u('glR', 'uniform1i', e.resolution);
  u('glB', 'uniform1i', e.block);
  u('glNb', 'uniform1i', e.nb);
  u('glLo', 'uniform1f', e.lo);
  u('glPitch', 'uniform1f', e.pitch);
  u('glLevels', 'uniform1i', e.n_levels);
  u('glOffs', 'uniform1iv', e.offsets);
  u('glShape', 'uniform2iv', e.shapes.flat());
  u('glSig', 'uniform1fv', e.sigmas);
  u('glStride', 'uniform1fv', e.strides);
  u('glMapSize', 'uniform2i', e.map[0], e.map[1]);
  u('glSigmaMin', 'uniform1f', e.sigma_min);
  u('glSr', 'uniform1f', e.intrinsic_roughness);
  u('glDirect', 'uniform1i', e.direct ? 1 : 0);
  if (e.moments) {
    const c = e.moments.cov;
    u('glMomentMean', 'uniform2f', e.moments.mean[0], e.moments.mean[1]);
    u('glMomentCov', 'uniform3f', c[0][0], c[1][1], c[0][1]);
  }
  return unit0 + GLINT_TEXTURES.length;
}

export const GLINTS_HEAD = 'precision highp sampler2DArray;\nprecision highp isampler2DArray;\n#define GLINTS\n';

// the glints mode's program: the viewer shader with GLINTS defined, the glints GLSL before it
// and shaders/glints.frag.glsl (shadeGlints) after it
export function glintsProgram(gl, compile, head, vert, snippets, frag, glintsGlsl, glintsFrag) {
  const prog = gl.createProgram();
  gl.attachShader(prog, compile(gl, gl.VERTEX_SHADER, head + vert));
  gl.attachShader(prog, compile(gl, gl.FRAGMENT_SHADER,
    [head + GLINTS_HEAD, glintsGlsl, ...snippets, frag, glintsFrag].join('\n')));
  gl.linkProgram(prog);
  if (!gl.getProgramParameter(prog, gl.LINK_STATUS)) throw new Error('link (glints): ' + gl.getProgramInfoLog(prog));
  const uniforms = {};
  const n = gl.getProgramParameter(prog, gl.ACTIVE_UNIFORMS);
  for (let i = 0; i < n; ++i) {
    const info = gl.getActiveUniform(prog, i);
    uniforms[info.name.replace(/\[0\]$/, '')] = gl.getUniformLocation(prog, info.name);
  }
  return {prog, uniforms};
}

// -- the viewer's glints mode ------------------------------------------------------------------

export const GLINT_METHODS = ['glints', 'glints-smooth'];

async function text(url) {
  const r = await fetch(url);
  if (!r.ok) throw new Error(`${url}: HTTP ${r.status}`);
  return r.text();
}

// compile the glints program and load the first map (f32); viewer.glints holds the state
export async function loadGlintMode(viewer, base, compile, head, vert, snippets, frag, methods) {
  const gl = viewer.gl, g = viewer.manifest.glints;
  const [glsl, gfrag] = await Promise.all([text(base + g.glsl), text('shaders/glints.frag.glsl')]);
  const ids = `#define METHOD_GLINTS ${methods.indexOf('glints')}\n` +
    `#define METHOD_GLINTS_SMOOTH ${methods.indexOf('glints-smooth')}\n`;
  const state = glintsProgram(gl, compile, head, vert, snippets, frag, ids + glsl, gfrag);
  state.base = base;
  state.maps = {};
  state.kind = Object.keys(g.maps)[0];
  state.codes = 'f32';
  await ensureGlintMap(viewer, state, state.kind, state.codes);
  return state;
}

// load (once) the textures of map `kind` in code variant `codes`
export async function ensureGlintMap(viewer, state, kind, codes) {
  const entry = (viewer.manifest.glints.maps[kind] || {})[codes];
  if (!entry) throw new Error(`glints map ${kind} (${codes}) is not in this export`);
  const key = `${kind}/${codes}`;
  if (!state.maps[key]) state.maps[key] = await fetchGlints(viewer.gl, state.base, entry);
  return state.maps[key];
}

export async function selectGlintMap(viewer, kind, codes = 'f32') {
  const s = viewer.glints;
  await ensureGlintMap(viewer, s, kind, codes);
  s.kind = kind;
  s.codes = codes;
}

export function bindGlintMode(viewer, unit0) {
  const s = viewer.glints;
  return bindGlints(viewer.gl, s.maps[`${s.kind}/${s.codes}`], (n, fn, ...a) => viewer._u(n, fn, ...a), unit0);
}
