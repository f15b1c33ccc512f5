// Page wiring: controls, orbit camera, FPS counter, and `window.prefilterViewer` for tests.
import {METHODS, Viewer, toBase64} from './viewer.js';
import {GLINT_CODES, selectGlintMap} from './glints.js';

const $ = (id) => document.getElementById(id);
const canvas = $('canvas');
let viewer = null, dirty = true;

function orbit(v, dPhi, dTheta, zoom) {
  const c = v.camera, t = c.target;
  const d = [0, 1, 2].map(i => c.origin[i] - t[i]);
  let r = Math.hypot(...d), theta = Math.acos(d[1] / r), phi = Math.atan2(d[0], d[2]);
  phi += dPhi; theta = Math.min(Math.max(theta + dTheta, 0.05), Math.PI - 0.05); r *= zoom;
  c.origin = [t[0] + r * Math.sin(theta) * Math.sin(phi), t[1] + r * Math.cos(theta),
              t[2] + r * Math.sin(theta) * Math.cos(phi)];
}

function bindControls(v) {
  const P = v.params;
  for (const m of METHODS) if (v.glints || !m.startsWith('glints')) $('method').add(new Option(m, m));
  for (const m of v.mapNames()) $('map').add(new Option(m, m));
  const update = () => {
    P.methodLeft = $('method').value;
    const glints = P.methodLeft.startsWith('glints');
    P.methodRight = $('split').checked ? (glints ? 'glints-smooth' : 'ltc') : P.methodLeft;
    P.split = $('split').checked ? 0.5 : -1;
    v.precision = $('precision').value;
    P.map = $('map').value;
    P.lightOffset = [+$('light-x').value, +$('light-y').value, 0];
    P.lightScale = +$('light-size').value;
    P.exposure = Math.pow(2, +$('exposure').value);
    dirty = true;
  };
  const rough = () => {
    P.roughness = +$('roughness').value;
    P.anisotropy = +$('anisotropy').value;
    $('roughness-v').textContent = P.roughness.toFixed(2);
    $('anisotropy-v').textContent = P.anisotropy.toFixed(2);
    dirty = true;
  };
  for (const id of ['method', 'split', 'precision', 'map', 'light-x', 'light-y', 'light-size', 'exposure'])
    $(id).addEventListener('input', update);
  for (const id of ['roughness', 'anisotropy']) $(id).addEventListener('input', rough);
  if (v.glints) {  // glint map and code variant: loaded on first choice
    for (const k of Object.keys(v.manifest.glints.maps)) $('glint-map').add(new Option(k, k));
    for (const c of GLINT_CODES) $('glint-codes').add(new Option(c, c));
    const pick = () => selectGlintMap(v, $('glint-map').value, $('glint-codes').value)
      .then(() => { dirty = true; }, e => { $('error').textContent = String(e.message || e); });
    for (const id of ['glint-map', 'glint-codes']) $(id).addEventListener('input', pick);
  }
  update();
  let drag = null;
  canvas.addEventListener('pointerdown', e => { drag = [e.clientX, e.clientY]; canvas.setPointerCapture(e.pointerId); });
  canvas.addEventListener('pointerup', () => { drag = null; });
  canvas.addEventListener('pointermove', e => {
    if (!drag) return;
    orbit(v, -(e.clientX - drag[0]) * 0.01, -(e.clientY - drag[1]) * 0.01, 1.0);
    drag = [e.clientX, e.clientY]; dirty = true;
  });
  canvas.addEventListener('wheel', e => { e.preventDefault(); orbit(v, 0, 0, Math.exp(e.deltaY * 0.001)); dirty = true; }, {passive: false});
}

let last = performance.now(), ema = 0;
function loop() {
  if (dirty && viewer) {
    viewer.draw();
    viewer.gl.finish();
    dirty = false;
    const now = performance.now(), dt = now - last;
    ema = ema ? 0.8 * ema + 0.2 * dt : dt;
    $('fps').textContent = `${(1000 / ema).toFixed(1)} fps (${ema.toFixed(1)} ms)`;
  }
  last = performance.now();
  requestAnimationFrame(loop);
}

window.prefilterViewer = {
  ready: (async () => {
    try {
      viewer = await new Viewer(canvas).load('data/');
      const c = viewer.camera;
      canvas.width = c.width; canvas.height = c.height;
      bindControls(viewer);
      requestAnimationFrame(loop);
      return true;
    } catch (e) {
      $('error').textContent = String(e && e.message || e);
      throw e;
    }
  })(),
  get viewer() { return viewer; },
  // linear radiance (base64 float32 RGBA, row 0 at the top) of `method` at the scene camera
  // (opts: method, precision, split = fraction of the width drawn by `method`, methodRight)
  renderLinear(opts = {}) {
    const P = viewer.params;
    const keep = {...P, precision: viewer.precision};
    const m = opts.method || 'ltc';
    Object.assign(P, {methodLeft: m, methodRight: opts.methodRight || m,
                      split: opts.split === undefined ? -1 : opts.split});
    viewer.precision = opts.precision || 'f32';
    const px = viewer.renderLinear(opts.width, opts.height);
    viewer.precision = keep.precision; delete keep.precision;
    Object.assign(P, keep);
    dirty = true;
    return toBase64(px);
  },
  frameTime(n = 10) { return viewer.frameTime(n); },
  // the glints mode's map and code variant (async: loads its textures on first use)
  selectGlints(kind, codes = 'f32') { return selectGlintMap(viewer, kind, codes); },
  redraw() { viewer.draw(); viewer.gl.finish(); dirty = false; },
  error() { return $('error').textContent; },
};
