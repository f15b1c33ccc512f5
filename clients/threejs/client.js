// A GGX plane under one RectAreaLight, rendered by three.js's WebGLRenderer into a float render
// target (no tone mapping, linear output) and read back as float32 radiance.
//
// window.threejsClient.render(opts) -> base64 of a Float32Array (height x width x 4, row 0 at
// the bottom, as readPixels returns it). opts:
//   width, height                  render target size in pixels
//   camera  {origin, target, up, fov}        fov: vertical, degrees
//   plane   {size: [sx, sz]}                 centred at the origin, normal +y, tangent +x
//   light   {center, target, width, height, radiance}
//           RectAreaLight: lookAt(target) points its emitting side (local -z) at `target`
//   roughness                      MeshStandardMaterial.roughness (perceptual: alpha = r^2)
//   f0      [r, g, b]              linear colour with metalness 1: F0 of the LTC Fresnel
//   tables  'stock' | 'prefilter'  three's RectAreaLightTexturesLib or the exported module
//                                  at ./tables/PrefilterLTCTexturesLib.js
//   horizon 'sphere' | 'clip'      three's shader as shipped (LTC_ClippedSphereFormFactor: the
//                                  polygon's vector form factor treated as a sphere's) or the
//                                  polygon clipped at the horizon, as Heitz et al.'s reference
//                                  code does (ClipQuadToHorizon), everything else unchanged
import * as THREE from 'three';
import { RectAreaLightUniformsLib } from 'three/addons/lights/RectAreaLightUniformsLib.js';

const canvas = document.createElement('canvas');
document.body.appendChild(canvas);
const renderer = new THREE.WebGLRenderer({ canvas, antialias: false });
renderer.toneMapping = THREE.NoToneMapping;
renderer.setPixelRatio(1);

RectAreaLightUniformsLib.init();
const stock = {};
for (const k of ['LTC_FLOAT_1', 'LTC_FLOAT_2', 'LTC_HALF_1', 'LTC_HALF_2']) {
  stock[k] = THREE.UniformsLib[k];
}

// The transformed polygon clipped to z >= 0 (Sutherland-Hodgman: a convex quad keeps at most 5
// corners), then integrated edge by edge with three's own LTC_EdgeVectorFormFactor.
const CLIP_GLSL = `
float LTC_ClippedPolygonFormFactor( const in vec3 c[ 4 ] ) {
	vec3 p[ 5 ];
	int n = 0;
	for ( int i = 0; i < 4; i ++ ) {
		vec3 a = c[ i ];
		vec3 b = c[ ( i + 1 ) % 4 ];
		if ( a.z >= 0.0 && n < 5 ) { p[ n ] = a; n ++; }
		if ( ( a.z >= 0.0 ) != ( b.z >= 0.0 ) && n < 5 ) {
			p[ n ] = normalize( mix( a, b, a.z / ( a.z - b.z ) ) );
			n ++;
		}
	}
	float s = 0.0;
	for ( int i = 0; i < 5; i ++ ) {
		if ( i >= n ) break;
		s += LTC_EdgeVectorFormFactor( p[ i ], p[ ( i + 1 ) % n ] ).z;
	}
	return max( s, 0.0 );
}
`;

function physicalChunk(horizon) {
  const chunk = THREE.ShaderChunk.lights_physical_pars_fragment;
  if (horizon === 'sphere') return chunk;
  if (horizon !== 'clip') throw new Error(`horizon: expected 'sphere' or 'clip', got ${horizon}`);
  const evaluate = 'vec3 LTC_Evaluate(';
  const sphere = 'float result = LTC_ClippedSphereFormFactor( vectorFormFactor );';
  if (!chunk.includes(evaluate) || !chunk.includes(sphere)) {
    throw new Error('horizon: three\'s LTC_Evaluate has changed; cannot patch it');
  }
  return chunk.replace(evaluate, CLIP_GLSL + evaluate)
    .replace(sphere, 'float result = LTC_ClippedPolygonFormFactor( coords );');
}

async function tables(name) {
  if (name === 'stock') return stock;
  if (name !== 'prefilter') throw new Error(`tables: expected 'stock' or 'prefilter', got ${name}`);
  const { PrefilterLTCTexturesLib } = await import('./tables/PrefilterLTCTexturesLib.js');
  return PrefilterLTCTexturesLib.init();
}

function toBase64(f32) {
  const bytes = new Uint8Array(f32.buffer);
  let s = '';
  for (let i = 0; i < bytes.length; i += 0x8000) {
    s += String.fromCharCode.apply(null, bytes.subarray(i, i + 0x8000));
  }
  return btoa(s);
}

async function render(opts) {
  const ltc = await tables(opts.tables);
  // WebGLLights picks the float pair when OES_texture_float_linear exists, the half pair
  // otherwise; a new material takes the textures up when its program is built.
  for (const k of ['LTC_FLOAT_1', 'LTC_FLOAT_2', 'LTC_HALF_1', 'LTC_HALF_2']) {
    THREE.UniformsLib[k] = ltc[k];
  }
  const { width, height } = opts;
  const scene = new THREE.Scene();

  const c = opts.camera;
  const camera = new THREE.PerspectiveCamera(c.fov, width / height, 0.01, 100);
  camera.up.fromArray(c.up);
  camera.position.fromArray(c.origin);
  camera.lookAt(new THREE.Vector3().fromArray(c.target));

  const material = new THREE.MeshStandardMaterial({ roughness: opts.roughness, metalness: 1 });
  material.color.setRGB(...opts.f0, THREE.LinearSRGBColorSpace);
  const horizon = opts.horizon || 'sphere';
  const chunk = physicalChunk(horizon);
  material.onBeforeCompile = (shader) => {
    shader.fragmentShader = shader.fragmentShader.replace(
      '#include <lights_physical_pars_fragment>', chunk);
  };
  material.customProgramCacheKey = () => horizon;
  const plane = new THREE.Mesh(new THREE.PlaneGeometry(opts.plane.size[0], opts.plane.size[1]),
                               material);
  plane.rotation.x = -Math.PI / 2;  // PlaneGeometry's normal +z -> +y; its x stays +x
  scene.add(plane);

  const l = opts.light;
  const light = new THREE.RectAreaLight(0xffffff, l.radiance, l.width, l.height);
  light.position.fromArray(l.center);
  light.lookAt(new THREE.Vector3().fromArray(l.target));
  scene.add(light);

  const target = new THREE.WebGLRenderTarget(width, height, {
    type: THREE.FloatType, format: THREE.RGBAFormat, minFilter: THREE.NearestFilter,
    magFilter: THREE.NearestFilter, depthBuffer: true });
  renderer.setSize(width, height, false);
  renderer.setClearColor(0x000000, 0);
  renderer.setRenderTarget(target);
  renderer.render(scene, camera);
  const px = new Float32Array(width * height * 4);
  renderer.readRenderTargetPixels(target, 0, 0, width, height, px);
  renderer.setRenderTarget(null);
  target.dispose();
  material.dispose();
  plane.geometry.dispose();
  const gl = renderer.getContext();
  return { pixels: toBase64(px), revision: THREE.REVISION,
           floatLinear: gl.getExtension('OES_texture_float_linear') !== null };
}

window.threejsClient = { ready: Promise.resolve(), render, revision: THREE.REVISION };
